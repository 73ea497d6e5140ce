"""Serde: ROS 2 messages as little-endian CDR bytes, apart from any storage (as rosbags keeps
``serde`` apart from ``rosbag2``).

A whole column of messages at a time (:mod:`.cdr`: :func:`encode_columns`,
:func:`decode_columns`, :class:`CdrLayout`), one message at a time for the nodes
(:mod:`.live`: :class:`CdrEncoder`, :class:`CdrReader`), and the templates of INTERFACES.md's
messages (:mod:`.messages`). Used by :mod:`road_force_estimator.bagio` (bags) and
:mod:`road_force_estimator.ros` (the nodes' raw bytes); the message definitions come from the
rosbags typestore for Jazzy (:data:`TYPESTORE`).
"""
from road_force_estimator.serde.cdr import (
    NS_PER_S, TYPESTORE, CdrLayout, ColumnRows, LazyColumns, cdr_layout, decode_columns,
    encode_columns, ns_to_stamps, stamps_to_ns)
from road_force_estimator.serde.errors import SerdeError
from road_force_estimator.serde.live import CdrEncoder, CdrEncoderGroup, CdrReader
from road_force_estimator.serde.messages import (
    DEFAULT_START_STAMP_NS, DEFAULT_TRACK_WIDTH_M, message_class, message_template,
    stamp_columns)

__all__ = [
    'TYPESTORE', 'NS_PER_S', 'CdrLayout', 'cdr_layout', 'ColumnRows', 'LazyColumns',
    'encode_columns', 'decode_columns', 'stamps_to_ns', 'ns_to_stamps', 'SerdeError',
    'CdrEncoder', 'CdrEncoderGroup', 'CdrReader', 'message_class', 'message_template',
    'stamp_columns', 'DEFAULT_START_STAMP_NS', 'DEFAULT_TRACK_WIDTH_M',
]
