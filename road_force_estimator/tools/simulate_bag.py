"""`simulate_bag`: the plant driven over a road, offline (no DDS), into a drive bag.

    simulate_bag --road SOURCE --speed V --rate HZ [--duration S] [--params-file FILE]
                 [-p NAME:=VALUE]... --output DIR [--seed N] [--noise-deflection M]
                 [--noise-roll RAD]
                 [--tire-envelope M] [--gnss-rate HZ] [--lateral-acceleration A[@T]]
                 [--no-ground-truth] [--force] [--no-progress]

SOURCE is a road spec (``iso8608:C:seed=1``, ``jpcp:seed=1``, ``flat``) or a path to an LPA
bag, CSV or ERD profile (:func:`road_force_estimator.core.road.road_from_source`). The plant
(:class:`core.plant.Plant`, the tire envelope ``simulator.tire_envelope_length``)
runs at the rate for the duration, or to the end of the road; the sensors
(:class:`road_force_estimator.core.sensors.SensorModel`: ``simulator.noise.*``, ``simulator.seed``)
measure it, the deflections from a mechanical zero with ``vehicle.deflection_reference:
zero_load`` (MODEL.md "Measurements": a payload is a file with a larger sprung mass or static
load than the observer's). The bag DIR (:func:`road_force_estimator.bagio.write_drive_bag`)
holds the measurements ``/suspension/deflections`` and ``/vehicle/twist``, the ground truth
``/ground_truth/wheel_load/*`` and ``/ground_truth/road_profile/*``, and ``/fix`` at
``simulator.gnss.rate`` (0 = none) on the route of :func:`road_force_estimator.core.gnss.route`
(a fix at the first sample of each GNSS period, as the plant_simulator node publishes them;
the route is integrated between fixes with the lateral acceleration at the fixes, so a step
of a_y is smeared over one GNSS period: about a centimetre of position at 2 m/s^2), with the
receiver's white noise ``simulator.gnss.noise`` (m, :class:`~.core.gnss.FixNoise`). The twist
carries the speed times ``1 + simulator.speed_scale_error`` (an odometer that reads high for
e > 0); the plant, the route and the fixes follow the true speed.
Sample k is stamped ``start + round(k / rate)`` ns. The parameters used go to the bag's
``custom_data``.

The bag is built beside its place and renamed into it when complete (:mod:`.output_folder`);
``--force`` replaces only a bag simulate_bag wrote (its ``custom_data`` says so) that holds
nothing else, never the road it reads.

Values come from the defaults, then the parameter file, then ``-p NAME:=VALUE``, then the
options (``--help`` shows the defaults). Exit status 0
on success, 1 for bad input (bad parameter, unreadable road, existing output), 2 for a bad
command line; each with one line on stderr.
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
import sys
from types import SimpleNamespace

import numpy as np

from road_force_estimator.tools import cli, output_folder

__all__ = ['PROG', 'build_parser', 'parameters_from', 'simulate', 'twist_speed', 'gnss_fixes',
           'main']

PROG = 'simulate_bag'
#: Peak memory of a simulated sample and of a synthetic road point (bytes), rounded up from
#: the peak resident size of runs of two lengths (``/usr/bin/time -f %M simulate_bag ...``;
#: 20 and 80 s at 1 kHz, roads of 20 and 80 km): a drive that cannot fit in the memory
#: available is refused before it starts.
BYTES_PER_SAMPLE = 1000
BYTES_PER_ROAD_POINT = 256

# Command-line option -> parameter name.
_OPTIONS = {
    'road': 'simulator.road', 'speed': 'simulator.speed', 'rate': 'simulator.rate',
    'duration': 'simulator.duration', 'seed': 'simulator.seed',
    'noise_deflection': 'simulator.noise.deflection', 'noise_roll': 'simulator.noise.roll',
    'tire_envelope': 'simulator.tire_envelope_length', 'gnss_rate': 'simulator.gnss.rate',
}


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``simulate_bag``."""
    from road_force_estimator.core.parameters import defaults

    d = defaults('simulator.')

    def dflt(option: str) -> str:
        return f' (default {d[_OPTIONS[option]]!r})'

    p = cli.Parser(prog=PROG, description='Drive the plant over a road offline and write a bag '
                'with measurements and ground truth.',
                epilog='Values: defaults < --params-file < -p NAME:=VALUE < command-line '
                       'options.')
    p.add_argument('--road', metavar='SOURCE',
                   help='road: iso8608:<A-H>[:seed=N], jpcp[:seed=N] (jointed concrete), flat, '
                        'or an LPA bag / CSV / ERD path'
                        + dflt('road'))
    number = cli.finite_float
    p.add_argument('--speed', type=number, metavar='V', help='speed, m/s' + dflt('speed'))
    p.add_argument('--rate', type=number, metavar='HZ', help='sample rate, Hz' + dflt('rate'))
    p.add_argument('--duration', type=cli.finite_float, metavar='S',
                   help='duration, s (the drive also stops at the end of the road)'
                        + dflt('duration'))
    cli.add_params_file(p, 'ROS 2 parameter file (/**: ros__parameters:) with vehicle.* and '
                           'simulator.* (default: none, the package defaults)')
    cli.add_overrides(p)
    cli.add_output(p, 'bag folder to create')
    p.add_argument('--seed', type=int, metavar='N',
                   help='seed of the sensor noise' + dflt('seed'))
    p.add_argument('--noise-deflection', type=cli.finite_float, metavar='M',
                   help='deflection noise standard deviation, m' + dflt('noise_deflection'))
    p.add_argument('--noise-roll', type=cli.finite_float, metavar='RAD',
                   help='roll noise standard deviation, rad' + dflt('noise_roll'))
    p.add_argument('--tire-envelope', type=cli.finite_float, metavar='M',
                   help='tire envelope length, m (0 = point contact)' + dflt('tire_envelope'))
    p.add_argument('--gnss-rate', type=cli.finite_float, metavar='HZ',
                   help='rate of /fix, Hz (0 = none)' + dflt('gnss_rate'))
    p.add_argument('--lateral-acceleration', metavar='A[@T]',
                   help='lateral acceleration a_y, m/s^2 (> 0 to the left), from time T s on '
                        '(default 0 s); bends the GNSS route (default: none, 0 m/s^2)')
    p.add_argument('--no-ground-truth', action='store_true',
                   help='write the measurements only, as a real truck records them')
    cli.add_force(p, 'replace a bag folder simulate_bag wrote')
    cli.add_no_progress(p)
    return p


def parameters_from(args: argparse.Namespace):
    """``(VehicleParameters, SimulatorParameters)``: defaults < params file < ``-p`` <
    options (the front axle's; :func:`parameter_mapping` for any vehicle model)."""
    return _front_parameters(parameter_mapping(args))


def parameter_mapping(args: argparse.Namespace) -> dict:
    """``{dotted name: value}`` of the names given: the params file, ``-p``, the options."""
    from road_force_estimator.core.parameters import validate_parameter
    values = cli.parameter_values(args.params_file, ('plant_simulator', PROG),
                                  getattr(args, 'overrides', ()))
    for option, name in _OPTIONS.items():
        value = getattr(args, option)
        if value is not None:
            values[name] = validate_parameter(name, value)
    return values


def _front_parameters(values: dict):
    """The front axle's dataclasses; a name of the articulated model is refused."""
    from road_force_estimator.core.articulated_parameters import check_model_names
    from road_force_estimator.core.parameters import SimulatorParameters, VehicleParameters
    check_model_names(values, values)
    return VehicleParameters.from_parameters(values), SimulatorParameters.from_parameters(values)


def _lateral(text: str | None):
    """``A[@T]`` -> (a_y, t_on) or None."""
    if text is None:
        return None
    value, _, start = text.partition('@')
    try:
        a_y, t_on = float(value), float(start) if start else 0.0
    except ValueError:
        raise cli.UsageError(f'--lateral-acceleration {text!r}: expected A or A@T (numbers)') \
            from None
    if not (math.isfinite(a_y) and math.isfinite(t_on) and abs(a_y) <= 20.0 and t_on >= 0.0):
        raise cli.UsageError(f'--lateral-acceleration {text!r}: |A| <= 20 m/s^2 and T >= 0 s')
    return a_y, t_on


def simulate(vehicle, sim, *, lateral=None, progress: bool = False):
    """Run the plant and the sensors.

    Parameters
    ----------
    vehicle : VehicleParameters
    sim : SimulatorParameters
    lateral : (a_y, t_on) or None
        Lateral acceleration a_y (m/s^2) from ``t_on`` (s) on.
    progress : bool
        Show a progress bar (stderr) on long runs.

    Returns
    -------
    trajectory, q_meas (n, 2), roll_meas (n,), fixes or None, road, stop_reason
        ``trajectory`` has ``t_s``, ``distance_m``, ``q_m``, ``roll_rad``, ``wheel_load_n``,
        ``road_m``, ``lateral_accel_mps2`` (arrays per sample) and ``speed_mps`` (the true
        speed; the twist's is :func:`twist_speed`).
    """
    from road_force_estimator.core.plant import Plant
    from road_force_estimator.bagio import road_from_source
    from road_force_estimator.core.sensors import SensorModel
    from road_force_estimator.core.speed_profile import read_speed_profile
    from road_force_estimator.core.vehicle_model import SpringOptions

    from road_force_estimator.core.lateral_profile import parse_lateral_profile
    from road_force_estimator.interfaces import DEFLECTION_JOINTS

    profile = read_speed_profile(sim.speed_profile) if sim.speed_profile else None
    length_m = _travel_m(sim, profile) + 2.0 * sim.tire_envelope_length_m + 1.0
    _check_memory(_synthetic_points(sim.road, length_m) * BYTES_PER_ROAD_POINT,
                  f'a synthetic road of {length_m:.6g} m')
    road = road_from_source(sim.road, length_m=length_m)
    accel = parse_lateral_profile(sim.lateral_profile)
    if lateral is not None:
        a_y, t_on = lateral

        def accel(t_s: float) -> float:
            return a_y if t_s >= t_on else 0.0

    plant = Plant(vehicle, road, speed_mps=sim.speed_mps, rate_hz=sim.rate_hz,
                  lateral_acceleration=accel, tire_envelope_m=sim.tire_envelope_length_m,
                  speed_profile=profile, springs=SpringOptions.from_simulator(sim),
                  friction_start=sim.leaf_spring_friction_start,
                  crossfall_rad=sim.road_crossfall_rad)
    wanted = min(int(math.floor(sim.duration_s * sim.rate_hz + 1e-9)),
                 plant.last_sample_index) + 1
    _check_memory(wanted * BYTES_PER_SAMPLE,
                  f'{wanted} samples ({wanted / sim.rate_hz:.6g} s at {sim.rate_hz:g} Hz)')
    cols = {k: [] for k in ('t_s', 'distance_m', 'q_m', 'roll_rad', 'wheel_load_n', 'road_m',
                            'lateral_accel_mps2')}
    appenders = [(cols[k].append, k) for k in cols]
    with cli.sample_progress(wanted, progress, f'{PROG}: plant') as bar:
        done = 0
        while done < wanted:
            sample = plant.step()
            if sample is None:
                break
            for append, key in appenders:
                append(getattr(sample, key))
            done += 1
            if done % 5000 == 0:
                bar.update(5000)
        bar.update(done % 5000)
    if done == 0:
        raise ValueError(f'road {sim.road!r}: too short for a single sample')
    traj = SimpleNamespace(
        t_s=np.array(cols['t_s']), distance_m=np.array(cols['distance_m']),
        q_m=np.array(cols['q_m']), roll_rad=np.array(cols['roll_rad']),
        wheel_load_n=np.array(cols['wheel_load_n']), road_m=np.array(cols['road_m']),
        lateral_accel_mps2=np.array(cols['lateral_accel_mps2']))
    traj.speed_mps = sim.speed_mps if profile is None else plant.speed_at(traj.t_s)  # twist
    sensors = SensorModel.from_simulator(sim, vehicle, channels=DEFLECTION_JOINTS)
    if sensors.roll_sensor is None:
        q_meas, roll_meas = sensors.measure(traj.q_m, traj.roll_rad)
    else:       # a pendulum reads a_y too
        q_meas, roll_meas = sensors.measure(traj.q_m, traj.roll_rad, traj.lateral_accel_mps2)
    traj.sensors = sensors
    fixes = gnss_fixes(traj, sim, profile) if sim.gnss_rate_hz > 0.0 else None
    _jitter_stamps(traj, sensors)
    requested = int(math.floor(sim.duration_s * sim.rate_hz + 1e-9)) + 1
    reason = ''
    if done < requested:
        reason = (f'the road ends at {plant.road.end_m:g} m: drive cut to {done} of {requested} '
                  f'samples ({traj.t_s[-1]:g} s)')
    return traj, q_meas, roll_meas, fixes, road, reason


def _main_articulated(args: argparse.Namespace, values: dict, lateral) -> int:
    """``vehicle.model: articulated`` (:mod:`.articulated_simulation`)."""
    from road_force_estimator.core.articulated_setup import ArticulatedDrive
    from road_force_estimator.core.lateral_profile import LateralProfile
    from road_force_estimator.tools import articulated_simulation as articulated

    drive = ArticulatedDrive.from_values(
        values, lateral=None if lateral is None else LateralProfile.step(*lateral))
    sim = drive.sim
    road_path = Path(sim.road).expanduser()
    target = output_folder.BagOutput(
        Path(args.output), PROG, force=args.force, owned=_written_here,
        inputs=[road_path] if road_path.exists() else [])
    target.check()
    result = articulated.simulate(drive, route=gnss_fixes, progress=not args.no_progress,
                                  prog=PROG)
    custom = articulated.custom_data(drive, result, PROG)
    if lateral is not None:
        custom['road_force_estimator.lateral_acceleration'] = args.lateral_acceleration
    with target.staged() as bag:
        count = articulated.write(bag, drive, result, custom, twist_speed=twist_speed,
                                  ground_truth=not args.no_ground_truth)
    t = result.trajectory.t_s
    if result.reason:
        print(f'{PROG}: {result.reason}', file=sys.stderr)
    print(f'{PROG}: wrote {count} messages ({t.size} samples, {t[-1]:g} s, '
          f'{result.trajectory.distance_m[-1] - result.trajectory.distance_m[0]:.1f} m at '
          f'{_speed_text(sim)}, {len(drive.vehicle.axles)} axles, '
          f'{drive.model.statics().gross_weight_kg / 1000:.2f} t) over '
          f'{result.road.name or sim.road} to {args.output}', file=sys.stderr)
    return 0


def _synthetic_points(source: str, length_m: float) -> float:
    """The points of a synthetic road of ``length_m`` (0 for a file: its size bounds it)."""
    head, _, options = str(source).strip().partition(':')
    if head.lower() not in ('iso8608', 'flat', 'jpcp'):
        return 0.0
    dx = 0.05
    for option in options.split(':'):
        key, _, value = option.partition('=')
        if key.strip() == 'dx':
            try:
                dx = float(value)
            except ValueError:
                return 0.0          # refused with its reason by the road's parser
    return length_m / dx if dx > 0.0 and math.isfinite(dx) else 0.0


def _check_memory(need_bytes: float, what: str) -> None:
    """Raise ValueError when ``need_bytes`` exceed the memory available now."""
    available = cli.available_memory()
    if available is not None and need_bytes > available:
        raise ValueError(f'{what} would need about {need_bytes / 1e9:.3g} GB of memory, more '
                         f'than the {available / 1e9:.3g} GB available: shorten --duration or '
                         'lower --rate')


def _jitter_stamps(traj, sensors) -> None:
    """With ``simulator.stamp_jitter``: the samples stay at their true times, their stamps
    (and those of the sample's truth and twist) move (``traj.stamps_ns``)."""
    if sensors.stamp_jitter_s > 0.0:
        from road_force_estimator.bagio.drive import DEFAULT_START_STAMP_NS
        traj.stamps_ns = DEFAULT_START_STAMP_NS + np.round(
            (traj.t_s + sensors.stamp_offsets_s(traj.t_s.size)) * 1e9).astype(np.int64)


def gnss_fixes(traj, sim, profile):
    """The fixes of a drive (``core.gnss.GnssRoute``): one at the first sample of each GNSS
    period, on the true route, with the receiver noise."""
    from road_force_estimator.core.gnss import FixNoise, route

    period = np.floor(traj.t_s * sim.gnss_rate_hz + 1e-9).astype(np.int64)
    first = np.concatenate([[True], period[1:] > period[:-1]])
    idx = np.flatnonzero(first)
    fixes = route(traj.t_s[idx], traj.speed_mps if profile is None else traj.speed_mps[idx],
                  start_latitude_deg=sim.gnss_start_latitude_deg,
                  start_longitude_deg=sim.gnss_start_longitude_deg,
                  heading_deg=sim.gnss_heading_deg,
                  lateral_accel_mps2=traj.lateral_accel_mps2[idx])
    if sim.gnss_noise_m > 0.0:
        lat, lon = FixNoise(sim.gnss_noise_m, sim.seed).apply(fixes.latitude_deg,
                                                               fixes.longitude_deg)
        fixes = type(fixes)(fixes.time_s, lat, lon, fixes.heading_deg)
    return fixes


def main(argv: list[str] | None = None) -> int:
    """Run ``simulate_bag``; the exit status (0 ok, 1 bad input, 2 bad command line)."""
    from road_force_estimator.bagio import BagReadError, BagWriteError

    return cli.run_main(PROG, build_parser(), _main, argv,
                        {(ValueError, BagReadError, BagWriteError, OSError): 1})


def _main(args: argparse.Namespace) -> int:
    """The command's work: :func:`simulate`, the bag (:class:`~.output_folder.BagOutput`:
    built beside it, renamed into place; ``--force`` replaces only a bag of simulate_bag),
    the one-line result."""
    from road_force_estimator import bagio

    from road_force_estimator.core.articulated_parameters import vehicle_model

    lateral = _lateral(args.lateral_acceleration)
    values = parameter_mapping(args)
    if vehicle_model(values) == 'articulated':
        return _main_articulated(args, values, lateral)
    vehicle, sim = _front_parameters(values)
    road_path = Path(sim.road).expanduser()
    target = output_folder.BagOutput(
        Path(args.output), PROG, force=args.force, owned=_written_here,
        inputs=[road_path] if road_path.exists() else [])
    target.check()
    traj, q_meas, roll_meas, fixes, road, reason = simulate(
        vehicle, sim, lateral=lateral, progress=not args.no_progress)
    used = _recorded_parameters({**vehicle.to_parameters(), **sim.to_parameters()})
    custom = {'road_force_estimator.parameters': json.dumps(used, sort_keys=True),
              'road_force_estimator.road_name': road.name or sim.road,
              'road_force_estimator.writer_command': PROG}
    if lateral is not None:
        custom['road_force_estimator.lateral_acceleration'] = args.lateral_acceleration
    if traj.sensors.faults is not None:         # where the faults struck (a detector's truth)
        custom['road_force_estimator.sensor_faults'] = json.dumps(traj.sensors.faults.truth())
    with target.staged() as bag:
        count = bagio.write_drive_bag(bag, traj, q_meas, roll_meas, fixes=fixes,
                                      speed_mps=twist_speed(traj.speed_mps, sim),
                                      track_width_m=vehicle.track_width_m,
                                      ground_truth=not args.no_ground_truth, custom_data=custom)
    n = len(traj.t_s)
    if reason:
        print(f'{PROG}: {reason}', file=sys.stderr)
    print(f'{PROG}: wrote {count} messages ({n} samples, {traj.t_s[-1]:g} s, '
          f'{traj.distance_m[-1] - traj.distance_m[0]:.1f} m at '
          f'{_speed_text(sim)}) over '
          f'{road.name or sim.road} to {args.output}', file=sys.stderr)
    return 0


#: Effects that came later, off by default: recorded in ``custom_data`` only when set, so a drive
#: simulated without them is the very bag it was before (rosbag2 keeps the metadata in the
#: MCAP file too).
_RECORDED_WHEN_SET = ('simulator.gnss.noise', 'simulator.speed_scale_error',
                      'simulator.spring_progression', 'simulator.bump_stop_clearance',
                      'simulator.bump_stop_stiffness', 'simulator.sensor_scale_error.deflection',
                      'simulator.sensor_scale_error.roll', 'simulator.sensor_offset.deflection',
                      'simulator.sensor_offset.roll', 'simulator.stamp_jitter')


def _recorded_parameters(used: dict) -> dict:
    """The parameters for ``custom_data``: all but those of :data:`_RECORDED_WHEN_SET` at
    their defaults (a reader takes the default for a missing one)."""
    from road_force_estimator.core.parameters import SPECS

    return {k: v for k, v in used.items()
            if not (k in _RECORDED_WHEN_SET and v == SPECS[k].default)}


def twist_speed(speed_mps, sim):
    """The speed the twist carries (m/s): the true one times ``1 + speed_scale_error`` (the
    very values when the error is 0)."""
    if sim.speed_scale_error == 0.0:
        return speed_mps
    return np.asarray(speed_mps, dtype=float) * (1.0 + sim.speed_scale_error)


def _written_here(custom: dict[str, str]) -> bool:
    """A bag's ``custom_data`` says simulate_bag wrote it."""
    return custom.get('road_force_estimator.writer_command') == PROG


def _travel_m(sim, profile) -> float:
    """The distance (m) the drive covers in simulator.duration: constant speed, or the
    integral of the speed profile ``(time_s, speed_mps)``."""
    from road_force_estimator.core.speed_profile import profile_distance, speed_knots

    if profile is None:
        return sim.speed_mps * sim.duration_s
    return profile_distance(speed_knots(*profile), sim.duration_s)


def _speed_text(sim) -> str:
    """The speed of the summary line: constant, or the profile's file."""
    return f'{sim.speed_mps:g} m/s' if not sim.speed_profile else \
        f'the speed profile {sim.speed_profile}'


if __name__ == '__main__':
    sys.exit(main())
