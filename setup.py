"""Packaging for road_force_estimator (ament_python; also installable with plain pip)."""
from glob import glob
import os

from setuptools import find_packages, setup

PACKAGE = 'road_force_estimator'

# Executables of ../shared/design/INTERFACES.md: console-script name = module name, in the
# subpackage of its concern (ros/: nodes, tools/: offline commands).
EXECUTABLES = {
    'plant_simulator': 'ros',
    'observer': 'ros',
    'bag_recorder': 'ros',
    'bag_player': 'ros',
    'simulate_bag': 'tools',
    'estimate_bag': 'tools',
    'profile_to_bag': 'tools',
    'road_profile_iri': 'tools',
    'estimate_fleet': 'tools',
    'calibrate_vehicle': 'tools',
}


def _tree(folder):
    """data_files entries that keep the folder layout of ``folder`` under share/PACKAGE."""
    entries = {}
    for path in glob(os.path.join(folder, '**', '*'), recursive=True):
        if os.path.isfile(path):
            target = os.path.join('share', PACKAGE, os.path.dirname(path))
            entries.setdefault(target, []).append(path)
    return sorted(entries.items())


setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*', 'bench', 'bench.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml']),
        ('share/' + PACKAGE + '/config', glob('config/*.yaml')),
        ('share/' + PACKAGE + '/launch', glob('launch/*.launch.xml')),
    ] + _tree('bags'),
    # The ROS 2 Python packages (rclpy, the message packages) are deliberately absent:
    # on a Jazzy machine they come from apt; scripts/setup installs the PyPI wheels.
    install_requires=[
        'setuptools',
        'numpy>=1.24,<3',
        'scipy>=1.10,<2',
        'PyYAML>=6,<7',
        'rosbags>=0.10,<0.12',
        'mcap>=1.1,<2',
        'mcap-ros2-support>=0.5,<0.7',
        'matplotlib>=3.7,<4',
        'tqdm>=4.60,<5',
    ],
    extras_require={
        'fleet': ['dask[distributed]>=2024.1', 'pyarrow>=14'],
        'test': ['pytest>=7,<10', 'ruff>=0.5,<1', 'colcon-core>=0.15,<0.22',
                 'colcon-ros>=0.4,<0.6'],
    },
    zip_safe=True,
    maintainer='road_force_estimator developers',
    maintainer_email='dev@road-force-estimator.invalid',
    description='Road profile and vertical wheel load estimation with a Kalman unknown-input '
                'observer on the roll-plane model.',
    license='Apache-2.0',
    python_requires='>=3.10,<3.14',
    entry_points={
        'console_scripts': [
            # the nodes through ros/launcher.py (SIGINT caught before their heavy imports)
            f'{name} = {PACKAGE}.ros.launcher:{name}' if sub == 'ros'
            else f'{name} = {PACKAGE}.{sub}.{name}:main' for name, sub in EXECUTABLES.items()
        ],
    },
)
