"""The articulated observer's inputs read back from a drive bag (bagio/articulated_readings.py):
the readings in the observer's channel order and the speed held at each sample, and the estimate
from the bag = the estimate from the arrays written into it."""
import pathlib

import numpy as np
import pytest

from road_force_estimator.bagio.articulated_drive import write_articulated_drive_bag
from road_force_estimator.bagio.articulated_readings import read_articulated_readings
from road_force_estimator.bagio.errors import BagReadError
from road_force_estimator.core.articulated_setup import ArticulatedDrive
from road_force_estimator.core.parameters import load_params_file
from road_force_estimator.estimation.articulated import estimate_articulated
from road_force_estimator.estimation.models.articulated import channel_names

CONFIG = pathlib.Path(__file__).resolve().parents[2] / 'config' / 'tractor_semitrailer.yaml'


def test_readings_and_speed_come_back_in_the_observers_order(tmp_path):
    drive = ArticulatedDrive.from_values(load_params_file(CONFIG))
    names = channel_names(drive.model)
    rng = np.random.default_rng(3)
    m = 400
    stamps = 10**18 + np.arange(m, dtype=np.int64) * 1_000_000
    readings = 1e-3 * rng.standard_normal((m, len(names)))
    speed = 20.0 + 0.01 * np.arange(m)
    # the bag holds the joints in another order: the reader puts them back in the observer's
    order = np.r_[len(names) - 1, np.arange(len(names) - 1)]
    write_articulated_drive_bag(tmp_path / 'd', stamps_ns=stamps, speed_mps=speed,
                                readings=readings[:, order],
                                names=[names[k] for k in order], truth=None)
    got = read_articulated_readings(tmp_path / 'd', names)
    np.testing.assert_array_equal(got.stamps_ns, stamps)
    np.testing.assert_array_equal(got.readings, readings)
    np.testing.assert_array_equal(got.speed_mps, speed)
    est = estimate_articulated(drive.vehicle, got.stamps_ns, got.readings, got.speed_mps,
                               latency_s=0.01)
    ref = estimate_articulated(drive.vehicle, stamps, readings, speed, latency_s=0.01)
    np.testing.assert_array_equal(est.load_n, ref.load_n)
    assert est.load_n.shape == (10, m)


def test_a_bag_without_deflections_is_refused(tmp_path):
    with pytest.raises(BagReadError):
        read_articulated_readings(tmp_path, ('front_left_suspension',))
