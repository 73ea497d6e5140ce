"""launch/*.launch.xml (issue 17): the `launch` package is not on PyPI, so the files are parsed
here: every executable, package, parameter and parameter file they name exists."""
import ast
import importlib
import pathlib
import re
import xml.etree.ElementTree as ET

import pytest

REPO = pathlib.Path(__file__).resolve().parents[1]
PACKAGE = ET.parse(REPO / 'package.xml').getroot().findtext('name')
LAUNCH_FILES = sorted((REPO / 'launch').glob('*.launch.xml'))


def executables() -> dict[str, str]:
    """setup.py's EXECUTABLES (name -> subpackage), read from its source."""
    tree = ast.parse((REPO / 'setup.py').read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and getattr(node.targets[0], 'id', '') == 'EXECUTABLES':
            return ast.literal_eval(node.value)
    raise AssertionError('setup.py has no EXECUTABLES')


def resolve(text: str, args: dict[str, str]) -> str:
    """$(var NAME) and $(find-pkg-share PACKAGE) as launch substitutes them (the package's
    share folder is laid out as the checkout: config/, launch/)."""
    text = re.sub(r'\$\(var (\w+)\)', lambda m: args[m.group(1)], text)
    text = text.replace(f'$(find-pkg-share {PACKAGE})', str(REPO))
    assert '$(' not in text, f'unresolved substitution in {text!r}'
    return text


def test_both_launch_files_exist_and_are_installed():
    assert [p.name for p in LAUNCH_FILES] == ['replay.launch.xml', 'simulation.launch.xml']
    assert "('share/' + PACKAGE + '/launch', glob('launch/*.launch.xml'))" in (
        REPO / 'setup.py').read_text()


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_every_node_parameter_and_file_named_exists(path):
    root = ET.parse(path).getroot()
    assert root.tag == 'launch'
    args = {a.get('name'): a.get('default') for a in root.findall('arg')}
    assert all(v is not None for v in args.values()), args
    nodes = root.findall('node')
    assert nodes
    exes = executables()
    for node in nodes:
        exe = node.get('exec')
        assert node.get('pkg') == PACKAGE
        assert exe in exes and exes[exe] == 'ros', exe
        specs = {s.name for s in importlib.import_module(f'{PACKAGE}.ros.{exe}').SPECS}
        for param in node.findall('param'):
            if param.get('from') is not None:
                file = pathlib.Path(resolve(param.get('from'), args))
                assert file.is_file(), file
                assert file.suffix == '.yaml'
            else:
                assert param.get('name') in specs, (exe, param.get('name'))
                resolve(param.get('value'), args)


def test_simulation_and_replay_start_the_nodes_the_readme_says():
    names = {p.name: [n.get('exec') for n in ET.parse(p).getroot().findall('node')]
             for p in LAUNCH_FILES}
    assert sorted(names['simulation.launch.xml']) == ['bag_recorder', 'observer',
                                                      'plant_simulator']
    assert sorted(names['replay.launch.xml']) == ['bag_recorder', 'observer']


# ------------------------------------------------------------------------------------------
# Both launch files run by the real launch / launch_ros (issue 29), where they import.

def real_launch_missing() -> str | None:
    """Why the real ``launch`` cannot run here (None: it can)."""
    try:
        import launch  # noqa: F401
        import launch_ros  # noqa: F401
        import launch_xml  # noqa: F401
    except ImportError as exc:
        return (f'no module {exc.name!r}: launch, launch_xml and launch_ros are not on PyPI '
                '(pip download --no-deps ros-jazzy-launch / ros-jazzy-launch-ros: no such '
                'distribution), and launch_ros imports composition_interfaces, a message '
                'package with no PyPI wheel; a Jazzy install from apt has them all')
    return None


# What `ros2 launch FILE NAME:=VALUE...` does (ros2launch.api.launch_a_launch_file).
RUN_LAUNCH = """
import sys
from launch import LaunchService
from launch.actions import IncludeLaunchDescription
from launch.launch_description_sources import AnyLaunchDescriptionSource
path, *args = sys.argv[1:]
service = LaunchService(argv=args)
service.include_launch_description(IncludeLaunchDescription(
    AnyLaunchDescriptionSource(path), launch_arguments=[a.split(':=', 1) for a in args]))
sys.exit(service.run())
"""


def install_prefix(root: pathlib.Path) -> pathlib.Path:
    """The layout colcon installs (the ament index marker, share/, lib/<package>/<exe>), made
    of links to this checkout and this environment's console scripts."""
    import sys
    prefix = root / 'install'
    marker = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / PACKAGE
    marker.parent.mkdir(parents=True)
    marker.write_text('')
    share = prefix / 'share' / PACKAGE
    share.mkdir(parents=True)
    for name in ('launch', 'config', 'package.xml'):
        (share / name).symlink_to(REPO / name)
    lib = prefix / 'lib' / PACKAGE
    lib.mkdir(parents=True)
    for exe, sub in executables().items():
        if sub == 'ros':
            (lib / exe).symlink_to(pathlib.Path(sys.executable).parent / exe)
    return prefix


def launch_prefix() -> str:
    """The install prefix whose ament index lists the ``launch`` package (launch_xml looks its
    share up): /opt/ros/jazzy on a Jazzy install (on AMENT_PREFIX_PATH once sourced), the
    environment's prefix for a pip install. A workspace's setup.bash alone does not give it."""
    import launch as module
    for parent in pathlib.Path(module.__file__).resolve().parents:
        if (parent / 'share' / 'ament_index' / 'resource_index' / 'packages' / 'launch').is_file():
            return str(parent)
    return ''


def launch(path: pathlib.Path, prefix: pathlib.Path, *args: str):
    import os
    import subprocess
    import sys
    env = dict(os.environ, PYTHONUNBUFFERED='1', AMENT_PREFIX_PATH=os.pathsep.join(
        p for p in (str(prefix), launch_prefix(), os.environ.get('AMENT_PREFIX_PATH', ''))
        if p))
    return subprocess.Popen([sys.executable, '-c', RUN_LAUNCH, str(path), *args], cwd=REPO,
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)


def read_until(process, text: str, timeout_s: float) -> str:
    """The process's output up to the line holding ``text`` (fails on timeout or exit)."""
    import threading
    seen: list[str] = []
    found = threading.Event()

    def pump():
        for line in process.stdout:
            seen.append(line)
            if text in line:
                found.set()
                return
    threading.Thread(target=pump, daemon=True).start()
    assert found.wait(timeout_s), f'no {text!r} within {timeout_s} s: {"".join(seen)[-3000:]}'
    return ''.join(seen)


def stop_launch(process) -> str:
    import signal
    import subprocess
    process.send_signal(signal.SIGINT)
    try:
        rest, _ = process.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        process.kill()
        raise
    assert process.returncode == 0, rest[-3000:]
    return rest


@pytest.mark.skipif(real_launch_missing() is not None, reason=str(real_launch_missing()))
def test_simulation_launch_runs_the_three_nodes_and_the_bag_has_every_sample(tmp_path):
    from road_force_estimator.bagio import iter_messages, read_drive_bag
    params = tmp_path / 'short.yaml'
    params.write_text('/**:\n  ros__parameters:\n    simulator:\n      duration: 2.0\n')
    process = launch(REPO / 'launch' / 'simulation.launch.xml', install_prefix(tmp_path),
                     f'params_file:={params}', f'output:={tmp_path / "drive"}')
    out = ''
    try:
        out = read_until(process, 'drive finished after 2001 samples', 120.0)
    finally:
        out += stop_launch(process)
    assert 'starting the drive anyway' not in out and 'Traceback' not in out, out[-3000:]
    drive = read_drive_bag(tmp_path / 'drive')
    assert len(drive.stamps_ns) == 2001                   # every sample, from the first on
    states = sum(1 for _ in iter_messages(tmp_path / 'drive', ['/observer/states']))
    assert states == 2001                                 # an estimate for every one


@pytest.mark.skipif(real_launch_missing() is not None, reason=str(real_launch_missing()))
def test_replay_launch_estimates_a_drive_played_into_it(tmp_path, ros_context):
    import subprocess
    import sys

    from node_harness import Collector, close, make_executor
    from ros_helpers import spin_until
    from road_force_estimator.bagio import iter_messages
    from road_force_estimator.tools.simulate_bag import main as simulate_bag
    assert simulate_bag(['--road', 'iso8608:C:seed=3', '--speed', '20', '--rate', '1000',
                         '--duration', '0.8', '--output', str(tmp_path / 'drive'),
                         '--no-progress']) == 0
    collector = Collector(ros_context, ['/observer/states'])
    executor = make_executor(ros_context, collector)
    process = launch(REPO / 'launch' / 'replay.launch.xml', install_prefix(tmp_path),
                     f'output:={tmp_path / "est"}')
    try:
        player = subprocess.run(
            [str(pathlib.Path(sys.executable).parent / 'bag_player'), str(tmp_path / 'drive'),
             '--topics', '/suspension/deflections', '/vehicle/twist', '--wait-for', 'observer',
             'bag_recorder'], cwd=REPO, capture_output=True, text=True, timeout=180)
        assert player.returncode == 0 and 'played 1602 messages' in player.stderr, \
            player.stderr
        got = spin_until(executor, lambda: collector.count('/observer/states') >= 801, 60.0)
    finally:
        close(executor, collector)
        out = stop_launch(process)
    assert got, (collector.count('/observer/states'), out[-3000:])
    recorded = sum(1 for _ in iter_messages(tmp_path / 'est', ['/observer/states']))
    assert recorded == 801, out[-3000:]
