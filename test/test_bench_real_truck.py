"""bench/accuracy/real_truck.py: the drives it describes are the ones it builds (parameters against
the package defaults), a drive needing a parameter the package lacks is listed and skipped, and
on (e) the nominal file trips model_fit while the true file does not."""
from __future__ import annotations

from dataclasses import replace
import math

import numpy as np

from bench.accuracy import real_truck as rt
from road_force_estimator.core.parameters import VehicleParameters


def _drive(name: str) -> rt.TruckDrive:
    return next(d for d in rt.DRIVES if d.name == name)


def test_every_parameter_of_e_is_off_by_15_percent_with_both_signs():
    truth, _ = rt.truth_vehicle(_drive('params-15'))
    nominal = VehicleParameters()
    ratios = []
    for name in ('sprung_mass_kg', 'roll_inertia_kgm2', 'cg_height_m', 'unsprung_mass_kg',
                 'suspension_stiffness_npm', 'suspension_damping_nspm', 'tire_stiffness_npm'):
        ratios += list(np.atleast_1d(np.asarray(getattr(truth, name), float)
                                     / np.asarray(getattr(nominal, name), float)))
    assert len(ratios) == 11          # 3 scalars, 4 pairs
    np.testing.assert_allclose(np.abs(np.array(ratios) - 1.0), 0.15, rtol=1e-12)
    assert min(ratios) < 1.0 < max(ratios)
    # the nominal file is the defaults with the truth's (weighed) static loads
    files = rt.files_for(_drive('params-15'), truth)
    assert set(files) == {'nominal', 'true'}
    assert files['nominal'].static_load_n == truth.static_load_n
    assert files['nominal'].sprung_mass_kg == nominal.sprung_mass_kg


def test_a_drive_needing_an_unknown_parameter_is_listed_and_skipped():
    drive = rt.TruckDrive('x', 'needs-test', 'a parameter no package has',
                          {'vehicle.no_such_thing': 1.0})
    assert rt.missing(drive) == ['vehicle.no_such_thing']
    result = rt.run_drive(drive, 4.0, {})
    assert result == {'needs': ['vehicle.no_such_thing']}


def test_params_15_nominal_trips_model_fit_and_true_does_not():
    drive = replace(_drive('params-15'), duration_s=6.0)
    result = rt.run_drive(drive, 6.0, {})
    fit = result['model_fit']
    assert fit['nominal'][1] == 'mismatch' and fit['true'][1] == 'ok', fit
    files = result['files']
    for method, _, _ in rt.METHODS:
        for f in ('nominal', 'true'):
            assert math.isfinite(files[f][method]['load']), (f, method, files[f][method])
    assert files['true']['ours']['load'] < files['nominal']['ours']['load']
    table = rt.markdown({'params-15': result}, 6.0)
    assert '| (e) params-15 | nominal = stated |' in table
