"""tools.fleet_drives: drive discovery (ids, nesting, the output folder left out) and the
resume keys (every change of input bytes or settings changes them)."""
import pytest

from road_force_estimator.tools import fleet_drives
from road_force_estimator.tools.fleet_drives import FleetError, find_drives


def test_find_drives_ids_nesting_and_output_exclusion(tmp_path):
    def bag(path):
        path.mkdir(parents=True)
        (path / 'metadata.yaml').write_text('x: 1\n')
        (path / 'inner').mkdir()
        (path / 'inner' / 'metadata.yaml').write_text('x: 1\n')   # inside a bag: not a drive
    bag(tmp_path / 'in' / 'truck1' / 'mon')
    bag(tmp_path / 'in' / 'truck2' / 'tue')
    bag(tmp_path / 'in' / 'out' / 'drives' / 'old' / 'bag')         # the output folder
    bag(tmp_path / 'single')
    found = find_drives([tmp_path / 'in', tmp_path / 'single'], exclude=[tmp_path / 'in' / 'out'])
    assert [d.drive_id for d in found] == ['single', 'truck1/mon', 'truck2/tue']
    assert found[0].path == (tmp_path / 'single').resolve()
    with pytest.raises(FleetError, match='twice'):
        find_drives([tmp_path / 'single', tmp_path / 'single'])
    (tmp_path / 'empty').mkdir()
    with pytest.raises(FleetError, match='no bag folder'):
        find_drives([tmp_path / 'empty'])
    bag(tmp_path / 'in2' / 'a')
    bag(tmp_path / 'in3' / 'a' / 'b')          # id 'a/b' below id 'a': outputs would nest
    with pytest.raises(FleetError, match='nest'):
        find_drives([tmp_path / 'in2', tmp_path / 'in3'])


def _bag(path):
    path.mkdir(parents=True)
    (path / 'metadata.yaml').write_text('x: 1\n')


def test_the_search_stays_inside_its_input_and_names_the_links_it_does_not_follow(tmp_path):
    """Issue 28: a link to / walked the whole machine (/proc/<pid>/cwd included), a link to
    .. pulled in the drives beside the input."""
    _bag(tmp_path / 'beside' / 'other')           # outside the input: never a drive of it
    top = tmp_path / 'fleet'
    _bag(top / 'truck1' / 'mon')
    _bag(top / 'truck1' / 'tue')
    (top / 'root').symlink_to('/')
    (top / 'up').symlink_to('..')
    (top / 'again').symlink_to(top / 'truck1')    # inside: followed (the same drives once)
    linked = top / 'truck2' / 'wed'
    _bag(linked)
    (linked / 'data_0.mcap').symlink_to(tmp_path / 'beside' / 'x.mcap')   # a file out
    skipped = []
    found = find_drives([top], skipped=skipped)
    assert [d.drive_id for d in found] == ['truck1/mon', 'truck1/tue']
    assert all(fleet_drives._is_inside(d.path.resolve(), top.resolve()) for d in found)
    text = '\n'.join(skipped)
    assert f'{top}/root: a link out of {top} (to /): not followed' in text
    assert f'{top}/up: a link out of {top} (to {tmp_path}): not followed' in text
    assert f'{top}/truck2/wed: not a drive of {top}: data_0.mcap link out of it' in text
    assert len(skipped) == 3
    with pytest.raises(FleetError, match='data_0.mcap link out of the bag folder'):
        find_drives([linked])


def test_the_temporary_folders_of_unfinished_writes_are_no_drives(tmp_path):
    """Issue 28: a simulate_bag killed while writing left .<bag>.tmp-* with a bag inside,
    which the fleet took for a drive."""
    top = tmp_path / 'fleet'
    _bag(top / 'mon')
    _bag(top / '.tue.tmp-k2j3h4' / 'tue')
    skipped = []
    assert [d.drive_id for d in find_drives([top], skipped=skipped)] == ['mon']
    assert skipped == [f'{top}/.tue.tmp-k2j3h4: the temporary folder of an unfinished write '
                       '(not a drive)']


def test_input_hash_and_key_see_every_change(tmp_path):
    bag = tmp_path / 'bag'
    bag.mkdir()
    (bag / 'metadata.yaml').write_text('a: 1\n')
    (bag / 'bag_0.mcap').write_bytes(bytes(range(256)) * 10)
    h0 = fleet_drives.input_sha256(bag)
    assert fleet_drives.input_sha256(bag) == h0
    data = bytearray((bag / 'bag_0.mcap').read_bytes())
    data[1000] ^= 1
    (bag / 'bag_0.mcap').write_bytes(bytes(data))
    assert fleet_drives.input_sha256(bag) != h0
    s = {'mode': 'online', 'segment_length_m': 100.0, 'figures': True,
         'parameters': {'vehicle.sprung_mass': 5000.0}}
    k = fleet_drives.drive_key(h0, s)
    assert fleet_drives.drive_key(h0, dict(s)) == k
    for change in ({'mode': 'offline'}, {'segment_length_m': 160.9344}, {'figures': False},
                   {'parameters': {'vehicle.sprung_mass': 5001.0}}):
        assert fleet_drives.drive_key(h0, {**s, **change}) != k


def test_output_inside_a_bag_folder_is_not_part_of_its_input(tmp_path):
    """A fleet output folder inside a bag folder given directly (issue 16): neither a drive
    nor part of the drive's input hash, so the drive is not recomputed on every run."""
    bag = tmp_path / 'bag'
    bag.mkdir()
    (bag / 'metadata.yaml').write_text('a: 1\n')
    (bag / 'bag_0.mcap').write_bytes(bytes(range(256)) * 10)
    out = bag / 'out'
    found = find_drives([bag], exclude=[out])
    assert [(d.drive_id, d.path) for d in found] == [('bag', bag.resolve())]
    h0 = fleet_drives.input_sha256(bag, exclude=[out])
    (out / 'drives' / 'bag' / 'bag').mkdir(parents=True)
    (out / 'drives' / 'bag' / 'bag' / 'metadata.yaml').write_text('b: 2\n')
    (out / 'segments.csv').write_text('drive\n')
    assert fleet_drives.input_sha256(bag, exclude=[out]) == h0
    assert fleet_drives.input_sha256(bag) != h0                # without it: seen


def test_output_lock_refuses_or_waits(tmp_path):
    """One estimate_fleet run per output folder (issue 16): a second one refuses at once, or
    waits for the first with ``wait``."""
    import threading

    out = tmp_path / 'out'
    out.mkdir()
    waiting = threading.Event()
    got = []
    with fleet_drives.output_lock(out):
        with pytest.raises(FleetError, match='another estimate_fleet run'):
            with fleet_drives.output_lock(out):
                pass

        def second():
            with fleet_drives.output_lock(out, wait=True, on_wait=waiting.set):
                got.append('locked')

        thread = threading.Thread(target=second)
        thread.start()
        assert waiting.wait(60)
        assert got == []                                       # still waiting
    thread.join(60)
    assert got == ['locked']
    with fleet_drives.output_lock(out):                         # free again
        pass
