"""A synthetic jointed plain concrete pavement (JPCP): slabs, faulted joints, curl, roughness.

A JPCP road is a row of concrete slabs of length ``L`` (the joint spacing, about 4.6 m on
highways) separated by transverse joints that cross both wheel paths. Its profile is (MODEL.md
"Road profiles" terms: elevation of the left and right wheel paths against distance, m)

    u(x) = u_iso(x) + u_fault(x) + u_curl(x)

- **faulting**: at each joint the slab after it (in the direction of travel) sits lower than
  the one before by a step ``f_j`` (traffic pumps the support from under the leave slab). With
  the road level on average, every slab rises over its length by the mean of the steps at its
  two ends: slab j goes from ``-f_j / 2`` just after its joint to ``+f_{j+1} / 2`` just before
  the next, where the road steps down by ``f_{j+1}``: a saw-tooth. The step is a straight ramp
  over the joint's width ``w`` (5 mm by default: the sawn joint; the tire's 250 mm envelope
  makes it a ramp anyway). Each joint's step is ``faulting`` times a factor drawn uniformly
  in [0.5, 1.5], plus, per wheel path, one drawn uniformly in [-0.15, 0.15] (a joint faults
  unevenly across the lane), the sum clipped to [0.5, 1.5]: ``faulting = 2 mm`` gives steps
  of 1-3 mm;
- **curl**: a slab whose top is colder or drier than its bottom curls up at its ends: slab j
  adds ``c (2 s - 1)^2``, s in [0, 1] along the slab, so its two ends stand ``c`` (the curl)
  above its middle, the same on both wheel paths; a negative curl is a slab warped down at its
  ends (a hot afternoon);
- **roughness**: a mild ISO 8608 road underneath (class A by default, the package's left/right
  coherence model, :func:`road_force_estimator.core.road.iso8608_profile`), or none.

The random draws (the roughness's seed, then the steps, then the per-path factors) come from
``numpy.random.default_rng(seed)``: a seed gives one road, and the same joints with or
without the roughness. Joints are at ``start + k L``,
k = 1, 2, ...

Source string (``simulator.road``, ``simulate_bag --road``, the plant node):
``jpcp[:joint_spacing=4.6][:faulting=2e-3][:curl=1e-3][:roughness=A|none][:seed=1]
[:joint_width=0.005][:length=..][:dx=0.05][:start=0]`` (lengths in m).

This module imports numpy only, with :mod:`.road` (core).
"""
from __future__ import annotations

import math

import numpy as np

from road_force_estimator.core.road import DEFAULT_SYNTHETIC_LENGTH_M, RoadProfile, iso8608_profile

__all__ = ['DEFAULT_JOINT_SPACING_M', 'DEFAULT_FAULTING_M', 'DEFAULT_CURL_M',
           'DEFAULT_JOINT_WIDTH_M', 'DEFAULT_ROUGHNESS', 'FAULT_SPREAD', 'SIDE_SPREAD',
           'jpcp_profile', 'jpcp_from_source']

#: Joint spacing (slab length) of a typical highway JPCP (m).
DEFAULT_JOINT_SPACING_M = 4.6
#: Mean faulting step (m): steps are drawn in [0.5, 1.5] x this, 1-3 mm.
DEFAULT_FAULTING_M = 2e-3
#: Slab curl: rise of a slab's ends above its middle (m).
DEFAULT_CURL_M = 1e-3
#: Width of the joint over which the step ramps (m).
DEFAULT_JOINT_WIDTH_M = 0.005
#: ISO 8608 class of the roughness underneath.
DEFAULT_ROUGHNESS = 'A'
#: A joint's step is faulting x a factor drawn in [1 - FAULT_SPREAD, 1 + FAULT_SPREAD]...
FAULT_SPREAD = 0.5
#: ... plus, per wheel path, one drawn in [-SIDE_SPREAD, SIDE_SPREAD] (the sum clipped to the
#: first range).
SIDE_SPREAD = 0.15


def _checked(name: str, value: float, low: float, high: float) -> float:
    value = float(value)
    if not (math.isfinite(value) and low <= value <= high):
        raise ValueError(f'jpcp {name} = {value!r}: must be in [{low:g}, {high:g}]')
    return value


def jpcp_profile(length_m: float = DEFAULT_SYNTHETIC_LENGTH_M, *,
                 joint_spacing_m: float = DEFAULT_JOINT_SPACING_M,
                 faulting_m: float = DEFAULT_FAULTING_M, curl_m: float = DEFAULT_CURL_M,
                 roughness: str | None = DEFAULT_ROUGHNESS, seed: int = 1,
                 joint_width_m: float = DEFAULT_JOINT_WIDTH_M, dx_m: float = 0.05,
                 start_m: float = 0.0) -> RoadProfile:
    """A jointed concrete road (module notes): slabs, faulted joints, curl, ISO roughness.

    Parameters
    ----------
    length_m : float
        Length (m), > 0.
    joint_spacing_m : float
        Slab length L (m), in [1, 30].
    faulting_m : float
        Mean step at a joint (m, the slab after the joint lower), in [0, 0.05].
    curl_m : float
        Rise of each slab's ends above its middle (m), in [-0.02, 0.02].
    roughness : str or None
        ISO 8608 class of the roughness underneath ('A'..'H'), or None / 'none'.
    seed : int
        Seed of every random draw, >= 0.
    joint_width_m : float
        Width of the ramp of a step (m), in (0, L / 10].
    dx_m : float
        Grid spacing inside a slab (m), in (0, L / 4].
    start_m : float
        Distance of the first point (m).

    Returns
    -------
    RoadProfile
        On a grid of ``dx_m`` plus, at each joint x_j, the points x_j and x_j + w (the step
        between them).
    """
    length = _checked('length', length_m, 0.0, 1e7)
    spacing = _checked('joint_spacing', joint_spacing_m, 1.0, 30.0)
    fault = _checked('faulting', faulting_m, 0.0, 0.05)
    curl = _checked('curl', curl_m, -0.02, 0.02)
    width = _checked('joint_width', joint_width_m, 1e-6, 0.1 * spacing)
    dx = _checked('dx', dx_m, 1e-4, 0.25 * spacing)
    start = float(start_m)
    if not (length > 0.0 and math.isfinite(start)):
        raise ValueError(f'jpcp length = {length!r} m must be > 0, start = {start!r} finite')
    seed = int(seed)
    if seed < 0:
        raise ValueError(f'jpcp seed = {seed}: must be >= 0')
    rng = np.random.default_rng(seed)
    rough_class = None if roughness in (None, '', 'none') else str(roughness).upper()
    # the ISO road has its own generator, seeded from ours (drawn with or without roughness:
    # the steps of a seed are the same either way)
    iso_seed = int(rng.integers(2**31))
    iso = None if rough_class is None else iso8608_profile(rough_class, length, seed=iso_seed,
                                                           dx_m=dx, start_m=start)
    joints = start + spacing * np.arange(1, int(math.floor(length / spacing - 1e-9)) + 1)
    joints = joints[joints + width < start + length]
    factor = rng.uniform(1.0 - FAULT_SPREAD, 1.0 + FAULT_SPREAD, joints.size)
    side = rng.uniform(-SIDE_SPREAD, SIDE_SPREAD, (joints.size, 2))
    steps = fault * np.clip(factor[:, None] + side, 1.0 - FAULT_SPREAD, 1.0 + FAULT_SPREAD)
    x = _grid(start, length, dx, joints, width)
    z = _slabs(x, start, start + length, joints, width, steps, curl)
    if iso is not None:
        z = z + iso.elevation_at(x)
    name = (f'jpcp:joint_spacing={spacing:g}:faulting={fault:g}:curl={curl:g}:'
            f'roughness={rough_class or "none"}:seed={seed}')
    return RoadProfile(x, z, name=name)


def _grid(start: float, length: float, dx: float, joints: np.ndarray,
          width: float) -> np.ndarray:
    """The grid points outside the joints' ramps, and each ramp's two ends."""
    npts = int(math.ceil(length / dx - 1e-9)) + 1
    x = start + dx * np.arange(npts)
    x[-1] = min(x[-1], start + length)
    if joints.size:
        j = np.maximum(np.searchsorted(joints, x, side='right') - 1, 0)
        inside = (x > joints[j]) & (x < joints[j] + width)
        x = x[~inside]
    x = np.union1d(x, np.concatenate([joints, joints + width]))
    keep = np.concatenate([[True], np.diff(x) > 1e-9])
    return x[keep]


def _slabs(x: np.ndarray, start: float, end: float, joints: np.ndarray, width: float,
           steps: np.ndarray, curl: float) -> np.ndarray:
    """Faulting saw-tooth and curl (n, 2) at ``x``: slab k from ``begin_k`` (start, or a
    joint's x_j + w) to ``end_k`` (the next joint, or the road's end); ``steps`` (joints, 2)."""
    begin = np.concatenate([[start], joints + width])
    finish = np.concatenate([joints, [end]])
    zeros = np.zeros((1, 2))
    f_in = np.concatenate([zeros, steps])         # step at the joint before slab k
    f_out = np.concatenate([steps, zeros])        # step at the joint after slab k
    k = np.clip(np.searchsorted(begin, x, side='right') - 1, 0, begin.size - 1)
    s = np.clip((x - begin[k]) / (finish[k] - begin[k]), 0.0, 1.0)
    z = -0.5 * f_in[k] + s[:, None] * 0.5 * (f_in[k] + f_out[k])
    z += (curl * (2.0 * s - 1.0) ** 2)[:, None]
    # inside a joint's ramp (finish_k < x < begin_k+1) the profile interpolates linearly
    # between the two knots: no grid point lies there (_grid)
    return z


def jpcp_from_source(text: str, length_m: float | None = None) -> RoadProfile:
    """A JPCP road from its source string (module notes); ``length_m`` when the string gives
    none (default :data:`~road_force_estimator.core.road.DEFAULT_SYNTHETIC_LENGTH_M`).
    Raises ValueError on a bad string."""
    parts = [p.strip() for p in str(text).split(':')]
    if parts[0].lower() != 'jpcp':
        raise ValueError(f'road source {text!r}: not a "jpcp[:name=value...]" road')
    names = {'joint_spacing': 'joint_spacing_m', 'faulting': 'faulting_m', 'curl': 'curl_m',
             'joint_width': 'joint_width_m', 'length': 'length_m', 'dx': 'dx_m',
             'start': 'start_m'}
    kwargs: dict = {'length_m': DEFAULT_SYNTHETIC_LENGTH_M if length_m is None else length_m}
    for part in parts[1:]:
        if '=' not in part:
            raise ValueError(f'road source {text!r}: option {part!r} is not name=value')
        name, value = (s.strip() for s in part.split('=', 1))
        name = name.lower()
        if name == 'roughness':
            kwargs['roughness'] = value
        elif name == 'seed':
            try:
                kwargs['seed'] = int(value)
            except ValueError:
                raise ValueError(f'road source {text!r}: seed = {value!r} is not an '
                                 'integer') from None
        elif name in names:
            try:
                kwargs[names[name]] = float(value)
            except ValueError:
                raise ValueError(f'road source {text!r}: {name} = {value!r} is not a '
                                 'number') from None
        else:
            allowed = ', '.join(sorted([*names, 'roughness', 'seed']))
            raise ValueError(f'road source {text!r}: unknown option {name!r} (allowed: '
                             f'{allowed})')
    try:
        return jpcp_profile(**kwargs)
    except ValueError as exc:
        raise ValueError(f'road source {text!r}: {exc}') from None
