"""estimate_bag online on an articulated drive with the whole vehicle's samples turned into
arrays in small chunks (``estimation.whole_vehicle.CHUNK_ROWS`` made 500: a 3 s drive at
1 kHz is 7 chunks; issue 32 "memory stays bounded"): the estimate bag, read by the mcap
library, holds the bits of the estimator stepped sample by sample on the inputs the mcap
library decodes from the drive bag (the node's numbers), the fused points too."""
from pathlib import Path
import subprocess
import sys

import numpy as np

from road_force_estimator.tools.estimate_bag import load_parameters, main as estimate_bag
from test_estimate_whole_vehicle import decoded, inputs, stamp

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / 'config' / 'tractor_semitrailer.yaml'
BIN = Path(sys.executable).parent


def test_online_in_small_chunks_is_the_estimator_sample_by_sample(tmp_path, monkeypatch):
    from road_force_estimator.estimation import whole_vehicle
    from road_force_estimator.estimation.whole_vehicle import WholeVehicleEstimator

    bag = tmp_path / 'drive'
    sim = subprocess.run([str(BIN / 'simulate_bag'), '--params-file', str(CONFIG), '--road',
                          'iso8608:C:seed=7', '--speed', '20', '--rate', '1000',
                          '--duration', '3', '--gnss-rate', '0', '--no-progress',
                          '--output', str(bag)], capture_output=True, text=True, timeout=300)
    assert sim.returncode == 0, sim.stderr
    monkeypatch.setattr(whole_vehicle, 'CHUNK_ROWS', 500)
    out = tmp_path / 'est'
    assert estimate_bag([str(bag), '--params-file', str(CONFIG), '--output', str(out),
                         '--mode', 'online', '--no-figures', '--no-progress']) == 0
    vehicle, observer = load_parameters(str(CONFIG))
    est = WholeVehicleEstimator(vehicle, observer)
    stamps, readings, speed = inputs(bag, est.channel_names)
    samples = []
    for s, row, v in zip(stamps.tolist(), readings, speed.tolist()):
        samples += est.step(s, row, v)
    samples += est.finish()
    assert len(samples) == stamps.size > 7 * 400
    topics = decoded(out / 'bag')
    rows = topics['/wheel_loads']
    np.testing.assert_array_equal([stamp(m) for _, m in rows], [s.stamp_ns for s in samples])
    np.testing.assert_array_equal([m.effort for _, m in rows], [s.load_n for s in samples])
    for u, unit in enumerate(('tractor', 'trailer', 'combination')):
        rows = topics[f'/load_transfer/{unit}']
        np.testing.assert_array_equal([m.vector.x for _, m in rows],
                                      [s.ltr[u] for s in samples])
        np.testing.assert_array_equal([m.vector.y for _, m in rows],
                                      [s.ltr_quasi_static[u] for s in samples])
    points = [p for s in samples for p in s.fused]
    assert len(points) > 10
    for side, word in enumerate(('left', 'right')):
        rows = topics[f'/road_profile/{word}']
        np.testing.assert_array_equal([m.point.z for _, m in rows],
                                      [s.road_m[side] for s in samples])
        rows = topics[f'/road_profile/fused/{word}']
        np.testing.assert_array_equal([stamp(m) for _, m in rows], [p[0] for p in points])
        np.testing.assert_array_equal([m.point.x for _, m in rows], [p[1] for p in points])
        np.testing.assert_array_equal([m.point.z for _, m in rows],
                                      [p[2 + side] for p in points])
