"""The diagnostics of the estimator as plain data: one builder for the node and the bags.

The ``observer`` node (per ~1 s of wall time, from its counters) and ``estimate_bag`` (per
second of data time, from the batch's arrays) report the same statuses with the same words;
both build them here and only convert at their edge (``ros/messages.py`` to
``diagnostic_msgs/DiagnosticStatus``, ``bagio`` to the bag's CDR). No ROS, no bag library.

Levels follow ``diagnostic_msgs/DiagnosticStatus``: 0 OK, 1 WARN, 2 ERROR, 3 STALE.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

__all__ = ['OK', 'WARN', 'ERROR', 'STALE', 'Status', 'text', 'status', 'estimator_message',
           'estimator_status', 'model_fit_values', 'sensor_values', 'sensor_totals',
           'fault_message', 'batch_diagnostics']

OK, WARN, ERROR, STALE = 0, 1, 2, 3
#: The sensor flags' words by code (:data:`.sensor_health.CODES`).
_FLAG_WORDS = ('ok', 'stuck', 'drift')
_NS = 1_000_000_000


@dataclass(frozen=True)
class Status:
    """One diagnostic status: ``values`` are (key, text) pairs in the order reported."""

    name: str
    hardware_id: str
    level: int
    message: str
    values: tuple[tuple[str, str], ...]

    def as_dict(self) -> dict[str, Any]:
        """The status as the plain mapping :func:`road_force_estimator.bagio.diagnostic_array`
        takes (``name``, ``level``, ``message``, ``hardware_id``, ``values``)."""
        return {'name': self.name, 'level': self.level, 'message': self.message,
                'hardware_id': self.hardware_id, 'values': dict(self.values)}


def text(value: Any) -> str:
    """A value as diagnostics show it: booleans ``true`` / ``false``, floats to 6 digits."""
    if isinstance(value, (bool, np.bool_)):
        return 'true' if value else 'false'
    if isinstance(value, float):
        return f'{value:.6g}'
    return str(value)


def status(name: str, hardware_id: str, message: str, values: Mapping[str, Any],
           level: int | None = None) -> Status:
    """A :class:`Status`; its level is OK when ``message`` is ``'ok'``, else WARN, unless
    ``level`` is given."""
    if level is None:
        level = OK if message == 'ok' else WARN
    if level not in (OK, WARN, ERROR, STALE):
        raise ValueError(f'diagnostic level = {level!r}: one of 0 (OK), 1 (WARN), 2 (ERROR), '
                         '3 (STALE)')
    return Status(name, hardware_id, level, message,
                  tuple((str(k), text(v)) for k, v in values.items()))


def estimator_message(converged: bool, lift_off_samples: int, restarts: int = 0,
                      speed_contradicted: int = 0, model_fit: str = 'ok',
                      faults: str = '') -> str:
    """The estimator status' words: the sensor faults (``faults``, :func:`fault_message`),
    'speed contradicted by the deflections (N samples)', 'converging', the model-fit advice
    (:data:`.model_fit.ADVICE`, when ``model_fit`` is 'mismatch'), 'N lift-off samples',
    'N restarts' or 'ok' (in that order of precedence)."""
    from road_force_estimator.estimation.fit_check import ADVICE, MISMATCH

    if faults:
        return faults
    if speed_contradicted:
        return f'speed contradicted by the deflections ({speed_contradicted} samples)'
    if not converged:
        return 'converging'
    if model_fit == MISMATCH:
        return ADVICE
    if lift_off_samples:
        return f'{lift_off_samples} lift-off samples'
    if restarts:
        return f'{restarts} restarts'
    return 'ok'


def estimator_status(name: str, hardware_id: str, values: Mapping[str, Any], *,
                     converged: bool, lift_off_samples: int, restarts: int = 0,
                     speed_contradicted: int = 0, model_fit: str = 'ok') -> Status:
    """The estimator's status (sensor faults from the ``sensor.<channel>`` values, speed
    contradicted, convergence, model fit, lift-offs, restarts) with ``values``; WARN unless
    'ok'."""
    faults = fault_message({k[len('sensor.'):]: v for k, v in values.items()
                            if k.startswith('sensor.')})
    return status(name, hardware_id, estimator_message(converged, lift_off_samples, restarts,
                                                       speed_contradicted, model_fit, faults),
                  values)


def fault_message(flags: Mapping[str, str]) -> str:
    """'sensor fault: left_suspension stuck, roll drift' for the channels whose flag
    (:mod:`.sensor_health`) is not 'ok'; '' when none."""
    bad = [f'{name} {flag}' for name, flag in flags.items() if flag != 'ok']
    return 'sensor fault: ' + ', '.join(bad) if bad else ''


def sensor_values(flags: Mapping[str, str], gated: Mapping[str, int] | None = None
                  ) -> dict[str, Any]:
    """The status values of the sensors: ``sensor.<channel>`` ('ok' | 'stuck' | 'drift',
    :mod:`.sensor_health`) and, when given, ``innovations_gated.<channel>`` (the samples the
    innovation gate kept from the filter in the status' period)."""
    out: dict[str, Any] = {f'sensor.{name}': flag for name, flag in flags.items()}
    if gated is not None:
        out.update({f'innovations_gated.{name}': int(n) for name, n in gated.items()})
    return out


def sensor_totals(st) -> dict[str, int]:
    """Whole-run counts of an :class:`.EstimatorStatus` per channel (reported as
    ``total.<key>``): ``innovations_gated.<channel>``, ``stuck.<channel>`` and
    ``drift.<channel>`` (flags raised)."""
    out: dict[str, int] = {}
    for key, attr in (('innovations_gated', 'innovations_gated'), ('stuck', 'stuck_episodes'),
                      ('drift', 'drift_episodes')):
        counts = getattr(st, attr, None) or {}
        out.update({f'{key}.{name}': int(n) for name, n in counts.items()})
    return out


def model_fit_values(ratio: float, word: str) -> dict[str, Any]:
    """The status values of the model-fit diagnostic (:mod:`.fit_check`): ``model_fit``
    ('ok' | 'mismatch') and ``model_fit_ratio`` (band RMS of the residual over sigma_M)."""
    return {'model_fit': word, 'model_fit_ratio': float(ratio)}


def batch_diagnostics(stamp_ns: np.ndarray, valid: np.ndarray, converged: np.ndarray,
                      lift_off: np.ndarray, ltr: np.ndarray, residual_nm: np.ndarray,
                      totals: Mapping[str, Any], name: str, hardware_id: str,
                      speed_contradicted: np.ndarray | None = None,
                      model_fit: tuple[float, str] | None = None,
                      sensors: tuple[Sequence[str], np.ndarray] | None = None
                      ) -> list[tuple[int, list[Status]]]:
    """The estimator status per second of data time over a batch of estimates.

    Parameters
    ----------
    stamp_ns, valid, converged : (n,) arrays
        Stamps (ns), rows that hold an estimate, convergence flags.
    lift_off : (n, 2) bool array
        Lift-off flags (left, right).
    ltr, residual_nm : (n,) arrays
        Load transfer ratio and model residual (N m).
    totals : mapping
        Whole-drive counts, reported as ``total.<key>`` on the last status.
    name, hardware_id : str
        The status' name and hardware id.
    speed_contradicted : (n,) bool array, optional
        Samples whose standing speed the deflections contradicted: a window with some
        reports ``speed_contradicted_samples`` and WARNs.
    model_fit : (ratio, 'ok' | 'mismatch'), optional
        The drive's model-fit verdict (:func:`.model_fit.assess`), reported by every status
        (:func:`model_fit_values`); 'mismatch' WARNs with the advice to calibrate.
    sensors : (channel names, (n, channels) flag codes), optional
        The sensor flags per sample (:mod:`.sensor_health` CODES): every status reports each
        channel's flag at its last row (:func:`sensor_values`), a fault WARNs naming it.

    Returns
    -------
    list of (stamp_ns, [Status])
        One entry per second of valid rows (seconds counted from the first valid stamp),
        stamped with that second's last stamp; empty when no row is valid.
    """
    rows = np.flatnonzero(valid)
    if rows.size == 0:
        return []
    stamps = np.asarray(stamp_ns, dtype=np.int64)[rows]
    second = (stamps - stamps[0]) // _NS
    ends = np.flatnonzero(np.diff(second)) + 1
    bounds = list(zip(np.concatenate([[0], ends]).tolist(),
                      np.concatenate([ends, [rows.size]]).tolist()))
    abs_ltr = np.abs(np.asarray(ltr)[rows])
    abs_res = np.abs(np.asarray(residual_nm)[rows])
    lifted = np.asarray(lift_off)[rows].any(axis=1)
    conv = np.asarray(converged)[rows]
    contra = (np.zeros(rows.size, bool) if speed_contradicted is None
              else np.asarray(speed_contradicted, bool)[rows])
    out = []
    for j, (a, b) in enumerate(bounds):
        values = _window_values(b - a, bool(conv[b - 1]), lifted[a:b], abs_ltr[a:b],
                                abs_res[a:b])
        bad_speed = int(np.count_nonzero(contra[a:b]))
        if bad_speed:
            values['speed_contradicted_samples'] = bad_speed
        if model_fit is not None:
            values.update(model_fit_values(*model_fit))
        if sensors is not None:
            codes = np.asarray(sensors[1])[rows[b - 1]]
            values.update(sensor_values({n: _FLAG_WORDS[int(c)]
                                         for n, c in zip(sensors[0], codes)}))
        if j == len(bounds) - 1:
            values.update({f'total.{k}': v for k, v in totals.items()})
        out.append((int(stamps[b - 1]), [estimator_status(
            name, hardware_id, values, converged=values['converged'],
            lift_off_samples=values['lift_off_samples'], speed_contradicted=bad_speed,
            model_fit=values.get('model_fit', 'ok'))]))
    return out


def _window_values(samples: int, converged: bool, lifted: Sequence[bool], abs_ltr: np.ndarray,
                   abs_residual: np.ndarray) -> dict[str, Any]:
    return {'samples': samples, 'converged': converged,
            'lift_off_samples': int(np.count_nonzero(lifted)),
            'max_abs_ltr': float(np.max(abs_ltr)),
            'max_abs_residual_nm': float(np.max(abs_residual))}
