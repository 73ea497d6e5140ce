"""tools.fleet_outputs: summary.md in the units of --units (no cluster: made-up outcomes)."""
import numpy as np

from road_force_estimator.core.segments import SEGMENT_COLUMNS
from road_force_estimator.tools.fleet_drives import DriveOutcome
from road_force_estimator.tools.fleet_outputs import FleetResult, fleet_table, summary_markdown


def outcome(name, iri):
    k = len(iri)
    table = {c: np.full(k, np.nan) for c in SEGMENT_COLUMNS}
    table['start_m'] = 160.9344 * np.arange(k)
    table['end_m'] = table['start_m'] + 160.9344
    table['iri_left_m_per_km'] = np.asarray(iri, dtype=float)
    table['iri_right_m_per_km'] = np.asarray(iri, dtype=float)
    table['lift_offs'] = np.zeros(k, np.int64)
    return DriveOutcome(name, 'processed', table=table, seconds=1.0)


def test_summary_in_us_units_by_hand():
    outcomes = [outcome('a', [1.0, 2.0]), outcome('b', [3.0])]
    settings = {'mode': 'online', 'segment_length_m': 160.9344, 'figures': False,
                'units': 'us', 'run_info': {'command': 'estimate_fleet x --units us',
                                            'overrides': ['observer.latency:=0.01']}}
    result = FleetResult(outcomes, 'local', 1.0, settings)
    md = summary_markdown(result, fleet_table(outcomes), False, None)
    # a: mean 1.5 m/km = 95.04 in/mi over 0.2 mi; b: 3 m/km = 190.08 in/mi over 0.1 mi.
    assert '| a | processed | 2 | 0.200 | 95.04 (1.500) | 95.04 (1.500) |' in md
    assert '| b | processed | 1 | 0.100 | 190.08 (3.000) |' in md
    assert 'IRI left in/mi (m/km)' in md and 'distance (mi)' in md
    assert '| b | 0.0 | 528.0 | 190.08 (3.000) |' in md            # roughest, feet
    assert 'IRI in in/mi (= m/km x 63.36)' in md
    assert '`estimate_fleet x --units us`' in md and 'observer.latency:=0.01' in md
    settings['units'] = 'si'
    md = summary_markdown(FleetResult(outcomes, 'local', 1.0, settings),
                          fleet_table(outcomes), False, None)
    assert '| a | processed | 2 | 0.322 | 1.500 (95.04) |' in md
