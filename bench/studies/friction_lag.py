"""Friction and a sensor lag together, both stated in the parameter file (issue 30): the load
error at zero latency, at 10 ms and offline against the matched drive (no friction, no lag).

``.venv/bin/python -m bench.studies.friction_lag [--duration S] [--road-seeds N ...] [--only NAME
...] [--decompose | --whole-vehicle | --fit-detail | --fit-bias]``

Drives (:func:`bench.studies.truck_effects.build`): ISO 8608 class C, 20 m/s, 1 kHz, 10 um of
deflection noise (100 urad of roll), the scoring of :func:`bench.accuracy.scenarios.score` (load
error in % of the true dynamic-load RMS after the 2 s skip), per road seed (default 1, 2, 3):

- ``matched``: the nominal truck and file;
- ``friction``: 1.5 kN of leaf-spring friction per spring, stated in the file;
- ``lag``: a 3 ms first-order lag of every sensor, stated in the file;
- ``friction+lag``: both, stated in the file (the truth's tanh ``v_f`` = 0.01 m/s, the
  package's);
- ``friction+lag, truth v_f 0.005``: the same truck whose friction is steeper (the plant's
  ``vehicle.leaf_spring_friction_velocity`` 0.005 m/s), the file as before (the package's
  0.01);
- ``friction, truth v_f 0.005``: the friction alone with that steeper truth;
- ``... , file v_f 0.005``: those two drives again with the file stating the truth's v_f
  (``vehicle.leaf_spring_friction_velocity`` 0.005 in the observer's file too): what is left
  when the law is right.

Then where the cost comes from: the forward filter's posterior std of the suspension rate
(its design at 10 um and 20 m/s) without and with the lag, and on the ``friction+lag`` drive
(road seed 1) the 10 ms load error where the true rate is below 2 cm/s (the spring near
sticking) and elsewhere.

``--decompose``: where the cost of the sharper truth comes from, per drive (road seed 1) at
10 ms: the load error, the smoothed rate's error against the truth's (mm/s), the friction
force's error (the file's law at the estimated rate against the truth's law at the truth's
rate, N RMS per spring) and the part of it that is the law's own (the file's law at the
truth's rate); then, on the road seeds given, the causal candidates for the friction input:
the tanh law's expectation over the rate's Gaussian error, ``tanh(m / sqrt(v_f^2 + pi/2 s^2))``,
with s the forward filter's posterior std (``expect-forward``) or the fixed-lag estimate's
(``expect-correction``, at each delayed correction's lag), and the equivalent damping's
factor at 10 ms (``damping F``; the package's 0.5), against the package's law; and how
fast a causal v_f fit could decide: the innovations' log-likelihood lead (nats) of each v_f of
:data:`road_force_estimator.estimation.friction_fit.FIT_GRID` over the file's, zero-latency
filters over the drive's first seconds (as ``observer.friction_velocity_fit`` offline),
and what switching once at that moment could give at most: the 10 ms loads of the file's v_f
before it and of the truth's after it, spliced (the switch's transient ignored).

``--whole-vehicle``: the same question on MODEL.md's tractor and semi-trailer (the drives of
:mod:`bench.accuracy.articulated_wim`'s ``friction`` part: class C, road seed 1, 20 m/s,
zero-load readings, the payload unknown, ``--duration`` s), at 10 ms: per axle the
dynamic-load error with neither, with the 3 ms lag, with both (v_f 0.01), and with the
truth's v_f 0.005 against the file's 0.01 and told it, each against the drive with neither.
Then offline (the file's truck read from the equilibrium: the fit does not run under
``zero_load``): neither, friction + lag and the truth's v_f 0.005 with the offline v_f fit
(``observer.friction_velocity_fit`` 1, the default) and without it (0), and told it, with
the v_f the smoother took and each estimate's wall time. Then whether the lag's cost is the
information's (``--whole-vehicle``'s second table): the
same class C drives with the file's vehicle and readings from the equilibrium (no payload
change, no zero-load readings, so that the peer's model is the truth's), neither and the lag,
ours at 10 ms beside :class:`bench.accuracy.articulated_peer.ArticulatedKalmanPeer` at its
exact 10-sample fixed lag, tuned on the truth, with a lag state per channel on the lag drive
(the plant's discrete lag exactly): per axle each one's lag / neither ratio. Last, why not
under ``zero_load``: the v_f the fit would take on the first table's zero-load drives, on
the static-load tracker's readings.

``--fit-bias``: the front axle's fit per drive and road seed (:func:`fit_bias`): with a lag the
zero-latency likelihood leans sharper than the truth, so the file's v_f stands unless the
likeliest leads it by ``FIT_LEAD_NATS``.

``--fit-detail``: the whole vehicle's fit per v_f tried (:func:`fit_detail`): the samples
converged and summed, each v_f's nll less the likeliest's and the nll a sample, on the
test's drives (``test/estimation/test_whole_vehicle_friction_fit.py``), 8 s of them with
the lag and the offline table's drive.

Target (issue 30): ``friction+lag`` and ``friction+lag, truth v_f 0.005`` within 1.3 x the
matched drive at 10 ms and offline. Prints a Markdown table: per drive the errors (mean over
the seeds) and the ratio to the matched drive (the mean of the per-seed ratios, and the
worst seed's).

What it found: docs/notes/friction_lag.md.
"""
from __future__ import annotations

import argparse
from dataclasses import replace
import sys
import time

import numpy as np

from road_force_estimator.core.parameters import VehicleParameters
from road_force_estimator.estimation.friction_fit import FIT_LEAD_NATS

NOMINAL = VehicleParameters()
FRICTION = replace(NOMINAL, leaf_spring_friction_n=(1500.0, 1500.0))
LAG = replace(NOMINAL, sensor_time_constant_s=(0.003, 0.003))
BOTH = replace(FRICTION, sensor_time_constant_s=(0.003, 0.003))
#: (name, the truck (plant) = the file the observer is given, the plant's v_f (m/s), the
#: observer's v_f (m/s))
DRIVES = (
    ('matched', NOMINAL, 0.01, 0.01),
    ('friction', FRICTION, 0.01, 0.01),
    ('lag', LAG, 0.01, 0.01),
    ('friction+lag', BOTH, 0.01, 0.01),
    ('friction, truth v_f 0.005', FRICTION, 0.005, 0.01),
    ('friction+lag, truth v_f 0.005', BOTH, 0.005, 0.01),
    ('friction, truth v_f 0.005, file v_f 0.005', FRICTION, 0.005, 0.005),
    ('friction+lag, truth v_f 0.005, file v_f 0.005', BOTH, 0.005, 0.005),
)
MODES = ('online', '10 ms', 'offline')
TARGET = 1.3
JUDGED = ('friction+lag', 'friction+lag, truth v_f 0.005')


def build(truck: VehicleParameters, v_f: float, duration_s: float, road_seed: int):
    """The drive of ``truck`` on class C (road seed ``road_seed``, noise seed 100 + it) with
    the plant's friction velocity ``v_f`` (m/s, ``vehicle.leaf_spring_friction_velocity``)."""
    from bench.studies import truck_effects

    return truck_effects.build('C', replace(truck, leaf_spring_friction_velocity_mps=v_f),
                               duration_s, road_seed - 1, road_seed=road_seed)


def measure(duration_s: float, road_seeds, only=None, log=None) -> dict:
    """``{drive: {seed: {mode: error (% dyn)}}}``."""
    from bench.studies import truck_effects

    out: dict = {}
    for name, truck, v_f, v_obs in DRIVES:
        if only and name not in only and name != 'matched':
            continue
        out[name] = {}
        for seed in road_seeds:
            t0 = time.perf_counter()
            drive = build(truck, v_f, duration_s, seed)
            out[name][seed] = truck_effects.errors(
                drive, replace(truck, leaf_spring_friction_velocity_mps=v_obs))
            if log:
                log(f'.. {name}, road seed {seed}: ' + ', '.join(
                    f'{m} {out[name][seed][m]:.2f} %' for m in MODES)
                    + f' ({time.perf_counter() - t0:.0f} s)')
    return out


def table(res: dict) -> list[str]:
    """The Markdown table of :func:`measure`'s result."""
    ref = res['matched']
    lines = ['| drive | ' + ' | '.join(f'{m} (% dyn)' for m in MODES)
             + ' | ratio to matched, mean (worst seed): ' + ' / '.join(MODES) + ' |',
             '|---|' + '---:|' * len(MODES) + '---|']
    verdicts = []
    for name, per_seed in res.items():
        seeds = list(per_seed)
        mean = {m: float(np.mean([per_seed[s][m] for s in seeds])) for m in MODES}
        ratios = {m: [per_seed[s][m] / ref[s][m] for s in seeds] for m in MODES}
        cells = ' / '.join(f'{np.mean(ratios[m]):.2f} ({max(ratios[m]):.2f})' for m in MODES)
        lines.append(f'| {name} | ' + ' | '.join(f'{mean[m]:.2f}' for m in MODES)
                     + f' | {cells} |')
        if name in JUDGED:
            worst = max(max(ratios['10 ms']), max(ratios['offline']))
            verdicts.append(f'{name}: worst seed {worst:.2f} x matched at 10 ms / offline '
                            f'({"MET" if worst <= TARGET else "NOT MET"}, target {TARGET:g})')
    return lines + [''] + [f'- {v}' for v in verdicts]


def diagnostics(duration_s: float) -> list[str]:
    """The rate's posterior std with and without the lag, and the split of the 10 ms load
    error of the ``friction+lag`` drive (road seed 1) by the true rate."""
    from bench.accuracy.run_benchmark import per_sample
    from road_force_estimator.core.parameters import ObserverParameters
    from road_force_estimator.estimation import estimate_batch
    from road_force_estimator.estimation.models.front_axle import FrontAxleModel, State
    from road_force_estimator.estimation.observer.schedule import GainSchedule, dt_level

    stds = []
    for truck in (FRICTION, BOTH):
        sched = GainSchedule(FrontAxleModel(truck), ObserverParameters(noise_deflection_m=1e-5,
                                                       noise_roll_rad=1e-4))
        sched.set_speed(20.0)
        sched.levels['dt'] = dt_level(1e-3)
        g = sched.design(1e-3, 0)
        stds.append(1000.0 * float(np.sqrt(g.p_post[State.DQ1, State.DQ1])))
    lines = ['- The forward filter posterior std of dq_1 (10 um, 20 m/s): '
             f'{stds[0]:.1f} mm/s without the lag, {stds[1]:.1f} mm/s with the 3 ms lag.']
    drive = build(BOTH, 0.01, duration_s, 1)
    est = per_sample(estimate_batch(drive.stamps_ns, drive.q_m, drive.roll_rad,
                                    drive.speed_mps, BOTH,
                                    ObserverParameters(latency_s=0.01)), drive.stamps_ns)
    k0 = drive.skip
    err = (np.asarray(est.wheel_load_n) - drive.truth['wheel_load_n'])[k0:]
    dq = np.abs(np.gradient(drive.truth['q_m'], drive.t_s, axis=0))[k0:]
    slow = dq < 0.02
    lines.append(f'- friction+lag, road seed 1, 10 ms: load error RMS '
                 f'{np.sqrt(np.mean(err[slow] ** 2)):.0f} N where |dq| < 2 cm/s '
                 f'({100 * slow.mean():.0f} % of the samples), '
                 f'{np.sqrt(np.mean(err[~slow] ** 2)):.0f} N elsewhere.')
    return lines


#: The drives of the decomposition: (name, its truth, the plant's v_f, the file's v_f).
DECOMPOSED = (
    ('matched', NOMINAL, 0.01, 0.01),
    ('lag', LAG, 0.01, 0.01),
    ('friction', FRICTION, 0.01, 0.01),
    ('friction+lag', BOTH, 0.01, 0.01),
    ('friction, truth v_f 0.005, file v_f 0.005', FRICTION, 0.005, 0.005),
    ('friction, truth v_f 0.005', FRICTION, 0.005, 0.01),
    ('friction+lag, truth v_f 0.005, file v_f 0.005', BOTH, 0.005, 0.005),
    ('friction+lag, truth v_f 0.005', BOTH, 0.005, 0.01),
)
#: The causal candidates for the friction input (:func:`candidate`).
CANDIDATES = ('package', 'expect-forward', 'expect-correction', 'damping 0.25', 'damping 1')
#: The spread of the rate's error in the law's expectation: ``E[tanh(dq / v)]`` over dq ~ N(m,
#: s^2) ~ ``tanh(m / sqrt(v^2 + pi/2 s^2))`` (tanh ~ erf(sqrt(pi) x / 2) and the probit
#: integral).
RATE_SPREAD = np.pi / 2
#: The log-likelihood lead (nats) taken as a decision of a causal fit (:func:`fit_lead`): the
#: offline fit's own.
LEAD_NATS = FIT_LEAD_NATS


def _estimate(drive, vehicle: VehicleParameters, latency_s: float):
    from bench.accuracy.run_benchmark import per_sample
    from road_force_estimator.core.parameters import ObserverParameters
    from road_force_estimator.estimation import estimate_batch

    est = estimate_batch(drive.stamps_ns, drive.q_m, drive.roll_rad, drive.speed_mps, vehicle,
                         ObserverParameters(latency_s=latency_s))
    return est, per_sample(est, drive.stamps_ns)


def decompose(duration_s: float) -> list[str]:
    """The 10 ms figures of :data:`DECOMPOSED` on road seed 1 (Markdown table rows)."""
    from bench.accuracy.scenarios import score

    lines = ['| drive (10 ms, road seed 1) | load error (% dyn) | ratio to matched | rate error '
             '(mm/s) | friction error (N) | of it the law at the true rate (N) |',
             '|---|---:|---:|---:|---:|---:|']
    ref = None
    for name, truck, v_true, v_file in DECOMPOSED:
        drive = build(truck, v_true, duration_s, 1)
        est, ps = _estimate(drive, replace(truck, leaf_spring_friction_velocity_mps=v_file),
                            0.01)
        err = score(drive, ps)['load_rms_pct_dyn']
        ref = err if ref is None else ref
        k0 = drive.skip
        dq_true = np.gradient(drive.truth['q_m'], drive.t_s, axis=0)[k0:]
        dq_est = np.asarray(est.dq)[k0:]
        f_n = float(truck.leaf_spring_friction_n[0])
        f_true = -f_n * np.tanh(dq_true / v_true)
        f_est = -f_n * np.tanh(dq_est / v_file)
        f_law = -f_n * np.tanh(dq_true / v_file)
        rms = lambda a: float(np.sqrt(np.mean(a ** 2)))     # noqa: E731
        lines.append(f'| {name} | {err:.2f} | {err / ref:.3f} | '
                     f'{1000 * rms(dq_est - dq_true):.1f} | {rms(f_est - f_true):.0f} | '
                     f'{rms(f_law - f_true):.0f} |')
    return lines


class candidate:
    """Within it, the observer's friction input is the candidate ``name`` of
    :data:`CANDIDATES` (public methods of :class:`.observer.friction.KnownFriction` wrapped;
    put back on exit)."""

    def __init__(self, name: str) -> None:
        self.name = name

    def __enter__(self):
        from road_force_estimator.estimation.observer.friction import KnownFriction

        from road_force_estimator.estimation.models import leaf_friction

        self.saved = (KnownFriction.select, KnownFriction.update, KnownFriction.correction)
        self.factor = leaf_friction.FRICTION_DAMPING_FACTOR_LATENCY
        if self.name.startswith('damping '):     # the equivalent damping's factor at 10 ms
            leaf_friction.FRICTION_DAMPING_FACTOR_LATENCY = float(self.name.split()[1])
        if self.name == 'package' or self.name.startswith('damping '):
            return self
        select, update, correction = self.saved

        def law(fr, velocities):
            f_n = np.asarray(fr.model_friction_n)
            v = np.asarray(velocities)

            def forces(dq, ceq):
                dq = np.asarray(dq, dtype=float)
                return -f_n * np.tanh(dq / v) + np.asarray(ceq) * dq
            return forces

        def spread(fr, p):
            s2 = np.maximum(np.diag(p)[list(fr.rates)], 0.0)
            return np.sqrt(fr.v_f ** 2 + RATE_SPREAD * s2)

        def new_select(fr, g, dt):
            # the forward filter's law (posterior std) and each lag's, of the gains g
            select(fr, g, dt)
            if not hasattr(fr, 'package_law'):
                fr.package_law = fr.law
                fr.v_f = fr.package_law.__self__.friction_velocity_mps
                fr.model_friction_n = fr.package_law.__self__.friction_n
            if getattr(fr, 'laws_of', None) is not g:
                fr.laws_of, fr.lag_laws = g, {}
                fr.forward_law = law(fr, spread(fr, g.p_post))

        def lag_law(fr, g, lag):
            if lag not in fr.lag_laws:
                p = g.p_post.copy()
                for i in range(min(lag, g.lag_gains.shape[0])):
                    b = g.lag_gains[i]
                    p -= b @ g.s @ b.T
                fr.lag_laws[lag] = law(fr, spread(fr, p))
            return fr.lag_laws[lag]

        def new_update(fr, sv, x):
            if self.name != 'expect-forward':
                return update(fr, sv, x)
            fr.law = fr.forward_law
            try:
                return update(fr, sv, x)
            finally:
                fr.law = fr.package_law

        def new_correction(fr, g, dt, lag, index, dq):
            if self.name != 'expect-correction':
                return correction(fr, g, dt, lag, index, dq)
            fr.law = lag_law(fr, g, lag)
            try:
                return correction(fr, g, dt, lag, index, dq)
            finally:
                fr.law = fr.package_law

        KnownFriction.select, KnownFriction.update = new_select, new_update
        KnownFriction.correction = new_correction
        return self

    def __exit__(self, *exc) -> None:
        from road_force_estimator.estimation.models import leaf_friction
        from road_force_estimator.estimation.observer.friction import KnownFriction

        KnownFriction.select, KnownFriction.update, KnownFriction.correction = self.saved
        leaf_friction.FRICTION_DAMPING_FACTOR_LATENCY = self.factor


def candidates(duration_s: float, road_seeds) -> list[str]:
    """The 10 ms ratio to the matched drive per candidate (:data:`CANDIDATES`) on the
    ``friction+lag`` drives (Markdown table rows)."""
    from bench.accuracy.scenarios import score

    drives = [('friction+lag', BOTH, 0.01, 0.01),
              ('friction+lag, truth v_f 0.005', BOTH, 0.005, 0.01),
              ('friction+lag, truth v_f 0.005, file v_f 0.005', BOTH, 0.005, 0.005)]
    ref = {s: score(d, _estimate(d, NOMINAL, 0.01)[1])['load_rms_pct_dyn']
           for s, d in ((s, build(NOMINAL, 0.01, duration_s, s)) for s in road_seeds)}
    lines = ['| drive (10 ms) | ' + ' | '.join(CANDIDATES) + ' |',
             '|---|' + '---:|' * len(CANDIDATES)]
    for name, truck, v_true, v_file in drives:
        ratios = {c: [] for c in CANDIDATES}
        for s in road_seeds:
            drive = build(truck, v_true, duration_s, s)
            for c in CANDIDATES:
                with candidate(c):
                    _, ps = _estimate(
                        drive, replace(truck, leaf_spring_friction_velocity_mps=v_file), 0.01)
                ratios[c].append(score(drive, ps)['load_rms_pct_dyn'] / ref[s])
        lines.append(f'| {name} | ' + ' | '.join(
            f'{np.mean(ratios[c]):.3f} ({max(ratios[c]):.3f})' for c in CANDIDATES) + ' |')
    return lines


def fit_lead(duration_s: float, road_seeds, chunk_s: float = 0.5) -> list[str]:
    """When the truth's v_f leads the file's by :data:`LEAD_NATS` in the innovations'
    log-likelihood (zero-latency filters, one per v_f of the offline fit's grid), per drive
    and road seed."""
    from road_force_estimator.core.parameters import ObserverParameters
    from road_force_estimator.estimation.estimator import BatchRun
    from road_force_estimator.estimation.friction_fit import FIT_GRID

    lines = []
    for name, truck, v_true in (('friction+lag, truth v_f 0.005', BOTH, 0.005),
                                ('friction+lag', BOTH, 0.01)):
        for s in road_seeds:
            drive = build(truck, v_true, duration_s, s)
            n, step = drive.stamps_ns.size, int(round(chunk_s * drive.scenario.rate_hz))
            traces = {}
            for factor in FIT_GRID:
                run = BatchRun(replace(truck, leaf_spring_friction_velocity_mps=0.01 * factor),
                               ObserverParameters())
                terms = run.estimator.core.nll_terms = []
                trace = []
                for a in range(0, n, step):
                    run.feed(drive.stamps_ns[a:a + step], drive.q_m[a:a + step],
                             drive.roll_rad[a:a + step], drive.speed_mps[a:a + step])
                    trace.append(sum(v for _, v in terms))
                traces[factor] = np.asarray(trace)
            lead = {f: traces[1.0] - t for f, t in traces.items() if f != 1.0}
            best = max(lead, key=lambda f: lead[f][-1])
            over = np.flatnonzero(np.max(list(lead.values()), axis=0) >= LEAD_NATS)
            when = (f'first at {(over[0] + 1) * chunk_s:g} s' if over.size
                    else 'never')
            if lead[best][-1] > 0.0:
                at_end = (f'{0.01 * best:g} m/s, {lead[best][-1]:.0f} nats ahead of the '
                          "file's")
            else:
                at_end = f"the file's, {-lead[best][-1]:.0f} nats ahead of the next"
            line = (f'- {name}, road seed {s}: after {duration_s:g} s the likeliest v_f '
                    f'is {at_end}; any other v_f {LEAD_NATS:g} nats ahead of the '
                    f"file's: {when}")
            if over.size and v_true != 0.01:
                line += '; ' + _spliced(drive, truck, v_true, (over[0] + 1) * step, duration_s, s)
            lines.append(line)
    return lines


#: ``--fit-bias``'s front-axle drives: (name, the truck, the truth's v_f, the file's v_f)
FIT_BIAS_DRIVES = (
    ('friction+lag, truth 0.005, file 0.005', BOTH, 0.005, 0.005),
    ('friction+lag, truth 0.005, file 0.01', BOTH, 0.005, 0.01),
    ('friction, truth 0.005, file 0.005', FRICTION, 0.005, 0.005),
)


def fit_bias(duration_s: float, road_seeds) -> list[str]:
    """The ``--fit-bias`` table (Markdown rows): the front axle's offline v_f fit
    (:func:`road_force_estimator.estimation.offline.fit_friction_velocity`) per drive of
    :data:`FIT_BIAS_DRIVES` and road seed: each v_f's lead over the file's in the innovations'
    log-likelihood (nats, > 0 ahead), the likeliest, the v_f the rule takes (the likeliest
    only where it leads the file's by ``FIT_LEAD_NATS``), and the offline load error (% dyn)
    with the likeliest and with the rule's v_f (the fit then off, the same smoother)."""
    from bench.accuracy.run_benchmark import per_sample
    from bench.accuracy.scenarios import score
    from road_force_estimator.core.parameters import ObserverParameters
    from road_force_estimator.estimation import estimate_recording
    from road_force_estimator.estimation.offline import fit_friction_velocity

    lines = ["| drive (front axle, C, 20 m/s) | road seed | lead over the file's per v_f "
             '(nats) | the likeliest | taken | offline, the likeliest / taken (% dyn) |',
             '|---|---:|---|---:|---:|---|']
    for name, truck, v_true, v_file in FIT_BIAS_DRIVES:
        file_ = replace(truck, leaf_spring_friction_velocity_mps=v_file)
        for seed in road_seeds:
            d = build(truck, v_true, duration_s, seed)
            restart = np.zeros(d.stamps_ns.size, bool)
            restart[0] = True
            table: list = []
            taken = fit_friction_velocity(file_, ObserverParameters(), d.stamps_ns, d.q_m,
                                          d.roll_rad, d.speed_mps, restart, table)
            at_file = next(row[3] for row in table if row[0] == v_file)
            likeliest = min(table, key=lambda row: row[3])[0]
            pct = {}
            for v in {likeliest, taken.leaf_spring_friction_velocity_mps}:
                est = estimate_recording(
                    d.stamps_ns, d.q_m, d.roll_rad, d.speed_mps,
                    replace(truck, leaf_spring_friction_velocity_mps=v),
                    ObserverParameters(friction_velocity_fit=0))
                pct[v] = score(d, per_sample(est, d.stamps_ns))['load_rms_pct_dyn']
            v_taken = taken.leaf_spring_friction_velocity_mps
            lines.append(f'| {name} | {seed} | ' + ', '.join(
                f'{row[0]:g}: {at_file - row[3]:+.1f}' for row in table)
                + f' | {likeliest:g} | {v_taken:g} | {pct[likeliest]:.2f} / '
                f'{pct[v_taken]:.2f} |')
    return lines


def _spliced(drive, truck: VehicleParameters, v_true: float, k: int, duration_s: float,
             road_seed: int) -> str:
    """The 10 ms load error, relative to the matched drive's on the same road, of the file's
    v_f before sample k and the truth's from it (outputs spliced), beside each alone."""
    from types import SimpleNamespace

    from bench.accuracy.scenarios import score

    matched = build(NOMINAL, 0.01, duration_s, road_seed)
    ref = score(matched, _estimate(matched, NOMINAL, 0.01)[1])['load_rms_pct_dyn']
    _, file_ = _estimate(drive, truck, 0.01)
    _, told = _estimate(drive, replace(truck, leaf_spring_friction_velocity_mps=v_true), 0.01)
    load = np.array(file_.wheel_load_n)
    load[k:] = np.asarray(told.wheel_load_n)[k:]
    spliced = SimpleNamespace(stamp_ns=file_.stamp_ns, wheel_load_n=load, road_m=file_.road_m,
                              ltr=file_.ltr)
    ratio = {n: score(drive, e)['load_rms_pct_dyn'] / ref
             for n, e in (('file', file_), ('told', told), ('spliced', spliced))}
    return (f"10 ms: the file's v_f {ratio['file']:.3f} x matched, the truth's "
            f"{ratio['told']:.3f} x, switched there {ratio['spliced']:.3f} x")


def whole_vehicle(duration_s: float) -> list[str]:
    """The ``--whole-vehicle`` table (Markdown rows)."""
    from bench.accuracy import articulated_wim as wim

    both = {**wim.TANH, **wim.LAG}
    sharp = {'vehicle.leaf_spring_friction_velocity': 0.005}
    base = {**wim.ZERO_LOAD, 'vehicle.trailer.mass': 25000.0}
    drives = (('neither', {}, {}), ('lag', wim.LAG, wim.LAG), ('friction+lag', both, both),
              ('friction+lag, truth v_f 0.005', {**both, **sharp}, both),
              ('friction+lag, truth v_f 0.005, file v_f 0.005', {**both, **sharp},
               {**both, **sharp}))
    lines = ['| drive (whole vehicle, C, 10 ms) | front, drive, trailer_1..3 (% dyn) | '
             'x neither, per axle |', '|---|---|---|']
    ref = None
    sims = {}
    for name, plant, file_ in drives:
        drive = sims[name] = wim.simulate('C', duration_s, 1e-5, {**base, **plant})
        est = wim.estimate(wim.file_vehicle({**wim.ZERO_LOAD, **file_}), drive, 0.01, False)
        pct = wim.dynamic_pct(drive, est)
        ref = pct if ref is None else ref
        lines.append(f'| {name} | ' + ', '.join(f'{v:.2f}' for v in pct) + ' | '
                     + ', '.join(f'{v:.2f}' for v in pct / ref) + ' |')
    return (lines + [''] + whole_vehicle_offline(duration_s, both, sharp) + ['']
            + lag_limit(duration_s) + [''] + zero_load_fit(sims, both))


def _offline(vehicle, drive: dict, fit: int) -> tuple:
    """The whole vehicle offline (:class:`.WholeVehicleOfflineStream` in one block, as
    ``estimate_whole_vehicle``) with ``observer.friction_velocity_fit`` = ``fit``: the
    estimate, the v_f its smoother took (m/s) and the wall time (s)."""
    from road_force_estimator.core.parameters import ObserverParameters
    from road_force_estimator.estimation.whole_vehicle import (
        WholeVehicleOfflineStream, concatenate_arrays)

    t0 = time.perf_counter()
    stream = WholeVehicleOfflineStream(vehicle, ObserverParameters(friction_velocity_fit=fit),
                                       eager=False)
    stream.feed(drive['stamps'], drive['y'], drive['speed'])
    est = concatenate_arrays(list(stream.finish()))
    return est, stream.friction_velocity_mps, time.perf_counter() - t0


def whole_vehicle_offline(duration_s: float, both: dict, sharp: dict) -> list[str]:
    """The ``--whole-vehicle`` offline table (Markdown rows): the file's truck read from the
    equilibrium (the fit does not run under ``zero_load``), neither, friction + lag (v_f
    0.01), the truth's v_f 0.005 against the file's 0.01 and told it, offline with the v_f
    fit (``observer.friction_velocity_fit`` 1, the default) and without it (0): the v_f the
    smoother took, per axle the error and its ratio to neither's, the estimate's wall time."""
    from bench.accuracy import articulated_wim as wim

    sims = {name: wim.simulate('C', duration_s, 1e-5, plant) for name, plant in (
        ('neither', {}), ('friction+lag', both), ('sharp', {**both, **sharp}))}
    rows = (('neither', 'neither', {}, 1),
            ("friction+lag (v_f 0.01, the file's)", 'friction+lag', both, 1),
            ("friction+lag (v_f 0.01, the file's)", 'friction+lag', both, 0),
            ("the truth's v_f 0.005, the file's 0.01", 'sharp', both, 1),
            ("the truth's v_f 0.005, the file's 0.01", 'sharp', both, 0),
            ('the same, the file told 0.005', 'sharp', {**both, **sharp}, 0))
    lines = ["| drive (whole vehicle, the file's truck, C, offline) | v_f fit | v_f taken (m/s) "
             '| front, drive, trailer_1..3 (% dyn) | x neither, per axle | s |',
             '|---|---:|---:|---|---|---:|']
    ref = None
    for label, name, file_, fit in rows:
        drive = sims[name]
        est, v_f, seconds = _offline(wim.file_vehicle(file_), drive, fit)
        pct = wim.dynamic_pct(drive, est)
        ref = pct if ref is None else ref
        lines.append(f'| {label} | {fit} | {v_f:g} | ' + ', '.join(f'{v:.2f}' for v in pct)
                     + ' | ' + ', '.join(f'{v:.2f}' for v in pct / ref)
                     + f' | {seconds:.0f} |')
    return lines


def zero_load_fit(sims: dict, both: dict) -> list[str]:
    """Why the whole vehicle's fit does not run under ``zero_load``: the v_f it would take
    on the first table's zero-load drives (``sims``, by name), on the static-load tracker's
    readings (less its offsets, as the smoother takes them) as if they were from the
    equilibrium."""
    from bench.accuracy import articulated_wim as wim
    from road_force_estimator.core.parameters import ObserverParameters
    from road_force_estimator.estimation.whole_vehicle import (
        WholeVehicleEstimator, fit_friction_velocity)

    vehicle = wim.file_vehicle({**wim.ZERO_LOAD, **both})
    lines = ["| zero-load drive (whole vehicle, C) | the truth's v_f | the fit on the "
             "tracker's readings (m/s) |", '|---|---:|---:|']
    for name, v_true in (('friction+lag', 0.01), ('friction+lag, truth v_f 0.005', 0.005)):
        drive = sims[name]
        tracker = WholeVehicleEstimator(vehicle).tracker      # no gap in these drives
        steps = np.concatenate([[0.0], np.diff(drive['stamps']) * 1e-9])
        y = np.array([tracker.update(row, dt)
                      for row, dt in zip(drive['y'].tolist(), steps.tolist())])
        fitted = fit_friction_velocity(replace(vehicle, deflection_reference='equilibrium'),
                                       ObserverParameters(), drive['stamps'], y,
                                       drive['speed'])
        lines.append(f'| {name} | {v_true:g} | {fitted.leaf_spring_friction_velocity_mps:g} |')
    return lines


def fit_detail() -> list[str]:
    """The ``--fit-detail`` table (Markdown rows): the whole vehicle's v_f fit
    (:func:`.whole_vehicle.fit_friction_velocity`, the file's 0.01 m/s, read from the
    equilibrium) per v_f tried on drives of class C at 20 m/s, 10 um: the test's
    (``test/estimation/test_whole_vehicle_friction_fit.py``: road seed 11, 1.5 kN of tanh
    friction per spring, no lag; 6 s, the plant's v_f 0.005 and 0.02, and 8 s, 0.005), 8 s of
    it with the 3 ms lag, and the offline table's 20 s drive (road seed 1, the lag, 0.005):
    the samples converged under it and under every v_f (those summed), the sum less the
    likeliest's (nats) and the sum per sample (nats), and the fit's CPU seconds (5 runs)."""
    from bench.accuracy import articulated_wim as wim
    from road_force_estimator.core.parameters import ObserverParameters
    from road_force_estimator.estimation.whole_vehicle import fit_friction_velocity

    lines = ["| drive (C, 20 m/s, the file's v_f 0.01) | v_f tried (m/s) | converged | summed "
             "| nll - the likeliest's (nats) | nll a sample (nats) | taken | CPU s |",
             '|---|---:|---:|---:|---:|---:|---|---:|']
    for name, seconds, seed, lag, v_true in (('6 s, seed 11, no lag', 6.0, 11, {}, 0.005),
                                             ('6 s, seed 11, no lag', 6.0, 11, {}, 0.02),
                                             ('8 s, seed 11, no lag', 8.0, 11, {}, 0.005),
                                             ('8 s, seed 11, 3 ms lag', 8.0, 11, wim.LAG, 0.005),
                                             ('20 s, seed 1, 3 ms lag', 20.0, 1, wim.LAG, 0.005)):
        file_ = {**wim.TANH, **lag}
        drive = wim.simulate('C', seconds, 1e-5,
                             {**file_, 'vehicle.leaf_spring_friction_velocity': v_true}, seed)
        table: list = []
        c0 = time.process_time()
        fitted = fit_friction_velocity(wim.file_vehicle(file_), ObserverParameters(),
                                       drive['stamps'], drive['y'], drive['speed'], table=table)
        cpu = time.process_time() - c0
        least = min(row[3] for row in table)
        for v_f, converged, summed, value in table:
            taken = 'yes' if v_f == fitted.leaf_spring_friction_velocity_mps else ''
            lines.append(f"| {name}, the truth's {v_true:g} | {v_f:g} | {converged} | {summed} "
                         f'| {value - least:.1f} | {value / summed:.1f} | {taken} | {cpu:.0f} |')
    return lines


def lag_limit(duration_s: float) -> list[str]:
    """The ``--whole-vehicle`` lag drives beside the truth-tuned peer (module notes)."""
    from bench.accuracy import articulated_wim as wim
    from bench.accuracy.articulated_peer import tuned
    from road_force_estimator.core.road import iso8608_psd
    from road_force_estimator.core.articulated_model import ArticulatedModel
    from road_force_estimator.core.articulated_sensors import channel_layout

    lines = ["| drive (whole vehicle, C, 10 ms, the file's truck) | who | front, drive, "
             'trailer_1..3 (% dyn) | lag / neither, per axle |', '|---|---|---|---|']
    ref: dict = {}
    for name, values in (('neither', {}), ('lag', wim.LAG)):
        drive = wim.simulate('C', duration_s, 1e-5, values)
        vehicle = drive['vehicle']
        judged = drive['t'] >= drive['t'][0] + 5.0
        dyn = drive['load'] - drive['static'][:, None]
        model = ArticulatedModel(vehicle)     # each channel's lag, as the plant's sensors
        lag_s = tuple(model.axles[ch[1]].sensor_time_constant_s if ch[0] == 'q'
                      else vehicle.roll_time_constant_s for ch in channel_layout(model))
        est_peer, _ = tuned(vehicle, drive['y'], dyn, judged, 10, speed_mps=20.0, dt_s=1e-3,
                            noise_m=1e-5,
                            noise_rad=1e-5 / vehicle.axles[0].spring_half_track_m,
                            road_gd_m3=float(iso8608_psd('C', [0.1])[0]), lag_s=lag_s)
        ours = wim.estimate(wim.file_vehicle(values), drive, 0.01, False)
        for who, load in (('ours', ours.load_n),
                          ('peer', est_peer + drive['static'][:, None])):
            pct = wim.dynamic_pct(drive, _Loads(load))
            ref.setdefault(who, pct)
            lines.append(f'| {name} | {who} | ' + ', '.join(f'{v:.2f}' for v in pct) + ' | '
                         + ', '.join(f'{v:.2f}' for v in pct / ref[who]) + ' |')
    return lines


class _Loads:
    """Loads (wheels x samples, N) as :func:`bench.accuracy.articulated_wim.dynamic_pct`
    takes an estimate."""

    def __init__(self, load_n: np.ndarray) -> None:
        self.load_n = load_n


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog='python -m bench.studies.friction_lag',
                                description=__doc__.splitlines()[0])
    p.add_argument('--duration', type=float, default=20.0, metavar='S', help='s per drive')
    p.add_argument('--road-seeds', type=int, nargs='+', default=[1, 2, 3], metavar='N')
    p.add_argument('--only', nargs='+', default=None, metavar='NAME',
                   help='drives to run (matched always runs)')
    p.add_argument('--decompose', action='store_true',
                   help="where the cost comes from, the causal candidates and the fit's lead "
                        'only (road seeds as given)')
    p.add_argument('--whole-vehicle', action='store_true',
                   help='the whole vehicle at 10 ms only (--duration s)')
    p.add_argument('--fit-detail', action='store_true',
                   help="the whole vehicle's v_f fit per v_f tried only (its own drives)")
    p.add_argument('--fit-bias', action='store_true',
                   help="the front axle's v_f fit per drive and road seed only")
    args = p.parse_args(argv)
    if args.fit_bias:
        t0 = time.perf_counter()
        print('\n'.join(fit_bias(args.duration, args.road_seeds)))
        print(f'\n({time.perf_counter() - t0:.0f} s; road seeds {args.road_seeds}, '
              f'{args.duration:g} s each)')
        return 0
    if args.fit_detail:
        t0 = time.perf_counter()
        print('\n'.join(fit_detail()))
        print(f'\n({time.perf_counter() - t0:.0f} s)')
        return 0
    if args.whole_vehicle:
        t0 = time.perf_counter()
        print('\n'.join(whole_vehicle(args.duration)))
        print(f'\n({time.perf_counter() - t0:.0f} s; {args.duration:g} s drives)')
        return 0
    if args.decompose:
        t0 = time.perf_counter()
        print('\n'.join(decompose(args.duration) + [''] + candidates(args.duration,
                                                                     args.road_seeds)
                        + [''] + fit_lead(args.duration, args.road_seeds)))
        print(f'\n({time.perf_counter() - t0:.0f} s; {args.duration:g} s drives)')
        return 0
    if args.duration < 5.0:
        print('friction_lag: --duration must be >= 5 s', file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    res = measure(args.duration, args.road_seeds, args.only,
                  log=lambda s: print(s, file=sys.stderr, flush=True))
    print('\n'.join(table(res)))
    print('\n'.join([''] + diagnostics(args.duration)))
    print(f'\n({time.perf_counter() - t0:.0f} s; road seeds {args.road_seeds}, '
          f'{args.duration:g} s each)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
