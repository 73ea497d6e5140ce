"""Light tests of the benchmark driver (bench/run_benchmark.py): its command line, one tiny
scenario end to end, the scoring of a perfect estimate, stamp alignment and the verdicts.

References: the ground truth itself (a perfect estimate scores zero), hand-built arrays and
result tables whose verdicts are known by construction. No timing is asserted.
"""
from __future__ import annotations

from dataclasses import replace
import json
import math
from types import SimpleNamespace

import numpy as np
import pytest

from bench import run_benchmark as rb
from bench.scenarios import scenario_by_name

TINY = replace(scenario_by_name('C20-1k-10um'), duration_s=6.0, skip_s=1.0)


class TestCommandLine:
    def test_parser_defaults_and_options(self):
        args = rb.build_parser().parse_args(['--scenarios', 'C20-1k-10um', '--methods',
                                             'kf-model', 'ours-online', '--duration', '5',
                                             '--no-speed'])
        assert args.scenarios == ['C20-1k-10um']
        assert args.methods == ['kf-model', 'ours-online']
        assert args.duration == 5.0 and args.no_speed and not args.no_node
        assert rb.build_parser().parse_args([]).output is None

    @pytest.mark.parametrize('argv, word', [
        (['--scenarios', 'nowhere'], 'nowhere'),
        (['--methods', 'nobody'], 'nobody'),
        (['--duration', '0.5'], '--duration'),
    ])
    def test_bad_input_is_one_line_and_status_2(self, argv, word, capsys):
        assert rb.main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert word in err and len(err.splitlines()) == 1

    def test_every_column_is_registered_once_in_latency_order(self):
        groups = [m.group for m in rb.METHODS.values()]
        assert groups == sorted(groups, key=rb.GROUPS.index)
        for name in ('ours-online', 'ours-chain-implicit', 'ours-no-smo', 'ours-latency-10ms',
                     'ours-offline', 'kf-model', 'lowpass-fd', 'zero-phase-offline'):
            assert name in rb.METHODS


def test_one_tiny_scenario_end_to_end(tmp_path, capsys):
    md, js = tmp_path / 'b.md', tmp_path / 'b.json'
    code = rb.main(['--scenarios', 'C20-1k-10um', '--duration', '6', '--methods',
                    'lowpass-fd', 'kf-model', 'ours-online', '--timing-repeats', '1',
                    '--no-speed', '--output', str(md), '--json', str(js)])
    assert code == 0
    text = md.read_text()
    assert text in capsys.readouterr().out
    assert '| C20-1k-10um |' in text and 'ours-online' in text and 'Wall time' in text
    doc = json.loads(js.read_text())
    for name in ('lowpass-fd', 'kf-model', 'ours-online'):
        fig = doc['results']['C20-1k-10um'][name]
        assert 'error' not in fig, fig
        assert 0.0 < fig['load_rms_pct_dyn'] < 100.0
        assert math.isfinite(fig['profile_rms_pct_band'])
    assert len(doc['targets']) == 7


class TestScoringAndColumns:
    @pytest.fixture(scope='class')
    @staticmethod
    def truth_run():
        def truth(drive, tuned):
            t = drive.truth
            return SimpleNamespace(wheel_load_n=t['wheel_load_n'], road_m=t['road_m'],
                                   ltr=t['ltr'])

        def missing(drive, tuned):
            raise rb.NotAvailable('not in this package')

        methods = [rb.Method('truth', truth), rb.Method('missing', missing)]
        return rb.run([TINY], methods, {}, timing_repeats=1), methods

    def test_the_truth_scores_zero(self, truth_run):
        out, _ = truth_run
        fig = out['results'][TINY.name]['truth']
        for key in ('load_rms_pct_dyn', 'load_rms_pct_static', 'profile_rms_pct_band',
                    'iri_err_pct_mean', 'iri_err_pct_max', 'ltr_rms'):
            assert fig[key] == pytest.approx(0.0, abs=1e-9), key
        for key in ('xcorr', 'xcorr_seg_min'):       # a profile rates 1 against itself
            assert fig[key] == pytest.approx(1.0, abs=1e-9), key

    def test_an_unavailable_column_shows_na_and_its_reason(self, truth_run):
        out, methods = truth_run
        text = rb.markdown(out, [TINY], methods, {})
        assert 'n/a' in text and 'not in this package' in text


def test_per_sample_places_estimates_on_their_stamps():
    stamps = np.arange(10, dtype=np.int64) * 1_000_000
    # a 3-sample latency: rows carry the stamps of earlier samples; the first 3 have none
    carried = stamps[:7]
    load = np.column_stack([np.arange(7.0), -np.arange(7.0)])
    est = SimpleNamespace(stamp_ns=carried, wheel_load_n=load, road_m=2 * load,
                          ltr=np.arange(7.0), valid=np.ones(7, bool))
    got = rb.per_sample(est, stamps)
    np.testing.assert_array_equal(got.wheel_load_n[:7, 0], np.arange(7.0))
    np.testing.assert_array_equal(got.wheel_load_n[7:, 0], 6.0)   # held
    np.testing.assert_array_equal(got.ltr[:7], np.arange(7.0))


def _table(values: dict[str, dict[str, float]]):
    return {'results': {sc: {m: {'load_rms_pct_dyn': v} for m, v in row.items()}
                        for sc, row in values.items()}}


def test_zero_latency_verdict_follows_the_numbers():
    scs = [scenario_by_name('C20-1k-10um'), scenario_by_name('C20-1k-0um')]
    good = _table({'C20-1k-10um': {'ours-online': 15.0, 'kf-model': 16.0, 'lowpass-fd': 40.0},
                   'C20-1k-0um': {'ours-online': 0.4, 'kf-model': 0.5, 'lowpass-fd': 1.0}})
    bad = _table({'C20-1k-10um': {'ours-online': 17.0, 'kf-model': 16.0, 'lowpass-fd': 40.0},
                  'C20-1k-0um': {'ours-online': 0.4, 'kf-model': 0.5, 'lowpass-fd': 1.0}})
    assert rb.targets(good, scs, None)[0].startswith('**Zero latency** (')
    assert ': MET:' in rb.targets(good, scs, None)[0]
    line = rb.targets(bad, scs, None)[0]
    assert 'NOT MET' in line and 'C20-1k-10um (17.0 vs 16.0)' in line
    methods = [rb.METHODS[n] for n in ('kf-model', 'ours-online')]
    assert 'C20-1k-10um (17.0 vs kf-model 16.0)' in rb.losses(bad, scs, methods)[0]


def test_cross_correlation_verdict_follows_the_numbers():
    scs = [scenario_by_name('C20-1k-10um'), scenario_by_name('jpcp')]

    def table(off, lag):
        return {'results': {sc.name: {'ours-offline': {'xcorr': o, 'xcorr_seg_min': o - 0.01},
                                      'ours-latency-10ms': {'xcorr': g, 'xcorr_seg_min': g}}
                            for sc, o, g in zip(scs, off, lag)}}

    line = rb._xcorr_target(table([0.995, 0.991], [0.985, 0.99]), [s.name for s in scs])
    assert ': MET:' in line
    line = rb._xcorr_target(table([0.995, 0.95], [0.985, 0.99]), [s.name for s in scs])
    assert 'NOT MET' in line and 'worst jpcp: 0.950' in line and 'segment 0.940' in line
    assert 'NOT MEASURED' in rb._xcorr_target({'results': {}}, [s.name for s in scs])
