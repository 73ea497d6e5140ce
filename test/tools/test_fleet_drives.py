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
