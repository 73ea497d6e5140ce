"""The whole vehicle's online roads (:class:`WheelRoads`): every wheel's filter stepped in one
product (:func:`.body_heave.step_matrix`) against each wheel's own :func:`.body_heave.step`
(the per-sample scalar filter, itself checked against the analytic response in
test_body_heave.py), and the matrix against :func:`scipy.signal.lfilter` of the filter's
transfer function built here from the Tustin lags' coefficients."""
from __future__ import annotations

import math

import numpy as np
from scipy import signal

from road_force_estimator.estimation import body_heave
from road_force_estimator.estimation.models.articulated_rows import (
    ROAD_RAMP_S, ROAD_START_S, WheelRoads)

DT = 1e-3
WCPS = body_heave.cutoff_per_speed(300.0)


def _reference_roads(w, accel, v, x, nw):
    """The roads of :class:`WheelRoads`' rules with one :func:`.body_heave.step` per wheel
    (its per-sample path before the product form)."""
    out = np.zeros_like(w)
    states = prev = None
    off = [0.0] * nw
    t = 0.0
    for i in range(w.shape[0]):
        t = 0.0 if i == 0 else t + DT
        ramp = (0.0 if t < ROAD_START_S else 1.0 if t >= ROAD_START_S + ROAD_RAMP_S else
                0.5 - 0.5 * math.cos(math.pi * (t - ROAD_START_S) / ROAD_RAMP_S))
        a = [ramp * float(c) for c in accel[i]]
        if states is None:
            states = [body_heave.start(c) for c in a]
        else:
            states = [body_heave.step(s, c, DT, float(v[i]), WCPS) for s, c in zip(states, a)]
        u = [float(wk) + s[-2] for wk, s in zip(w[i], states)]
        if prev is not None and x[i] == x[i - 1] and -1.0 < v[i] < 1.0:
            off = [o + a1 - a0 for o, a1, a0 in zip(off, u, prev)]
        prev = u
        out[i] = [a1 - o for a1, o in zip(u, off)]
    return out


def test_wheel_roads_are_each_wheels_scalar_filter_within_rounding():
    # ten wheels, 40 s: a pull-away (the cutoff rising: the states rescaled), a slow-down, a
    # stop (held), and the run's start ramp; random accelerations and tire deflections
    rng = np.random.default_rng(7)
    nw, m = 10, 40000
    t = np.arange(m) * DT
    v = np.interp(t, [0, 5, 15, 22, 24, 27, 40], [8, 8, 22, 22, 0, 0, 15])
    x = np.concatenate([[0.0], np.cumsum(np.abs(v[1:]) * DT)])
    accel = rng.normal(0.0, 2.0, (m, nw)) + np.sin(2 * np.pi * 0.7 * t)[:, None]
    w = rng.normal(0.0, 1e-3, (m, nw))
    roads = WheelRoads(nw, WCPS)
    got = np.array([roads.road(w[i].tolist(), accel[i].tolist(), DT, float(v[i]),
                               float(x[i])) for i in range(m)])
    ref = _reference_roads(w, accel, v, x, nw)
    z = ref - w
    assert np.sqrt(np.mean(z ** 2)) > 1e-3                 # a road, not zeros
    assert np.max(np.abs(got - ref)) < 1e-11 * np.max(np.abs(z))
    assert np.array_equal(got[:int(ROAD_START_S / DT)], w[:int(ROAD_START_S / DT)])


def test_step_matrix_is_the_tustin_cascade_of_lfilter():
    # z_s = sum_(k=2..8) (k - 1) w^(k - 2) y_k, y_k = L(y_(k-1)), y_0 = a, L the Tustin lag
    # hh (1 + q^-1) / (1 - g q^-1) of 1 / (s + w): eight of scipy's lfilter in cascade
    for wc in (WCPS * 20.0, 2.0 * math.pi * 20.0 / 5.0):
        n = body_heave.ORDER
        hh = 0.5 * DT / (1.0 + 0.5 * wc * DT)
        g = (1.0 - 0.5 * wc * DT) / (1.0 + 0.5 * wc * DT)
        rng = np.random.default_rng(3)
        a = rng.normal(0.0, 1.0, 20000)
        y, ref = a, np.zeros(a.size)
        for k in range(1, n + 1):
            y = signal.lfilter([hh, hh], [1.0, -g], y)
            if k >= 2:
                ref += (k - 1) * wc ** (k - 2) * y
        m = body_heave.step_matrix(DT, wc)
        state = np.zeros(n + 1)
        got = np.zeros(a.size)
        prev = 0.0
        for i, ak in enumerate(a):       # at rest before the first sample
            state[n] = prev + ak
            state = m @ state
            got[i] = state[n]
            prev = ak
        assert np.max(np.abs(got - ref)) < 1e-11 * np.max(np.abs(ref))


def test_body_road_gains_give_every_wheels_heave_from_the_plants_bodies(articulated_c):
    # MODEL.md: the wheel's heave z_a,j +- w_j sin(phi_a,j) from the plant's own coordinates
    # (z_b, theta_b, phi_b of each body, then each axle's heave and roll), against the gains'
    # from the bodies' coordinates and the plant's springs' extensions q_j,i; the tire's
    # deflection passes through
    from road_force_estimator.estimation.models.articulated_rows import body_road_gains

    d, tr, _, _ = articulated_c
    model = d.model
    n, nw = model.n_dof, 2 * model.n_axles
    x = tr.state[:, :n]                                   # the coordinates
    assert np.max(np.abs(x[:, [0, 3]])) > 1e-3            # the bodies move
    true = np.zeros((len(tr), nw))
    for j, a in enumerate(model.axles):
        za, phia = x[:, 6 + 2 * j], x[:, 7 + 2 * j]
        true[:, 2 * j] = za + a.wheel_half_track_m * np.sin(phia)
        true[:, 2 * j + 1] = za - a.wheel_half_track_m * np.sin(phia)
    c = body_road_gains(model)
    w = np.random.default_rng(1).normal(0.0, 1e-3, (len(tr), nw))
    lin = np.column_stack([x[:, [0, 1, 3, 4, 2, 5]], tr.q_m, w])
    got = lin @ c.T
    # within the small angles' linearisation (the plant's q_j,i are MODEL.md's sines)
    assert np.max(np.abs(got - w - true)) < 2e-4 * np.max(np.abs(true))
    assert np.sqrt(np.mean((got - w - true) ** 2)) < 5e-5 * np.sqrt(np.mean(true ** 2))
