"""The odometer error and the fusion through the commands: simulate_bag's
simulator.speed_scale_error and simulator.gnss.noise, estimate_bag's offline mode with
observer.distance_source = gnss.

References: the true speed and distance of a constant-speed drive (v, v t), the same drive
simulated without the options (the same seed: the noise is the only difference), the true
scale 1 / (1 + e).
"""
import csv
import json
from pathlib import Path

import numpy as np
import pytest

from road_force_estimator import bagio
from road_force_estimator.core.gnss import local_east_north
from road_force_estimator.tools.estimate_bag import main as estimate_main
from road_force_estimator.tools.simulate_bag import main as simulate_main

ERROR = 0.015


def simulate(folder: Path, *extra) -> Path:
    assert simulate_main(['--road', 'iso8608:C:seed=2', '--speed', '20', '--rate', '200',
                          '--duration', '60', '--output', str(folder), '--no-progress',
                          *map(str, extra)]) == 0
    return folder


@pytest.fixture(scope='module')
def drives(tmp_path_factory):
    """60 s (1.2 km) at 20 m/s, 200 Hz, GNSS 10 Hz: as it is, and with the speed read 1.5 %
    high and 2.5 m of fix noise."""
    root = tmp_path_factory.mktemp('odo')
    return (simulate(root / 'plain'),
            simulate(root / 'odo', '-p', f'simulator.speed_scale_error:={ERROR}',
                     '-p', 'simulator.gnss.noise:=2.5'))


def test_twist_reads_high_and_fixes_are_noisy_the_rest_unchanged(drives):
    plain, odo = (bagio.read_drive_bag(p) for p in drives)
    np.testing.assert_array_equal(plain.twist_speed_mps, 20.0)
    np.testing.assert_allclose(odo.twist_speed_mps, 20.0 * (1.0 + ERROR), rtol=1e-15)
    np.testing.assert_array_equal(odo.q_m, plain.q_m)
    np.testing.assert_array_equal(odo.truth.distance_m, plain.truth.distance_m)
    np.testing.assert_array_equal(odo.fixes.stamps_ns, plain.fixes.stamps_ns)
    e1, n1 = local_east_north(plain.fixes.latitude_deg, plain.fixes.longitude_deg)
    e2, n2 = local_east_north(odo.fixes.latitude_deg, odo.fixes.longitude_deg)
    # relative to the first fix (itself noisy, a common offset): 600 fixes per axis
    for diff in (e2 - e1, n2 - n1):
        assert np.std(diff[1:]) == pytest.approx(2.5, rel=0.1)
    custom = json.loads(odo.custom_data['road_force_estimator.parameters'])
    assert custom['simulator.speed_scale_error'] == ERROR
    assert 'simulator.speed_scale_error' not in json.loads(
        plain.custom_data['road_force_estimator.parameters'])      # default: not recorded


@pytest.fixture(scope='module')
def estimated(drives, tmp_path_factory):
    out = {}
    for fusion in ('speed', 'gnss'):
        folder = tmp_path_factory.mktemp(fusion) / 'out'
        assert estimate_main([str(drives[1]), '--output', str(folder), '--mode', 'offline',
                              '-p', f'observer.distance_source:={fusion}', '--no-figures',
                              '--no-progress']) == 0
        out[fusion] = folder
    return out


def test_offline_fusion_reports_the_scale_and_places_the_segments(estimated):
    s = json.loads((estimated['gnss'] / 'report' / 'report.json').read_text())
    odo = s['odometer']
    assert odo['scale'] == pytest.approx(1.0 / (1.0 + ERROR), rel=1e-3)
    assert odo['speed_error_pct'] == pytest.approx(100.0 * ERROR, abs=0.1)
    assert 0.0 < odo['scale_std'] < 1e-3 and odo['fixes_rejected'] == 0
    assert odo['fix_noise_m'] == pytest.approx(2.5, rel=0.2)
    assert s['distance_m'] == pytest.approx(1200.0, abs=1.0)       # 20 m/s for 60 s
    off = json.loads((estimated['speed'] / 'report' / 'report.json').read_text())
    assert 'odometer' not in off
    assert off['distance_m'] == pytest.approx(1200.0 * (1.0 + ERROR), abs=0.1)
    with open(estimated['gnss'] / 'report' / 'segments.csv') as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 12 and float(rows[-1]['end_m']) == pytest.approx(1200.0, abs=1.0)
    md = (estimated['gnss'] / 'report' / 'report.md').read_text()
    assert 'odometer scale from GNSS' in md and 'speed reads high by' in md
    diags = [m for _, _, m in bagio.iter_messages(estimated['gnss'] / 'bag',
                                                   topics=['/diagnostics'])]
    keys = {kv.key: kv.value for kv in diags[-1].status[0].values}
    assert float(keys['total.odometer_scale']) == pytest.approx(odo['scale'], rel=1e-6)  # %g
    assert keys['total.odometer_fixes_rejected'] == '0'


# ------------------------------------------------------------------------------------------
# observer.distance_source: auto, the default (issue 29)

@pytest.fixture(scope='module')
def by_default(drives, tmp_path_factory):
    """estimate_bag --mode offline with no parameter at all, on the drive whose speed reads
    1.5 % high (fixes with 2.5 m of noise), and on the same drive without /fix."""
    root = tmp_path_factory.mktemp('auto')
    nofix = simulate(root / 'nofix', '-p', f'simulator.speed_scale_error:={ERROR}',
                     '-p', 'simulator.gnss.rate:=0')
    out = {}
    for name, drive in (('fix', drives[1]), ('nofix', nofix)):
        assert estimate_main([str(drive), '--output', str(root / f'{name}-est'), '--mode',
                              'offline', '--no-figures', '--no-progress']) == 0
        out[name] = (drive, root / f'{name}-est')
    return out


def mark_position_m(drive: Path, estimate: Path, mark_m: float) -> float:
    """Where the truck truly was (m) when the estimate's distance reached ``mark_m``."""
    truth = bagio.read_drive_bag(drive)
    stamps, x = [], []
    for _, _, msg in bagio.iter_messages(estimate / 'bag', topics=['/road_profile/left']):
        stamps.append(msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec)
        x.append(msg.point.x)
    at = stamps[int(np.searchsorted(np.asarray(x), mark_m))]
    return float(np.interp(at, truth.stamps_ns, truth.truth.distance_m))


def test_by_default_the_distance_is_the_fixes_when_the_drive_has_them(by_default):
    drive, est = by_default['fix']
    s = json.loads((est / 'report' / 'report.json').read_text())
    assert s['parameters']['observer.distance_source'] == 'auto'
    assert s['distance']['used'] == 'gnss' and s['distance']['fixes'] == 601
    assert '601 of 601 fixes used' in s['distance']['reason']
    assert 'reads 1.5' in s['distance']['reason'] and '% high' in s['distance']['reason']
    assert abs(mark_position_m(drive, est, 1000.0) - 1000.0) <= 2.0
    xcorr = s['accuracy']['profile_xcorr']
    assert min(np.atleast_1d(xcorr)) >= 0.95, xcorr
    md = (est / 'report' / 'report.md').read_text()
    assert '| distance (observer.distance_source = auto) | GNSS-corrected' in md


def test_without_fixes_the_report_says_the_distance_is_the_speeds(by_default):
    drive, est = by_default['nofix']
    s = json.loads((est / 'report' / 'report.json').read_text())
    assert s['distance'] == {'requested': 'auto', 'used': 'speed',
                             'reason': 'no /fix in the drive', 'fixes': 0}
    md = (est / 'report' / 'report.md').read_text()
    assert ("| distance (observer.distance_source = auto) | the speed's (the integral of "
            '/vehicle/twist): no /fix in the drive |') in md
    assert mark_position_m(drive, est, 1000.0) == pytest.approx(1000.0 / (1.0 + ERROR),
                                                                abs=0.5)
