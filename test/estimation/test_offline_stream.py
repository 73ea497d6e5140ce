"""The offline estimate piece by piece (estimation.offline_stream) against smooth() in one
piece, the chunked RTS pass (estimation.rts_pass) against the textbook sample loop, and the
static loads' rows in pieces (Reconstruction.restatic) against one call."""
import dataclasses
import os

import numpy as np
import pytest

from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.core.plant import simulate
from road_force_estimator.core.road import iso8608_profile
from road_force_estimator.core.sensors import SensorModel
from road_force_estimator.estimation import offline_stream
from road_force_estimator.estimation.smoothing.lti import Powers
from road_force_estimator.estimation.offline_stream import OfflineStream
from road_force_estimator.estimation.outputs import FIELD_COLUMNS, Column, field_columns
from road_force_estimator.estimation.reconstruction import Reconstruction
from road_force_estimator.estimation.smoothing.rts_pass import smoothed_chunks
from road_force_estimator.estimation.offline import smooth

VEHICLE = VehicleParameters()
BASE = 1_700_000_000 * 10**9
#: braking to a stop, standing, pulling away (t s, v m/s)
STOP = ([0.0, 2.0, 4.0, 6.0, 8.0, 10.0], [20.0, 20.0, 0.0, 0.0, 20.0, 20.0])


def _drive(vehicle, duration_s=10.0, profile=None, seed=3):
    road = iso8608_profile('C', 20.0 * duration_s + 60.0, seed=seed)
    d = simulate(vehicle, road, speed_mps=20.0, rate_hz=1000.0, duration_s=duration_s,
                 tire_envelope_m=0.25, **({'speed_profile': profile} if profile else {}))
    q, phi = SensorModel(deflection_std_m=1e-5, roll_std_rad=1e-4, seed=5).measure(
        d.q_m, d.roll_rad)
    t = np.asarray(d.t_s)
    v = np.interp(t, *profile) if profile else np.full(t.size, 20.0)
    q = np.array(q) + np.asarray(vehicle.deflection_offset_m)
    return BASE + np.round(t * 1e9).astype(np.int64), q, np.array(phi), v


def _defects(stamps, q):
    """Rejected samples (one before the first accepted), a duplicate stamp, a 0.4 s gap."""
    q, stamps = q.copy(), stamps.copy()
    q[[0, 100, 5000], 0] = np.nan
    stamps[200] = stamps[199]
    stamps[6000:] += 400_000_000
    return stamps, q


CASES = {
    'plain': (VEHICLE, None, False),
    'defects': (VEHICLE, None, True),
    'zero_load': (dataclasses.replace(VEHICLE, deflection_reference='zero_load'), None, True),
    'friction': (dataclasses.replace(VEHICLE, leaf_spring_friction_n=(1500.0, 1500.0)), None,
                 False),
    'stop': (VEHICLE, STOP, False),
}


@pytest.mark.parametrize('case', list(CASES))
@pytest.mark.parametrize('window', [None, (1500, 700)])
def test_pieces_equal_one_piece(case, window, monkeypatch):
    """Concatenated, the pieces are smooth()'s arrays bit for bit, whether the runs are in
    one piece or in windows (each window's rows handed out as it comes), with the inputs
    fed in blocks; the status too."""
    vehicle, profile, defects = CASES[case]
    stamps, q, phi, v = _drive(vehicle, 8.0 if case == 'friction' else 10.0, profile)
    if defects:
        stamps, q = _defects(stamps, q)
    observer = ObserverParameters()
    monkeypatch.setattr(offline_stream, 'PIECE_ROWS', 1000)
    whole = smooth(stamps, q, phi, v, vehicle, observer, window=window)
    stream = OfflineStream(vehicle, observer, window=window, capacity=100)
    for a in range(0, stamps.size, 777):
        assert stream.feed(stamps[a:a + 777], q[a:a + 777], phi[a:a + 777],
                           v[a:a + 777]) == []
    pieces = list(stream.finish())
    assert len(pieces) >= 8 and max(len(p.stamp_ns) for p in pieces) <= 1000
    for name in ['stamp_ns', 'valid', 'speed_contradicted', *FIELD_COLUMNS]:
        got = np.concatenate([getattr(p, name) for p in pieces])
        np.testing.assert_array_equal(got, getattr(whole, name), err_msg=name)
    assert dataclasses.asdict(stream.status) == dataclasses.asdict(whole.status)
    assert stream.last_stamp_ns == whole.status.last_stamp_ns
    np.testing.assert_array_equal(np.concatenate([p.fault_flags for p in pieces]),
                                  whole.fault_flags)      # (estimation.sensor_health)


@pytest.mark.parametrize('case', [*CASES, 'stuck'])
def test_spilled_pieces_equal_one_piece(case, tmp_path, monkeypatch):
    """With ``spill`` (estimate_bag in pieces) the readings wait in a file (read back a
    piece at a time by the smoother's statistics, windows and profile pass, the fault
    detector and the stuck-sensor rule; a run with a rejected sample inside or not in
    windows reads its rows whole) and a windowed run's profile pass keeps its columns in a
    file, its road built over pieces (OfflineRows.road_pieces, here pieces and the cubic's
    chunks of 1000 samples; a run with a stop reads them whole): the pieces are smooth()'s
    arrays bit for bit (a roll sensor stuck for 2 s too: its readings left out, its flags),
    and no file is left open."""
    from road_force_estimator.estimation import body_heave
    from road_force_estimator.estimation.models import front_axle_rows

    vehicle, profile, defects = CASES['plain' if case == 'stuck' else case]
    stamps, q, phi, v = _drive(vehicle, 8.0 if case == 'friction' else 10.0, profile)
    if defects:
        stamps, q = _defects(stamps, q)
    if case == 'stuck':
        phi[4000:6000] = phi[4000]
    monkeypatch.setattr(body_heave, 'CHUNK', 1000)
    calls = []
    road_pieces = front_axle_rows.OfflineRows.road_pieces

    def counted(self, *args, **kwargs):
        calls.append(args[1])
        return road_pieces(self, *args, **kwargs)

    monkeypatch.setattr(front_axle_rows.OfflineRows, 'road_pieces', counted)
    whole = smooth(stamps, q, phi, v, vehicle, window=(1500, 700))
    assert calls == []
    fds = len(os.listdir('/proc/self/fd'))
    stream = OfflineStream(vehicle, window=(1500, 700), capacity=100, spill=tmp_path)
    for a in range(0, stamps.size, 777):
        stream.feed(stamps[a:a + 777], q[a:a + 777], phi[a:a + 777], v[a:a + 777])
    pieces = list(stream.finish())
    assert calls and max(calls) > 2000                    # the windowed runs' roads
    assert len(os.listdir('/proc/self/fd')) == fds
    assert case != 'stuck' or sum(whole.status.stuck_samples.values()) > 1000
    for name in ['stamp_ns', 'valid', 'speed_contradicted', *FIELD_COLUMNS]:
        got = np.concatenate([getattr(p, name) for p in pieces])
        np.testing.assert_array_equal(got, getattr(whole, name), err_msg=name)
    assert dataclasses.asdict(stream.status) == dataclasses.asdict(whole.status)


def test_a_long_stretch_of_rejected_samples_comes_in_pieces(monkeypatch):
    """2500 rejected samples between two runs: pieces of at most PIECE_ROWS rows, holding
    the last accepted row, as smooth()."""
    stamps, q, phi, v = _drive(VEHICLE, 6.0)
    q[2000:4500] = np.nan
    monkeypatch.setattr(offline_stream, 'PIECE_ROWS', 600)
    whole = smooth(stamps, q, phi, v, VEHICLE)
    stream = OfflineStream(VEHICLE)
    stream.feed(stamps, q, phi, v)
    pieces = list(stream.finish())
    assert max(len(p.stamp_ns) for p in pieces) <= 600
    got = np.concatenate([p.wheel_load_n for p in pieces])
    np.testing.assert_array_equal(got, whole.wheel_load_n)
    np.testing.assert_array_equal(got[3000], whole.wheel_load_n[1999])


def test_a_differentiator_scheme_does_not_stream():
    with pytest.raises(ValueError, match='model smoother'):
        OfflineStream(VEHICLE, dataclasses.replace(ObserverParameters(),
                                                   discretization='implicit'))


def test_chunked_rts_pass_is_the_sample_loop():
    """smoothed_chunks (forward states kept per chunk, recomputed backwards) against the
    steady-state filter and the adjoint-form RTS smoother written out sample by sample, on
    two stretches with their own matrices and chunks that do not divide them."""
    rng = np.random.default_rng(4)
    nx, ny, m = 4, 2, 1000
    segs, mats = [(0, 430, None), (430, m, None)], []
    for _ in segs:
        a = np.diag(rng.uniform(0.5, 0.9, nx)) + 0.02 * rng.standard_normal((nx, nx))
        c = rng.standard_normal((ny, nx))
        k = 0.02 * rng.standard_normal((nx, ny))
        assert max(abs(np.linalg.eigvals((np.eye(nx) - k @ c) @ a))) < 0.97   # stable
        p_post = np.eye(nx) + 0.1 * np.ones((nx, nx))
        s_inv = np.linalg.inv(np.eye(ny) * 2.0 + 0.1)
        mats.append(dict(a=a, c=c, k=k, p=p_post, s_inv=s_inv))
    y = rng.standard_normal((m, ny))
    x0 = rng.standard_normal(nx)
    packed = [(Powers((np.eye(nx) - d['k'] @ d['c']) @ d['a']), d['k'].T, (d['c'] @ d['a']).T,
               Powers((d['a'] @ (np.eye(nx) - d['k'] @ d['c'])).T), (d['c'].T @ d['s_inv']).T,
               (d['p'] @ d['a'].T).T, None, None) for d in mats]
    got = np.empty((m, nx))
    for k0, k1, xs in smoothed_chunks(segs, packed, y, x0, 97):
        if k0 >= 0:
            got[k0:k1] = xs
    # the textbook loop: forwards, stretch j's matrices for the steps into its samples
    which = np.searchsorted([s for s, _, _ in segs], np.arange(m), side='right') - 1
    xf, nu = np.empty((m, nx)), np.zeros((m, ny))
    xf[0] = x0
    for i in range(1, m):
        d = mats[which[i]]
        xp = d['a'] @ xf[i - 1]
        nu[i] = y[i] - d['c'] @ xp
        xf[i] = xp + d['k'] @ nu[i]
    # backwards, row k - 1 (and the lam_k it takes) with row k - 1's stretch
    want, lam = xf.copy(), np.zeros(nx)
    for i in range(m - 1, 0, -1):
        d = mats[which[i - 1]]
        lam = d['c'].T @ d['s_inv'] @ nu[i] + (
            (np.eye(nx) - d['k'] @ d['c']).T @ (d['a'].T @ lam) if i < m - 1 else 0.0)
        want[i - 1] = xf[i - 1] + d['p'] @ (d['a'].T @ lam)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-10 * np.abs(want).max())


def test_restatic_in_pieces_is_one_call():
    """The static loads' rows of a run in pieces (t_prev given) equal one call's, the
    quasi-static LTR's low-pass going on across the pieces."""
    rng = np.random.default_rng(1)
    m = 3000
    t = np.arange(m) * 1e-3
    cols = field_columns(m)[1]
    cols[Column.DF1][:] = 3000.0 * rng.standard_normal(m)
    cols[Column.DF2][:] = 3000.0 * rng.standard_normal(m)
    static = 30000.0 + 500.0 * rng.standard_normal((m, 2)).cumsum(axis=0) / 50.0
    one = [c.copy() for c in cols]
    Reconstruction(VEHICLE).restatic(one, static, t)
    rec = Reconstruction(VEHICLE)
    parts = [c.copy() for c in cols]
    for a, b in ((0, 700), (700, 701), (701, 2000), (2000, m)):
        part = [c[a:b] for c in parts]
        rec.restatic(part, static[a:b], t[a:b], None if a == 0 else float(t[a - 1]))
    for j in (Column.FN1, Column.FN2, Column.LTR, Column.LTR_QUASI_STATIC, Column.LIFT_OFF1,
              Column.STATIC_LOAD2):
        np.testing.assert_array_equal(parts[j], one[j], err_msg=str(j))


def test_jittered_stamps_are_smoothed_on_their_clock(monkeypatch):
    """Stamps scattered +-50 us about a regular 1 kHz clock (the samples on it, as
    simulator.stamp_jitter makes them), one sample lost: the smoother runs on the clock's
    grid (never step by step, which keeps a transition per sample), and its loads are those
    of the regular stamps to within 1 % of their RMS (measured 0.2 %: the noise statistics
    see the stamps' steps); in windows too."""
    from road_force_estimator.estimation.smoothing import smoother as sm

    stamps, q, phi, v = _drive(VEHICLE, 8.0)
    rng = np.random.default_rng(9)
    jittered = stamps + np.round(rng.uniform(-5e4, 5e4, stamps.size)).astype(np.int64)
    keep = np.ones(stamps.size, bool)
    keep[3000] = False
    regular = smooth(stamps[keep], q[keep], phi[keep], v[keep], VEHICLE)

    def step_by_step(*args, **kwargs):
        raise AssertionError('smoothed step by step')

    monkeypatch.setattr(sm.Smoother, '_uneven', step_by_step)
    for window in (None, (1500, 700)):
        est = smooth(jittered[keep], q[keep], phi[keep], v[keep], VEHICLE, window=window)
        f, g = est.tire_force_dynamic_n, regular.tire_force_dynamic_n
        assert np.sqrt(np.mean((f - g) ** 2)) < 1e-2 * np.sqrt(np.mean(g ** 2))


def test_a_stop_in_windows_takes_the_gains_of_its_speed():
    """A run with a stop smoothed in windows takes the gains per stretch of speed in each
    window, as in one piece: the dynamic tire force within 1e-3 of its RMS of one piece's
    (with the run's one design in every window it was 1.6e-2)."""
    stamps, q, phi, v = _drive(VEHICLE, 10.0, STOP)
    one = smooth(stamps, q, phi, v, VEHICLE)
    win = smooth(stamps, q, phi, v, VEHICLE, window=(2500, 1200))
    f, g = win.tire_force_dynamic_n, one.tire_force_dynamic_n
    assert np.sqrt(np.mean((f - g) ** 2)) < 1e-3 * np.sqrt(np.mean(g ** 2))


def test_eager_windows_are_the_explicit_windows(monkeypatch):
    """``eager`` (estimate_bag's stream): every run longer than a window and its overlap goes
    in windows of window_samples's size, as smooth() with those windows given; smooth()
    by default keeps such a run whole (shorter than WINDOWED_RUNS windows' work)."""
    from road_force_estimator.estimation.smoothing import smoother as sm

    monkeypatch.setattr(sm, 'window_samples', lambda *a, **k: (1500, 700))
    stamps, q, phi, v = _drive(VEHICLE, 10.0)
    stream = OfflineStream(VEHICLE, eager=True)
    stream.feed(stamps, q, phi, v)
    got = np.concatenate([p.wheel_load_n for p in stream.finish()])
    np.testing.assert_array_equal(got, smooth(stamps, q, phi, v, VEHICLE,
                                              window=(1500, 700)).wheel_load_n)
    assert not np.array_equal(got, smooth(stamps, q, phi, v, VEHICLE).wheel_load_n)


def test_spilled_stream_does_not_hold_the_readings_or_the_road(tmp_path):
    """Spilled (estimate_bag in pieces), what the stream holds when its first piece comes
    out grows with the drive by < 40 bytes a sample (measured 34: its accepted indices,
    seconds and model speeds, 24, and the flags), without spill by > 60 (measured 90: with
    the readings, 24, the profile pass's road, 16, the distance and output stamps, 16).
    Traced (tracemalloc, current at the first piece, from before
    the inputs are fed) on 15 s and 30 s drives in windows of 1500 samples, after a first
    run (the modules' one-time caches)."""
    import tracemalloc

    drives = {s: _drive(VEHICLE, s) for s in (15.0, 30.0)}
    held: dict = {'spill': [], 'memory': []}
    for seconds in (15.0, 15.0, 30.0):
        stamps, q, phi, v = drives[seconds]
        for key in held:
            tracemalloc.start()
            try:
                stream = OfflineStream(VEHICLE, window=(1500, 700), capacity=stamps.size,
                                       spill=tmp_path if key == 'spill' else None)
                stream.feed(stamps, q, phi, v)
                pieces = stream.finish()
                first = next(pieces)
                held[key].append(tracemalloc.get_traced_memory()[0])
            finally:
                tracemalloc.stop()
            assert first.stamp_ns.size > 0
            pieces.close()
            del stream, pieces, first
    n = {s: drives[s][0].size for s in drives}
    growth = {k: (h[2] - h[1]) / (n[30.0] - n[15.0]) for k, h in held.items()}
    assert growth['spill'] < 40.0, growth
    assert growth['memory'] > 60.0, growth


def test_a_window_is_let_go_before_the_next_is_computed(tmp_path, monkeypatch):
    """A windowed run's previous window (its columns, ``field_columns`` of the window and its
    overlaps) is no longer held when the next window's columns are made (``smoothed_rows``'
    loop once held it, round 42: two windows' columns at a time on a 40-min drive). Traced
    (tracemalloc, current when each middle window's columns are made, the consumer keeping no
    piece), spilled, on a 20 s drive in windows of 1500 and 3000 samples (overlap 700): what
    is held grows with the window by less than half of what 1500 more rows of columns take
    (their own traced size: ~244 bytes a row; measured ~30 a row, ~270 with the old loop).
    After a first run (the modules' one-time caches)."""
    import statistics
    import tracemalloc

    from road_force_estimator.estimation.models import front_axle_rows

    stamps, q, phi, v = _drive(VEHICLE, 20.0)
    made = front_axle_rows.OfflineRows.field_columns
    held: dict = {}
    for window in (1500, 1500, 3000):
        at: list = []

        def columns(m, at=at):
            at.append((m, tracemalloc.get_traced_memory()[0]))
            return made(m)

        monkeypatch.setattr(front_axle_rows.OfflineRows, 'field_columns',
                            staticmethod(columns))
        tracemalloc.start()
        try:
            stream = OfflineStream(VEHICLE, window=(window, 700), capacity=stamps.size,
                                   spill=tmp_path)
            stream.feed(stamps, q, phi, v)
            n = 0
            for piece in stream.finish():
                n += piece.stamp_ns.size
                del piece             # (not held while the next window is computed)
        finally:
            tracemalloc.stop()
        assert n == stamps.size
        middle = [c for m, c in at if m == window + 2 * 700]      # the load pass's windows
        assert len(middle) >= 4, at
        held[window] = statistics.median(middle)
        del stream
    tracemalloc.start()
    try:
        c0 = tracemalloc.get_traced_memory()[0]
        one = field_columns(10_000)
        per_row = (tracemalloc.get_traced_memory()[0] - c0) / 10_000
    finally:
        tracemalloc.stop()
    del one
    assert held[3000] - held[1500] < 0.5 * 1500 * per_row, (held, per_row)
