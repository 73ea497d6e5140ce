"""The report says what it shows (issue 29): the static loads' origin, one convergence figure,
the tail segment named, "reference" for a reference, the tire envelope against a survey, and
the IRI legend clear of the bars."""
from __future__ import annotations

import pytest

from report_case import VEHICLE, make_case
from road_force_estimator import report
from road_force_estimator.core.parameters import VehicleParameters
from road_force_estimator.core.road import RoadProfile
from road_force_estimator.report.markdown import write_markdown


def markdown(tmp_path, *args, **kwargs) -> str:
    summary, segments, _ = report.summarize(*args, **kwargs)
    write_markdown(tmp_path / 'report.md', summary, segments, [])
    return (tmp_path / 'report.md').read_text()


def test_static_loads_say_configured_unless_estimated(tmp_path):
    est, drive, _ = make_case()
    text = markdown(tmp_path, est, drive, VEHICLE)
    assert 'zero_load' not in text.split('## Summary')[1].split('\n\n')[0]
    assert '| static wheel loads, left / right (N; configured: vehicle.static_load' in text
    zero = VehicleParameters(deflection_reference='zero_load')
    text = markdown(tmp_path, est, drive, zero)
    assert ('| static wheel loads at the end, left / right (N; estimated: '
            'vehicle.deflection_reference = zero_load) |') in text


@pytest.mark.parametrize('settling', [0.0, 0.2])
def test_one_convergence_figure_without_truth(tmp_path, settling):
    """Without truth t_0 is the first converged sample (0.2 s here); a settling time of 0
    (the model observer has none) is not printed beside it as if it contradicted it."""
    est, drive, _ = make_case(with_truth=False)
    est.status.settling_time_s = settling
    text = markdown(tmp_path, est, drive, VEHICLE)
    assert '| convergence time t_0 (s) | 0.200 |' in text
    assert 'the time of its first converged sample (0.200 s after the start' in text
    assert 'settling time is 0.000' not in text and '0.000 s, after the start' not in text


def test_the_tail_segment_is_named(tmp_path):
    est, drive, _ = make_case()                     # 600 m: 5 x 110 m + 50 m, joined
    text = markdown(tmp_path, est, drive, VEHICLE, segment_length_m=110.0)
    assert ('The last segment (440.0 to 600.0 m) is 160.0 m long, not 110.0: a remainder '
            'shorter than half a segment joins it.') in text
    text = markdown(tmp_path, est, drive, VEHICLE, segment_length_m=100.0)
    assert 'The last segment' not in text           # 6 x 100 m: nothing to say


def test_a_reference_profile_is_called_reference_and_the_envelope_is_said(tmp_path):
    est, drive, road = make_case(with_truth=False)
    survey = RoadProfile(distance_m=road.distance_m, elevation_m=road.elevation_m,
                         name='lpa survey')
    text = markdown(tmp_path, est, drive, VEHICLE, reference=survey, reference_offset_m=0.0)
    table = text.split('## Segments')[1]
    assert 'reference IRI L' in table and 'true IRI' not in table
    assert 'The estimate is the road as the tire follows it: enveloped' in text
    truth = markdown(tmp_path, *make_case()[:2], VEHICLE)
    assert 'true IRI L' in truth.split('## Segments')[1]
    assert 'The estimate is the road as the tire follows it' not in truth


def test_the_iri_legend_covers_no_bar(tmp_path, monkeypatch):
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    figures = {}
    real = Figure.savefig
    monkeypatch.setattr(Figure, 'savefig', lambda fig, path, **kw: figures.__setitem__(
        str(path).rsplit('/', 1)[-1], fig) or real(fig, path, **kw))
    est, drive, _ = make_case()
    summary, segments, al = report.summarize(est, drive, VEHICLE)
    report.write_figures(tmp_path, est, al, drive, segments=segments)
    fig = figures['overview.png']
    ax = fig.axes[3]
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    renderer = FigureCanvasAgg(fig).get_renderer()
    legend = ax.get_legend().get_window_extent(renderer)
    bars = [b for bars in ax.containers for b in bars if isinstance(b, Rectangle)
            and b.get_height() > 0]                # the bars (not the condition bands)
    assert len(bars) >= 4 * len(segments['start_m']) - 1
    assert not any(legend.overlaps(b.get_window_extent(renderer)) for b in bars)
    assert ax.get_window_extent(renderer).contains(legend.x0, legend.y0)   # inside its axes
