"""The report of an estimated drive and the map of a fleet's segments.

:func:`write_report` writes a drive's report folder (``report.md``, ``report.json``,
``segments.csv``, the figures; :mod:`.folder`) from :func:`summarize`'s numbers
(:mod:`.summary`; what was run and the reference profile: :mod:`.drive_info`) on the
estimate aligned with its truth or a reference (:func:`align`,
:mod:`.alignment`); :mod:`.markdown` and :mod:`.figures` draw it. :mod:`.fleet_map` gives the
segments' polylines, their GeoJSON and a map picture (``estimate_fleet``).
"""
from road_force_estimator.report.alignment import REFERENCE_SEARCH_M, Aligned, align
from road_force_estimator.report.drive_info import raw_road, run_description
from road_force_estimator.report.figures import FIGURES, write_figures
from road_force_estimator.report.fleet_map import (
    IN_PER_MI_PER_M_PER_KM, plot_segments_map, segment_lines, segments_geojson, write_geojson)
from road_force_estimator.report.folder import (
    SEGMENT_DECIMALS, csv_cell, write_report, write_segments_csv)
from road_force_estimator.report.markdown import write_markdown
from road_force_estimator.report.summary import (
    DEFAULT_SEGMENT_LENGTH_M, accuracy, drive_segments, summarize)

__all__ = [
    'FIGURES', 'DEFAULT_SEGMENT_LENGTH_M', 'REFERENCE_SEARCH_M', 'IN_PER_MI_PER_M_PER_KM',
    'Aligned', 'align', 'accuracy', 'drive_segments', 'summarize', 'csv_cell', 'SEGMENT_DECIMALS',
    'write_segments_csv', 'write_markdown', 'write_figures', 'write_report', 'segment_lines',
    'segments_geojson', 'write_geojson', 'plot_segments_map', 'raw_road', 'run_description',
]
