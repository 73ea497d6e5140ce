"""Second-order robust exact differentiator (Levant), three discretizations, and Levant and
Livne's filtering differentiator.

Per channel f(t) with ``|f'''| <= L``, the differentiator of MODEL.md (recursive form, gains
3, 1.5, 1.1)::

    v_0 = -3.0 L^(1/3) |z_0 - f|^(2/3) sign(z_0 - f) + z_1
    v_1 = -1.5 L^(1/2) |z_1 - v_0|^(1/2) sign(z_1 - v_0) + z_2
    v_2 = -1.1 L sign(z_2 - v_1)
    dz_0 = v_0,  dz_1 = v_1,  dz_2 = v_2

gives ``z_0 -> f``, ``z_1 -> f'``, ``z_2 -> f''`` in finite time. In continuous time it equals
the non-recursive form ``dz_0 = -k1 L^(1/3) |e|^(2/3) sign(e) + z_1``,
``dz_1 = -k2 L^(2/3) |e|^(1/3) sign(e) + z_2``, ``dz_2 = -k3 L sign(e)`` with ``e = z_0 - f``,
``k1 = 3``, ``k2 = 1.5 sqrt(3)``, ``k3 = 1.1``.

Schemes (``scheme=``):

``'euler'``
    The paper's scheme, kept unchanged as the reference to beat: explicit Euler of the
    recursive form, ``z(t_k) = z(t_{k-1}) + dt_k v(z(t_{k-1}), f(t_{k-1}))``.
``'taylor'``
    Livne and Levant's homogeneous discrete differentiator: the same explicit step plus the
    Taylor term ``dt^2/2 z_2`` in ``z_0``, which makes it exact on quadratics in exact
    arithmetic (in floating point it chatters within its discretization bound).
``'implicit'``
    Backward Euler of the non-recursive form with the set-valued sign. The step reduces to one
    scalar cubic ``y^3 + k1 y^2 + k2 y + k3 = |p| / (dt^3 L)`` (``p`` the one-step prediction
    error, ``|z_0 - f|^(1/3) = dt L^(1/3) y``), monotone for ``y >= 0``: a unique root, solved
    in closed form (Cardano: one real root there; relative residual ~1e-15). When
    ``|p| <= k3 dt^3 L`` the step ends exactly on the sliding set (``z_0 = f``). There the
    backward-Euler velocity is the backward difference, i.e. ``f'`` half a step late: the
    velocity kept and output is corrected by ``+ dt/2 z_2`` (and un-corrected with the next
    step's dt before that step, so that quadratics stay exact under irregular steps).

``'filtering'``
    Levant and Livne's robust exact filtering differentiator of differentiation order
    n_d = 2 and filtering order n_f = :data:`FILTERING_ORDER` (the method family's
    noise-robust form, MODEL.md). With ``n = n_d + n_f``, ``[x]^g = |x|^g sign(x)`` and the
    gains ``lambda_0 .. lambda_n`` of the standard n-th order differentiator
    (:data:`FILTERING_GAINS`, the table the paper uses), in continuous time::

        dw_i    = -lambda_(n+1-i) L^(i/(n+1)) [w_1]^((n+1-i)/(n+1)) + w_(i+1),  i < n_f
        dw_n_f  = -lambda_(n_d+1) L^(n_f/(n+1)) [w_1]^((n_d+1)/(n+1)) + z_0 - f
        dz_j    = -lambda_(n_d-j) L^((j+1+n_f)/(n+1)) [w_1]^((n_d-j)/(n+1)) + z_(j+1),  j < n_d
        dz_n_d  = -lambda_0 L sign(w_1)

    i.e. the n-th order differentiator of the n_f-fold integral of f (w_1 is its error):
    exact in finite time without noise when the third derivative of f is bounded by L, like
    the others, while the noise enters only through its n_f-fold integral, so that noise of
    small local average (sensor noise, above the signal's band) is filtered instead of
    passed at ``L^(i/3) eps^((3-i)/3)``. Discretization (the paper's: explicit Euler for the
    filter states ``w``; for ``z`` Livne and Levant's homogeneous discrete differentiator,
    the explicit step plus the Taylor terms ``dt^k / k! z_(j+k)``); the sample at the start
    of the step enters (explicit, as ``euler`` and ``taylor``). Without noise its error
    after convergence is ``|z_j - f^(j)| <= mu_j L dt^(3-j)`` (tested in
    ``test/estimation/test_differentiator.py``: the errors shrink as ``dt^(3-j)``). State:
    ``z`` and the n_f values ``w``, all 0 but ``z_0 = f(t_0)`` after a reset.

Which instant the outputs refer to: after the sample ``f(t_k)`` with step ``dt_k = t_k -
t_{k-1}`` the outputs are estimates of ``f, f', f''`` **at t_k**. The explicit schemes
(``euler``, ``taylor``) compute them from samples up to ``t_{k-1}`` only (a one-step
prediction: the newest sample enters at the next step); ``implicit`` uses ``f(t_k)`` itself.

Accuracy (tests in ``test/test_differentiator.py``): without noise and with ``|f'''| <= L``,
once on the sliding set, ``implicit`` gives ``z_0 = f(t_k)`` exactly, ``|z_1 - f'| <= L dt^2``
and ``|z_2 - f''| <= 5/3 L dt`` (it stays on the set while ``|f'''| <= 1.1 L``; on
polynomials of degree <= 2 it is exact, to rounding, also with irregular steps). ``taylor``
stays within ``mu_i L dt^(3-i)`` (measured mu ~ 2.4, 3.5, 3.2 on a sine with L = 1.25
max|f'''|); ``euler`` has in addition a first-order velocity bias ``dt f''/2`` (``z_1`` is the
chord slope over the next step), so its ``z_1`` error is O(dt), not O(dt^2). Both explicit
schemes chatter: ``z_2`` jumps by ``1.1 L dt`` at every step, which is what limits them in the
estimator (the load error grows with L). With bounded noise ``eps`` the errors scale as
``L^(i/3) eps^((3-i)/3)`` (Levant 2003; constant <= 1 measured for all three schemes).

References
----------
A. Levant, "Higher-order sliding modes, differentiation and output-feedback control",
Int. J. Control 76(9-10), 2003. M. Livne, A. Levant, "Proper discretization of homogeneous
differentiators", Automatica 50(8), 2014. M. R. Mojallizadeh, B. Brogliato, V. Acary,
"Time-discretizations of differentiators: design of implicit algorithms and comparative
analysis", Int. J. Robust Nonlinear Control 31(16), 2021. A. Levant, M. Livne, "Robust exact
filtering differentiators", European Journal of Control 55, 2020, 33-44 (arXiv 2019: the
filtering differentiator, its gains and its discretization). B. Andritsch et al., "The robust
exact differentiator toolbox revisited: filtering and discretization features", IEEE ICM
2021 (the same gains and discrete form, a second source checked against).
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

__all__ = [
    'SCHEMES', 'GAINS', 'FILTERING_ORDER', 'FILTERING_GAINS', 'LevantDifferentiator',
    'FilteringConstants', 'differentiate', 'step_function', 'euler_step', 'taylor_step',
    'implicit_step', 'filtering_step',
]

#: Discretizations: 'euler' is the paper's (the reference), the others ours; 'filtering' is
#: Levant and Livne's filtering differentiator (its own state: :func:`filtering_step`).
SCHEMES = ('euler', 'taylor', 'implicit', 'filtering')
#: Filtering order n_f of the 'filtering' scheme: 2, the best of 1-3 in the chain on the
#: benchmark's class C drive at 1 kHz with 10 um of noise (``python -m bench.studies.chain_rate
#: --rates 1000 --filtering-order N``).
FILTERING_ORDER = 2
#: Gains ``lambda_0 .. lambda_n`` of the non-recursive n-th order differentiator, by n: the
#: recursive parameters 1.1, 1.5, 2, 3, 5, 7 of Levant (2003) in the non-recursive form, as
#: Levant and Livne (2020) use them (``lambda_(n-1) = 2 x 3^(2/3)`` = 4.16 for n = 3, ...).
FILTERING_GAINS = {
    3: (1.1, 3.06, 4.16, 3.0),
    4: (1.1, 4.57, 9.30, 10.03, 5.0),
    5: (1.1, 6.75, 20.26, 32.24, 23.72, 7.0),
}
#: Gains of the recursive form (lambda_2, lambda_1, lambda_0), MODEL.md / the paper.
GAINS = (3.0, 1.5, 1.1)

_LAM2, _LAM1, _LAM0 = GAINS
# Non-recursive gains (the same differentiator): k1 = lambda_2, k2 = lambda_1 sqrt(lambda_2).
_K1 = _LAM2
_K2 = _LAM1 * math.sqrt(_LAM2)
_K3 = _LAM0
# Cubic y^3 + K1 y^2 + K2 y + (K3 - P) = 0 with y = t - K1/3: t^3 + _PC t + (_QC0 - P) = 0.
_PC = _K2 - _K1 * _K1 / 3.0
_QC0 = 2.0 * _K1 ** 3 / 27.0 - _K1 * _K2 / 3.0 + _K3
_PC3 = _PC / 3.0
_PC3_CUBED = _PC3 * _PC3 * _PC3
_SHIFT = _K1 / 3.0

_cbrt = getattr(math, 'cbrt', None) or (lambda x: math.copysign(abs(x) ** (1.0 / 3.0), x))

# One step of one channel: (z0, z1, z2, f_prev, f_new, dt, L, L^(1/3), L^(1/2))
#   -> (z0, z1, z2), the state at the end of the step, which is also the output.
StepFunction = Callable[[float, float, float, float, float, float, float, float, float],
                        tuple[float, float, float]]


def euler_step(z0: float, z1: float, z2: float, f_prev: float, f_new: float, dt: float,
               lip: float, lip13: float, lip12: float) -> tuple[float, float, float]:
    """Explicit Euler of the recursive form (the paper's scheme), one channel, one step.

    ``f_prev`` is the sample at the start of the step (the one the correction uses), ``f_new``
    is not used (explicit). Returns the state at the end of the step.
    """
    e = z0 - f_prev
    v0 = z1 - _LAM2 * lip13 * _cbrt(e * e) * ((e > 0.0) - (e < 0.0))
    d = z1 - v0
    v1 = z2 - _LAM1 * lip12 * math.sqrt(abs(d)) * ((d > 0.0) - (d < 0.0))
    g = z2 - v1
    v2 = -_LAM0 * lip * ((g > 0.0) - (g < 0.0))
    return z0 + dt * v0, z1 + dt * v1, z2 + dt * v2


def taylor_step(z0: float, z1: float, z2: float, f_prev: float, f_new: float, dt: float,
                lip: float, lip13: float, lip12: float) -> tuple[float, float, float]:
    """Livne-Levant Taylor-corrected explicit step, one channel (see :func:`euler_step`):
    the explicit Euler step plus the Taylor term ``dt^2 z2 / 2`` on ``z0``."""
    n0, n1, n2 = euler_step(z0, z1, z2, f_prev, f_new, dt, lip, lip13, lip12)
    return n0 + 0.5 * dt * dt * z2, n1, n2


def implicit_step(z0: float, z1: float, z2: float, f_prev: float, f_new: float, dt: float,
                  lip: float, lip13: float, lip12: float) -> tuple[float, float, float]:
    """Implicit (backward-Euler) step with the set-valued sign, one channel.

    Solves ``z_0+ = z_0 + dt(-k1 L^(1/3)|e+|^(2/3) s + w_1+)``, ``w_1+ = w_1 + dt(-k2 L^(2/3)
    |e+|^(1/3) s + z_2+)``, ``z_2+ = z_2 - dt k3 L s`` with ``e+ = z_0+ - f_new``,
    ``s in Sign(e+)``, and ``w_1`` the backward-Euler velocity, which is the mean slope over
    the step (``f'`` half a step late). The state velocity is the corrected one,
    ``z_1 = w_1 + dt/2 z_2`` at the end of the step, and ``w_1 = z_1 - dt/2 z_2`` at the start
    of the next (with that step's dt), so quadratics stay exact under irregular steps.
    ``f_prev`` is not used.
    """
    w1 = z1 - 0.5 * dt * z2
    p = z0 + dt * (w1 + dt * z2) - f_new
    a = dt * dt * dt * lip
    big_p = abs(p) / a
    if big_p <= _K3:
        # On the sliding set: e+ = 0, s = p / (k3 dt^3 L) in [-1, 1].
        z2n = z2 - p / (dt * dt)
        return f_new, w1 + 1.5 * dt * z2n, z2n
    # Unique positive root of y^3 + K1 y^2 + K2 y + K3 = P (Cardano: one real root here since
    # P > K3 makes the discriminant positive; relative residual ~1e-15, no polishing needed).
    q_half = 0.5 * (_QC0 - big_p)
    u = _cbrt(math.sqrt(q_half * q_half + _PC3_CUBED) - q_half)
    y = u - _PC3 / u - _SHIFT
    if y < 0.0:
        y = 0.0
    if p > 0.0:
        z2n = z2 - dt * _K3 * lip
        return f_new + a * y * y * y, w1 + 1.5 * dt * z2n - dt * dt * _K2 * lip * y, z2n
    z2n = z2 + dt * _K3 * lip
    return f_new - a * y * y * y, w1 + 1.5 * dt * z2n + dt * dt * _K2 * lip * y, z2n


class FilteringConstants:
    """The constants of one channel of the filtering differentiator, for L (units of f per
    s^3) and the filtering order ``n_f`` (1 to 3): the products ``lambda L^(k/(n+1))`` of
    the module notes, ``cw[i]`` in the equation of ``w_(i+1)``, ``cz[j]`` in that of
    ``z_j``."""

    __slots__ = ('n_f', 'inv', 'cw', 'cz')

    def __init__(self, lipschitz: float, n_f: int | None = None) -> None:
        n_f = FILTERING_ORDER if n_f is None else n_f
        n = 2 + n_f
        if n not in FILTERING_GAINS:
            raise ValueError(f'filtering order n_f = {n_f!r}: must be 1, 2 or 3')
        lam = FILTERING_GAINS[n]
        lip = float(lipschitz)
        self.n_f = n_f
        self.inv = 1.0 / (n + 1)
        self.cw = tuple(lam[n + 1 - i] * lip ** (i / (n + 1)) for i in range(1, n_f + 1))
        self.cz = tuple(lam[2 - j] * lip ** ((j + 1 + n_f) / (n + 1)) for j in range(3))


def filtering_step(z0: float, z1: float, z2: float, w: tuple, f_prev: float, dt: float,
                   c: FilteringConstants) -> tuple[float, float, float, tuple]:
    """One step of the filtering differentiator (the module notes: its discretization), one
    channel: the state ``(z0, z1, z2)`` and the filter states ``w`` (n_f) at the start of
    the step, ``f_prev`` the sample there; returns ``(z0, z1, z2, w)`` at its end."""
    w1 = w[0]
    sg = (w1 > 0.0) - (w1 < 0.0)
    r = abs(w1) ** c.inv          # |w_1|^(1/(n+1)): [w_1]^(k/(n+1)) = sign(w_1) r^k
    n_f = c.n_f
    cw = c.cw
    top = n_f + 2                 # the exponent (n+1-i)/(n+1) of w_i is (top + 1 - i) * inv
    new_w = tuple(
        w[i] + dt * ((w[i + 1] if i + 1 < n_f else z0 - f_prev) - cw[i] * sg * r ** (top - i))
        for i in range(n_f))
    cz0, cz1, cz2 = c.cz
    return (z0 + dt * (z1 - cz0 * sg * r * r) + 0.5 * dt * dt * z2,
            z1 + dt * (z2 - cz1 * sg * r),
            z2 - dt * cz2 * sg,
            new_w)


_STEPS: dict[str, StepFunction] = {
    'euler': euler_step, 'taylor': taylor_step, 'implicit': implicit_step}


def step_function(scheme: str) -> StepFunction:
    """The one-channel step function of ``scheme`` (for callers that keep scalar state);
    ``'filtering'`` keeps filter states too (:func:`filtering_step`)."""
    try:
        return _STEPS[scheme]
    except (KeyError, TypeError):
        if scheme == 'filtering':
            raise ValueError("scheme = 'filtering' keeps filter states: use filtering_step "
                             'with FilteringConstants') from None
        raise ValueError(
            f'scheme = {scheme!r}: must be one of {", ".join(SCHEMES)}') from None


def _check_lipschitz(lipschitz) -> np.ndarray:
    lip = np.atleast_1d(np.asarray(lipschitz, dtype=float))
    if lip.ndim != 1 or lip.size == 0:
        raise ValueError(f'lipschitz = {lipschitz!r}: expected one value per channel, (c,)')
    if not np.all(np.isfinite(lip)) or np.any(lip <= 0.0):
        raise ValueError(f'lipschitz = {lipschitz!r}: each value must be finite and > 0 '
                         '(units of f per s^3)')
    return lip


class LevantDifferentiator:
    """Second-order robust exact differentiator, vectorised over channels (one L each).

    Parameters
    ----------
    lipschitz : array_like, shape (c,)
        Bound ``L`` on ``|f'''|`` per channel (units of f per s^3), > 0.
    scheme : {'implicit', 'taylor', 'euler', 'filtering'}
        Discretization; ``'euler'`` is the paper's explicit scheme, ``'filtering'`` Levant and
        Livne's filtering differentiator (see the module notes).

    Notes
    -----
    State per channel ``(z_0, z_1, z_2)`` (and with ``'filtering'`` the filter states ``w``)
    is kept as Python floats and advanced with scalar math; :meth:`update` writes into one
    preallocated output array (returned, overwritten by the next call: copy it to keep it).
    After :meth:`reset` with ``f(t_0)`` the state is ``(f(t_0), 0, 0)`` (and ``w = 0``).

    Examples
    --------
    >>> d = LevantDifferentiator([10.0])
    >>> out = d.reset([0.0])
    >>> for k in range(1, 3001):
    ...     out = d.update([0.5 * (k * 1e-3) ** 2], 1e-3)   # f = t^2 / 2
    >>> [round(float(x), 9) for x in out[:, 0]]
    [4.5, 3.0, 1.0]
    """

    def __init__(self, lipschitz, scheme: str = 'implicit') -> None:
        lip = _check_lipschitz(lipschitz)
        # the filtering differentiator: its constants and filter states per channel
        self._filter = ([FilteringConstants(float(x)) for x in lip] if scheme == 'filtering'
                        else None)
        self._step = None if self._filter else step_function(scheme)
        self._w = [(0.0,) * c.n_f for c in self._filter or ()]
        self._scheme = scheme
        self._lip = lip.copy()
        self._lip.flags.writeable = False
        self._consts = [(float(x), float(x) ** (1.0 / 3.0), math.sqrt(float(x))) for x in lip]
        n = lip.size
        self._channels = range(n)
        self._z0 = [0.0] * n
        self._z1 = [0.0] * n
        self._z2 = [0.0] * n
        self._f = [0.0] * n
        self._fs = [0.0] * n
        self._out = np.zeros((3, n))
        self._initialised = False

    @property
    def scheme(self) -> str:
        """The discretization."""
        return self._scheme

    @property
    def lipschitz(self) -> np.ndarray:
        """L per channel (read-only)."""
        return self._lip

    @property
    def state(self) -> np.ndarray:
        """Internal state (3, c): ``z_0, z_1, z_2`` (equal to the last output), a copy."""
        return np.array([self._z0, self._z1, self._z2])

    @property
    def output(self) -> np.ndarray:
        """The last output (3, c) ``[f, f', f'']``, the array :meth:`update` returns."""
        return self._out

    def reset(self, f0) -> np.ndarray:
        """Restart at the sample ``f0`` (c,): state ``(f0, 0, 0)``; returns the output."""
        out = self._out
        for i in self._channels:
            f = float(f0[i])
            if not math.isfinite(f):
                raise ValueError(f'f0[{i}] = {f!r}: samples must be finite')
            self._z0[i] = f
            self._z1[i] = 0.0
            self._z2[i] = 0.0
            if self._filter:
                self._w[i] = (0.0,) * self._filter[i].n_f
            self._f[i] = f
            out[0, i] = f
            out[1, i] = 0.0
            out[2, i] = 0.0
        self._initialised = True
        return out

    def update(self, f, dt_s: float) -> np.ndarray:
        """Advance by ``dt_s`` (s, > 0) to the new sample ``f`` (c,); returns ``[z0, z1, z2]``.

        The output (3, c) estimates ``f, f', f''`` at the new sample's instant (see the
        module notes: the explicit schemes do not use ``f`` itself before the next step). The
        first call on a differentiator that was never reset resets it at ``f``. A non-finite
        sample raises :class:`ValueError` and leaves the state unchanged.
        """
        if not self._initialised:
            return self.reset(f)
        dt_s = float(dt_s)
        if not dt_s > 0.0 or not math.isfinite(dt_s):
            raise ValueError(f'dt_s = {dt_s!r}: must be finite and > 0 s')
        fs = self._fs
        for i in self._channels:
            fn = float(f[i])
            if not math.isfinite(fn):
                raise ValueError(f'f[{i}] = {fn!r}: samples must be finite (state unchanged)')
            fs[i] = fn
        step = self._step
        z0, z1, z2, fp, out = self._z0, self._z1, self._z2, self._f, self._out
        for i, (lip, lip13, lip12) in enumerate(self._consts):
            fn = fs[i]
            if step is None:
                a, b, c, self._w[i] = filtering_step(z0[i], z1[i], z2[i], self._w[i], fp[i],
                                                     dt_s, self._filter[i])
            else:
                a, b, c = step(z0[i], z1[i], z2[i], fp[i], fn, dt_s, lip, lip13, lip12)
            z0[i] = a
            z1[i] = b
            z2[i] = c
            fp[i] = fn
            out[0, i] = a
            out[1, i] = b
            out[2, i] = c
        return out


def differentiate(f, t_s, lipschitz, scheme: str = 'implicit') -> np.ndarray:
    """Batch form of :class:`LevantDifferentiator`: the same numbers, sample by sample.

    Parameters
    ----------
    f : array_like, shape (n, c) or (n,)
        Samples (finite).
    t_s : array_like, shape (n,)
        Sample times (s), strictly increasing.
    lipschitz : array_like, shape (c,) or scalar
        L per channel.
    scheme : str
        See :data:`SCHEMES`.

    Returns
    -------
    numpy.ndarray, shape (n, 3, c) (or (n, 3) for 1-D ``f``)
        ``[z0, z1, z2]`` after each sample; row 0 is the reset ``[f(t_0), 0, 0]``.
    """
    f = np.asarray(f, dtype=float)
    one_d = f.ndim == 1
    f2 = f[:, None] if one_d else f
    t = np.asarray(t_s, dtype=float)
    if f2.ndim != 2 or t.shape != (f2.shape[0],):
        raise ValueError(f'f has shape {f.shape} and t_s {t.shape}: expected (n, c) and (n,)')
    if not np.all(np.isfinite(f2)) or not np.all(np.isfinite(t)):
        raise ValueError('f and t_s must be finite')
    n, c = f2.shape
    lip = _check_lipschitz(lipschitz)
    if lip.size == 1 and c > 1:
        lip = np.full(c, lip[0])
    if lip.size != c:
        raise ValueError(f'lipschitz has {lip.size} values for {c} channels')
    dts = np.diff(t)
    if np.any(dts <= 0.0):
        raise ValueError('t_s must be strictly increasing')
    out = np.empty((n, 3, c))
    if n == 0:
        return out[:, :, 0] if one_d else out
    filtering = scheme == 'filtering'
    step = None if filtering else step_function(scheme)
    dt_list = dts.tolist()
    for i in range(c):
        lip_i = float(lip[i])
        lip13, lip12 = lip_i ** (1.0 / 3.0), math.sqrt(lip_i)
        consts = FilteringConstants(lip_i) if filtering else None
        w = (0.0,) * consts.n_f if filtering else ()
        col = f2[:, i].tolist()
        z0, z1, z2, fp = col[0], 0.0, 0.0, col[0]
        rows = [(z0, 0.0, 0.0)]
        append = rows.append
        for k in range(1, n):
            fn = col[k]
            if filtering:
                z0, z1, z2, w = filtering_step(z0, z1, z2, w, fp, dt_list[k - 1], consts)
            else:
                z0, z1, z2 = step(z0, z1, z2, fp, fn, dt_list[k - 1], lip_i, lip13, lip12)
            fp = fn
            append((z0, z1, z2))
        out[:, :, i] = rows
    return out[:, :, 0] if one_d else out
