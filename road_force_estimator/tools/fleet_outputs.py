"""estimate_fleet's outputs: the fleet table (CSV, Parquet), the GeoJSON, the map, the
failures and ``summary.md``.

``segments.parquet`` and ``segments.csv`` hold :data:`~.fleet_drives.FLEET_COLUMNS`, one row
per segment of every drive done, drives in id order (coordinates NaN without ``/fix``), then
an articulated drive's columns and its model fit per axle (:data:`FIT_COLUMN`, repeated on
its rows: :func:`fleet_table`);
then :data:`FRICTION_COLUMN` where a drive's offline estimate states it;
``segments.geojson`` one LineString per segment (:mod:`road_force_estimator.report.fleet_map`);
``segments_map.png`` the segments coloured by IRI, when any has coordinates; ``failures.csv``
``drive,reason``. Every file is written to a temporary name and renamed into place.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass, field
import io
import json
import math
import os
from pathlib import Path
from typing import Sequence
import uuid

import numpy as np

from road_force_estimator.tools.fleet_drives import FLEET_COLUMNS, INT_COLUMNS, DriveOutcome

__all__ = ['ROUGHEST', 'FIT_COLUMN', 'FRICTION_COLUMN', 'FleetResult', 'fleet_table',
           'summary_markdown', 'write_outputs']

#: Number of roughest segments listed in summary.md.
ROUGHEST = 10
#: The fleet table's columns of a drive's model fit per axle (``report.json``
#: ``whole_vehicle_estimate.model_fit``: the drive's verdict, online the last), on every row
#: of the drive, NaN in a drive without a verdict: ``model_fit_mismatch`` (1 when it names
#: an axle or sensor, else 0), then ``model_fit_misfit_<axle>`` (the misfit's bound, a
#: fraction) per axle; the culprits by name in ``summary.md``.
FIT_COLUMN = 'model_fit_'
#: The fleet table's column of the tanh friction's ``v_f`` (m/s) a drive's offline estimate
#: took (``report.json`` ``friction_velocity.taken_mps``, the whole vehicle's where
#: articulated: :attr:`.DriveOutcome.friction_velocity`), on every row of the drive, NaN in a
#: drive without it (online, no tanh friction in the file); only when some drive has it.
FRICTION_COLUMN = 'friction_velocity_mps'


@dataclass
class FleetResult:
    """A fleet run: one outcome per drive (id order), the engine used, the wall time (s).

    ``timings`` (s): ``prepare`` (finding the drives, checking those already done),
    ``engine_start`` (starting or reaching the cluster), ``processing`` (first task submitted
    to last result back), ``write`` (tables, GeoJSON, map, summary).
    """

    outcomes: list[DriveOutcome]
    engine: str
    seconds: float
    settings: dict
    timings: dict[str, float] = field(default_factory=dict)

    def count(self, status: str) -> int:
        return sum(1 for o in self.outcomes if o.status == status)

    @property
    def exit_code(self) -> int:
        return 1 if self.count('failed') else 0


def fleet_table(outcomes: Sequence[DriveOutcome]) -> dict[str, np.ndarray]:
    """The fleet table (:data:`~.fleet_drives.FLEET_COLUMNS`, then the whole vehicle's
    columns of the articulated drives in the order first met, then their model fit's
    (:data:`FIT_COLUMN`), then the friction's ``v_f`` (:data:`FRICTION_COLUMN`), NaN in a
    drive without them): the segments of every drive done, in the order of ``outcomes``."""
    done = [o for o in outcomes if o.status != 'failed' and o.table is not None]
    table: dict[str, np.ndarray] = {'drive': np.array(
        [o.drive_id for o in done for _ in range(len(o.table['start_m']))], dtype=object)}
    fits = [_fit_columns(o) for o in done]
    names = list(dict.fromkeys([*FLEET_COLUMNS[1:], *(c for o in done for c in o.table),
                                *(c for f in fits for c in f)]))
    friction = [_friction_column(o) for o in done]
    if any(friction):
        names.append(FRICTION_COLUMN)
        fits = [{**f, **v} for f, v in zip(fits, friction)]
    for name in names:
        dtype = np.int64 if name in INT_COLUMNS else float
        parts = [np.asarray(o.table[name], dtype=dtype) if name in o.table
                 else np.full(len(o.table['start_m']), f.get(name, np.nan))
                 for o, f in zip(done, fits)]
        table[name] = np.concatenate(parts) if parts else np.zeros(0, dtype=dtype)
    return table


def _fit_columns(o: DriveOutcome) -> dict[str, float]:
    """A drive's model fit as the fleet table's values (:data:`FIT_COLUMN`; {} without a
    verdict)."""
    fit = o.model_fit
    if not fit or fit.get('verdict') not in ('ok', 'mismatch'):
        return {}
    out = {f'{FIT_COLUMN}mismatch': float(fit['verdict'] == 'mismatch')}
    for axle, m in dict(fit.get('misfit') or {}).items():
        out[f'{FIT_COLUMN}misfit_{axle}'] = math.nan if m is None else float(m)
    return out


def _friction_column(o: DriveOutcome) -> dict[str, float]:
    """A drive's friction ``v_f`` taken as the fleet table's value (:data:`FRICTION_COLUMN`;
    {} without one)."""
    taken = o.friction_velocity.get('taken_mps')
    return {} if taken is None else {FRICTION_COLUMN: float(taken)}


def _atomic_write(path: Path, data: bytes | str) -> None:
    tmp = path.with_name(f'.{path.name}.{uuid.uuid4().hex[:8]}.tmp')
    if isinstance(data, str):
        tmp.write_text(data, encoding='utf-8')
    else:
        tmp.write_bytes(data)
    os.replace(tmp, path)


def _csv_text(header: Sequence[str], rows) -> str:
    """CSV text; the segment columns rounded as in a drive's ``segments.csv``
    (:data:`road_force_estimator.report.SEGMENT_DECIMALS`), the model fit's as they are."""
    from road_force_estimator.report import SEGMENT_DECIMALS, csv_cell
    from road_force_estimator.report.whole_vehicle import column_decimals

    decimals = [SEGMENT_DECIMALS.get(name) if name in FLEET_COLUMNS else None
                if name.startswith(FIT_COLUMN) else column_decimals(name) for name in header]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator='\n')
    w.writerow(header)
    for row in rows:
        w.writerow([csv_cell(v, d) for v, d in zip(row, decimals)])
    return buf.getvalue()


def _write_parquet(path: Path, table: dict[str, np.ndarray], settings: dict) -> None:
    """``segments.parquet``: the fleet table, the settings in the schema's metadata."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    columns = list(table)[1:]
    fields = [pa.field('drive', pa.string())] + [
        pa.field(c, pa.int64() if c in INT_COLUMNS else pa.float64()) for c in columns]
    meta = {b'road_force_estimator.settings': json.dumps(settings, sort_keys=True).encode()}
    schema = pa.schema(fields, metadata=meta)
    arrays = [pa.array(table['drive'].tolist(), type=pa.string())] + [
        pa.array(table[c], type=f.type) for c, f in zip(columns, fields[1:])]
    tmp = path.with_name(f'.{path.name}.{uuid.uuid4().hex[:8]}.tmp')
    pq.write_table(pa.Table.from_arrays(arrays, schema=schema), tmp)
    os.replace(tmp, path)


def _mean_iri(o: DriveOutcome, side: str) -> float:
    """Length-weighted mean IRI (m/km) of a drive's segments, NaN without one."""
    t = o.table
    v = np.asarray(t[f'iri_{side}_m_per_km'], dtype=float)
    w = np.asarray(t['end_m'], dtype=float) - np.asarray(t['start_m'], dtype=float)
    ok = np.isfinite(v) & (w > 0)
    return float(np.sum(v[ok] * w[ok]) / np.sum(w[ok])) if ok.any() else math.nan


def _f(value: float, fmt: str = '.2f') -> str:
    return 'n/a' if value is None or not math.isfinite(value) else format(value, fmt)


def _md(text: str) -> str:
    return str(text).replace('|', '\\|').replace('\n', ' ')


def summary_markdown(result: FleetResult, table: dict[str, np.ndarray], map_written: bool,
                     params_file: str | None) -> str:
    """``summary.md``: the run, the map, one row per drive, the roughest segments, the failures
    and the warnings."""
    lines = _summary_head(result, table, params_file)
    if map_written:
        lines += ['## Map', '', 'Segments coloured by IRI (mean of left and right), on '
                  'longitude/latitude (WGS84):', '',
                  '[![segments coloured by IRI](segments_map.png)](segments_map.png)', '']
    else:
        lines += ['## Map', '', 'No segment has coordinates (no drive with `/fix`): no map.', '']
    from road_force_estimator.core.units import units

    u = units(result.settings.get('units', 'si'))
    lines += _drives_section(result.outcomes, u)
    lines += _sensors_section(result.outcomes)
    lines += _rejected_section(result.outcomes)
    lines += _model_fit_section(result.outcomes)
    lines += _roughest_section(table, u)
    failed = [o for o in result.outcomes if o.status == 'failed']
    if failed:
        lines += ['## Failures', '', '| drive | reason |', '|---|---|']
        lines += [f'| {_md(o.drive_id)} | {_md(o.reason)} |' for o in failed]
        lines.append('')
    warned = [o for o in result.outcomes if o.warnings]
    if warned:
        lines += ['## Warnings (processed up to the break)', '']
        lines += [f'- {_md(o.drive_id)}: {_md(w)}' for o in warned for w in o.warnings]
        lines.append('')
    return '\n'.join(lines)


def _summary_head(result: FleetResult, table: dict[str, np.ndarray],
                  params_file: str | None) -> list[str]:
    """The title and the run: drives, segments, settings, engine and times."""
    from road_force_estimator.report import IN_PER_MI_PER_M_PER_KM as K

    from road_force_estimator.core.units import units

    s = result.settings
    u = units(s.get('units', 'si'))
    n = len(result.outcomes)
    seg = s['segment_length_m']
    run = s.get('run_info') or {}
    iri_note = (f'- IRI in m/km (= mm/m); in/mi = m/km x {K:g}.' if u.name == 'si' else
                f'- IRI in in/mi (= m/km x {K:g}); distances in feet (0.3048 m).')
    return [
        '# Fleet summary (`estimate_fleet`)', '',
        f'- Drives: {n}; processed {result.count("processed")}, skipped (already done) '
        f'{result.count("skipped")}, failed {result.count("failed")}'
        + (' (see `failures.csv`)' if result.count('failed') else '') + '.',
        f'- Segments in the tables: {len(table["start_m"])} (`segments.csv`, '
        '`segments.parquet`, `segments.geojson`).',
        f'- Mode: {s["mode"]}; segment length {seg:g} m ({seg / 1609.344:.4g} mi); report '
        f'figures: {"yes" if s["figures"] else "no"}; parameters: '
        f'{params_file or "package defaults"}.',
        f'- Engine: {result.engine}; wall time {result.seconds:.1f} s (engine start '
        f'{result.timings.get("engine_start", 0.0):.1f} s, processing '
        f'{result.timings.get("processing", 0.0):.1f} s).',
        iri_note] + ([f'- Command: `{run["command"]}`.'] if run.get('command') else []) + [
        f'- Overrides (-p): {", ".join(run["overrides"])}.' if run.get('overrides') else
        '- Overrides (-p): none.', '']


def _iri_pair(u, v: float) -> str:
    """IRI (m/km) in the units ``u``, the other system's in parentheses."""
    from road_force_estimator.core.units import units

    other = units('us' if u.name == 'si' else 'si')
    return f'{u.iri_text(v)} ({other.iri_text(v)})'


def _iri_head(u) -> str:
    return f'{u.iri_unit} ({"in/mi" if u.name == "si" else "m/km"})'


def _drives_section(outcomes: Sequence[DriveOutcome], u=None) -> list[str]:
    """One row per drive: status, segments, distance, mean IRI, peak load, LTR, lift-offs."""
    from road_force_estimator.core.units import units

    u = units() if u is None else u
    dist_unit = 'mi' if u.name == 'us' else 'km'
    lines = ['## Drives', '',
             f'| drive | status | segments | distance ({dist_unit}) | IRI left {_iri_head(u)} | '
             f'IRI right {_iri_head(u)} | peak load (kN) | max abs LTR | lift-offs | GNSS | '
             'time (s) |',
             '|---|---|---:|---:|---:|---:|---:|---:|---:|---|---:|']
    for o in outcomes:
        if o.status == 'failed' or o.table is None:
            lines.append(f'| {_md(o.drive_id)} | failed | | | | | | | | | '
                         f'{o.seconds:.1f} |')
        else:
            lines.append(_drive_row(o, u))
    lines.append('')
    lines.append('IRI per drive: length-weighted mean of its segments. Time: the processing of '
                 'the drive (for a skipped drive, in the run that made it).')
    lines.append('')
    return lines


def _drive_row(o: DriveOutcome, u) -> str:
    """The row of a drive done (processed or skipped), IRI in the units ``u``."""
    from road_force_estimator.core.units import M_PER_MILE

    t = o.table
    k = len(t['start_m'])
    dist = (float(t['end_m'][-1] - t['start_m'][0])) if k else 0.0
    dist /= M_PER_MILE if u.name == 'us' else 1000.0
    il, ir = _mean_iri(o, 'left'), _mean_iri(o, 'right')
    peak = np.fmax(t['peak_load_left_n'], t['peak_load_right_n']) if k else np.zeros(0)
    peak_kn = float(np.nanmax(peak)) / 1000.0 if k and np.isfinite(peak).any() else math.nan
    ltr = float(np.nanmax(t['max_abs_ltr'])) if k and np.isfinite(t['max_abs_ltr']).any() \
        else math.nan
    gnss = 'yes' if k and np.isfinite(t['start_lat']).any() else 'no'
    return (
        f'| {_md(o.drive_id)} | {o.status} | {k} | {dist:.3f} | {_iri_pair(u, il)}'
        f' | {_iri_pair(u, ir)} | {_f(peak_kn, ".1f")} | {_f(ltr, ".3f")} | '
        f'{int(np.sum(t["lift_offs"])) if k else 0} | {gnss} | {o.seconds:.1f} |')


def _sensors_section(outcomes: Sequence[DriveOutcome]) -> list[str]:
    """Per drive and sensor: innovations gated (spikes), stuck and drift flags raised
    (each drive's ``report.json`` ``sensors``); the sensors with nothing are left out."""
    rows = [(o.drive_id, name, v) for o in outcomes for name, v in sorted(o.sensors.items())
            if v.get('innovations_gated') or v.get('stuck_flags') or v.get('drift_flags')]
    lines = ['## Sensors', '']
    if not rows:
        return lines + ['No sensor had an innovation gated, a stuck or a drift flag.', '']
    lines += ['| drive | sensor | innovations gated | stuck flags | drift flags | at the end |',
              '|---|---|---:|---:|---:|---|']
    lines += [f'| {_md(d)} | `{n}` | {int(v.get("innovations_gated", 0))} | '
              f'{int(v.get("stuck_flags", 0))} | {int(v.get("drift_flags", 0))} | '
              f'{v.get("flag", "ok")} |' for d, n, v in rows]
    return lines + ['']


def _rejected_section(outcomes: Sequence[DriveOutcome]) -> list[str]:
    """Per drive, topic and reason: the messages rejected (each drive's ``report.json``
    ``rejected``: the readers', an articulated drive's those of the whole vehicle's, and the
    estimator's), then the tractor IMU's samples with a held (stale) or no (missing) a_y,
    left out (``whole_vehicle_estimate.tractor_imu``); the drives with none left out."""
    rows = [(o.drive_id, topic, reason, int(count)) for o in outcomes
            for topic, reasons in sorted(o.rejected.items())
            for reason, count in sorted(reasons.items()) if count]
    from road_force_estimator.interfaces import IMU

    rows += [(o.drive_id, IMU, f'samples {word} (a_y {what})', int(n))
             for o in outcomes for word, what in (('stale', 'held'), ('missing', 'none'))
             if (n := o.tractor_imu.get(word, 0))]
    lines = ['## Rejected inputs', '']
    if not rows:
        return lines + ['No message was rejected; no sample lacked a fresh IMU a_y.', '']
    lines += ['| drive | topic | reason | count |', '|---|---|---|---:|']
    lines += [f'| {_md(d)} | `{t}` | {_md(r)} | {n} |' for d, t, r, n in sorted(rows)]
    return lines + ['']


def _model_fit_section(outcomes: Sequence[DriveOutcome]) -> list[str]:
    """Per articulated drive with a verdict: the model fit per axle (``report.json``
    ``whole_vehicle_estimate.model_fit``: the verdict, the culprits, each axle's misfit bound
    in %, online how many verdicts and how many named something); none without one."""
    rows = [(o.drive_id, o.model_fit) for o in outcomes
            if o.status != 'failed' and o.model_fit.get('verdict') in ('ok', 'mismatch')]
    if not rows:
        return []
    lines = ['## Model fit per axle (the whole vehicle)', '',
             '| drive | model fit | culprits | misfit bound per axle (%) | threshold (%) | '
             'online verdicts (named) |', '|---|---|---|---|---:|---|']
    for drive, fit in rows:
        cells = ', '.join(f'{a} {_f(100 * m if m is not None else math.nan, ".1f")}'
                          for a, m in dict(fit.get('misfit') or {}).items())
        n = int(fit.get('online_verdicts') or 0)
        online = f'{n} ({int(fit.get("online_mismatches") or 0)})' if n else 'offline'
        lines.append(f'| {_md(drive)} | {fit["verdict"]} | '
                     f'{_md(", ".join(fit.get("culprits") or ())) or "none"} | {cells} | '
                     f'{_f(100 * float(fit.get("threshold", math.nan)), "g")} | {online} |')
    return lines + ['', "The drive's verdict (online the last): each axle's road against the "
                    "other axles' at the same distance; `mismatch` names the axle, or its "
                    'sensor, that does not fit the parameter file.', '']


def _roughest_section(table: dict[str, np.ndarray], u=None) -> list[str]:
    """The :data:`ROUGHEST` segments by mean IRI (none without a finite IRI)."""
    from road_force_estimator.core.units import units

    u = units() if u is None else u
    mean = 0.5 * (table['iri_left_m_per_km'] + table['iri_right_m_per_km'])
    order = [int(j) for j in np.argsort(-np.where(np.isfinite(mean), mean, -np.inf))
             if np.isfinite(mean[j])][:ROUGHEST]
    if not order:
        return []
    lines = [f'## Roughest segments (top {len(order)} by mean IRI)', '',
             f'| drive | start ({u.length_unit}) | end ({u.length_unit}) | IRI left '
             f'{_iri_head(u)} | IRI right {_iri_head(u)} | start lat, lon | end lat, lon |',
             '|---|---:|---:|---:|---:|---|---|']
    for j in order:
        def pos(a, b):
            la, lo = table[a][j], table[b][j]
            return f'{la:.6f}, {lo:.6f}' if np.isfinite(la) and np.isfinite(lo) else 'n/a'
        il, ir = table['iri_left_m_per_km'][j], table['iri_right_m_per_km'][j]
        lines.append(
            f'| {_md(table["drive"][j])} | {u.length_text(table["start_m"][j], 1)} | '
            f'{u.length_text(table["end_m"][j], 1)} | {_iri_pair(u, il)} | {_iri_pair(u, ir)}'
            f' | {pos("start_lat", "start_lon")} | '
            f'{pos("end_lat", "end_lon")} |')
    lines.append('')
    return lines


def write_outputs(output: str | Path, result: FleetResult, *,
                  params_file: str | None = None) -> dict[str, np.ndarray]:
    """Write the fleet tables, GeoJSON, map, failures and summary into ``output``; returns the
    fleet table (:data:`FLEET_COLUMNS` and an articulated drive's, :func:`fleet_table`)."""
    from road_force_estimator.report import plot_segments_map, segments_geojson

    out = Path(output)
    table = fleet_table(result.outcomes)
    columns = tuple(table)
    rows = zip(*(table[c].tolist() for c in columns))
    _atomic_write(out / 'segments.csv', _csv_text(columns, rows))
    _write_parquet(out / 'segments.parquet', table, result.settings)
    lines = [line for o in result.outcomes if o.status != 'failed' and o.table is not None
             for line in (o.lines or [None] * len(o.table['start_m']))]
    doc = segments_geojson(table, lines, columns)
    _atomic_write(out / 'segments.geojson',
                  json.dumps(doc, allow_nan=False, separators=(',', ':')) + '\n')
    failed = [(o.drive_id, o.reason) for o in result.outcomes if o.status == 'failed']
    _atomic_write(out / 'failures.csv', _csv_text(('drive', 'reason'), failed))
    png = out / 'segments_map.png'
    mean = 0.5 * (table['iri_left_m_per_km'] + table['iri_right_m_per_km'])
    tmp_png = out / f'.segments_map.{uuid.uuid4().hex[:8]}.png'
    from road_force_estimator.core.units import units

    u = units(result.settings.get('units', 'si'))
    drives = [o.drive_id for o in result.outcomes if o.status != 'failed' and o.table is not None
              for _ in range(len(o.table['start_m']))]
    if plot_segments_map(tmp_png, lines, mean, labels=drives, units=u.name,
                         title=f'IRI per {u.segment_text(result.settings["segment_length_m"])} '
                               f'segment, {len({d for d in table["drive"]})} drives'):
        os.replace(tmp_png, png)
        map_written = True
    else:
        map_written = False
        png.unlink(missing_ok=True)
    _atomic_write(out / 'summary.md', summary_markdown(result, table, map_written, params_file))
    return table
