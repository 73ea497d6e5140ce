"""Estimate bags (bagio.estimates): the observer's topics, diagnostics from objects and
from plain dicts."""
from types import SimpleNamespace

import numpy as np
import pytest

from bag_samples import BASE_NS, T, header
from road_force_estimator import bagio, interfaces


class TestEstimateBag:
    def test_observer_topics(self, tmp_path):
        rng = np.random.default_rng(2)
        n = 50
        e = SimpleNamespace(
            stamp_ns=BASE_NS + 2_000_000 * np.arange(n), valid=np.ones(n, bool),
            distance_m=0.04 * np.arange(n), q_m=rng.normal(size=(n, 2)),
            dq=rng.normal(size=(n, 2)), roll_rad=rng.normal(size=n), droll=rng.normal(size=n),
            body_heave_m=rng.normal(size=n), body_heave_rate=rng.normal(size=n),
            wheel_heave_m=rng.normal(size=(n, 2)), wheel_heave_rate=rng.normal(size=(n, 2)),
            road_m=rng.normal(size=(n, 2)), wheel_load_n=rng.normal(2e4, 1e3, (n, 2)),
            ltr=rng.normal(size=n))
        e.valid[3] = False
        e.road_m[7, 1] = np.nan
        status = T['diagnostic_msgs/msg/DiagnosticStatus'](
            level=b'\x00'[0], name='observer', message='ok', hardware_id='', values=[])
        diag = T['diagnostic_msgs/msg/DiagnosticArray'](header=header(BASE_NS, ''),
                                                       status=[status])
        plain = [{'name': 'observer', 'level': 1, 'message': 'rejects',
                  'values': {'rejected': 3}}]
        result = bagio.write_estimate_bag(tmp_path / 'e', e, diagnostics=[
            (BASE_NS, diag), (BASE_NS + 10**9, plain)])
        assert result == {'written': 48, 'invalid': 1, 'nonfinite': 1}
        keep = np.ones(n, bool)
        keep[[3, 7]] = False
        cols = bagio.read_topic_columns(tmp_path / 'e', {
            '/observer/states': 'sensor_msgs/msg/JointState',
            '/wheel_load/left': 'geometry_msgs/msg/WrenchStamped',
            '/road_profile/right': 'geometry_msgs/msg/PointStamped',
            '/load_transfer_ratio': 'std_msgs/msg/Float64'})
        (g,) = cols['/observer/states'].groups
        assert g.layout.strings['name'] == interfaces.STATE_JOINTS
        np.testing.assert_array_equal(g.columns['position'][:, 3], e.body_heave_m[keep])
        np.testing.assert_array_equal(g.columns['velocity'][:, 4:], e.wheel_heave_rate[keep])
        np.testing.assert_array_equal(g.columns['velocity'][:, 2], e.droll[keep])
        load, _ = cols['/wheel_load/left'].column('wrench.force.z')
        np.testing.assert_array_equal(load, e.wheel_load_n[keep, 0])
        y, _ = cols['/road_profile/right'].column('point.y')
        assert set(y.tolist()) == {-1.0}
        ltr, _ = cols['/load_transfer_ratio'].column('data')
        np.testing.assert_array_equal(ltr, e.ltr[keep])
        stamps, ok = cols['/wheel_load/left'].stamps_ns()
        assert ok.all()
        np.testing.assert_array_equal(stamps, e.stamp_ns[keep])
        np.testing.assert_array_equal(cols['/wheel_load/left'].log_ns, e.stamp_ns[keep])
        diags = list(bagio.iter_messages(tmp_path / 'e', ['/diagnostics']))
        assert [m.status[0].name for _, _, m in diags] == ['observer', 'observer']
        last = diags[1][2]
        assert (last.header.stamp.sec, last.status[0].level, last.status[0].values[0].value) \
            == (BASE_NS // 10**9 + 1, 1, '3')
        with pytest.raises(ValueError, match='diagnostic level'):
            bagio.diagnostic_array(0, [{'name': 'x', 'level': 7}])


def test_load_transfer_topic_carries_both_ratios(tmp_path):
    # /load_transfer (INTERFACES.md): Vector3Stamped, x = LTR, y = quasi-static LTR, z = 0,
    # frame base_link, reliable; beside /load_transfer_ratio.
    rng = np.random.default_rng(3)
    n = 20
    e = SimpleNamespace(
        stamp_ns=BASE_NS + 1_000_000 * np.arange(n), distance_m=0.02 * np.arange(n),
        q_m=rng.normal(size=(n, 2)), dq=rng.normal(size=(n, 2)), roll_rad=rng.normal(size=n),
        droll=rng.normal(size=n), body_heave_m=rng.normal(size=n),
        body_heave_rate=rng.normal(size=n), wheel_heave_m=rng.normal(size=(n, 2)),
        wheel_heave_rate=rng.normal(size=(n, 2)), road_m=rng.normal(size=(n, 2)),
        wheel_load_n=rng.normal(2e4, 1e3, (n, 2)), ltr=rng.normal(size=n),
        ltr_quasi_static=rng.normal(size=n))
    bagio.write_estimate_bag(tmp_path / 'e', e)
    msgs = list(bagio.iter_messages(tmp_path / 'e', [interfaces.LOAD_TRANSFER]))
    assert len(msgs) == n
    assert interfaces.TOPIC_TYPES[interfaces.LOAD_TRANSFER] == 'geometry_msgs/msg/Vector3Stamped'
    assert interfaces.qos_kind(interfaces.LOAD_TRANSFER) == interfaces.RELIABLE
    for k, (_, _, m) in enumerate(msgs):
        assert m.header.frame_id == 'base_link'
        assert (m.vector.x, m.vector.y, m.vector.z) == (e.ltr[k], e.ltr_quasi_static[k], 0.0)
        assert m.header.stamp.sec * 10**9 + m.header.stamp.nanosec == e.stamp_ns[k]
