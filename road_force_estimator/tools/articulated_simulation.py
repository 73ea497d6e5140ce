"""``simulate_bag`` with ``vehicle.model: articulated``: the tractor and semi-trailer driven
offline into a drive bag (:mod:`road_force_estimator.bagio.articulated_drive`).

The same options as the front axle's drive (road, speed and its profile with stops, rate,
duration, lateral acceleration, tire envelope, GNSS, stamp jitter, every plant-only effect),
per axle where the vehicle has axles. :func:`simulate` runs the plant
(:class:`~.core.articulated_plant.ArticulatedPlant`'s batch path) and the sensors; the truth
of each unit's load transfer comes from :mod:`~.core.unit_loads`.
"""
from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np

__all__ = ['simulate', 'custom_data', 'write']


def simulate(drive, *, route, progress: bool = False, prog: str = 'simulate_bag'):
    """Run an :class:`~.core.articulated_setup.ArticulatedDrive`: a namespace with the
    trajectory, the readings and their names, the IMU, the truth, the stamps, the fixes,
    the road and why the drive was cut (``reason``, '' when it was not). ``route(traj, sim,
    speed_profile)``: the GNSS fixes (simulate_bag's, the front axle's drive alike)."""
    from road_force_estimator import interfaces as api
    from road_force_estimator.bagio import road_from_source
    from road_force_estimator.bagio import DEFAULT_START_STAMP_NS
    from road_force_estimator.core.articulated_plant import simulate_articulated
    from road_force_estimator.core.unit_loads import unit_load_transfer
    from road_force_estimator.tools import cli

    sim = drive.sim
    road = road_from_source(sim.road, length_m=drive.road_length_m)
    plant = drive.plant(road)
    wanted = min(int(math.floor(sim.duration_s * sim.rate_hz + 1e-9)),
                 plant.last_sample_index) + 1
    with cli.sample_progress(wanted, progress, f'{prog}: plant') as bar:
        traj = simulate_articulated(drive.vehicle, road, speed_mps=sim.speed_mps,
                                    rate_hz=sim.rate_hz, duration_s=sim.duration_s,
                                    progress=bar.update, **_options(drive))
    n = len(traj)
    if n == 0:
        raise ValueError(f'road {sim.road!r}: too short for a single sample')
    names = api.articulated_deflection_joints(drive.instrumented_axles,
                                              drive.vehicle.trailer_roll_sensor)
    sensors = drive.sensors(names)
    readings = sensors.measure(traj)
    imu = sensors.imu(traj) if drive.vehicle.tractor_imu else None
    statics = drive.model.statics()
    loads = traj.wheel_load_n
    ltr = unit_load_transfer([a.body for a in drive.vehicle.axles],
                             statics.output_wheel_load_n, 1.0 / sim.rate_hz, loads)
    t = traj.t_s
    stamps = DEFAULT_START_STAMP_NS + np.round(t * 1e9).astype(np.int64)
    if sim.stamp_jitter_s > 0.0:
        stamps = DEFAULT_START_STAMP_NS + np.round(
            (t + sensors.stamp_offsets_s(n)) * 1e9).astype(np.int64)
    speed = traj.speed_mps
    path = SimpleNamespace(t_s=t, speed_mps=speed if drive.speed_profile is not None
                           else sim.speed_mps, lateral_accel_mps2=traj.lateral_accel_mps2)
    fixes = route(path, sim, drive.speed_profile) if sim.gnss_rate_hz > 0.0 else None
    requested = int(math.floor(sim.duration_s * sim.rate_hz + 1e-9)) + 1
    reason = ''
    if n < requested:
        reason = (f'the road ends at {plant.road.end_m:g} m: drive cut to {n} of {requested} '
                  f'samples ({t[-1]:g} s)')
    front = drive.vehicle.axles[0]
    truth = {'distance_m': traj.distance_m, 'front_road_m': traj.road_m[:, :2],
             'front_half_track_m': front.wheel_half_track_m,
             'wheel_names': api.wheel_joints(drive.vehicle.axle_names),
             'wheel_load_n': loads, 'unit_ltr': ltr}
    return SimpleNamespace(trajectory=traj, readings=readings, names=names, imu=imu,
                           truth=truth, stamps_ns=stamps, speed_mps=speed, fixes=fixes,
                           road=road, reason=reason, sensors=sensors, plant=plant)


def _options(drive) -> dict:
    sim = drive.sim
    return dict(speed_profile=drive.speed_profile, lateral_acceleration=drive.lateral,
                tire_envelope_m=sim.tire_envelope_length_m, crossfall_rad=sim.road_crossfall_rad,
                friction_start=sim.leaf_spring_friction_start, model=drive.model)


def custom_data(drive, result, prog: str) -> dict:
    """The bag's ``custom_data``: the parameters, the statics, the front axle's joints (what
    a front-axle tool reads), where the faults struck."""
    from road_force_estimator import interfaces as api
    from road_force_estimator.bagio.vehicle_layout import (
        AXLES_KEY, FRONT_JOINTS_KEY, STATIC_KEY, WHEELS_KEY)

    v = drive.vehicle
    params = {**v.to_parameters(), **drive.sim.to_parameters()}
    params['simulator.noise.imu_acceleration'], params['simulator.noise.imu_rate'] = \
        drive.imu_noise
    front = v.axles[0]
    joints = (*api.axle_deflection_joints(front.name), api.TRACTOR_ROLL_JOINT) \
        if front.instrumented else ()
    statics = drive.model.statics()
    custom = {'road_force_estimator.parameters': json.dumps(params, sort_keys=True),
              'road_force_estimator.road_name': result.road.name or drive.sim.road,
              'road_force_estimator.writer_command': prog,
              'road_force_estimator.track_width_m': repr(2.0 * front.wheel_half_track_m),
              FRONT_JOINTS_KEY: ','.join(joints),
              WHEELS_KEY: json.dumps(list(api.wheel_joints(v.axle_names))),
              AXLES_KEY: json.dumps([a.body for a in v.axles]),
              STATIC_KEY: json.dumps(statics.output_wheel_load_n.reshape(-1).tolist()),
              'road_force_estimator.kingpin_load_n': repr(statics.kingpin_load_n)}
    if result.sensors.faults is not None:
        custom['road_force_estimator.sensor_faults'] = json.dumps(result.sensors.faults.truth())
    return custom


def write(bag, drive, result, custom: dict, *, twist_speed,
          ground_truth: bool = True) -> int:
    """Write the bag folder ``bag``; the messages written. ``twist_speed(speed, sim)``: what
    the twist carries (simulate_bag's odometer error)."""
    from road_force_estimator.bagio.articulated_drive import write_articulated_drive_bag

    return write_articulated_drive_bag(
        bag, stamps_ns=result.stamps_ns,
        speed_mps=twist_speed(result.speed_mps, drive.sim), readings=result.readings,
        names=result.names, truth=result.truth if ground_truth else None, imu=result.imu,
        imu_std=drive.imu_noise, fixes=result.fixes, custom_data=custom)
