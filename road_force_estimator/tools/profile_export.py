"""``estimate_bag --export-profile FILE``: the estimated road profile for ProVAL and pavement
management systems.

The profile is read back from the bag of estimates that ``estimate_bag`` wrote
(:func:`.bagio.read_profile_bag`: ``/road_profile/fused/*`` when the bag has it, else
``/road_profile/*``), so that the file holds what the bag holds, whichever way the drive was
estimated (in one piece or block by block), and what ``road_profile_iri`` and
``profile_to_bag`` read from the same bag. It is laid on the even grid the package's IRI runs
on (:func:`.core.iri.evenly_spaced`: the estimate's own samples when they are evenly spaced,
else resampled linearly from the first distance at min(median spacing, 0.25 m)), one row per
point, both wheel paths: the file's IRI per segment is the report's. By FILE's suffix:

``.erd``
    UMTRI ERD text file, as ProVAL imports it: two channels ``Left`` / ``Right`` in metres
    (``UNITSNAM m``), distance in metres (``XUNITS m``), the step in line 2, the header
    keywords ``TITLE``, ``SHORTNAM``, ``LONGNAME``, ``GENNAME``, ``UNITSNAM``, ``XLABEL``,
    ``XUNITS``, ``XSTART`` and ``SOURCE`` / ``FILTER`` / ``SPACING`` (what it is).
``.csv``
    ``distance_m,left_m,right_m`` (INTERFACES.md's CSV profile; metres, every digit).
``.txt``
    whitespace columns ``distance left right`` in metres after ``#`` comment lines, the layout
    of ``../shared/data/profile_1.txt`` with both wheel paths (every digit).

Every digit, and the ERD step at full precision where 6 digits do not hold it: the IRI's slope
base is ``round(0.25 m / spacing)`` samples, and at 20 m/s and 1 kHz the spacing (0.02 m) puts
it on 12.5: a spacing rounded to 0.02 m reads as 12 samples where the estimate's own
0.0199999999999934 m gives 13, 0.2 % of IRI apart.

The estimate is the road as the tire follows it (enveloped by the tire's contact, not a
profiler's point) and band-passed (``observer.profile_cutoff_wavelength``, 100 m by default):
its mean and grade are not the road's, as a high-pass filtered profiler file's are not. The
file is written beside its place and renamed into it when complete; an existing file is
replaced only with ``--force`` and only if it is one this command wrote.
"""
from __future__ import annotations

from pathlib import Path

from road_force_estimator.tools import cli, output_folder

__all__ = ['FORMATS', 'target', 'export_profile']

PROG = 'estimate_bag'
#: File suffix -> what is written.
FORMATS = {'.erd': 'UMTRI ERD (ProVAL)', '.csv': 'CSV distance_m,left_m,right_m',
           '.txt': 'text columns distance left right (m)'}
_TITLE = 'road_force_estimator estimate'


def target(path: str | Path, *, force: bool, inputs=()) -> output_folder.FileOutput:
    """The export file's output, checked now (before the drive is estimated).

    Raises
    ------
    cli.UsageError
        A suffix other than those of :data:`FORMATS`.
    OutputError
        The file exists and is not one this command wrote (or ``force`` is not given).
    """
    path = Path(path).expanduser()
    if path.suffix.lower() not in FORMATS:
        raise cli.UsageError(f'--export-profile {path}: the file must end in '
                             f'{", ".join(FORMATS)} ({"; ".join(FORMATS.values())})')
    out = output_folder.FileOutput(path, PROG, force=force, owned=_written_here,
                                   inputs=list(inputs))
    out.check()
    return out


def _written_here(path: Path) -> bool:
    """The file's first lines say this command wrote it."""
    try:
        with path.open('rb') as f:
            head = f.read(4096).decode('utf-8', 'replace')
    except OSError:
        return False
    return _TITLE in head or head.startswith('distance_m,left_m,right_m\n')


def export_profile(bag: str | Path, out: output_folder.FileOutput, *,
                   cutoff_wavelength_m: float) -> str:
    """Write the estimated profile of the bag of estimates ``bag`` to ``out``; one line saying
    what was written.

    Raises
    ------
    BagReadError
        The bag holds no profile.
    ValueError
        A profile too short to lay on a grid.
    """
    from road_force_estimator.bagio import read_profile_bag
    from road_force_estimator.core import road_files
    from road_force_estimator.core.iri import evenly_spaced
    from road_force_estimator.core.road import RoadProfile

    notes: list[str] = []
    profile = read_profile_bag(bag, issues=notes)
    grid, z, dx = evenly_spaced(profile.distance_m, profile.elevation_m)
    topics = next((n for n in notes if n.startswith('the estimated profile of')), '')
    even = RoadProfile(distance_m=grid, elevation_m=z, name=f'{_TITLE}: {Path(bag).parent.name}')
    about = {'SOURCE': f'{Path(bag)}: {topics or "/road_profile/left, /road_profile/right"}',
             'FILTER': f'tire-enveloped road, high-passed at {cutoff_wavelength_m:g} m '
                       '(observer.profile_cutoff_wavelength)',
             'SPACING': f"{dx!r} m (the grid of the IRI; linear between the estimate's "
                        'samples where they are uneven)'}
    suffix = out.path.suffix.lower()
    with out.staged() as tmp:
        if suffix == '.erd':
            road_files.write_erd_profile(tmp, even, keywords=about)
        elif suffix == '.csv':
            road_files.write_csv_profile(tmp, even, exact=True)
        else:
            road_files.write_text_profile(tmp, even, exact=True, comments=[
                _TITLE, *(f'{k.lower()}: {v}' for k, v in about.items())])
    return (f'profile: {out.path} ({FORMATS[suffix]}; {grid.size} points every {dx:.6g} m, '
            f'{grid[0]:.3f} to {grid[-1]:.3f} m)')
