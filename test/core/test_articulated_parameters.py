"""The articulated vehicle's parameters (INTERFACES.md "The whole vehicle"): names declared
from vehicle.axles, MODEL.md's defaults, any number of axles from a file, one-line refusals."""
import pathlib

import numpy as np
import pytest
import yaml
from scipy.integrate import solve_ivp

from articulated_reference import G, Reference, defaults, statics
from road_force_estimator.core.articulated_model import ArticulatedModel
from road_force_estimator.core.articulated_parameters import (
    ArticulatedParameters, axle_specs, check_model_names)
from road_force_estimator.core.articulated_plant import simulate_articulated
from road_force_estimator.core.articulated_setup import ArticulatedDrive
from road_force_estimator.core.parameters import load_params_file
from road_force_estimator.core.road import iso8608_profile

REPO = pathlib.Path(__file__).resolve().parents[2]
CONFIG = REPO / 'config'


def test_the_config_file_is_model_md_s_combination():
    values = load_params_file(CONFIG / 'tractor_semitrailer.yaml')
    assert values['vehicle.model'] == 'articulated'
    assert ArticulatedParameters.from_parameters(values) == ArticulatedParameters.from_parameters(
        {})
    p = defaults()
    v = ArticulatedParameters.from_parameters(values)
    for a, ref in zip(v.axles, p['axles']):
        assert (a.name, a.position_m, a.mass_kg, a.roll_inertia_kgm2, a.spring_half_track_m,
                a.wheel_half_track_m) == (ref['name'], ref['xi'], ref['m'], ref['ia'], ref['s'],
                                          ref['w'])
        assert a.suspension_stiffness_npm == (ref['k'],) * 2
        assert a.tire_stiffness_npm == (ref['kt'],) * 2
        assert a.auxiliary_roll_stiffness_nmprad == ref['kphi']
    assert (v.tractor.mass_kg, v.trailer.mass_kg, v.fifth_wheel.position_m) == (6500, 29000, 3.2)


def _plain(path):
    """The 6x4 file as plain numbers for the reference, read with PyYAML (not the package)."""
    doc = yaml.safe_load(path.read_text())['/**']['ros__parameters']['vehicle']
    p = defaults()
    trailer_axle = dict(p['axles'][2])
    axles = [dict(p['axles'][0])]
    for name in doc['axles'][1:]:
        given = doc['axle'][name]
        if 'body' in given:
            axles.append(dict(name=name, body='t' if given['body'] == 'tractor' else 'r',
                              xi=given['position'], m=given['mass'], ia=given['roll_inertia'],
                              s=given['spring_half_track'], w=given['wheel_half_track'],
                              k=given['suspension_stiffness'][0],
                              c=given['suspension_damping'][0],
                              kphi=given['auxiliary_roll_stiffness'],
                              kt=given['tire_stiffness'][0], hrc=given['roll_centre_height'],
                              rho=given['wheel_radius']))
        else:
            axles.append(dict(trailer_axle, name=name, xi=given['position']))
    bodies = {k: dict(M=doc[n]['mass'], xi=doc[n]['cg_position'], iy=doc[n]['pitch_inertia'],
                      ix=doc[n]['roll_inertia'], H=doc[n]['cg_height'],
                      h=doc[n]['cg_height_above_roll_axis'])
              for k, n in (('t', 'tractor'), ('r', 'trailer'))}
    fifth = dict(p['fifth'], xi=doc['fifth_wheel']['position'])
    return dict(axles=axles, bodies=bodies, fifth=fifth)


def test_a_6x4_tractor_and_a_tandem_trailer_are_a_parameter_file():
    """Other axles, no code: statics equal the test's balance, the sum the weight, stable
    modes, and the plant follows the test's solve_ivp on a class C road."""
    path = CONFIG / 'tractor_6x4_semitrailer_tandem.yaml'
    drive = ArticulatedDrive.from_values(load_params_file(path))
    p = _plain(path)
    model = drive.model
    assert model.vehicle.axle_names == ('front', 'drive_1', 'drive_2', 'trailer_1', 'trailer_2')
    ref = statics(p)
    st = model.statics()
    np.testing.assert_allclose(st.wheel_load_n.sum(1), ref['wheel'], rtol=1e-9)
    weight = (sum(b['M'] for b in p['bodies'].values()) + sum(a['m'] for a in p['axles'])) * G
    assert st.wheel_load_n.sum() == pytest.approx(weight, rel=1e-9)
    assert np.all(model.poles().real < 0.0)
    road = iso8608_profile('C', 120.0, seed=11)
    tr = simulate_articulated(model.vehicle, road, speed_mps=20.0, rate_hz=1000.0,
                              duration_s=2.0, tire_envelope_m=0.25, model=model)
    env = road.enveloped(0.25)
    r = Reference(p, lambda x: np.stack([np.interp(x, env.distance_m, env.elevation_m[:, i])
                                         for i in (0, 1)], -1),
                  lambda t: tr.distance_m[0] + 20.0 * t, lambda t: 0.0, lambda t: 0.0,
                  ref['spring'], ref['wheel'])
    sol = solve_ivp(r, (0.0, 2.0), tr.state[0], method='RK45', rtol=1e-8, atol=1e-9,
                    t_eval=tr.t_s, max_step=2e-3)
    loads = np.array([r.wheel_loads(t, y) for t, y in zip(sol.t, sol.y.T)])
    dyn = loads - np.repeat(ref['wheel'] / 2, 2)
    err = tr.wheel_load_n - loads
    assert np.sqrt(np.mean(err ** 2)) <= 1e-4 * np.sqrt(np.mean(dyn ** 2))


def test_per_axle_names_are_declared_from_vehicle_axles_with_their_defaults():
    specs = {s.name: s for s in axle_specs({'vehicle.axles': ['front', 'drive', 'tag']})}
    assert specs['vehicle.axle.front.mass'].default == 900.0
    assert specs['vehicle.axle.drive.tire_stiffness'].default == [2000e3, 2000e3]
    assert specs['vehicle.axle.tag.mass'].default is None          # must be given
    assert specs['vehicle.axle.tag.instrumented'].default is True
    # the per-axle forms of a whole-vehicle effect default to the whole-vehicle value
    specs = {s.name: s for s in axle_specs({'vehicle.axles': ['front', 'x'],
                                            'vehicle.leaf_spring_friction': (1500.0, 1200.0),
                                            'vehicle.sensor_time_constant': (0.003, 0.001)})}
    assert specs['vehicle.axle.front.leaf_spring_friction'].default == [1500.0, 1200.0]
    assert specs['vehicle.axle.x.sensor_time_constant'].default == 0.003
    assert not any(n.startswith('vehicle.axle.trailer_1') for n in specs)


@pytest.mark.parametrize('values, message', [
    ({'vehicle.axle.trailer_4.mass': 800.0},
     r"^vehicle\.axle\.trailer_4\.mass: no axle 'trailer_4' in vehicle\.axles \(front, drive, "
     r'trailer_1, trailer_2, trailer_3\)$'),
    ({'simulator.axle.dolly.sensor_offset': [0.0, 0.0]},
     r"^simulator\.axle\.dolly\.sensor_offset: no axle 'dolly' in vehicle\.axles"),
    ({'vehicle.axle.drive.body': 'dolly'},
     r"^vehicle\.axle\.drive\.body = 'dolly': must be one of tractor, trailer$"),
    ({'vehicle.axle.trailer_1.position': 3.0, 'vehicle.axle.drive.position': 2.5},
     r'^vehicle\.axle\.trailer_1\.position = 3 m: a trailer axle must be behind the kingpin '
     r'\(vehicle\.fifth_wheel\.position = 3\.2 m\)$'),
    ({'vehicle.sprung_mass': 5000.0},
     r'^vehicle\.sprung_mass: a parameter of the front-axle model, refused with '
     r'vehicle\.model: articulated: use vehicle\.tractor\.mass and vehicle\.trailer\.mass$'),
    ({'vehicle.axles': ['front', 'drive', 'tag', 'trailer_1']},
     r"^vehicle\.axle\.tag\.body: not given \(axle 'tag' has no default values"),
    ({'vehicle.axle.front.position': 0.5},
     r"^vehicle\.axle\.front: the first axle of vehicle\.axles is the tractor's front axle at "
     r'position 0 m'),
    ({'vehicle.axles': ['front', 'drive', 'drive']}, r'^vehicle\.axles: drive listed twice$'),
])
def test_a_vehicle_is_refused_in_one_line(values, message):
    with pytest.raises(ValueError, match=message) as err:
        ArticulatedDrive.from_values({'vehicle.model': 'articulated', **values})
    assert '\n' not in str(err.value)


@pytest.mark.parametrize('values, message', [
    # the trailer's centre of gravity behind its last axle: the kingpin would pull
    ({'vehicle.trailer.cg_position': 14.0},
     r'^the vehicle cannot stand: the kingpin would pull'),
    # the tractor's centre of gravity far ahead of its front axle: the drive axle's springs pull
    ({'vehicle.tractor.cg_position': -4.0, 'vehicle.tractor.mass': 30000.0},
     r'^the vehicle cannot stand: the left spring of axle drive would pull'),
    # a trailer so high that its weight out-rolls every spring (the roll margin)
    ({'vehicle.trailer.cg_height_above_roll_axis': 5.0, 'vehicle.trailer.mass': 60000.0,
      'vehicle.fifth_wheel.roll_stiffness': 0.0},
     r'^the vehicle cannot stand: the static stiffness is not positive \(mode trailer_roll'),
])
def test_a_vehicle_whose_statics_fail_is_refused_in_one_line(values, message):
    with pytest.raises(ValueError, match=message) as err:
        ArticulatedDrive.from_values({'vehicle.model': 'articulated', **values})
    assert '\n' not in str(err.value)


def test_the_articulated_names_are_refused_for_a_front_axle():
    with pytest.raises(ValueError, match=r'^vehicle\.axle\.front\.mass: a parameter of '
                                         r'vehicle\.model: articulated \(this vehicle is '
                                         r'front_axle'):
        check_model_names(['vehicle.axle.front.mass'], {})
    check_model_names(['vehicle.sprung_mass', 'simulator.rate'], {})     # front-axle names


def test_the_static_load_setting_replaces_the_statics_in_the_outputs_only():
    v = ArticulatedParameters.from_parameters({'vehicle.axle.front.static_load': [40e3, 40e3]})
    model = ArticulatedModel(v)
    st = model.statics()
    assert np.all(st.output_wheel_load_n[0] == 40e3)
    assert st.wheel_load_n[0, 0] == pytest.approx(ArticulatedModel(
        ArticulatedParameters.from_parameters({})).statics().wheel_load_n[0, 0])
