"""Issue 20's other identification: a frequency-domain fit of the linear model's transfer
functions, on the drives of :mod:`bench.studies.calibration` (same seeds: the same trucks and
drives).

    python -m bench.studies.calibration_frequency [--repeats N] [--first R] [--rate HZ] [--duration
                                          S] [--roads 1|2] [--nperseg-s S] [--band LO HI]
                                          [--friction N] [--time-domain]

``--friction N``: the trucks have a leaf-spring friction of N per side (what no linear
transfer function has); ``--time-domain``: the time-domain calibration
(:func:`~road_force_estimator.calibration.calibrate.calibrate`, the friction freed with
``--friction``) of the same drives beside, errors and time.

Per drive, from the data only (no truth, nothing from the time-domain fit):

1. Alignment as :func:`~road_force_estimator.calibration.calibrate.calibrate` does it: the
   observer's profile (nominal parameters) cross-correlated with the enveloped survey
   (:func:`~road_force_estimator.calibration.alignment.align`).
2. The H1 estimate ``H = S_yu S_uu^-1`` of the transfer functions road (left, right; one input
   on a single-track survey) -> (q_1, q_2, phi), Welch's averaging (Hann, ``--nperseg-s`` s
   segments, half overlap), and each output's residual spectrum
   ``S_nn = S_yy - H S_uy`` (the part not coherent with the road).
3. Least squares on ``(H_model - H) / se`` over the band, ``se = sqrt(S_nn [S_uu^-1]_jj /
   n_d)`` each element's standard error (coherence weighting: ``n_d`` Welch segments): to
   first order the log magnitude and phase errors ``log(H_model / H)`` weighted by
   ``|H| / se``, without their singularity where an element of the model vanishes (the roll
   of a left-right symmetric truck, the nominal start, on a single-track survey). Free: every
   physical parameter of the linear model but the left tire stiffness (the force scale, as
   in the time-domain fit, then fixed by the static load), and a pure delay (the fine
   alignment: a position error of ``d`` m delays the road by ``d / v``). The model is
   ``C (i w - A)^-1 (B_u + i w B_du)`` of
   :func:`~road_force_estimator.calibration.model.linear_plant`: the linearised
   plant, without the roll's sin / cos, the gravity moment's nonlinearity, the tire's
   lift-off, friction or a sensor lag (what the time-domain fit carries through the plant's
   defect).

Prints per parameter the worst and RMS error over the repeats and the fit's time (alignment
included). :mod:`bench.studies.calibration` ``--frequency-domain`` runs the same fit beside the
time-domain calibration of each drive.

What it found: docs/notes/calibration_frequency.md.
"""
from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np
from scipy import optimize, signal

from road_force_estimator.bagio import road_from_source
from road_force_estimator.core.parameters import GRAVITY_MPS2, ObserverParameters
from road_force_estimator.core.parameters import VehicleParameters
from road_force_estimator.estimation import estimate_batch
from road_force_estimator.calibration.alignment import align
from road_force_estimator.calibration.model import (
    SLOTS, linear_plant, slot_value, vehicle_with)

PHYSICAL = [s for s in SLOTS if s.physical]
ENVELOPE = 0.25


def spectra(u: np.ndarray, y: np.ndarray, fs: float, nperseg: int):
    """Welch cross-spectra: (f, S_uu (nf, k, k), S_yu (nf, c, k), S_yy (nf, c), segments).

    ``S_ab[i, j] = E[conj(a_i) b_j]`` (scipy's ``csd(a_i, b_j)``)."""
    k, c = u.shape[1], y.shape[1]
    kw = {'fs': fs, 'nperseg': nperseg, 'window': 'hann', 'noverlap': nperseg // 2}
    f = signal.csd(u[:, 0], u[:, 0], **kw)[0]
    suu = np.empty((f.size, k, k), complex)
    syu = np.empty((f.size, c, k), complex)
    syy = np.empty((f.size, c))
    for i in range(k):
        for j in range(k):
            suu[:, i, j] = signal.csd(u[:, i], u[:, j], **kw)[1]
        for m in range(c):
            syu[:, m, i] = signal.csd(u[:, i], y[:, m], **kw)[1]
    for m in range(c):
        syy[:, m] = signal.csd(y[:, m], y[:, m], **kw)[1].real
    segments = 1 + (u.shape[0] - nperseg) // (nperseg - nperseg // 2)
    return f, suu, syu, syy, segments


def h1(suu, syu, syy, segments):
    """(H (nf, c, k), standard error of each element (nf, c, k), coherence (nf, c))."""
    inv = np.linalg.inv(suu.transpose(0, 2, 1))              # S_yu = H S_uu^T
    h = np.einsum('fcj,fji->fci', syu, inv)
    coherent = np.einsum('fci,fci->fc', np.conj(h), syu).real   # the road's part of S_yy
    snn = np.maximum(syy - coherent, 1e-12 * syy)
    se = np.sqrt(snn[:, :, None] * np.abs(np.diagonal(inv, axis1=1, axis2=2))[:, None, :]
                 / max(segments, 1))
    return h, se, coherent / syy


def model_h(vehicle: VehicleParameters, w: np.ndarray, one_track: bool) -> np.ndarray:
    """The linear model's transfer functions (nf, 3, k) road -> (q_1, q_2, phi) at ``w``."""
    plant = linear_plant(vehicle)
    b = plant.inputs[:, :2] + 1j * w[:, None, None] * plant.inputs[:, 2:4]   # (nf, 8, 2)
    h = np.einsum('cm,fm,fmi->fci', plant.outputs, 1.0 / (1j * w[:, None] - plant.eig), b)
    return h.sum(axis=2, keepdims=True) if one_track else h


def drive_alignment(stamps, q, roll, speed, road, nominal):
    """The alignment as the time-domain calibration finds it (nominal observer, enveloped
    survey, start searched +- 50 m from the survey's start)."""
    est = estimate_batch(stamps, q, roll, speed, nominal, ObserverParameters())
    dt = float(np.median(np.diff(stamps))) * 1e-9
    s = np.broadcast_to(np.asarray(speed, float), stamps.shape)
    distance = np.concatenate(([0.0], np.cumsum(0.5 * (s[1:] + s[:-1]) * dt)))
    return align(distance[est.valid], est.road_m[est.valid], road, start_m=road.start_m), \
        distance


def frequency_fit(stamps, q, roll, speed, survey, nominal: VehicleParameters,
                  static_load_n, *, nperseg_s: float = 16.0, band=(0.5, 30.0)):
    """The transfer-function fit of one drive: (values by slot, info dict); module notes."""
    clock, cpu = time.perf_counter(), time.process_time()
    road = survey.enveloped(ENVELOPE)
    alignment, distance = drive_alignment(stamps, q, roll, speed, road, nominal)
    x = alignment.survey_m(distance)
    inside = (x > road.start_m + 1.0) & (x < road.end_m - 1.0)
    u = road.elevation_at(x[inside])
    y = np.column_stack([q[inside], roll[inside]])
    fs = 1e9 / float(np.median(np.diff(stamps)))
    one_track = bool(np.allclose(u[:, 0], u[:, 1]))
    if one_track:
        u = u[:, :1]
    nper = int(min(u.shape[0] // 4, round(nperseg_s * fs)))
    f, suu, syu, syy, segments = spectra(u, y, fs, nper)
    keep = (f >= band[0]) & (f <= min(band[1], 0.4 * fs))
    h_est, se, coherence = h1(suu[keep], syu[keep], syy[keep], segments)
    w = 2.0 * math.pi * f[keep]
    free = [s for s in PHYSICAL if not (s.name == 'vehicle.tire_stiffness' and s.index == 0)
            and slot_value(nominal, s) > 0.0 and not s.plant_only]
    fixed = {s: slot_value(nominal, s) for s in PHYSICAL if s not in free}
    v = float(np.mean(np.asarray(speed, float))) * alignment.scale

    def values_of(theta):
        out = dict(fixed)
        out.update({s: slot_value(nominal, s) * math.exp(t) for s, t in zip(free, theta)})
        return out

    def residuals(theta):
        h = model_h(vehicle_with(nominal, values_of(theta[:-1])), w, one_track)
        h = h * np.exp(-1j * w * theta[-1] / v)[:, None, None]
        r = (h - h_est) / se      # = log(h / h_est) |h_est| / se to first order
        return np.concatenate([r.real.ravel(), r.imag.ravel()])

    span = math.log(10.0)
    lo = np.r_[np.full(len(free), -span), -1.0]
    hi = np.r_[np.full(len(free), span), 1.0]
    sol = optimize.least_squares(residuals, np.zeros(len(free) + 1), method='trf',
                                 x_scale='jac', bounds=(lo, hi), ftol=1e-12, xtol=1e-12,
                                 gtol=1e-12)
    values = values_of(sol.x[:-1])
    masses = sum(val for s, val in values.items()
                 if s.name in ('vehicle.sprung_mass', 'vehicle.unsprung_mass'))
    factor = (static_load_n[0] + static_load_n[1]) / GRAVITY_MPS2 / masses
    scaled = {s: (val * factor if s.kind == 'scale' else val) for s, val in values.items()}
    chi2 = float(np.sum(sol.fun ** 2)) / max(sol.fun.size - sol.x.size, 1)
    return scaled, {'seconds': time.perf_counter() - clock,
                    'cpu_s': time.process_time() - cpu, 'delay_m': float(sol.x[-1]),
                    'alignment': alignment, 'chi2': chi2, 'bins': int(w.size),
                    'segments': segments, 'coherence_min': float(np.min(coherence)),
                    'free': [s.label for s in free], 'nfev': int(sol.nfev)}


def _truck(r: int, friction_n: float) -> VehicleParameters:
    from bench.studies import calibration as bc
    truck = bc.random_truck(100 + r)
    if friction_n > 0.0:
        params = truck.to_parameters()
        params['vehicle.leaf_spring_friction'] = [friction_n, friction_n]
        truck = VehicleParameters.from_parameters(params)
    return truck


def _cases(args):
    """(repeat, road name, truck, drive) of :mod:`bench.studies.calibration`'s protocol."""
    from bench.studies import calibration as bc
    roads = [('ISO 8608 C', road_from_source('iso8608:C:seed=11', length_m=1400.0)),
             ('profile_1.txt', road_from_source(bc.profile_1()))]
    for r in range(args.first, args.first + args.repeats):
        truck = _truck(r, args.friction)
        for k, (name, road) in enumerate(roads[:args.roads]):
            seed = 10 * r + k
            rng = np.random.default_rng(seed + 1000)
            start = road.start_m + ENVELOPE + rng.uniform(20.0, 45.0)
            duration = min(args.duration, (road.end_m - start - 2.0) / bc.SPEED - 0.5)
            _, stamps, q, roll = bc.drive(truck, road, start_m=start, duration_s=duration,
                                          rate_hz=args.rate, seed=seed)
            yield r, name, road, truck, (stamps, q, roll,
                                         np.full(stamps.size, bc.SPEED / bc.ODOMETER))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog='bench.studies.calibration_frequency',
                                description=__doc__.split('\n')[0])
    p.add_argument('--repeats', type=int, default=5)
    p.add_argument('--first', type=int, default=0, help='first repeat (seed) index')
    p.add_argument('--rate', type=float, default=1000.0)
    p.add_argument('--duration', type=float, default=60.0)
    p.add_argument('--roads', type=int, default=2, choices=(1, 2))
    p.add_argument('--nperseg-s', type=float, default=16.0, help='Welch segment (s)')
    p.add_argument('--band', type=float, nargs=2, default=(0.5, 30.0), metavar=('LO', 'HI'))
    p.add_argument('--friction', type=float, default=0.0, metavar='N',
                   help='leaf-spring friction of the trucks, per side (N)')
    p.add_argument('--time-domain', action='store_true',
                   help='also the time-domain calibration of each drive')
    args = p.parse_args(argv)
    print('bench.studies.calibration_frequency: repeats '
          f'{args.first}..{args.first + args.repeats - 1}'
          f' at {args.rate:g} Hz, drives up to {args.duration:g} s, Welch {args.nperseg_s:g} s,'
          f' band {args.band[0]:g}-{args.band[1]:g} Hz')
    table: dict[tuple[str, str], dict[str, list[float]]] = {}
    times: dict[tuple[str, str], list[float]] = {}
    for r, name, road, truck, data in _cases(args):
        values, info = frequency_fit(*data, road, VehicleParameters(), truck.static_load_n,
                                     nperseg_s=args.nperseg_s, band=tuple(args.band))
        found = {'frequency': (values, info['seconds'])}
        print(f"repeat {r}, {name}: frequency fit {info['seconds']:.1f} s ({info['cpu_s']:.1f} s "
              f"CPU), {info['bins']} bins"
              f" x {info['segments']} segments, min coherence {info['coherence_min']:.3f}, "
              f"chi2/dof {info['chi2']:.2f}, delay {100 * info['delay_m']:+.1f} cm")
        if args.time_domain:
            found['time'] = _time_domain(data, road, truck, args.friction)
        for method, (vals, seconds) in found.items():
            err = {s.label: 100.0 * (vals[s] / slot_value(truck, s) - 1.0) for s in PHYSICAL
                   if s in vals and slot_value(truck, s) > 0.0}
            print(f'  {method}: ' + ', '.join(f'{k.replace("vehicle.", "")} {e:+.3f}'
                                             for k, e in err.items()))
            for k, e in err.items():
                table.setdefault((name, method), {}).setdefault(k, []).append(e)
            times.setdefault((name, method), []).append(seconds)
        sys.stdout.flush()
    _print_table(table, times)
    return 0


def _time_domain(data, road, truck, friction_n):
    """The time-domain calibration of one drive: (values by slot, seconds)."""
    from road_force_estimator.calibration.calibrate import CalibrationOptions, calibrate
    free = frozenset({'vehicle.leaf_spring_friction'}) if friction_n > 0.0 else frozenset()
    clock, cpu = time.perf_counter(), time.process_time()
    result = calibrate(*data, road, VehicleParameters(),
                       options=CalibrationOptions(static_load_n=truck.static_load_n, free=free))
    values = {e.slot: e.value for e in result.parameters if e.slot.physical}
    seconds = time.perf_counter() - clock
    print(f'  time-domain calibration {seconds:.1f} s ({time.process_time() - cpu:.1f} s CPU)')
    return values, seconds


def _print_table(table, times) -> None:
    for (name, method), rows in table.items():
        n = len(times[(name, method)])
        print(f'\n{name}, {method}-domain fit over {n} drives: median '
              f'{np.median(times[(name, method)]):.1f} s')
        print('| parameter | worst error % | RMS error % |')
        print('|---|---|---|')
        for k, e in rows.items():
            a = np.abs(e)
            print(f'| {k} | {a.max():.3f} | {math.sqrt(np.mean(a ** 2)):.3f} |')


if __name__ == '__main__':
    sys.exit(main())
