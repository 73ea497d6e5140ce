"""tools.cli: the exit-status wrapper (usage error 2, listed errors their status, --help 0,
anything else raised), the positive-length check and the shared options."""
import argparse

import pytest

from road_force_estimator.tools import cli


class InputTrouble(Exception):
    pass


def parser():
    p = cli.Parser(prog='demo')
    p.add_argument('value', type=float)
    cli.add_output(p, 'where')
    cli.add_mode(p)
    cli.add_segment_length(p, 'segments')
    cli.add_force(p, 'replace')
    cli.add_no_progress(p)
    return p


def run(argv, body, capsys):
    rc = cli.run_main('demo', parser(), body, argv, {(InputTrouble, OSError): 1})
    return rc, capsys.readouterr()


class TestRunMain:
    def test_the_body_status_and_the_parsed_options(self, capsys):
        seen = {}

        def body(args):
            seen.update(vars(args))
            return 7

        rc, out = run(['1.5', '-o', 'x', '--force'], body, capsys)
        assert rc == 7 and out.err == ''
        assert seen == {'value': 1.5, 'output': 'x', 'mode': 'online', 'segment_length': 100.0,
                        'force': True, 'no_progress': False}

    def test_a_bad_command_line_is_one_line_and_status_2(self, capsys):
        rc, out = run(['nan?', '-o', 'x'], lambda args: 0, capsys)
        assert rc == 2
        assert out.err.startswith('demo: error: ') and out.err.count('\n') == 1
        rc, out = run(['1', '-o', 'x', '--mode', 'sideways'], lambda args: 0, capsys)
        assert rc == 2 and "invalid choice: 'sideways'" in out.err

    def test_a_usage_error_raised_by_the_body(self, capsys):
        def body(args):
            cli.check_positive('--segment-length', args.segment_length)
            return 0

        rc, out = run(['1', '-o', 'x', '--segment-length', '0'], body, capsys)
        assert (rc, out.err) == (2, 'demo: error: --segment-length 0.0: must be > 0 m\n')
        rc, out = run(['1', '-o', 'x', '--segment-length', 'inf'], body, capsys)
        assert (rc, out.err) == (2, "demo: error: argument --segment-length: 'inf': must be a "
                                    'finite number\n')

    def test_listed_errors_print_one_line_that_keeps_all_of_the_message(self, capsys):
        def body(args):
            raise InputTrouble('first line\nsecond line')

        rc, out = run(['1', '-o', 'x'], body, capsys)
        assert (rc, out.err) == (1, 'demo: first line\\nsecond line\n')
        rc, out = run(['1', '-o', 'x'], lambda args: (_ for _ in ()).throw(
            FileNotFoundError(2, 'No such file', 'f.yaml')), capsys)
        assert rc == 1 and out.err == "demo: [Errno 2] No such file: 'f.yaml'\n"

    def test_the_status_of_the_first_matching_group(self, capsys):
        def body(args):
            raise KeyError('k')

        rc = cli.run_main('demo', parser(), body, ['1', '-o', 'x'],
                          {(ValueError,): 1, (LookupError,): 2})
        assert rc == 2 and capsys.readouterr().err == "demo: 'k'\n"

    def test_help_exits_0_and_other_errors_propagate(self, capsys):
        rc, out = run(['--help'], lambda args: 1, capsys)
        assert rc == 0 and 'usage: demo' in out.out
        with pytest.raises(ZeroDivisionError):
            run(['1', '-o', 'x'], lambda args: 1 / 0, capsys)


class TestChecks:
    def test_check_positive(self):
        cli.check_positive('--length', None)
        cli.check_positive('--length', 0.1)
        cli.check_positive('--length', float('inf'), finite=False)
        for bad in (0.0, -1.0, float('nan'), float('inf')):
            with pytest.raises(cli.UsageError, match=r'^--length .*: must be > 0 m$'):
                cli.check_positive('--length', bad)
        with pytest.raises(cli.UsageError, match='nan'):
            cli.check_positive('--length', float('nan'), finite=False)

    def test_one_line(self):
        assert cli.one_line(ValueError('  a\nb')) == 'a\\nb'
        assert (cli.one_line(ValueError('/data/x\r\ny: no such bag'))
                == '/data/x\\r\\ny: no such bag')
        assert cli.one_line(ValueError()) == 'ValueError'

    def test_finite_float_refuses_what_is_not_a_finite_number(self):
        assert cli.finite_float('1e-3') == 1e-3
        for bad in ('nan', 'inf', '-inf', 'NaN', 'x'):
            with pytest.raises(argparse.ArgumentTypeError):
                cli.finite_float(bad)

    def test_estimator_parameters_default_and_from_a_file(self, tmp_path):
        from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
        vehicle, observer = cli.load_estimator_parameters(None, ('observer',))
        assert vehicle == VehicleParameters() and observer == ObserverParameters()
        f = tmp_path / 'p.yaml'
        f.write_text('/**:\n  ros__parameters:\n    observer.lipschitz_deflection: 2500.0\n')
        _, observer = cli.load_estimator_parameters(str(f), ('observer',))
        assert observer.lipschitz_deflection_mps3 == 2500.0
        with pytest.raises(ValueError, match='missing.yaml'):
            cli.load_estimator_parameters(str(tmp_path / 'missing.yaml'), ('observer',))

    def test_p_overrides_a_file_value_and_refuses_an_unknown_name(self, tmp_path):
        f = tmp_path / 'p.yaml'
        f.write_text('/**:\n  ros__parameters:\n    observer.lipschitz_deflection: 2500.0\n'
                     '    observer.latency: 0.005\n')
        _, observer = cli.load_estimator_parameters(
            str(f), ('observer',),
            ['observer.lipschitz_deflection:=1800', 'observer.latency:=1e-2'])
        assert observer.lipschitz_deflection_mps3 == 1800.0      # -p after the file
        assert observer.latency_s == 0.01                         # YAML 1e-2 read as a double
        vehicle, _ = cli.load_estimator_parameters(None, ('observer',),
                                                   ['vehicle.unsprung_mass:=[400, 420]'])
        assert tuple(vehicle.unsprung_mass_kg) == (400.0, 420.0)
        with pytest.raises(ValueError, match="unknown parameter 'observer.lipschits'"):
            cli.load_estimator_parameters(None, ('observer',), ['observer.lipschits:=1'])
        with pytest.raises(ValueError, match='expected NAME:=VALUE'):
            cli.load_estimator_parameters(None, ('observer',), ['observer.latency=0.01'])
        with pytest.raises(ValueError, match='out of range'):
            cli.load_estimator_parameters(None, ('observer',), ['observer.latency:=-1'])

    def test_p_and_units_on_the_commands(self):
        from road_force_estimator.tools import (
            estimate_bag, estimate_fleet, road_profile_iri, simulate_bag)
        for module in (estimate_bag, estimate_fleet, simulate_bag):
            text = module.build_parser().format_help()
            assert '-p NAME:=VALUE' in text, module.__name__
        for module in (estimate_bag, estimate_fleet, road_profile_iri):
            args = module.build_parser().parse_args(
                [a for a in ('x', '-o', 'y', '--units', 'us')
                 if module is not road_profile_iri or a not in ('-o', 'y')])
            assert args.units == 'us' and cli.segment_length(args) == pytest.approx(160.9344)
        args = estimate_fleet.build_parser().parse_args(['x', '-o', 'y'])   # no --params-file
        assert args.params_file is None and cli.segment_length(args) == 100.0

    def test_command_line_is_the_arguments_given(self, monkeypatch):
        assert cli.command_line('demo', ['2', '-o', 'a b']) == "demo 2 -o 'a b'"
        monkeypatch.setattr('sys.argv', ['x', '3', "it's"])     # main(None): the process's
        assert cli.command_line('demo', None) == """demo 3 'it'"'"'s'"""

    def test_the_estimate_commands_report_their_own_arguments(self, monkeypatch, capsys):
        """estimate_bag and estimate_fleet give the report ``main``'s argv, run after run in
        one process (nothing kept from the run before)."""
        from road_force_estimator.tools import estimate_bag, estimate_fleet
        seen = []

        def stop(*args, run_info, **kw):
            seen.append(run_info['command'])
            raise ValueError('stop here')

        monkeypatch.setattr(estimate_bag, 'run', stop)
        monkeypatch.setattr(estimate_fleet, 'run_fleet', stop)
        monkeypatch.setattr('sys.argv', ['estimate_bag', 'from', 'the', 'shell'])
        assert estimate_bag.main(['a.bag', '-o', 'out dir']) == 1
        assert estimate_bag.main(['b.bag', '-o', 'out']) == 1
        with pytest.raises(ValueError):
            estimate_fleet.main(['c.bag', 'd.bag', '-o', 'fleet'])
        assert estimate_bag.main(None) == 2              # sys.argv's: not a valid command line
        assert seen == ["estimate_bag a.bag -o 'out dir'", 'estimate_bag b.bag -o out',
                        'estimate_fleet c.bag d.bag -o fleet']
