"""Reports (interim)."""
from road_force_estimator.report.fleet_map import (  # noqa: F401
    IN_PER_MI_PER_M_PER_KM, plot_segments_map, segment_lines, segments_geojson)
