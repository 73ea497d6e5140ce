"""The online estimate block by block (estimation.stream_run) against estimate_batch."""
import dataclasses

import numpy as np
import pytest

from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.estimation import estimate_batch
from road_force_estimator.estimation.outputs import FIELD_COLUMNS
from road_force_estimator.estimation.stream_run import OnlineStream


def _inputs(n=3000, seed=2):
    rng = np.random.default_rng(seed)
    stamps = 10**9 + 10**6 * np.arange(n, dtype=np.int64)
    t = np.arange(n) * 1e-3
    q = np.column_stack([0.01 * np.sin(2 * np.pi * 1.3 * t), 0.01 * np.cos(2 * np.pi * t)])
    q = q + 1e-5 * rng.standard_normal(q.shape)
    roll = 1e-3 * np.sin(2 * np.pi * 0.7 * t)
    speed = np.full(n, 20.0)
    q[[5, 700, 701, 1999], 0] = np.nan                 # rejected samples
    stamps[1500] = stamps[1499]                         # a duplicate stamp
    stamps[2400:] += 3 * 10**9                          # a gap: a restart
    return stamps, q, roll, speed


@pytest.mark.parametrize('latency_s, block', [(0.0, 257), (0.01, 100), (0.01, 1), (0.0, 10**6)])
def test_pieces_equal_one_piece(latency_s, block):
    vehicle = VehicleParameters()
    observer = dataclasses.replace(ObserverParameters(), latency_s=latency_s)
    stamps, q, roll, speed = _inputs()
    q[:3, 0] = np.nan                                   # rejected before the first accepted
    whole = estimate_batch(stamps, q, roll, speed, vehicle, observer)
    stream = OnlineStream(vehicle, observer)
    pieces = []
    for a in range(0, stamps.size, block):
        b = a + block
        pieces += stream.feed(stamps[a:b], q[a:b], roll[a:b], speed[a:b])
    pieces += stream.finish()
    if block < 300:
        assert len(pieces) > 5
    for name in ['stamp_ns', 'valid', 'speed_contradicted', *FIELD_COLUMNS]:
        got = np.concatenate([getattr(p, name) for p in pieces])
        np.testing.assert_array_equal(got, getattr(whole, name), err_msg=name)
    assert dataclasses.asdict(stream.status) == dataclasses.asdict(whole.status)
