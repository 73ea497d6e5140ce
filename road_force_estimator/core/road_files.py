"""Road profile files: CSV, UMTRI ERD and text columns; and a profile from a source string.

Formats (INTERFACES.md, MODEL.md "Road profiles"): CSV with a ``distance_m,left_m,right_m`` or
``distance_m,elevation_m`` header, ERD text files (as ProVAL and RoadRuf write them), and the
2-column text format of ``../shared/data/profile_1.txt``. Rows with a non-finite value or a
distance that does not increase are dropped and counted in the profile's ``notes``.
:func:`road_from_source` adds the synthetic roads of :mod:`.road`; LPA bags are read by
:func:`road_force_estimator.bagio.road_from_source`.
"""
from __future__ import annotations

import csv
import itertools
import math
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from road_force_estimator.core.road import RoadProfile, synthetic_profile
from road_force_estimator.core.road_jpcp import jpcp_from_source
from road_force_estimator.core.units import IN_PER_MI_PER_M_PER_KM

__all__ = [
    'read_csv_profile', 'write_csv_profile', 'read_erd_profile', 'write_erd_profile',
    'write_text_profile',
    'read_text_profile', 'road_from_source', 'erd_stored_iri', 'ERD_IRI_KEYS',
    'MAX_ELEVATION_M', 'MAX_DISTANCE_M', 'MAX_STEP_M',
]

#: Physical bounds of a profile file's values; beyond them the file is refused (naming the
#: line): no road is higher or deeper than 10 km (elevations are relative or above sea
#: level), longer than 10,000 km, or sampled more coarsely than every 100 m (an ERD STEP).
#: They also bound what a consumer resamples the profile to.
MAX_ELEVATION_M = 1e4
MAX_DISTANCE_M = 1e7
MAX_STEP_M = 100.0

_LENGTH_UNITS_M = {
    'm': 1.0, 'meter': 1.0, 'meters': 1.0, 'metre': 1.0, 'metres': 1.0,
    'cm': 0.01, 'mm': 0.001, 'km': 1000.0,
    'in': 0.0254, 'inch': 0.0254, 'inches': 0.0254,
    'ft': 0.3048, 'feet': 0.3048, 'foot': 0.3048,
    'mi': 1609.344, 'mile': 1609.344, 'miles': 1609.344,
    'mil': 2.54e-5, 'mils': 2.54e-5,
}


def _check_physical(distance: np.ndarray, elevation: np.ndarray, name: str,
                    line_numbers) -> None:
    """Refuse finite values beyond :data:`MAX_DISTANCE_M` / :data:`MAX_ELEVATION_M`, naming
    the first such row's line (``line_numbers[i]`` of row i)."""
    for values, bound, what in ((distance[:, None], MAX_DISTANCE_M, 'distance'),
                                (elevation, MAX_ELEVATION_M, 'elevation')):
        beyond = np.flatnonzero(np.any(np.abs(values) > bound, axis=1)
                                & np.all(np.isfinite(values), axis=1))
        if beyond.size:
            i = int(beyond[0])
            worst = values[i][np.argmax(np.abs(values[i]))]
            raise ValueError(f'{name}, line {int(line_numbers[i])}: {what} {worst:.6g} m is '
                             f'beyond +-{bound:g} m, not a road profile (a wrong unit or a '
                             f'corrupt value?); {beyond.size} such row(s)')


def _clean(distance: np.ndarray, elevation: np.ndarray, name: str,
           notes: list[str] | None = None, line_numbers=None,
           where: str | None = None) -> RoadProfile:
    """Refuse physically impossible values (:func:`_check_physical`: ``line_numbers`` of the
    rows, default the row index + 2, in file ``where``, default ``name``); drop non-finite
    rows and rows whose distance does not increase, counted in notes."""
    notes = list(notes or [])
    distance = np.asarray(distance, dtype=np.float64)
    elevation = np.asarray(elevation, dtype=np.float64)
    if elevation.ndim == 1:
        elevation = np.column_stack((elevation, elevation))
    if line_numbers is None:
        line_numbers = np.arange(distance.size) + 2
    _check_physical(distance, elevation, where or name, line_numbers)
    finite = np.isfinite(distance) & np.all(np.isfinite(elevation), axis=1)
    if not np.all(finite):
        notes.append(f'{int(np.sum(~finite))} rows with a non-finite value dropped')
        distance, elevation = distance[finite], elevation[finite]
    if distance.size:
        # Keep a row only if its distance exceeds every distance kept before it.
        running = np.maximum.accumulate(distance)
        keep = np.ones(distance.size, dtype=bool)
        keep[1:] = distance[1:] > running[:-1]
        if not np.all(keep):
            notes.append(f'{int(np.sum(~keep))} rows with a duplicate or decreasing distance '
                         f'dropped')
            distance, elevation = distance[keep], elevation[keep]
    if distance.size < 2:
        raise ValueError(f'{name}: fewer than 2 usable profile points')
    return RoadProfile(distance, elevation, name=name, notes=tuple(notes))


def read_csv_profile(path: str | Path) -> RoadProfile:
    """Read a CSV profile (INTERFACES.md): header ``distance_m,left_m,right_m`` or
    ``distance_m,elevation_m`` (one track, used for both wheels); metres.

    Columns are found by name (any order, extra columns ignored); a UTF-8 byte-order mark (as
    Excel writes) is read. Rows with a non-finite value or a distance that does not increase
    are dropped and counted in ``notes``; a row that is not numbers raises
    :class:`ValueError` naming the file and line. Read :data:`CHUNK_LINES` lines at a time:
    the memory is that of the numbers (a few times 8 bytes per value), not of the text.
    """
    path = Path(path)
    with _open_text(path, newline='') as f:
        numbered = _numbered_lines(f, path)
        header_line = next(((i, t) for i, t in numbered if t.strip()), None)
        if header_line is None:
            raise ValueError(f'{path}: empty CSV profile')
        header = [c.strip() for c in next(csv.reader([header_line[1]]))]
        try:
            cols = [header.index('distance_m')]
            if 'left_m' in header and 'right_m' in header:
                cols += [header.index('left_m'), header.index('right_m')]
            else:
                cols.append(header.index('elevation_m'))
        except ValueError:
            raise ValueError(f'{path}: header {",".join(header)!r} must be '
                             f'"distance_m,left_m,right_m" or "distance_m,elevation_m"') from None

        def bad(no: int, text: str) -> str | None:
            row = next(csv.reader([text]))
            try:
                [float(row[c]) for c in cols]
                return None
            except (ValueError, IndexError):
                return (f'{path}, line {no}: expected {len(header)} numbers, got '
                        f'{",".join(row)!r}')

        data, numbers = _parse_rows(numbered, len(cols), bad, delimiter=',',
                                    usecols=cols)
    elevation = data[:, 1:] if len(cols) == 3 else data[:, 1]
    return _clean(data[:, 0], elevation, name=str(path), line_numbers=numbers)


#: Lines of a profile file parsed at a time (bounds the memory of the text).
CHUNK_LINES = 1 << 16


def _open_text(path: Path, **kwargs):
    """``path`` opened for reading text, UTF-8 with or without a byte-order mark (undecodable
    bytes replaced); ValueError naming the file when it cannot be opened."""
    try:
        return path.open(encoding='utf-8-sig', errors='replace', **kwargs)
    except OSError as exc:
        raise ValueError(f'cannot read profile {path}: {exc.strerror}') from None


def _numbered_lines(f, path: Path):
    """``(line number, text)`` of a file's lines (1-based, no line end); ValueError naming
    the file on a read error."""
    try:
        for i, line in enumerate(f, 1):
            yield i, line.rstrip('\r\n')
    except OSError as exc:
        raise ValueError(f'cannot read profile {path}: {exc.strerror}') from None


def _parse_rows(numbered, width: int, bad, *, delimiter=None, usecols=None, comments=None,
                clean=None) -> tuple[np.ndarray, np.ndarray]:
    """The numbers of the remaining lines of ``numbered`` ((line number, text) pairs), read
    :data:`CHUNK_LINES` at a time: ``(rows (m, width) float64, line numbers (m,) int64)``.

    Blank lines (and, with ``comments``, lines starting with it) are skipped; ``clean(text)``
    rewrites a line first. When a chunk does not parse, ``bad(line number, text)`` finds the
    faulty line and its message (raised as ValueError).
    """
    blocks, line_blocks = [], []
    texts: list[str] = []
    nums: list[int] = []

    def flush() -> None:
        if not texts:
            return
        try:
            block = np.loadtxt(texts, delimiter=delimiter, usecols=usecols, ndmin=2,
                               dtype=np.float64, comments=None, quotechar='"' if delimiter
                               else None)
            if block.shape[1] != width:
                raise ValueError('width')
        except ValueError:
            for no, text in zip(nums, texts):
                message = bad(no, text)
                if message:
                    raise ValueError(message) from None
            raise ValueError(f'line {nums[0]}..{nums[-1]}: not a table of {width} numbers') \
                from None
        blocks.append(block)
        line_blocks.append(np.asarray(nums, dtype=np.int64))
        texts.clear()
        nums.clear()

    for no, text in numbered:
        stripped = text.strip()
        if not stripped.strip(', \t') or (comments and stripped.startswith(comments)):
            continue
        texts.append(clean(stripped) if clean else stripped)
        nums.append(no)
        if len(texts) >= CHUNK_LINES:
            flush()
    flush()
    if not blocks:
        return np.empty((0, width)), np.empty(0, dtype=np.int64)
    data = blocks[0] if len(blocks) == 1 else np.concatenate(blocks)
    blocks.clear()
    return data, np.concatenate(line_blocks)


def _number(exact: bool):
    return repr if exact else (lambda v: f'{v:.12g}')


def write_csv_profile(path: str | Path, profile: RoadProfile, *, exact: bool = False) -> None:
    """Write ``distance_m,left_m,right_m`` CSV (metres, 12 significant digits; ``exact``:
    every digit, the shortest form that reads back to the same float)."""
    num = _number(exact)
    with Path(path).open('w', newline='') as f:
        f.write('distance_m,left_m,right_m\n')
        for x, (zl, zr) in zip(profile.distance_m.tolist(), profile.elevation_m.tolist()):
            f.write(f'{num(x)},{num(zl)},{num(zr)}\n')


def _numbers(text: str, path, line_no: int) -> list[float]:
    """The numbers of one line of a profile file (blank- or comma-separated)."""
    try:
        return [float(p) for p in text.replace(',', ' ').split()]
    except ValueError:
        raise ValueError(f'{path}, line {line_no}: not numbers: {text[:60]!r}') from None


def read_text_profile(path: str | Path) -> RoadProfile:
    """Read a whitespace-separated text profile (the format of ``profile_1.txt``).

    Two columns (distance m, elevation m: one track, used for both wheels) or three
    (distance, left, right), blank- or comma-separated. Blank lines and lines starting with
    '#' are skipped; a UTF-8 byte-order mark is read. Read in chunks, as
    :func:`read_csv_profile`.
    """
    path = Path(path)
    with _open_text(path) as f:
        numbered = _numbered_lines(f, path)
        first = next(((i, t) for i, t in numbered
                      if t.strip() and not t.strip().startswith('#')), None)
        if first is None:
            raise ValueError(f'{path}: no profile points')
        width = len(_numbers(first[1].strip(), path, first[0]))
        if width not in (2, 3):
            raise ValueError(f'{path}, line {first[0]}: expected 2 or 3 columns, got {width}')

        def bad(no: int, text: str) -> str | None:
            row = _numbers(text, path, no)
            if len(row) != width:
                return f'{path}, line {no}: expected {width} columns, got {len(row)}'
            return None

        rows = itertools.chain([first], numbered)
        data, numbers = _parse_rows(rows, width, bad, comments='#',
                                    clean=lambda t: t.replace(',', ' '))
    elevation = data[:, 1:] if width == 3 else data[:, 1]
    return _clean(data[:, 0], elevation, name=str(path), line_numbers=numbers)


def _unit_factor(unit: str, what: str, path: Path) -> float:
    key = unit.strip().lower().rstrip('.')
    if key not in _LENGTH_UNITS_M:
        raise ValueError(f'{path}: {what} unit {unit.strip()!r} is not a length unit '
                         f'(m, mm, in, ft, ...)')
    return _LENGTH_UNITS_M[key]


def read_erd_profile(path: str | Path) -> RoadProfile:
    """Read a UMTRI ERD profile file (text data, as ProVAL and RoadRuf write them).

    Format (MODEL.md "Road profiles"): line 1 ``ERDFILEV2.00``; line 2 seven comma-separated
    numbers ``NCHAN, NSAMP, ?, ?, KEY, STEP, ?`` (KEY = 5: text data; STEP: sample interval in
    XUNITS); then keyword lines (an 8-character keyword, then its value) up to ``END``; then
    one whitespace-separated row of NCHAN elevations per sample. ``UNITSNAM`` holds one
    8-character unit field per channel (m, mm, in, ft, ...), ``XUNITS`` the distance unit,
    ``SHORTNAM`` the channel names. The fields marked '?' are ignored.

    Distance of sample i is ``x0 + i * STEP`` with x0 from an ``XSTART`` keyword (written by
    :func:`write_erd_profile`, ignored by other tools) or 0. One channel is used for both
    wheels; with more, channels named left/right (``L``, ``LWP``, ``Left`` ...; ``R`` ...) are
    taken, else the first two (said so in ``notes``). Real profiler files are already high-pass
    filtered: their mean and grade are not the road's.
    """
    path = Path(path)
    with _open_text(path) as f:
        numbered = _numbered_lines(f, path)
        lines = _erd_head(numbered)
        nchan, nsamp, step = _erd_header(lines, path)
        keys, raw_keys, end = _erd_keywords(lines, path)
        _require_units(keys, path)
        x_factor = _unit_factor(keys['XUNITS'], 'XUNITS', path)
        units = _fixed_fields(raw_keys['UNITSNAM'], nchan)
        names = _fixed_fields(raw_keys.get('SHORTNAM', ''), nchan)
        notes: list[str] = []

        def bad(no: int, text: str) -> str | None:
            row = _numbers(text, path, no)
            if len(row) != nchan:
                return f'{path}, line {no}: expected {nchan} values, got {len(row)}'
            return None

        data, numbers = _parse_rows(numbered, nchan, bad)
    if nsamp > 0 and data.shape[0] < nsamp:
        notes.append(f'truncated: {data.shape[0]} of {nsamp} samples')
    elif nsamp > 0 and data.shape[0] > nsamp:
        notes.append(f'{data.shape[0] - nsamp} rows beyond NSAMP = {nsamp} ignored')
        data, numbers = data[:nsamp], numbers[:nsamp]
    if step * x_factor > MAX_STEP_M:
        raise ValueError(f'{path}, line 2: STEP = {step:.6g} {keys["XUNITS"]} is '
                         f'more than {MAX_STEP_M:g} m between samples: not a road profile')
    cols = _pick_tracks(names, nchan, notes)
    factors = [_unit_factor(units[c] or units[0], f'channel {c + 1}', path) for c in cols]
    notes += _unit_notes(keys['XUNITS'], x_factor, [units[c] or units[0] for c in cols],
                         factors)
    elevation = data[:, cols] * np.array(factors)
    try:
        x0 = float(keys.get('XSTART', '0') or 0.0)
    except ValueError:
        raise ValueError(f'{path}: XSTART {keys["XSTART"]!r} is not a number') from None
    distance = (x0 + step * np.arange(data.shape[0])) * x_factor
    title = keys.get('TITLE', '')
    name = f'{path}' + (f' ({title})' if title else '')
    return _clean(distance, elevation if elevation.shape[1] == 2 else elevation[:, 0], name,
                  notes, numbers, str(path))


def _unit_notes(x_unit: str, x_factor: float, z_units: list[str],
                z_factors: list[float]) -> list[str]:
    """The notes saying how an ERD file's units were converted to metres (none if in m)."""
    notes = []
    if x_factor != 1.0:
        notes.append(f'distance converted from {x_unit.strip()} to m (x {x_factor:g})')
    if any(f != 1.0 for f in z_factors):
        notes.append(f'elevation converted from {"/".join(u.strip() for u in z_units)} to m '
                     f'(x {"/".join(f"{f:g}" for f in z_factors)})')
    return notes


#: ERD header keywords of the IRI a profiler stored (left and right wheel path).
ERD_IRI_KEYS = ('IRILWP', 'IRIRWP')


def erd_stored_iri(path: str | Path) -> dict | None:
    """The IRI an ERD file's header stores (``IRILWP`` / ``IRIRWP``), or None without them.

    Returns
    -------
    dict
        ``left``, ``right`` (float or None, as stored), ``unit`` (``'in/mi'`` when the file's
        ``XUNITS`` are feet or inches, else ``'m/km'``: the keys carry no unit, the
        profiler writes the IRI in the units of its distances), ``left_m_per_km`` and
        ``right_m_per_km`` (converted).

    Raises
    ------
    ValueError
        Not a readable ERD file.
    """
    path = Path(path)
    with _open_text(path) as f:
        lines = _erd_head(_numbered_lines(f, path))
    _erd_header(lines, path)
    keys, _, _ = _erd_keywords(lines, path)
    values = {}
    for side, key in zip(('left', 'right'), ERD_IRI_KEYS):
        text = keys.get(key, '').lstrip('=:').split()
        try:
            values[side] = float(text[0]) if text else None
        except ValueError:
            values[side] = None
    if values['left'] is None and values['right'] is None:
        return None
    x_unit = (keys.get('XUNITS', 'm') or 'm').strip().lower().rstrip('.')
    us = x_unit in ('ft', 'feet', 'foot', 'in', 'inch', 'inches', 'mi', 'mile', 'miles')
    per = IN_PER_MI_PER_M_PER_KM if us else 1.0
    out = {'left': values['left'], 'right': values['right'], 'unit': 'in/mi' if us else 'm/km'}
    for side in ('left', 'right'):
        v = values[side]
        out[f'{side}_m_per_km'] = None if v is None else v / per
    return out


#: Header lines of an ERD file read at most (its keywords end with END well before).
_MAX_ERD_HEADER_LINES = 10_000


def _erd_head(numbered) -> list[str]:
    """The lines of an ERD file up to its ``END`` line (at most
    :data:`_MAX_ERD_HEADER_LINES`); the data rows stay in ``numbered``."""
    lines = []
    for _, text in numbered:
        lines.append(text)
        if (len(lines) > 2 and text.strip().upper() == 'END') \
                or len(lines) >= _MAX_ERD_HEADER_LINES:
            break
    return lines


def _require_units(keys: dict[str, str], path: Path) -> None:
    """Refuse an ERD file that does not state its units: a file without them is read as
    metres by some tools and as inches by others (an inch file taken for metres reads 39
    times too rough)."""
    missing = [k for k in ('UNITSNAM', 'XUNITS') if not keys.get(k, '').strip()]
    if missing:
        what = ' and '.join(missing)
        raise ValueError(f'{path}: the ERD header has no {what}: the units of the '
                         f'{"elevations" if "UNITSNAM" in missing else "distances"} are '
                         f'unknown; add the keyword line{"s" if len(missing) > 1 else ""} '
                         f'(e.g. "UNITSNAMin      in" and "XUNITS  ft") before END')


def _erd_header(lines: list[str], path: Path) -> tuple[int, int, float]:
    """``(NCHAN, NSAMP, STEP)`` from an ERD file's first two lines (text data only)."""
    if not lines or not lines[0].strip().upper().startswith('ERDFILE'):
        raise ValueError(f'{path}: not an ERD file (line 1 must be ERDFILEV2.00)')
    if len(lines) < 3:
        raise ValueError(f'{path}: truncated ERD header')
    fields_ = [p.strip() for p in lines[1].split(',') if p.strip()]
    try:
        nchan, nsamp = int(float(fields_[0])), int(float(fields_[1]))
        key, step = int(float(fields_[4])), float(fields_[5])
    except (ValueError, IndexError):
        raise ValueError(f'{path}, line 2: expected "NCHAN, NSAMP, ?, ?, KEY, STEP, ?", got '
                         f'{lines[1].strip()!r}') from None
    if key != 5:
        raise ValueError(f'{path}: ERD KEY = {key}: only text data (KEY = 5) is supported')
    if nchan < 1 or not (math.isfinite(step) and step > 0.0):
        raise ValueError(f'{path}, line 2: NCHAN = {nchan} must be >= 1 and STEP = {step!r} '
                         f'> 0')
    return nchan, nsamp, step


def _erd_keywords(lines: list[str], path: Path) -> tuple[dict[str, str], dict[str, str], int]:
    """The keyword lines from line 3 up to ``END``: ``(stripped values, raw values, index of
    the END line)``, keyed by the upper-case 8-character keyword."""
    keys: dict[str, str] = {}
    raw_keys: dict[str, str] = {}
    for i in range(2, len(lines)):
        line = lines[i]
        if line.strip().upper() == 'END':
            return keys, raw_keys, i
        if not line.strip():
            continue
        keyword = line[:8].strip().upper()
        keys[keyword] = line[8:].strip()
        raw_keys[keyword] = line[8:].rstrip('\n')
    raise ValueError(f'{path}: ERD header has no END line')


def _fixed_fields(text: str, count: int) -> list[str]:
    """Split an ERD value into ``count`` 8-character fields (or whitespace words)."""
    chunks = [text[8 * i:8 * i + 8].strip() for i in range(count)]
    if all(chunks):
        return chunks
    words = text.split()
    return words if len(words) == count else chunks


def _pick_tracks(names: list[str], nchan: int, notes: list[str]) -> list[int]:
    if nchan == 1:
        return [0]
    left = right = None
    for i, name in enumerate(names):
        key = name.strip().lower()
        if left is None and (key.startswith('l') or 'left' in key):
            left = i
        elif right is None and (key.startswith('r') or 'right' in key):
            right = i
    if left is not None and right is not None:
        return [left, right]
    if nchan > 2:
        notes.append(f'{nchan} channels without left/right names: channels 1 and 2 used')
    return [0, 1]


def write_erd_profile(path: str | Path, profile: RoadProfile, units: str = 'm', *,
                      keywords: Mapping[str, str] | None = None) -> None:
    """Write a text ERD file (two channels, left and right) in ``units`` (m, mm, in, ft...).

    The header has the keywords ProVAL and UMTRI's tools read: ``TITLE`` (the profile's
    name), ``SHORTNAM`` / ``LONGNAME`` / ``GENNAME`` (channel names), ``UNITSNAM`` (each
    channel's unit), ``XLABEL`` and ``XUNITS`` (distance, m), then ``XSTART`` (the first
    distance, for this package's reader) and ``keywords`` (8-character keyword -> text, e.g.
    how the profile was made), then ``END``. The profile must be evenly spaced (relative
    tolerance 1e-6); line 2 has its mean step, in 6 significant digits when they hold it
    exactly, else every digit (so that the profile reads back on the grid it was written on).
    """
    path = Path(path)
    factor = _unit_factor(units, 'units', path)
    x = profile.distance_m
    steps = np.diff(x)
    step = float(np.mean(steps))
    if np.max(np.abs(steps - step)) > 1e-6 * step:
        raise ValueError(f'{path}: an ERD file needs an evenly spaced profile (spacing '
                         f'{np.min(steps):g} .. {np.max(steps):g} m)')
    unit_field = f'{units:<8.8}'
    z = profile.elevation_m / factor
    with path.open('w') as f:
        f.write('ERDFILEV2.00\n')
        step_text = f'{step:13.6e}'
        if float(step_text) != step:        # a step of more digits: every digit it has
            step_text = repr(step)
        f.write(f'{2:7d},{x.size:7d},{1:7d},{1:7d},{5:7d},{step_text},{1:7d},\n')
        f.write(f'TITLE   {profile.name or "road profile"}\n')
        f.write(f'SHORTNAM{"Left":<8}{"Right":<8}\n')
        f.write(f'LONGNAME{"Left elevation":<32}{"Right elevation":<32}\n')   # 32-character
        f.write(f'GENNAME {"Elevation":<32}{"Elevation":<32}\n')             # fields
        f.write(f'UNITSNAM{unit_field}{unit_field}\n')
        f.write('XLABEL  Distance\n')
        f.write('XUNITS  m\n')
        f.write(f'XSTART  {float(x[0])!r}\n')
        for key, text in (keywords or {}).items():
            f.write(f'{key.upper():<8.8}{" ".join(str(text).split())}\n')
        f.write('END\n')
        for zl, zr in z.tolist():
            f.write(f'{zl:.10g} {zr:.10g}\n')


def write_text_profile(path: str | Path, profile: RoadProfile, *,
                       comments: Sequence[str] = (), exact: bool = False) -> None:
    """Write whitespace columns ``distance left right`` (m), the layout of
    ``profile_1.txt`` with a third column, after ``#`` comment lines (``comments``, then the
    column names): what :func:`read_text_profile` reads. Digits as
    :func:`write_csv_profile`'s."""
    num = _number(exact)
    with Path(path).open('w') as f:
        for line in comments:
            f.write(f'# {line}\n')
        f.write('# distance_m left_m right_m\n')
        for x, (zl, zr) in zip(profile.distance_m.tolist(), profile.elevation_m.tolist()):
            f.write(f'{num(x)} {num(zl)} {num(zr)}\n')


# --------------------------------------------------------------------------------------------
# Sources
# --------------------------------------------------------------------------------------------


def road_from_source(source: str, *, length_m: float | None = None) -> RoadProfile:
    """A road profile from a source string (``simulator.road``).

    Parameters
    ----------
    source : str
        ``iso8608:<A-H>[:option=value...]`` with options ``seed`` (int, default 1), ``length``
        (m), ``dx`` (m, default 0.05), ``coherence`` (default, identical, independent or a
        number), ``start`` (m); or ``flat[:length=..][:dx=..]``; or a jointed concrete road
        ``jpcp[:joint_spacing=..][:faulting=..][:curl=..][:roughness=..][:seed=..]``
        (:mod:`road_force_estimator.core.road_jpcp`); or a path: ``.csv``,
        ``.erd``, ``.txt`` / ``.dat`` (whitespace columns). A bag folder (holding
        ``metadata.yaml``) is refused: :func:`road_force_estimator.bagio.road_from_source`
        reads LPA bags and every source of this function.
    length_m : float, optional
        Length of a synthetic road when the source gives none (default 1000 m); ignored for
        files and bags.

    Raises
    ------
    ValueError
        Unknown source kind, bad option, unreadable file.
    """
    text = str(source).strip()
    head = text.split(':', 1)[0].lower()
    if head in ('iso8608', 'flat'):
        return synthetic_profile(text, length_m)
    if head == 'jpcp':
        return jpcp_from_source(text, length_m)
    path = Path(text).expanduser()
    if path.is_dir():
        if not (path / 'metadata.yaml').is_file():
            raise ValueError(f'road source {text!r}: a folder must be a bag (no metadata.yaml)')
        raise ValueError(f'road source {text!r} is a bag folder: read it with '
                         'road_force_estimator.bagio.road_from_source')
    if not path.exists():
        raise ValueError(f'road source {text!r}: no such file, and not "iso8608:<class>", '
                         f'"jpcp[...]" or "flat"')
    suffix = path.suffix.lower()
    if suffix == '.csv':
        return read_csv_profile(path)
    if suffix == '.erd':
        return read_erd_profile(path)
    if suffix in ('.txt', '.dat', '.prn', ''):
        with path.open(errors='replace') as f:
            first = f.readline()
        if first.strip().upper().startswith('ERDFILE'):
            return read_erd_profile(path)
        return read_text_profile(path)
    raise ValueError(f'road source {text!r}: unknown file type {suffix!r} (.csv, .erd, .txt, '
                     f'.dat or a bag folder)')

