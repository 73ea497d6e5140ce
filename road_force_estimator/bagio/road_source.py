"""A road profile from any source string, LPA bag folders included.

:func:`road_from_source` reads a bag folder (holding ``metadata.yaml``) with
:func:`.lpa.read_lpa_bag` and hands every other source (synthetic roads, CSV / ERD / text files)
to :func:`road_force_estimator.core.road_files.road_from_source`, which never reads bags.
"""
from __future__ import annotations

from pathlib import Path

from road_force_estimator.bagio.lpa import read_profile_bag
from road_force_estimator.core import road_files
from road_force_estimator.core.road import RoadProfile

__all__ = ['road_from_source']


def road_from_source(source: str, *, length_m: float | None = None) -> RoadProfile:
    """A road profile from a source string (``simulator.road``).

    Parameters
    ----------
    source : str
        A bag folder holding ``metadata.yaml`` (an LPA bag, or a bag of estimates: its
        ``/road_profile/*``, :func:`.lpa.read_profile_bag`), or any source of
        :func:`road_force_estimator.core.road_files.road_from_source`
        (``iso8608:<A-H>[:option=value...]``, ``flat[...]``, ``jpcp[...]``, a ``.csv``,
        ``.erd``, ``.txt`` / ``.dat`` file).
    length_m : float, optional
        Length of a synthetic road when the source gives none (default 1000 m); ignored for
        files and bags.

    Raises
    ------
    ValueError
        Unknown source kind, bad option, unreadable file.
    BagReadError
        A bag folder that holds no readable profile.
    """
    text = str(source).strip()
    head = text.split(':', 1)[0].lower()
    if head not in ('iso8608', 'flat', 'jpcp'):
        path = Path(text).expanduser()
        if path.is_dir() and (path / 'metadata.yaml').is_file():
            return read_profile_bag(path)
    return road_files.road_from_source(source, length_m=length_m)
