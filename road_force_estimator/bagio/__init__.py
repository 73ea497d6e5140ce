"""Bags: rosbag2 folders with MCAP storage, the only subpackage (with :mod:`..serde`, its
codec) that imports rosbags and mcap.

Writing (:class:`BagWriter`, as Jazzy's rosbag2 does) and reading (:func:`iter_messages`,
:func:`read_topic_columns`, :func:`bag_info`), and the bag formats of INTERFACES.md: drives
(:func:`write_drive_bag`, :func:`read_drive_bag`, block by block :class:`.DriveBlocks`), LPA
road profiles (:func:`write_lpa_bag`, :func:`read_lpa_bag`, :func:`road_from_source`) and the
observer's estimates (:func:`write_estimate_bag`, :func:`diagnostic_array`). Modules:
:mod:`.mcap_file` / :mod:`.mcap_scan` (the MCAP container), :mod:`.writer`,
:mod:`.row_blocks`, :mod:`.reader`, :mod:`.checks`, :mod:`.drive`, :mod:`.drive_blocks`,
:mod:`.lpa`, :mod:`.estimates`, :mod:`.road_source`. The messages' bytes are
:mod:`road_force_estimator.serde`'s.
"""
from road_force_estimator.bagio.drive import (
    Drive,
    Fixes,
    GroundTruth,
    read_drive_bag,
    write_drive_bag,
)
from road_force_estimator.bagio.errors import BagReadError, BagWriteError
from road_force_estimator.bagio.estimates import (
    ESTIMATE_FIELDS,
    diagnostic_array,
    write_estimate_bag,
)
from road_force_estimator.bagio.lpa import (
    DEFAULT_SURVEY_SPEED_MPS,
    read_lpa_bag,
    read_profile_bag,
    write_lpa_bag,
)
from road_force_estimator.bagio.reader import (
    BagInfo,
    TopicColumns,
    bag_custom_data,
    bag_info,
    iter_messages,
    read_topic_columns,
)
from road_force_estimator.bagio.road_source import road_from_source
from road_force_estimator.bagio.writer import (
    RELIABLE_QOS,
    RESERVE_NAME,
    ROSBAG2_VERSION,
    SENSOR_DATA_QOS,
    BagWriter,
)
from road_force_estimator.serde.messages import DEFAULT_START_STAMP_NS, DEFAULT_TRACK_WIDTH_M

__all__ = [
    'BagReadError', 'BagWriteError', 'BagWriter', 'BagInfo', 'bag_info', 'bag_custom_data',
    'iter_messages', 'TopicColumns', 'read_topic_columns', 'Drive', 'Fixes', 'GroundTruth',
    'read_drive_bag', 'write_drive_bag', 'read_lpa_bag', 'read_profile_bag', 'write_lpa_bag',
    'road_from_source', 'ESTIMATE_FIELDS', 'diagnostic_array', 'write_estimate_bag',
    'DEFAULT_START_STAMP_NS',
    'DEFAULT_TRACK_WIDTH_M', 'DEFAULT_SURVEY_SPEED_MPS', 'ROSBAG2_VERSION', 'SENSOR_DATA_QOS',
    'RELIABLE_QOS', 'RESERVE_NAME',
]
