"""The whole vehicle's short drives that the pipeline's in-pieces tests share (one set per
module that asks for them)."""
import pytest


@pytest.fixture(scope='module')
def drives(tmp_path_factory):
    """A 3 s drive of the file's combination with 0.3 s of deflections and twists lost (a gap),
    and one with the tractor IMU and pendulums through a curve: ``{name: (bag, params)}``."""
    from test_whole_vehicle_blocks import CONFIG, imu_params, simulate, with_gap

    root = tmp_path_factory.mktemp('drives')
    plain = simulate(root / 'plain', CONFIG, 3.0)
    params = imu_params(root)
    return {'gap': (with_gap(plain, root / 'gap'), CONFIG),
            'imu': (simulate(root / 'imu', params, 3.0), params)}
