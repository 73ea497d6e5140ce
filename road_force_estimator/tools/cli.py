"""What the offline commands share: the usage-error parser, the exit-status wrapper, options.

Every command is ``build_parser()`` plus ``main(argv=None) -> int``; ``main`` hands its body to
:func:`run_main`, which turns what the body raises into one line on stderr and an exit status:

- :class:`UsageError` (a bad command line, also argparse's own errors through
  :class:`Parser`): ``<prog>: error: <message>``, status 2;
- the exception types the command lists (bad input): ``<prog>: <message>``, the status it
  gives them (1 for most commands);
- ``SystemExit`` (``--help``): its code;
- SIGINT (Ctrl-C): ``<prog>: interrupted``, status 130; SIGTERM: ``<prog>: terminated``,
  status 143 (SIGTERM is raised as :class:`Terminated` in the main thread, so that the
  commands' clean-ups run: a temporary folder is removed, nothing half-written stays).

Messages are made one line with :func:`one_line`: a line break inside them (a file name with
a newline) is written as ``\\n``, so that nothing after it is lost.
"""
from __future__ import annotations

import argparse
import math
import signal
import sys
import threading
from typing import Callable, Mapping, Sequence

__all__ = [
    'MODES', 'UsageError', 'Terminated', 'Parser', 'run_main', 'one_line', 'finite_float',
    'check_positive', 'available_memory',
    'add_output', 'add_params_file', 'add_mode', 'add_segment_length', 'segment_length',
    'add_force',
    'add_no_progress', 'add_overrides', 'add_units', 'parameter_values',
    'load_estimator_parameters', 'PROGRESS_MIN_SAMPLES', 'NullBar', 'progress_bar',
    'sample_progress', 'command_line',
]

#: Estimation modes of estimate_bag and estimate_fleet.
MODES = ('online', 'offline')
#: Progress bars over samples appear from this many samples on.
PROGRESS_MIN_SAMPLES = 50_000


class UsageError(Exception):
    """A bad command line (exit status 2)."""


class Parser(argparse.ArgumentParser):
    """An argument parser whose errors raise :class:`UsageError` (one line, no usage dump)."""

    def error(self, message: str):
        raise UsageError(message)


class Terminated(BaseException):
    """SIGTERM, raised in the main thread by :func:`run_main` (not an ``Exception``: no
    ``except Exception`` takes it for a bad input)."""


def _terminate(signum, frame) -> None:
    raise Terminated()


def one_line(err: BaseException | str) -> str:
    """An exception's message (else its type's name) on one line: the line breaks in it (a
    file name with a newline, a multi-line library message) written as ``\\n``, ``\\r``."""
    text = str(err).strip()
    if not text:
        return type(err).__name__ if isinstance(err, BaseException) else ''
    return text.replace('\r', '\\r').replace('\n', '\\n')


def run_main(prog: str, parser: argparse.ArgumentParser,
             body: Callable[[argparse.Namespace], int], argv: Sequence[str] | None,
             errors: Mapping[tuple[type[BaseException], ...], int]) -> int:
    """Parse ``argv`` with ``parser``, run ``body(args)``; the exit status.

    Parameters
    ----------
    prog : str
        The command's name, first on every error line.
    parser : ArgumentParser
        The command's :class:`Parser` (``build_parser()``).
    body : callable
        ``body(args) -> int``: the command's work and its normal output.
    argv : sequence of str, optional
        The arguments (default ``sys.argv[1:]``).
    errors : mapping
        Exception types -> exit status; such an error prints ``<prog>: <first line>``.
    """
    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _terminate) if main_thread else None
    try:
        return body(parser.parse_args(argv))
    except SystemExit as done:          # --help
        return int(done.code or 0)
    except UsageError as err:
        print(f'{prog}: error: {one_line(err)}', file=sys.stderr)
        return 2
    except tuple(t for types in errors for t in types) as err:
        status = next(s for types, s in errors.items() if isinstance(err, types))
        print(f'{prog}: {one_line(err)}', file=sys.stderr)
        return status
    except KeyboardInterrupt:
        print(f'{prog}: interrupted (SIGINT); nothing half-written is left', file=sys.stderr)
        return 130
    except Terminated:
        print(f'{prog}: terminated (SIGTERM); nothing half-written is left', file=sys.stderr)
        return 143
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, previous)


def finite_float(text: str) -> float:
    """argparse type: a finite number (``nan``, ``inf`` refused with a one-line reason)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'{text!r} is not a number') from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f'{text!r}: must be a finite number')
    return value


def available_memory() -> float | None:
    """The memory (bytes) the system can give now without swapping (``MemAvailable`` of
    /proc/meminfo, else the free physical pages); None when it cannot be told."""
    try:
        with open('/proc/meminfo', encoding='ascii') as f:
            for line in f:
                if line.startswith('MemAvailable:'):
                    return float(line.split()[1]) * 1024.0
    except (OSError, ValueError, IndexError):
        pass
    try:
        import os
        return float(os.sysconf('SC_AVPHYS_PAGES')) * float(os.sysconf('SC_PAGE_SIZE'))
    except (ValueError, OSError, AttributeError):
        return None


def check_positive(option: str, value: float | None, *, finite: bool = True) -> None:
    """Raise :class:`UsageError` ``<option> <value>: must be > 0 m`` unless ``value`` (m) is
    None or > 0 (and finite when ``finite``)."""
    if value is None:
        return
    if not (value > 0.0 and (math.isfinite(value) or not finite)):
        raise UsageError(f'{option} {value!r}: must be > 0 m')


def add_output(parser: argparse.ArgumentParser, help: str, *, metavar: str = 'DIR') -> None:
    """``--output/-o PATH`` (required)."""
    parser.add_argument('--output', '-o', required=True, metavar=metavar, help=help)


def add_params_file(parser: argparse.ArgumentParser, help: str, *,
                    required: bool = False) -> None:
    """``--params-file FILE``: a ROS 2 parameter file."""
    parser.add_argument('--params-file', required=required, metavar='FILE', help=help)


def add_mode(parser: argparse.ArgumentParser) -> None:
    """``--mode online|offline`` (default online)."""
    parser.add_argument('--mode', choices=MODES, default='online',
                        help='online: what the observer node publishes (default); offline: '
                             'non-causal, the whole recording')


def add_segment_length(parser: argparse.ArgumentParser, help: str, *,
                       default: float | None = 100.0) -> None:
    """``--segment-length M`` (m, default 100; None: :func:`segment_length` gives the default
    of ``--units``)."""
    parser.add_argument('--segment-length', type=finite_float, default=default, metavar='M',
                        help=help)


def segment_length(args: argparse.Namespace) -> float:
    """``--segment-length`` (m), checked, else the default of ``--units`` (100 m, or 0.1 mi =
    160.9344 m for ``us``; 100 m for a command without ``--units``)."""
    from road_force_estimator.core.units import units
    if args.segment_length is None:
        return units(getattr(args, 'units', 'si')).segment_length_m
    check_positive('--segment-length', args.segment_length)
    return float(args.segment_length)


def add_force(parser: argparse.ArgumentParser, help: str) -> None:
    """``--force``: replace or recompute what exists."""
    parser.add_argument('--force', action='store_true', help=help)


def add_no_progress(parser: argparse.ArgumentParser) -> None:
    """``--no-progress``."""
    parser.add_argument('--no-progress', action='store_true', help='no progress bar')


def add_overrides(parser: argparse.ArgumentParser) -> None:
    """``-p NAME:=VALUE`` (repeatable): a parameter, applied after ``--params-file``."""
    parser.add_argument('-p', dest='overrides', action='append', default=[],
                        metavar='NAME:=VALUE',
                        help='set one parameter (repeatable), after --params-file, e.g. '
                             '-p observer.latency:=0.01; unknown names are refused')


def add_units(parser: argparse.ArgumentParser) -> None:
    """``--units si|us`` (default si)."""
    parser.add_argument('--units', choices=('si', 'us'), default='si',
                        help='si: IRI in m/km, distances in m, 100 m segments (default); us: '
                             'in/mi, feet, 0.1-mile (160.9344 m) segments')


def parameter_values(path: str | None, node_names: Sequence[str],
                     overrides: Sequence[str] = ()) -> dict:
    """``{dotted name: value}``: the parameter file's (none if None), then each ``-p
    NAME:=VALUE`` of ``overrides``.

    Raises
    ------
    ValueError, OSError
        A bad or unreadable file, a bad override or an unknown name.
    """
    from road_force_estimator.core.parameters import load_params_file, parse_override
    values = {} if path is None else load_params_file(path, node_names=tuple(node_names))
    for text in overrides:
        name, value = parse_override(text)
        values[name] = value
    return values


def load_estimator_parameters(path: str | None, node_names: Sequence[str],
                              overrides: Sequence[str] = ()):
    """``(vehicle, ObserverParameters)`` from a parameter file (defaults if None) and the
    ``-p`` overrides (:func:`parameter_values`): the vehicle a ``VehicleParameters``, or with
    ``vehicle.model: articulated`` an ``ArticulatedParameters`` (the whole vehicle's
    estimator, :mod:`road_force_estimator.pipeline.whole_vehicle`).

    Raises
    ------
    ValueError, OSError
        A bad or unreadable file, a bad override.
    """
    from road_force_estimator.core.articulated_parameters import (
        ArticulatedParameters, check_model_names, vehicle_model)
    from road_force_estimator.core.parameters import ObserverParameters, VehicleParameters
    values = parameter_values(path, node_names, overrides)
    check_model_names(values, values)
    if vehicle_model(values) == 'articulated':
        return (ArticulatedParameters.from_parameters(values),
                ObserverParameters.from_parameters(values))
    return VehicleParameters.from_parameters(values), ObserverParameters.from_parameters(values)


def command_line(prog: str, argv: Sequence[str] | None) -> str:
    """A command line for reports: ``prog`` and its arguments ``argv`` (``main``'s, which
    :func:`run_main` parses: ``sys.argv[1:]`` when None), shell-quoted."""
    import shlex
    return ' '.join(shlex.quote(a) for a in [prog, *(sys.argv[1:] if argv is None else argv)])


class NullBar:
    """A progress bar that shows nothing (tqdm's interface as the commands use it): what
    :func:`progress_bar` gives when no bar would be shown, without importing tqdm."""

    n = 0

    def update(self, n: int = 1) -> None:
        """Nothing."""

    def set_description_str(self, desc: str) -> None:
        """Nothing."""

    def close(self) -> None:
        """Nothing."""

    def __enter__(self) -> 'NullBar':
        return self

    def __exit__(self, *exc) -> None:
        return None


def progress_bar(enabled: bool, **kwargs):
    """A tqdm bar on stderr (``kwargs``: tqdm's), or a :class:`NullBar` when not ``enabled``
    or stderr is not a terminal (where tqdm would disable itself): tqdm imported only for a
    bar that shows."""
    isatty = getattr(sys.stderr, 'isatty', None)
    if not enabled or not (isatty is not None and isatty()):
        return NullBar()
    from tqdm import tqdm
    return tqdm(file=sys.stderr, **kwargs)


def sample_progress(total: int, enabled: bool, desc: str):
    """A tqdm progress bar over ``total`` samples on stderr (disabled when not ``enabled`` or
    under :data:`PROGRESS_MIN_SAMPLES` samples; tqdm's own choice off a terminal)."""
    return progress_bar(enabled and total >= PROGRESS_MIN_SAMPLES, total=total, desc=desc,
                        unit='sample', unit_scale=True, mininterval=0.5, leave=False)
