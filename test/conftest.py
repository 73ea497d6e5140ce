"""Test session set-up: an isolated ROS 2 domain on this host, before rclpy is imported."""
import os
import pathlib
import sys

import pytest

# One ROS_DOMAIN_ID per test session (from the pid, 1..100) and discovery kept on localhost,
# so that parallel sessions on one machine never see each other's nodes.
os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'

REPO = pathlib.Path(__file__).resolve().parents[1]
# The shared test helpers (node_harness, ros_helpers, mcap_walk) live here, beside the
# subfolders that mirror the package's subpackages.
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
SHARED_DATA = REPO.parent / 'shared' / 'data'


@pytest.fixture
def shared_data() -> pathlib.Path:
    """../shared/data beside the checkout (read in place, never copied in)."""
    if not SHARED_DATA.is_dir():
        pytest.fail(f'{SHARED_DATA} is missing: clone the project with shared/ beside it')
    return SHARED_DATA


@pytest.fixture
def ros_context():
    """A fresh rclpy context for one test, shut down after it."""
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context)
    try:
        yield context
    finally:
        rclpy.try_shutdown(context=context)
