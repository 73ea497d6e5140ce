"""Levant differentiator: analytic references, theory's bounds and scaling exponents.

References are analytic derivatives of the test signals. Bounds (L the Lipschitz constant of
f'', dt the step), after convergence and without noise:

- implicit: z0 = f exactly; |z1 - f'| <= L dt^2, |z2 - f''| <= 5/3 L dt while |f'''| <= L
  (in the sliding set z1, z2 are the corrected backward differences; the constants follow
  from Taylor's remainder, see the differentiator's module notes). On polynomials of degree
  <= 2: exact up to rounding, also with irregular steps.
- taylor: |z_i - f^(i)| <= mu_i L dt^(3-i), stated mu = (5, 7, 7) (measured ~2.4, 3.5, 3.2).
- euler: first order in dt for z1 (Livne and Levant's point), the reference to beat.
- filtering (Levant and Livne's filtering differentiator, n_f = 2): |z_i - f^(i)| <=
  mu_i L dt^(3-i), stated mu = (40, 20, 8); noise of small average (a high-frequency
  perturbation) filtered where the standard schemes pass it.
With bounded noise eps: |z_i - f^(i)| <= L^(i/3) eps^((3-i)/3) (mu = 1).
"""
import math

import numpy as np
import pytest

from road_force_estimator.estimation.chain.differentiator import (
    SCHEMES, LevantDifferentiator, differentiate, implicit_step, step_function)


def _ref_poly(t, c0, c1, c2):
    """f = c0 + c1 t + c2 t^2 / 2 and its derivatives, each (n,)."""
    return np.stack([c0 + c1 * t + 0.5 * c2 * t * t, c1 + c2 * t, np.full_like(t, c2)], 1)


def _ref_sines(t, amps, omegas, phases):
    """Sum of sines and its first three derivatives, each (n,)."""
    arg = np.outer(t, omegas) + phases
    f = (amps * np.sin(arg)).sum(1)
    d1 = (amps * omegas * np.cos(arg)).sum(1)
    d2 = -(amps * omegas ** 2 * np.sin(arg)).sum(1)
    d3 = -(amps * omegas ** 3 * np.cos(arg)).sum(1)
    return np.stack([f, d1, d2], 1), d3


def _irregular_times(rng, n, dt):
    return np.concatenate([[0.0], np.cumsum(rng.uniform(0.5 * dt, 1.5 * dt, n - 1))])


class TestValidation:
    def test_bad_scheme_lipschitz_and_dt_are_refused(self):
        with pytest.raises(ValueError, match=r"scheme = 'rk4'.*euler, taylor, implicit"):
            LevantDifferentiator([1.0], 'rk4')
        with pytest.raises(ValueError, match=r'lipschitz.*> 0'):
            LevantDifferentiator([1.0, 0.0])
        with pytest.raises(ValueError, match=r'lipschitz.*> 0'):
            LevantDifferentiator([math.nan])
        d = LevantDifferentiator([1.0, 2.0])
        d.reset([0.0, 0.0])
        for bad in (0.0, -1e-3, math.nan, math.inf):
            with pytest.raises(ValueError, match=r'dt_s'):
                d.update([0.0, 0.0], bad)
        with pytest.raises(ValueError, match=r'finite'):
            d.update([0.0, math.nan], 1e-3)
        with pytest.raises(ValueError, match=r'strictly increasing'):
            differentiate(np.zeros(3), [0.0, 1.0, 1.0], 1.0)

    def test_rejected_sample_leaves_the_state_untouched(self):
        d = LevantDifferentiator([3.0, 3.0], 'taylor')
        d.reset([1.0, 2.0])
        d.update([1.1, 2.1], 1e-2)
        before = d.state
        with pytest.raises(ValueError):
            d.update([1.2, math.inf], 1e-2)
        np.testing.assert_array_equal(d.state, before)

    def test_first_update_initialises_and_reset_gives_f0_0_0(self):
        d = LevantDifferentiator([5.0, 7.0])
        np.testing.assert_array_equal(d.update([1.5, -2.0], 1e-3), [[1.5, -2.0], [0, 0], [0, 0]])
        d.update([1.6, -2.1], 1e-3)
        np.testing.assert_array_equal(d.reset([3.0, 4.0]), [[3.0, 4.0], [0, 0], [0, 0]])


class TestPolynomials:
    @pytest.mark.parametrize('irregular', [False, True])
    def test_implicit_is_exact_on_quadratics(self, irregular):
        rng = np.random.default_rng(4)
        dt, n = 1e-3, 3000
        t = _irregular_times(rng, n, dt) if irregular else np.arange(n) * dt
        coeffs = [(1.0, 0.3, 1.0), (-0.02, 0.5, -20.0), (0.0, 0.0, 0.0)]
        f = np.stack([_ref_poly(t, *c)[:, 0] for c in coeffs], 1)
        out = differentiate(f, t, [10.0, 2000.0, 1.0], 'implicit')
        after = t > 1.5
        for i, c in enumerate(coeffs):
            ref = _ref_poly(t, *c)
            err = np.abs(out[after, :, i] - ref[after])
            # Rounding only: the steps amplify one ulp of f by up to 1/dt_min^2.
            ulp = np.spacing(np.abs(f[:, i]).max() + 1.0)
            dt_min = np.diff(t).min()
            assert err[:, 0].max() <= 4 * ulp
            assert err[:, 1].max() <= 1e3 * ulp / dt_min
            assert err[:, 2].max() <= 1e3 * ulp / dt_min ** 2

    def test_taylor_stays_within_its_bound_on_quadratics(self):
        dt, lip = 1e-3, 10.0
        t = np.arange(3000) * dt
        ref = _ref_poly(t, 1.0, 0.3, 1.0)
        out = differentiate(ref[:, 0], t, lip, 'taylor')
        err = np.abs(out - ref)[t > 1.5].max(0)
        assert np.all(err <= np.array([5.0, 7.0, 7.0]) * lip * dt ** np.array([3, 2, 1]))

    def test_euler_has_the_first_order_velocity_bias(self):
        # Explicit Euler in steady state on f'' = a: z0 advances by dt z1, so z1 settles on the
        # chord slope f'(t + dt/2), dt a / 2 ahead (the bias Livne and Levant's terms remove).
        dt, lip, a = 1e-3, 10.0, 1.0
        t = np.arange(3000) * dt
        ref = _ref_poly(t, 1.0, 0.3, a)
        out = differentiate(ref[:, 0], t, lip, 'euler')
        bias = (out[:, 1] - ref[:, 1])[t > 1.5]
        assert np.abs(bias.mean() - 0.5 * dt * a) < 0.1 * 0.5 * dt * a


class TestLipschitzInputs:
    def _signal(self, dt=1e-3, n=6000):
        rng = np.random.default_rng(7)
        omegas = rng.uniform(2.0, 30.0, 6)
        amps = rng.uniform(0.5, 1.0, 6) / omegas ** 3
        phases = rng.uniform(0, 2 * np.pi, 6)
        t = np.arange(n) * dt
        ref, d3 = _ref_sines(t, amps, omegas, phases)
        return t, ref, np.abs(d3).max()

    def test_implicit_meets_the_sliding_set_bounds(self):
        t, ref, d3max = self._signal()
        dt = t[1]
        for lip in (d3max, 3.0 * d3max):
            out = differentiate(ref[:, 0], t, lip, 'implicit')
            err = np.abs(out - ref)[t > 3.0].max(0)
            assert err[0] == 0.0
            assert err[1] <= lip * dt ** 2
            assert err[2] <= 5.0 / 3.0 * lip * dt

    @pytest.mark.parametrize('scheme', ['taylor', 'euler'])
    def test_explicit_schemes_converge_to_a_band(self, scheme):
        t, ref, d3max = self._signal()
        dt, lip = t[1], 1.2 * d3max
        out = differentiate(ref[:, 0], t, lip, scheme)
        err = np.abs(out - ref)[t > 3.0].max(0)
        bound = np.array([5.0, 7.0, 7.0]) * lip * dt ** np.array([3, 2, 1])
        if scheme == 'euler':
            bound[1] += 0.5 * dt * np.abs(ref[:, 2]).max()  # its first-order bias
        assert np.all(err <= bound)


class TestScaling:
    def test_sampling_exponents(self):
        """|z_i - f^(i)| ~ L dt^(3-i): fitted slopes of log error against log dt."""
        amp, omega = 1.0, 2.0
        lip = 1.25 * amp * omega ** 3
        dts = np.array([4e-3, 2e-3, 1e-3, 5e-4])
        errs = {s: [] for s in SCHEMES}
        for dt in dts:
            t = np.arange(0.0, 6.0, dt)
            ref, _ = _ref_sines(t, np.array([amp]), np.array([omega]), np.array([0.3]))
            for scheme in SCHEMES:
                out = differentiate(ref[:, 0], t, lip, scheme)
                errs[scheme].append(np.abs(out - ref)[t > 3.0].max(0))
        slopes = {s: [np.polyfit(np.log(dts), np.log(np.maximum(np.array(e)[:, i], 1e-300)),
                                 1)[0] for i in range(3)] for s, e in errs.items()}
        assert slopes['taylor'] == pytest.approx([3.0, 2.0, 1.0], abs=0.25)
        assert np.array(errs['implicit'])[:, 0].max() == 0.0
        assert slopes['implicit'][1:] == pytest.approx([2.0, 1.0], abs=0.1)
        assert slopes['euler'][1] == pytest.approx(1.0, abs=0.1)   # first order, not 2
        assert slopes['euler'][2] == pytest.approx(1.0, abs=0.25)

    def test_noise_exponents_and_bound(self):
        """|z_i - f^(i)| <= L^(i/3) eps^((3-i)/3) and its exponents in eps (bounded noise)."""
        rng = np.random.default_rng(11)
        eps = np.array([1e-5, 1e-4, 1e-3, 1e-2])
        dt, lip = 5e-5, 10.0
        t = np.arange(0.0, 2.0, dt)
        ref = np.stack([np.sin(t), np.cos(t), -np.sin(t)], 1)
        f = ref[:, :1] + rng.uniform(-1.0, 1.0, (t.size, eps.size)) * eps
        i = np.arange(3)[:, None]
        scale = lip ** (i / 3.0) * eps ** ((3 - i) / 3.0)
        for scheme in SCHEMES:
            out = differentiate(f, t, np.full(eps.size, lip), scheme)
            err = np.abs(out - ref[:, :, None])[t > 1.0].max(0)
            assert np.all(err <= scale), scheme
            slopes = np.array([np.polyfit(np.log(eps), np.log(err[k]), 1)[0] for k in range(3)])
            # Random noise averages over the convergence window, which widens with eps (fixed
            # dt): the slopes come out under the worst-case ones (measured 0.86, 0.56, 0.25).
            theory = np.array([1.0, 2.0 / 3.0, 1.0 / 3.0])
            assert np.all((slopes >= theory - 0.2) & (slopes <= theory + 0.05)), (scheme, slopes)

    @pytest.mark.parametrize('scheme', SCHEMES)
    def test_homogeneity_gives_the_noise_exponents_exactly(self, scheme):
        """Noise eps with dt ~ eps^(1/3) (L dt^3 / eps fixed): z_i scales as eps^((3-i)/3).

        That is the homogeneity (weights 3, 2, 1) the theory's exponents come from; with the
        same normalised noise sequence the error sequences are scaled copies.
        """
        rng = np.random.default_rng(12)
        unit = rng.uniform(-1.0, 1.0, 4000)
        lip, eps0, dt0 = 10.0, 1e-6, 1e-3
        errs = []
        eps = eps0 * 8.0 ** np.arange(4)        # powers of two: the scaling is exact in binary
        for k, e in enumerate(eps):
            dt = dt0 * 2.0 ** k
            t = np.arange(unit.size) * dt
            out = differentiate(e * unit, t, lip, scheme)
            errs.append(np.abs(out[2000:]).max(axis=0))
        slopes = [np.polyfit(np.log(eps), np.log(np.array(errs)[:, i]), 1)[0] for i in range(3)]
        assert slopes == pytest.approx([1.0, 2.0 / 3.0, 1.0 / 3.0], abs=1e-6)


class TestPaths:
    @pytest.mark.parametrize('scheme', SCHEMES)
    def test_per_sample_and_batch_paths_are_identical(self, scheme):
        rng = np.random.default_rng(3)
        t = _irregular_times(rng, 2000, 1e-3)
        f = np.stack([np.sin(7 * t), 0.01 * np.cos(3 * t), t ** 2], 1)
        f += rng.normal(0.0, 1e-5, f.shape)
        lip = [400.0, 5.0, 1.0]
        batch = differentiate(f, t, lip, scheme)
        d = LevantDifferentiator(lip, scheme)
        rows = [d.reset(f[0]).copy()]
        for k in range(1, t.size):
            rows.append(d.update(f[k], t[k] - t[k - 1]).copy())
        np.testing.assert_array_equal(np.array(rows), batch)

    def test_implicit_step_root_solves_the_backward_euler_equations(self):
        # Independent check of the implicit step: plug the result into the implicit equations
        # of the non-recursive form with the set-valued sign.
        rng = np.random.default_rng(5)
        k1, k2, k3 = 3.0, 1.5 * math.sqrt(3.0), 1.1
        for _ in range(500):
            z0, z1, z2, fn = rng.normal(0.0, 1.0, 4) * 10.0 ** rng.uniform(-6, 2, 4)
            dt, lip = 10.0 ** rng.uniform(-4, -1), 10.0 ** rng.uniform(-1, 4)
            a, b, c = implicit_step(z0, z1, z2, 0.0, fn, dt, lip, lip ** (1 / 3), lip ** 0.5)
            w1_0, w1 = z1 - 0.5 * dt * z2, b - 0.5 * dt * c
            e = a - fn
            s = (z2 - c) / (dt * k3 * lip)   # the sign value used, from the z2 equation
            assert abs(s) <= 1.0 + 1e-9
            if e != 0.0:
                assert s == pytest.approx(math.copysign(1.0, e))
            r0 = z0 + dt * (-k1 * lip ** (1 / 3) * abs(e) ** (2 / 3) * s + w1) - a
            r1 = w1_0 + dt * (-k2 * lip ** (2 / 3) * abs(e) ** (1 / 3) * s + c) - w1
            scale0 = abs(z0) + abs(fn) + dt * (abs(w1) + abs(w1_0)) + 1e-300
            scale1 = abs(w1_0) + abs(w1) + dt * abs(c) + dt * k3 * lip + 1e-300
            assert abs(r0) <= 1e-9 * scale0
            assert abs(r1) <= 1e-9 * scale1

    def test_step_function_names(self):
        assert step_function('implicit') is implicit_step
        with pytest.raises(ValueError, match='scheme'):
            step_function('rk4')

    @pytest.mark.parametrize('scheme', SCHEMES)
    def test_large_steps_and_jumps_stay_finite(self, scheme):
        d = LevantDifferentiator([5000.0], scheme)
        d.reset([0.0])
        for k, dt in enumerate([1e-3, 0.5, 1e-3, 10.0, 1e-6, 1e-3] * 5):
            out = d.update([(-1.0) ** k * 0.5], dt)
            assert np.all(np.isfinite(out))


def test_taylor_and_implicit_are_exact_on_quadratics_in_exact_arithmetic():
    # Dyadic step and coefficients make every operation exact in binary floating point: from
    # the exact state, the Taylor and implicit steps stay exact (sign(0) = 0 / the set-valued
    # sign), while Euler drifts by its dt f''/2 velocity bias at once.
    from road_force_estimator.estimation.chain.differentiator import euler_step, taylor_step
    dt, a, b, c = 2.0 ** -10, 1.0, 0.5, 0.25
    for step, exact in ((taylor_step, True), (implicit_step, True), (euler_step, False)):
        z = (c, b, a)
        worst = 0.0
        for k in range(1, 1001):
            t_prev, t = (k - 1) * dt, k * dt
            f_prev, f_new = c + b * t_prev + 0.5 * a * t_prev ** 2, c + b * t + 0.5 * a * t * t
            z = step(*z, f_prev, f_new, dt, 10.0, 10.0 ** (1 / 3), 10.0 ** 0.5)
            worst = max(worst, abs(z[0] - f_new), abs(z[1] - (b + a * t)), abs(z[2] - a))
        assert (worst == 0.0) == exact, (step.__name__, worst)


class TestFiltering:
    """Levant and Livne's filtering differentiator ('filtering'; the module notes)."""

    def test_converges_to_its_discretization_band_on_a_sine(self):
        # Without noise and with |f'''| <= L: |z_i - f^(i)| <= mu_i L dt^(3-i) after
        # convergence, the errors shrinking as dt^(3-i) (the paper's accuracy of the
        # homogeneous discretization; measured mu ~ 21-29, 13-15, 5-6 at n_f = 2).
        amp, omega = 1.0, 2.0 * math.pi
        lip = 1.25 * amp * omega ** 3
        dts = np.array([1e-3, 5e-4, 2.5e-4])
        errs = []
        for dt in dts:
            t = np.arange(0.0, 6.0, dt)
            ref, _ = _ref_sines(t, np.array([amp]), np.array([omega]), np.array([0.0]))
            out = differentiate(ref[:, 0], t, lip, 'filtering')
            err = np.abs(out - ref)[t > 3.0].max(0)
            assert np.all(err <= np.array([40.0, 20.0, 8.0]) * lip * dt ** np.array([3, 2, 1]))
            errs.append(err)
        slopes = [np.polyfit(np.log(dts), np.log(np.array(errs)[:, i]), 1)[0] for i in range(3)]
        assert slopes == pytest.approx([3.0, 2.0, 1.0], abs=0.3)

    def test_filters_noise_of_small_average_that_the_standard_one_passes(self):
        # The paper's claim: exact without noise, and noise of small average (here a
        # high-frequency perturbation of 10 % of the signal) is filtered, the more the higher
        # its frequency, while the standard differentiator's error is L^(i/3) eps^((3-i)/3)
        # at any frequency (compared with 'implicit', the best of the standard schemes).
        dt, lip = 1e-4, 2.0
        t = np.arange(0.0, 20.0, dt)
        ref = np.stack([np.sin(t), np.cos(t), -np.sin(t)], 1)
        late = t > 10.0
        errs = {}
        for hz in (100.0, 1000.0):
            f = ref[:, 0] + 0.1 * np.sin(2.0 * math.pi * hz * t + 0.3)
            for scheme in ('implicit', 'filtering'):
                out = differentiate(f, t, lip, scheme)
                errs[scheme, hz] = np.abs(out - ref)[late].max(0)
        for hz in (100.0, 1000.0):
            assert np.all(errs['filtering', hz] <= 0.2 * errs['implicit', hz]), errs
        assert np.all(errs['filtering', 1000.0] <= 0.5 * errs['filtering', 100.0]), errs
        assert np.all(errs['implicit', 1000.0] >= 0.8 * errs['implicit', 100.0]), errs
        clean = differentiate(ref[:, 0], t, lip, 'filtering')
        assert np.all(np.abs(clean - ref)[late].max(0) <= np.array([1e-9, 1e-6, 2e-3]))

    def test_step_solves_the_discrete_equations_written_here(self):
        # One step against the paper's discrete equations (n_d = 2, n_f = 2, n = 4, gains
        # 1.1, 4.57, 9.30, 10.03, 5), written out here term by term.
        from road_force_estimator.estimation.chain.differentiator import (FilteringConstants,
                                                                    filtering_step)
        rng = np.random.default_rng(21)
        lam = (1.1, 4.57, 9.30, 10.03, 5.0)
        for _ in range(200):
            x = rng.normal(0.0, 1.0, 6) * 10.0 ** rng.uniform(-6, 1, 6)
            z0, z1, z2, w1, w2, fk = x.tolist()
            dt, lip = (10.0 ** rng.uniform([-4, 0], [-2, 4])).tolist()

            def pw(x, g):
                return abs(x) ** g * math.copysign(1.0, x) if x != 0.0 else 0.0

            want = (z0 + dt * (-lam[2] * lip ** (3 / 5) * pw(w1, 2 / 5)) + dt * z1
                    + dt * dt / 2 * z2,
                    z1 + dt * (-lam[1] * lip ** (4 / 5) * pw(w1, 1 / 5)) + dt * z2,
                    z2 - dt * lam[0] * lip * pw(w1, 0.0),
                    w1 + dt * (-lam[4] * lip ** (1 / 5) * pw(w1, 4 / 5) + w2),
                    w2 + dt * (-lam[3] * lip ** (2 / 5) * pw(w1, 3 / 5) + z0 - fk))
            a, b, c, w = filtering_step(z0, z1, z2, (w1, w2), fk, dt,
                                        FilteringConstants(lip, 2))
            assert (a, b, c, *w) == pytest.approx(want, rel=1e-12, abs=1e-300)

    def test_orders_and_the_classic_step_function(self):
        from road_force_estimator.estimation.chain.differentiator import FilteringConstants
        with pytest.raises(ValueError, match='filtering order'):
            FilteringConstants(1.0, 4)
        with pytest.raises(ValueError, match='filtering_step'):
            step_function('filtering')
