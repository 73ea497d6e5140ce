"""estimate_bag offline on an articulated drive in pieces (pipeline.plan's threshold lowered to
1): the whole vehicle's stage read in blocks into WholeVehicleOfflineStream, its pieces
spilled to files, its model fit per axle and fused profile from the spilled columns, the front
axle's stage in blocks beside it (pipeline.blocks with BlockJoin), against the same drive in
one block: every message of the estimate bag the same (topic, log time, bytes; read by the
mcap library), segments.csv, report.md (but its command line) and report.json the same, with
a gap, with the tractor IMU and with tanh friction whose v_f is fitted (the plant's 0.02, the
file's 0.01), the smoother's windows made small (the same in both runs);
every spilled file closed at the end and on a failure. And the spilled fit and fused profile
alone against fit_axles and fuse_roads on the whole arrays: the same bits."""
from contextlib import closing
import json
from pathlib import Path
import sys

import numpy as np
import pytest

from road_force_estimator.bagio import drive_blocks
from road_force_estimator.pipeline import plan
from road_force_estimator.tools.estimate_bag import main as estimate_bag

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_whole_vehicle_blocks import (  # noqa: E402  (the same drives, the same reader)
    CONFIG, assert_fails_out_of_space, in_pieces, same_messages, simulate)


def friction_params(folder: Path, v_f: float) -> Path:
    """The file's combination with 1.5 kN of tanh friction per spring of v_f ``v_f`` (m/s)."""
    text = CONFIG.read_text()
    for old, new in (('leaf_spring_friction: [0.0, 0.0]',
                      'leaf_spring_friction: [1500.0, 1500.0]'),
                     ('leaf_spring_friction_velocity: 0.01',
                      f'leaf_spring_friction_velocity: {v_f!r}')):
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    path = folder / f'friction_{v_f:g}.yaml'
    path.write_text(text)
    return path


@pytest.fixture(scope='module')
def drives(drives, tmp_path_factory):
    """The shared drives (conftest.py) and a friction drive: the plant's v_f 0.02, the
    file's 0.01 (v_f fitted offline, in both runs)."""
    root = tmp_path_factory.mktemp('friction')
    return {**drives, 'friction': (simulate(root / 'friction', friction_params(root, 0.02), 3.0),
                                   friction_params(root, 0.01))}


def run(bag: Path, params: Path, out: Path) -> None:
    assert estimate_bag([str(bag), '--params-file', str(params), '--output', str(out),
                         '--mode', 'offline', '--segment-length', '10', '--no-figures',
                         '--no-progress']) == 0


@pytest.fixture
def spills(monkeypatch):
    """Every spill column the whole vehicle's stage opened (core.spill.SpillColumn, from
    estimation/ and pipeline/whole_vehicle.py), to check they are closed."""
    from road_force_estimator.core import spill

    opened = []
    original = spill.SpillColumn.__init__

    def init(self, *args, **kwargs):
        original(self, *args, **kwargs)
        if sys._getframe(1).f_code.co_filename.endswith('whole_vehicle.py'):
            opened.append(self)

    monkeypatch.setattr(spill.SpillColumn, '__init__', init)
    return opened


@pytest.mark.parametrize('drive, block, sink', [('gap', 300, 257), ('imu', 1 << 16, 97),
                                                ('friction', 300, 257)])
def test_offline_in_pieces_the_outputs_are_one_blocks(drives, tmp_path, monkeypatch, spills,
                                                      drive, block, sink):
    """``block``: the samples the drive is read in; ``sink``: the spilled samples read back at
    a time. The smoother's windows 1000 samples with 0.3 s of overlap in both runs (a 3 s
    drive goes in windows)."""
    from road_force_estimator.core import iri_chunks
    from road_force_estimator.estimation import whole_vehicle as estimation

    monkeypatch.setattr(estimation, 'STREAM_WINDOW_SAMPLES', 1000)
    monkeypatch.setattr(estimation, 'STREAM_OVERLAP_S', 0.3)
    bag, params = drives[drive]
    run(bag, params, tmp_path / 'one')
    calls = in_pieces(monkeypatch, block, sink)
    monkeypatch.setattr(iri_chunks, 'CHUNK', 1000)     # the fused profile's IRI in chunks
    spills.clear()
    run(bag, params, tmp_path / 'str')
    assert len(calls) == 1 and calls[0].source.n > 2500    # in pieces, the samples spilled
    assert calls[0].source.meta.road_m is not None and calls[0].fused is not None
    assert len(spills) > 10 and all(c._file.closed for c in spills)
    one, streamed = tmp_path / 'one', tmp_path / 'str'
    assert sorted(p.name for p in streamed.iterdir()) == sorted(p.name for p in one.iterdir())
    a = same_messages(one / 'bag', streamed / 'bag')
    assert len(a['/wheel_loads']) > 2500 and len(a['/road_profile/fused/left']) > 1000
    assert (one / 'report' / 'segments.csv').read_text() == \
        (streamed / 'report' / 'segments.csv').read_text()
    md = [(tmp_path / d / 'report' / 'report.md').read_text().replace(str(tmp_path / d), '')
          for d in ('one', 'str')]
    assert md[0] == md[1]
    ja, jb = (json.loads((tmp_path / d / 'report' / 'report.json').read_text())
              for d in ('one', 'str'))
    ja['run']['command'] = jb['run']['command'] = ''
    assert ja == jb
    assert ja['whole_vehicle_estimate']['gaps'] == (1 if drive == 'gap' else 0)


def test_a_failure_in_pieces_closes_every_spill(drives, tmp_path, monkeypatch, spills, capsys):
    """A full disk offline in pieces (the 21st spilled write fails: after the whole
    vehicle's columns were opened): one line, exit 1, nothing in the output folder, every
    file the whole vehicle spilled closed (unnamed temporary files: nothing left behind to
    look complete)."""
    import errno

    from road_force_estimator.core import spill

    calls = []
    append = spill.SpillColumn.append

    def full(self, rows):                    # the disk full after 20 appends
        calls.append(self)
        if len(calls) > 20:
            raise OSError(errno.ENOSPC, 'No space left on device')
        append(self, rows)

    bag, params = drives['gap']
    monkeypatch.setattr(plan, 'STREAM_MIN_SAMPLES', 1)
    monkeypatch.setattr(drive_blocks, 'BLOCK_SAMPLES', 300)
    monkeypatch.setattr(spill.SpillColumn, 'append', full)
    assert_fails_out_of_space(bag, params, tmp_path / 'o', 'offline', capsys)
    assert len(spills) > 10 and all(c._file.closed for c in spills)


@pytest.fixture(scope='module')
def offline_estimate():
    """8 s of class C at 20 m/s, 1 kHz, 10 um (the plant of core.articulated_plant) estimated
    offline in one block: (vehicle, its WholeVehicleArrays)."""
    from road_force_estimator.core.articulated_plant import simulate_articulated
    from road_force_estimator.core.articulated_setup import ArticulatedDrive
    from road_force_estimator.core.parameters import load_params_file
    from road_force_estimator.core.road import iso8608_profile
    from road_force_estimator.estimation.models.articulated import channel_names
    from road_force_estimator.estimation.whole_vehicle import estimate_whole_vehicle

    base = load_params_file(CONFIG)
    base.update({'simulator.noise.deflection': 1e-5, 'simulator.noise.roll': 1e-5 / 0.45,
                 'simulator.duration': 8.0})
    d = ArticulatedDrive.from_values(base)
    tr = simulate_articulated(d.vehicle, iso8608_profile('C', d.road_length_m, seed=11),
                              speed_mps=20.0, rate_hz=1000.0, duration_s=8.0,
                              tire_envelope_m=0.25, model=d.model)
    y = d.sensors(channel_names(d.model)).measure(tr)
    stamps = np.round(tr.t_s * 1e9).astype(np.int64)
    return d.vehicle, estimate_whole_vehicle(d.vehicle, stamps, y, 20.0, offline=True)


def test_the_spilled_fit_and_fused_profile_are_the_whole_arrays(offline_estimate, tmp_path,
                                                                  monkeypatch):
    """The model fit per axle and the fused profile of an estimate spilled in pieces of 997
    samples, read back 301 at a time: fit_axles' verdict (estimate_whole_vehicle's) and
    fused_profile on the whole arrays (fuse_roads), bit for bit."""
    from road_force_estimator.estimation.whole_vehicle import take_rows
    from road_force_estimator.pipeline import whole_vehicle

    vehicle, wv = offline_estimate
    assert wv.axle_fit is not None and wv.axle_fit.length_m > 100.0
    monkeypatch.setattr(whole_vehicle, 'SINK_ROWS', 301)
    spill = whole_vehicle.SpilledEstimate(tmp_path)
    n = len(wv.stamps_ns)
    for lo in range(0, n, 997):
        spill.add(take_rows(wv, lo, min(lo + 997, n)))
    spill.meta = take_rows(wv, 0, 0)
    try:
        fit = whole_vehicle.spilled_fit(spill, vehicle)
        for name in ('misfit', 'spread'):
            np.testing.assert_array_equal(getattr(fit, name), getattr(wv.axle_fit, name))
        assert (fit.axles, fit.sensors, fit.length_m) == \
            (wv.axle_fit.axles, wv.axle_fit.sensors, wv.axle_fit.length_m)
        spilled, one = (whole_vehicle.fused_profile(s, vehicle) for s in (spill, wv))
        got = spilled.read(0, spilled.n)
        spilled.close()
        assert one.distance_m.size > 6000 and spilled.n == one.distance_m.size
        for name in ('stamps_ns', 'distance_m', 'left_m', 'right_m'):
            np.testing.assert_array_equal(getattr(got, name), getattr(one, name))
        assert (got.axles, got.half_track_m) == (one.axles, one.half_track_m)
    finally:
        spill.close()


def test_between_the_stages_the_estimate_is_not_held(tmp_path):
    """Offline in pieces, what the whole vehicle's stage leaves held for the front axle's
    stage and the sinks (its SpilledEstimate, the fused profile, SpilledFused: both in
    files) grows with the drive by less than 40 bytes a sample (measured 27, 43 with the
    fused profile's four numbers a sample held; the rest not traced further), not by the
    estimate's 357 (its per-sample fields, the yardstick: their own bytes). Traced
    (tracemalloc) on 3 s and 6 s drives after a first run (the modules' one-time caches);
    the stage's own peak, its inputs held whole, still grows (docs/articulated.md)."""
    import tracemalloc

    from road_force_estimator.estimation.whole_vehicle import ROW_FIELDS
    from road_force_estimator.pipeline import whole_vehicle
    from road_force_estimator.tools.estimate_bag import load_parameters

    vehicle, observer = load_parameters(str(CONFIG))
    held, samples, per_sample = [], [], None
    bags = {s: simulate(tmp_path / f'd{s:g}', CONFIG, s) for s in (9.0, 14.0)}
    for seconds in (9.0, 9.0, 14.0):          # the first: the modules' one-time caches
        bag = bags[seconds]
        tracemalloc.start()
        spill = whole_vehicle.SpilledEstimate(tmp_path)
        try:
            whole_vehicle.estimate(bag, vehicle, observer, 'offline', windows=True,
                                   spill=spill)
            fused = whole_vehicle.fused_profile(spill, vehicle)
            held.append(tracemalloc.get_traced_memory()[0])
            tracemalloc.stop()
            samples.append(spill.n)
            if per_sample is None:           # the yardstick: the estimate's own bytes
                rows = spill.rows(0, spill.n)
                per_sample = sum(getattr(rows, f).nbytes for f in ROW_FIELDS
                                 if getattr(rows, f) is not None) / spill.n
        finally:
            tracemalloc.stop()
            spill.close()
        assert fused is not None and fused.n > 0.5 * spill.n
    growth = (held[2] - held[1]) / (samples[2] - samples[1])
    assert per_sample > 300.0
    assert growth < 40.0, (growth, per_sample)        # measured 27


def test_the_fit_and_fused_passes_do_not_hold_the_samples(tmp_path, monkeypatch):
    """The model fit per axle (spilled_fit) and the fused profile (fused_profile of the
    spilled estimate) read the spilled columns in pieces (here 500 samples): their traced
    peaks grow with the drive by less than the samples' columns they read (the fit: stamps,
    distance, 10 roads, loads, ~100 bytes a sample; read whole, as before, 200 and 333
    bytes a sample measured here). What still grows: the fit's arrays on the 5 cm grid
    (the band-passed roads' analytic signals are FFTs over the whole grid: not in pieces
    with the same bits), the fused profile's four numbers a point (32 bytes). Traced on 9 s
    and 14 s drives (the fit judges 128 m and 228 m) after a first run (the modules'
    one-time caches)."""
    import tracemalloc

    from road_force_estimator.pipeline import whole_vehicle
    from road_force_estimator.tools.estimate_bag import load_parameters

    monkeypatch.setattr(whole_vehicle, 'SINK_ROWS', 500)
    vehicle, observer = load_parameters(str(CONFIG))
    peaks: dict = {'fit': [], 'fused': []}
    samples = []
    bags = {s: simulate(tmp_path / f'd{s:g}', CONFIG, s) for s in (9.0, 14.0)}
    for seconds in (9.0, 9.0, 14.0):
        spill = whole_vehicle.SpilledEstimate(tmp_path)
        try:
            whole_vehicle.estimate(bags[seconds], vehicle, observer, 'offline', windows=True,
                                   spill=spill)
            samples.append(spill.n)
            for name, f in (('fit', whole_vehicle.spilled_fit),
                            ('fused', whole_vehicle.fused_profile)):
                tracemalloc.start()
                try:
                    got = f(spill, vehicle)
                    peaks[name].append(tracemalloc.get_traced_memory()[1])
                finally:
                    tracemalloc.stop()
                assert got is not None and (name == 'fused' or got.measured)
        finally:
            spill.close()
    growth = {k: (p[2] - p[1]) / (samples[2] - samples[1]) for k, p in peaks.items()}
    assert growth['fit'] < 80.0, growth          # measured 64 (the grid's arrays)
    assert growth['fused'] < 16.0, growth        # measured 2


@pytest.mark.parametrize('rows', [1, 7, 4099, None])
def test_the_report_reads_the_spilled_fused_profile_in_pieces(offline_estimate, tmp_path,
                                                               monkeypatch, rows):
    """The whole vehicle's report section (report.md, report.json: the fused profile's
    points, length and IRI) from the fused profile's arrays and from the same profile
    spilled (SpilledFused) and read ``rows`` points at a time (None: SUM_ROWS, one piece;
    the IRI's chunks 1000 intervals): the same bytes, the IRI finite."""
    from road_force_estimator.core import iri_chunks
    from road_force_estimator.pipeline import whole_vehicle
    from road_force_estimator.report import whole_vehicle as report

    vehicle, wv = offline_estimate
    one = whole_vehicle.fused_profile(wv, vehicle)
    texts = []
    with closing(whole_vehicle.SpilledFused(tmp_path, one.axles, one.half_track_m)) as spilled:
        step = 1000
        for lo in range(0, one.distance_m.size, step):
            spilled.append(*(getattr(one, f)[lo:lo + step] for f, _ in spilled.FIELDS))
        for name, fused in (('whole', one), ('pieces', spilled)):
            if name == 'pieces':
                monkeypatch.setattr(iri_chunks, 'CHUNK', 1000)
                monkeypatch.setattr(report, 'SUM_ROWS', rows or report.SUM_ROWS)
            folder = tmp_path / name
            folder.mkdir()
            (folder / 'report.md').write_text('# Report\n')
            (folder / 'report.json').write_text('{}\n')
            report.append_estimate(folder, wv, fused=fused)
            texts.append([(folder / f).read_bytes() for f in ('report.md', 'report.json')])
    assert texts[0] == texts[1]
    fp = json.loads(texts[0][1])['whole_vehicle_estimate']['fused_profile']
    assert fp['points'] == one.distance_m.size > 6000
    assert all(isinstance(v, float) and 0.0 < v < 50.0 for v in fp['iri_m_per_km'])


def test_the_reports_fused_iri_does_not_hold_the_profile(tmp_path, monkeypatch):
    """The report's IRI of a spilled fused profile (read 16384 points at a time, the IRI's
    chunks 32768 intervals): its traced peak does not grow with the profile (under 4 bytes
    a point between 150 000 and 300 000 points; measured -3); the profile read whole
    (as before): 127 bytes a point measured, the yardstick (over 64). Profiles of an uneven
    drive with stops (resampled as core.iri does); a first run for the one-time caches."""
    import gc
    import tracemalloc

    from road_force_estimator.core import iri_chunks
    from road_force_estimator.pipeline.whole_vehicle import SpilledFused
    from road_force_estimator.report.whole_vehicle import _fused_iri

    monkeypatch.setattr(iri_chunks, 'CHUNK', 1 << 15)
    rng = np.random.default_rng(3)
    step = rng.uniform(0.015, 0.025, 300_000)
    step[rng.random(step.size) < 0.01] = 0.0
    x = np.cumsum(step)
    z = 1e-4 * np.cumsum(rng.standard_normal((step.size, 2)), axis=0)
    peaks: dict = {'pieces': [], 'whole': []}
    sizes = (150_000, 150_000, 300_000)
    for n in sizes:
        with closing(SpilledFused(tmp_path, 5, 0.9)) as f:
            f.append(np.arange(n, dtype=np.int64), x[:n], z[:n, 0], z[:n, 1])
            for how in ('pieces', 'whole'):
                gc.collect()
                tracemalloc.start()
                try:
                    got = _fused_iri(f if how == 'pieces' else f.read(0, n), rows=1 << 14)
                    peaks[how].append(tracemalloc.get_traced_memory()[1])
                finally:
                    tracemalloc.stop()
                assert got['points'] == n and np.isfinite(got['iri_m_per_km']).all()
    growth = {k: (p[2] - p[1]) / (sizes[2] - sizes[1]) for k, p in peaks.items()}
    assert growth['whole'] > 64.0, growth        # measured 127
    assert growth['pieces'] < 4.0, growth       # measured -3 (where the chunks fall)
