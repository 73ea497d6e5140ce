"""The calibration report (through a real, short calibration)."""
import json

import numpy as np

from road_force_estimator.core.parameters import VehicleParameters
from road_force_estimator.core.plant import simulate
from road_force_estimator.bagio import road_from_source
from road_force_estimator.calibration.calibrate import CalibrationOptions, calibrate
from road_force_estimator.report.calibration import write_report


def test_report_has_every_parameter_the_alignment_and_figures(tmp_path, monkeypatch):
    truck = VehicleParameters(sprung_mass_kg=5600.0, suspension_stiffness_npm=(350e3, 430e3))
    road = road_from_source('iso8608:C:seed=8', length_m=300.0)
    traj = simulate(truck, road, speed_mps=20.0, rate_hz=200.0, duration_s=8.0,
                    tire_envelope_m=0.25, start_m=20.0)
    stamps = np.rint(traj.t_s * 1e9).astype(np.int64)
    result = calibrate(stamps, traj.q_m, traj.roll_rad, np.full(stamps.size, 20.0), road,
                       VehicleParameters(),
                       options=CalibrationOptions(static_load_n=truck.static_load_n))
    import matplotlib.pyplot as plt
    closed = []
    real_close = plt.close
    monkeypatch.setattr(plt, 'close', lambda fig=None: closed.append(fig) or real_close(fig))
    paths = write_report(result, tmp_path / 'r', drive='d', profile='p', output='o.yaml')
    assert {p.name for p in paths} == {'calibration.md', 'calibration.json', 'deflections.png',
                                       'spectra.png'}
    d = json.loads((tmp_path / 'r' / 'calibration.json').read_text())
    names = [p['name'] for p in d['parameters']]
    assert 'vehicle.sprung_mass' in names and 'sensor.offset.roll' in names
    assert d['alignment']['correlation'] > 0.8 and d['scale_known']
    md = (tmp_path / 'r' / 'calibration.md').read_text()
    assert '| `vehicle.sprung_mass` | kg | 5000 |' in md
    assert 'Fit residual against the sensor noise' in md
    # issue 29: the figures are linked from the report, titled, the PSD axes in units
    assert '![Measured and fitted signals' in md and '(deflections.png)' in md
    assert '(spectra.png)' in md and all((tmp_path / 'r' / n).is_file()
                                          for n in ('deflections.png', 'spectra.png'))
    signals, spectra = closed
    assert signals._suptitle.get_text().startswith('Measured and fitted signals')
    assert spectra._suptitle.get_text().startswith('Power spectral densities')
    assert [a.get_ylabel() for a in spectra.axes] == ['PSD (m²/Hz)', 'PSD (m²/Hz)',
                                                      'PSD (rad²/Hz)']
    assert all(a.get_title() for a in (*signals.axes, *spectra.axes))
