"""CDR a message at a time (serde.live): byte-exact against rosbags, templates' layouts kept,
any other layout refused by the reader."""
import math
import struct

import numpy as np
import pytest

from road_force_estimator import interfaces
from road_force_estimator.serde import TYPESTORE, CdrEncoder, CdrReader, message_template

WRENCH, POINT, JOINT, FLOAT = (interfaces.WRENCH, interfaces.POINT, interfaces.JOINT_STATE,
                               interfaces.FLOAT64)
EXTREMES = [0.0, -0.0, 1.0, -1.0, 5e-324, -5e-324, 2.2250738585072014e-308, 1e-300, -1e300,
            1.7976931348623157e308, -1.7976931348623157e308, math.pi, 1 / 3]
STAMPS = [0, 1, 999_999_999, 10**9, 10**9 + 1, 1_700_000_000_123_456_789,
          2**31 * 10**9 - 1]


def numbers(rng, k):
    """``k`` float64 of every size, extremes and signed zeros among them."""
    values = rng.normal(size=k) * 10.0 ** rng.integers(-300, 300, size=k)
    values[rng.random(k) < 0.3] = rng.choice(EXTREMES)
    return [float(v) for v in values]


def reference(msgtype, template, stamp_ns, fields):
    if stamp_ns is not None:
        template.header.stamp.sec, template.header.stamp.nanosec = divmod(stamp_ns, 10**9)
    for path, value in fields.items():
        obj, *parts = [template, *path.split('.')]
        for part in parts[:-1]:
            obj = getattr(obj, part)
        setattr(obj, parts[-1], np.asarray(value) if isinstance(value, list) else value)
    return bytes(TYPESTORE.serialize_cdr(template, msgtype))


@pytest.mark.parametrize('msgtype, frame, names, velocity, paths', [
    (WRENCH, 'front_left_wheel', (), False, ['wrench.force.z']),
    (WRENCH, 'front_right_wheel', (), False, ['wrench.force.x', 'wrench.torque.z']),
    (POINT, 'road', (), False, ['point.x', 'point.y', 'point.z']),
    (FLOAT, '', (), False, ['data']),
    (JOINT, 'base_link', interfaces.STATE_JOINTS, True, ['position', 'velocity']),
    (JOINT, 'base_link', interfaces.DEFLECTION_JOINTS, False, ['position']),
])
def test_encoded_equals_rosbags_and_reads_back(msgtype, frame, names, velocity, paths):
    rng = np.random.default_rng(5)
    encoder = CdrEncoder(msgtype, message_template(msgtype, frame, names, velocity), paths)
    reader = CdrReader(msgtype, message_template(msgtype, frame, names, velocity), paths)
    widths = [len(names) if p in ('position', 'velocity') else 1 for p in paths]
    assert encoder.count == sum(widths)
    stamped = msgtype != FLOAT
    for i in range(300):
        stamp = (STAMPS[i] if i < len(STAMPS) else int(rng.integers(0, 2**31 * 10**9))) \
            if stamped else None
        values = numbers(rng, encoder.count)
        data = encoder.encode(stamp, values)
        fields, k = {}, 0
        for path, w in zip(paths, widths):
            fields[path] = values[k] if path not in ('position', 'velocity') else values[k:k + w]
            k += w
        want = reference(msgtype, message_template(msgtype, frame, names, velocity), stamp,
                         fields)
        assert data == want
        got_stamp, got = reader.read(data)
        assert got_stamp == (stamp or 0)
        assert struct.pack(f'<{len(got)}d', *got) == struct.pack(f'<{len(values)}d', *values)


def test_reader_refuses_other_layouts():
    template = message_template(JOINT, 'base_link', interfaces.DEFLECTION_JOINTS)
    reader = CdrReader(JOINT, template, ['position'])
    good = CdrEncoder(JOINT, template, ['position']).encode(7, [1.0, 2.0, 3.0])
    assert reader.read(good) == (7, (1.0, 2.0, 3.0))
    others = [
        message_template(JOINT, 'base_link', ('right_suspension', 'left_suspension', 'roll')),
        message_template(JOINT, 'base_link', ('left_suspension', 'right_suspension', 'rolk')),
        message_template(JOINT, 'base_linx', interfaces.DEFLECTION_JOINTS),
        message_template(JOINT, 'base_link', interfaces.DEFLECTION_JOINTS, velocity=True),
        message_template(JOINT, 'base_link', interfaces.DEFLECTION_JOINTS[:2]),
    ]
    for other in others:
        assert reader.read(bytes(TYPESTORE.serialize_cdr(other, JOINT))) is None
    big = bytes(TYPESTORE.serialize_cdr(template, JOINT, little_endian=False))
    assert len(big) == len(good) and reader.read(big) is None
    assert reader.read(good[:-1]) is None and reader.read(good + b'\0') is None
    assert reader.read(b'') is None
    # Padding is not looked at (rmw may leave it uninitialised); the numbers are.
    padded = bytearray(good)
    padded[26:28] = b'\xab\xcd'  # after 'base_link\0', before the names' length
    assert reader.read(bytes(padded)) == (7, (1.0, 2.0, 3.0))


def test_encoder_checks_its_arguments():
    with pytest.raises(KeyError, match='no numeric field'):
        CdrEncoder(POINT, message_template(POINT, 'road'), ['point.w'])
    with pytest.raises(TypeError, match='not float64'):
        CdrEncoder(POINT, message_template(POINT, 'road'), ['header.stamp.sec'])
    encoder = CdrEncoder(POINT, message_template(POINT, 'road'), ['point.x', 'point.z'])
    assert [k for _, _, k in encoder.regions] == [1, 1]
    with pytest.raises(ValueError, match='2 numbers for 3'):
        CdrEncoder(POINT, message_template(POINT, 'road'), ['point.x', 'point.y',
                                                            'point.z']).encode(0, (1.0, 2.0))
