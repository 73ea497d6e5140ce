"""The package installs as ros2 run and pip users expect (INTERFACES.md, "Executables")."""
import os
import pathlib
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest

pytestmark = pytest.mark.slow   # `pytest -m 'not slow'` skips it; scripts/test runs it

REPO = pathlib.Path(__file__).resolve().parents[1]
PACKAGE = 'road_force_estimator'
EXECUTABLES = ['plant_simulator', 'observer', 'bag_recorder', 'bag_player', 'simulate_bag',
               'estimate_bag', 'profile_to_bag', 'road_profile_iri', 'estimate_fleet',
               'calibrate_vehicle']


def test_package_xml_declares_ament_python_and_ros_dependencies():
    root = ET.parse(REPO / 'package.xml').getroot()
    assert root.get('format') == '3'
    assert root.findtext('name') == PACKAGE
    assert root.find('export/build_type').text == 'ament_python'
    exec_deps = {e.text for e in root.findall('exec_depend')}
    assert {'rclpy', 'std_msgs', 'sensor_msgs', 'geometry_msgs', 'diagnostic_msgs'} <= exec_deps
    assert 'python3-pytest' in {e.text for e in root.findall('test_depend')}


def test_pip_install_puts_every_executable_on_path():
    bindir = pathlib.Path(sys.executable).parent
    path = os.pathsep.join([str(bindir), os.environ.get('PATH', '')])
    for name in EXECUTABLES:
        found = shutil.which(name, path=path)
        assert found is not None, f'{name} is not on PATH'
        # Every executable at least parses its command line (a usage error is exit 2).
        run = subprocess.run([found, '--help'], capture_output=True, text=True, timeout=120)
        assert run.returncode in (0, 2), (name, run.stderr[-500:])


@pytest.fixture(scope='module')
def colcon_install(tmp_path_factory):
    """``colcon build`` of this package alone into a temporary folder."""
    colcon = pathlib.Path(sys.executable).parent / 'colcon'
    assert colcon.exists(), 'colcon is installed by scripts/setup'
    work = tmp_path_factory.mktemp('colcon')
    src = work / 'src'
    # Only the package's own files (as a clone has them): no .venv, no build output.
    shutil.copytree(REPO, src / PACKAGE, ignore=shutil.ignore_patterns(
        '.venv', '.git', 'build', 'install', 'log', '__pycache__', '*.egg-info', 'out'))
    env = dict(os.environ, COLCON_HOME=str(work / 'colcon_home'))
    run = subprocess.run(
        [str(colcon), '--log-base', str(work / 'log'), 'build', '--base-paths', str(src),
         '--build-base', str(work / 'build'), '--install-base', str(work / 'install'),
         '--event-handlers', 'console_direct-'],
        cwd=work, env=env, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    return work / 'install'


def test_colcon_build_installs_executables_where_ros2_run_finds_them(colcon_install):
    from ament_index_python.packages import get_package_prefix
    import ament_index_python.constants as constants

    # Resolve as ros2run does: the package prefix from the ament index on AMENT_PREFIX_PATH,
    # then <prefix>/lib/<package>/<executable>.
    prefix_dir = colcon_install / PACKAGE
    old = os.environ.get(constants.AMENT_PREFIX_PATH_ENV_VAR)
    os.environ[constants.AMENT_PREFIX_PATH_ENV_VAR] = str(prefix_dir)
    try:
        prefix = pathlib.Path(get_package_prefix(PACKAGE))
    finally:
        if old is None:
            del os.environ[constants.AMENT_PREFIX_PATH_ENV_VAR]
        else:
            os.environ[constants.AMENT_PREFIX_PATH_ENV_VAR] = old
    assert prefix == prefix_dir
    for name in EXECUTABLES:
        exe = prefix / 'lib' / PACKAGE / name
        assert exe.is_file(), f'{exe} missing'
        assert os.access(exe, os.X_OK), f'{exe} is not executable'
    share = prefix / 'share' / PACKAGE
    assert (share / 'package.xml').is_file()
    assert (share / 'config' / 'road_force_estimator.yaml').is_file()
    for name in ('simulation.launch.xml', 'replay.launch.xml'):
        assert (share / 'launch' / name).is_file(), name
    assert (prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / PACKAGE).is_file()
