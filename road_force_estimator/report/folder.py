"""The report folder of an estimated drive: what :func:`write_report` writes
(``estimate_bag`` writes ``DIR/report/``).

``report.md``
    Summary (samples processed, rejected by topic and reason, breaks in the bag, restarts,
    convergence), accuracy against the ground truth when the bag has it (wheel-load error RMS
    as a % of the true dynamic-load RMS and of the static load, band-passed profile error %,
    LTR error), the IRI of the whole drive, the per-segment table and the figures
    (:mod:`.markdown`).
``segments.csv``
    One row per segment (default 100 m; SI units whatever ``--units``, named in the columns;
    rounded to what the measurement supports: :data:`SEGMENT_DECIMALS`):
    :data:`road_force_estimator.core.segments.SEGMENT_COLUMNS` (IRI left/right of the
    estimated and, when known, the true profile; DLC; peak loads; max |LTR|; lift-off events;
    coordinates when the drive has ``/fix``).
``report.json``
    The summary's numbers, for programs (:func:`~.summary.summarize`).
``states.png``, ``body.png``, ``wheels.png``, ``profile.png``, ``loads.png``, ``overview.png``
    :data:`~.figures.FIGURES` (:mod:`.figures`).
"""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
from road_force_estimator.core.segments import SEGMENT_COLUMNS
from road_force_estimator.report.figures import write_figures
from road_force_estimator.report.markdown import write_markdown
from road_force_estimator.report.summary import DEFAULT_SEGMENT_LENGTH_M, summarize

__all__ = ['SEGMENT_DECIMALS', 'csv_cell', 'write_segments_csv', 'write_report']

#: Decimals of ``segments.csv``'s float columns: 1 mm of distance, 0.001 m/km of IRI, 1 N of
#: load, 1e-4 of DLC and LTR, 1e-7 deg (about 1 cm) of latitude and longitude.
SEGMENT_DECIMALS = {
    'start_m': 3, 'end_m': 3, 'iri_left_m_per_km': 3, 'iri_right_m_per_km': 3,
    'true_iri_left_m_per_km': 3, 'true_iri_right_m_per_km': 3, 'dlc_left': 4, 'dlc_right': 4,
    'peak_load_left_n': 0, 'peak_load_right_n': 0, 'max_abs_ltr': 4, 'start_lat': 7,
    'start_lon': 7, 'end_lat': 7, 'end_lon': 7, 'static_load_left_n': 0,
    'static_load_right_n': 0, 'max_abs_ltr_quasi_static': 4,
}


def csv_cell(value, decimals: int | None = None) -> str:
    """A table cell as CSV text: ``true``/``false``, integers as such, text as it is, floats
    with ``decimals`` decimals (no ``-0``), or when None in their shortest exact form (``repr``:
    they read back bit for bit), ``nan`` if unknown."""
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value)).lower()
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, str):
        return value
    v = float(value)
    if math.isnan(v):
        return 'nan'
    if decimals is None or math.isinf(v):
        return repr(v)
    text = f'{v:.{decimals}f}'
    return text[1:] if text.startswith('-') and float(text) == 0.0 else text


def write_segments_csv(path: str | Path, segments: dict[str, np.ndarray]) -> None:
    """``segments.csv``: a header of :data:`SEGMENT_COLUMNS`, one row per segment (numbers
    rounded as :data:`SEGMENT_DECIMALS` says, ``nan`` where unknown)."""
    with Path(path).open('w', newline='') as f:
        w = csv.writer(f, lineterminator='\n')
        w.writerow(SEGMENT_COLUMNS)
        n = len(segments['start_m'])
        for i in range(n):
            w.writerow([csv_cell(segments[c][i], SEGMENT_DECIMALS.get(c))
                        for c in SEGMENT_COLUMNS])


def json_safe(obj):
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if math.isfinite(v) else None
    return obj


def static_line(summary: dict[str, Any], vehicle: VehicleParameters | None
                 ) -> tuple[float, float]:
    """The static loads drawn in the load figures: the configured ones, or the estimate at
    the end of the drive under zero_load (MODEL.md "Measurements")."""
    vehicle = vehicle or VehicleParameters()
    final = summary.get('static_load_final_n')
    return tuple(final) if vehicle.zero_load and final else vehicle.static_load_n


def write_report(folder: str | Path, est, drive=None, vehicle: VehicleParameters | None = None,
                 observer: ObserverParameters | None = None, *, mode: str = 'online',
                 input_name: str = '', reference=None, reference_offset_m: float | None = None,
                 segment_length_m: float = DEFAULT_SEGMENT_LENGTH_M, figures: bool = True,
                 extra: dict[str, Any] | None = None, units: str = 'si',
                 run_info: dict[str, Any] | None = None, raw_road=None) -> dict[str, Any]:
    """Write the report folder (see the module notes); returns the summary.

    Parameters are those of :func:`~.summary.summarize`, plus ``folder`` (created if needed) and
    ``figures`` (False: numbers and tables only).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    summary, segments, al = summarize(
        est, drive, vehicle, observer, mode=mode, input_name=input_name, reference=reference,
        reference_offset_m=reference_offset_m, segment_length_m=segment_length_m, extra=extra,
        units=units, run_info=run_info, raw_road=raw_road)
    names: list[str] = []
    if figures:
        names = write_figures(folder, est, al, drive, segments=segments,
                              title=f'{input_name} ({mode})' if input_name else mode,
                              units=units, static_load_n=static_line(summary, vehicle))
    summary['figures'] = names
    write_segments_csv(folder / 'segments.csv', segments)
    write_markdown(folder / 'report.md', summary, segments, names)
    (folder / 'report.json').write_text(json.dumps(json_safe(summary), indent=2) + '\n')
    return summary
