"""The contract of ``../shared/design/INTERFACES.md`` as data: topics, types, names, frames, QoS.

The one place that spells it: the nodes (``ros/``), the bag formats (``bagio/``) and the
tests read these names; none of them writes a topic name, joint name, frame or QoS kind of
its own. Plain Python only (no ROS, no bag library), so every layer may import it.

Sides are ordered (left, right) everywhere (MODEL.md: index 1 = left, 2 = right).
"""
from __future__ import annotations

__all__ = [
    'SIDES', 'DEFLECTION_JOINTS', 'STATE_JOINTS', 'BASE_FRAME', 'ROAD_FRAME', 'WHEEL_FRAMES',
    'DEFLECTIONS', 'TWIST', 'TRUE_LOAD', 'TRUE_ROAD', 'FIX', 'LOAD', 'STATIC_LOAD',
    'STATIC_LOAD_PERIOD_NS', 'static_load_due', 'ROAD', 'ROAD_FUSED', 'LTR',
    'LOAD_TRANSFER', 'STATES', 'DIAGNOSTICS', 'LPA', 'READERS', 'FIRST_STAMP_KEY',
    'JOINT_STATE', 'POINT', 'WRENCH',
    'TWIST_STAMPED', 'FLOAT64', 'VECTOR3_STAMPED', 'NAVSATFIX', 'DIAGNOSTIC_ARRAY',
    'TOPIC_TYPES', 'SENSOR_DATA', 'RELIABLE', 'TOPIC_QOS', 'qos_kind',
    'UNITS', 'TRACTOR_ROLL_JOINT', 'TRAILER_ROLL_JOINT', 'axle_deflection_joints',
    'articulated_deflection_joints', 'wheel_joints', 'WHEEL_LOADS', 'TRUE_WHEEL_LOADS',
    'STATIC_WHEEL_LOADS', 'UNIT_LOAD_TRANSFER', 'TRUE_LOAD_TRANSFER_RATIOS', 'IMU',
    'IMU_MSG', 'IMU_FRAME',
]

SIDES = ('left', 'right')

#: JointState names of /suspension/deflections: q_1, q_2 (m), phi (rad); mapped by name.
DEFLECTION_JOINTS = ('left_suspension', 'right_suspension', 'roll')
#: JointState names of /observer/states (positions and velocities).
STATE_JOINTS = DEFLECTION_JOINTS + ('body_heave', 'left_wheel_heave', 'right_wheel_heave')

BASE_FRAME = 'base_link'
ROAD_FRAME = 'road'
WHEEL_FRAMES = ('front_left_wheel', 'front_right_wheel')

# Topics; per-side topics are (left, right).
DEFLECTIONS = '/suspension/deflections'
TWIST = '/vehicle/twist'
TRUE_LOAD = ('/ground_truth/wheel_load/left', '/ground_truth/wheel_load/right')
TRUE_ROAD = ('/ground_truth/road_profile/left', '/ground_truth/road_profile/right')
FIX = '/fix'
LOAD = ('/wheel_load/left', '/wheel_load/right')
#: static wheel loads F_c,i (N) in wrench.force.z: configured, or estimated under zero_load
STATIC_LOAD = ('/wheel_load/static/left', '/wheel_load/static/right')
#: The static loads change slowly: they are published with the first estimate of each period
#: of this many ns of the stamps (10 Hz; the observer node and the estimate bags alike).
STATIC_LOAD_PERIOD_NS = 100_000_000
ROAD = ('/road_profile/left', '/road_profile/right')
#: The wheel paths' profile fused over every instrumented axle (``vehicle.model: articulated``)
ROAD_FUSED = ('/road_profile/fused/left', '/road_profile/fused/right')
LTR = '/load_transfer_ratio'
#: x = LTR, y = quasi-static LTR (MODEL.md step 8, rollover warnings), z = 0; frame base_link
LOAD_TRANSFER = '/load_transfer'
STATES = '/observer/states'
DIAGNOSTICS = '/diagnostics'
LPA = ('/lpa/left', '/lpa/right')

# The whole vehicle (INTERFACES.md "The whole vehicle", vehicle.model: articulated). The
# front axle's topics above keep their meaning there (the front axle's wheels).
#: The units of the combination, in the order of the per-unit topics.
UNITS = ('tractor', 'trailer', 'combination')
TRACTOR_ROLL_JOINT = 'tractor_roll'
TRAILER_ROLL_JOINT = 'trailer_roll'


def axle_deflection_joints(axle: str) -> tuple[str, str]:
    """``<axle>_left_suspension``, ``<axle>_right_suspension``."""
    return f'{axle}_left_suspension', f'{axle}_right_suspension'


def articulated_deflection_joints(instrumented_axles, trailer_roll: bool) -> tuple[str, ...]:
    """The names of an articulated truck's ``/suspension/deflections``: both sides of every
    instrumented axle (front first), then ``tractor_roll`` and, where fitted,
    ``trailer_roll``."""
    names = [n for axle in instrumented_axles for n in axle_deflection_joints(axle)]
    return tuple(names + [TRACTOR_ROLL_JOINT] + ([TRAILER_ROLL_JOINT] if trailer_roll else []))


def wheel_joints(axles) -> tuple[str, ...]:
    """``<axle>_left_wheel``, ``<axle>_right_wheel`` for every axle (``/wheel_loads``)."""
    return tuple(f'{a}_{side}_wheel' for a in axles for side in SIDES)


#: JointState, ``effort`` = vertical load per wheel (N): estimated, true, static.
WHEEL_LOADS = '/wheel_loads'
TRUE_WHEEL_LOADS = '/ground_truth/wheel_loads'
STATIC_WHEEL_LOADS = '/wheel_loads/static'
#: Vector3Stamped per unit (tractor, trailer, combination): x = LTR, y = quasi-static LTR.
UNIT_LOAD_TRANSFER = tuple(f'/load_transfer/{u}' for u in UNITS)
#: The units' true load transfer in one JointState per sample (plant simulator; not in
#: INTERFACES.md, added with the articulated plant: one message, not three, for the node's
#: CPU): ``name`` = UNITS, ``position`` = LTR, ``velocity`` = quasi-static LTR.
TRUE_LOAD_TRANSFER_RATIOS = '/ground_truth/load_transfer_ratios'
#: The tractor's IMU (sensor_msgs/Imu, frame base_link, at the tractor's centre of gravity).
IMU = '/imu/tractor'
IMU_FRAME = BASE_FRAME
#: The package's node that reads each input topic: what a publisher waits for at the start of
#: a drive (``plant_simulator``'s ``start_nodes``, ``bag_player``'s ``--wait-for``).
READERS = {DEFLECTIONS: 'observer', TWIST: 'observer', LPA[0]: 'plant_simulator',
           LPA[1]: 'plant_simulator'}
#: ``/diagnostics`` key prefix of a publisher's first stamp on a topic: ``first_stamp_ns:`` +
#: the topic, the value integer ns (plant_simulator, bag_player; read by the observer).
FIRST_STAMP_KEY = 'first_stamp_ns:'

# Message types, as rosbag2 and rosbags spell them.
JOINT_STATE = 'sensor_msgs/msg/JointState'
POINT = 'geometry_msgs/msg/PointStamped'
WRENCH = 'geometry_msgs/msg/WrenchStamped'
TWIST_STAMPED = 'geometry_msgs/msg/TwistStamped'
FLOAT64 = 'std_msgs/msg/Float64'
VECTOR3_STAMPED = 'geometry_msgs/msg/Vector3Stamped'
NAVSATFIX = 'sensor_msgs/msg/NavSatFix'
DIAGNOSTIC_ARRAY = 'diagnostic_msgs/msg/DiagnosticArray'
IMU_MSG = 'sensor_msgs/msg/Imu'

#: Every topic of INTERFACES.md and its message type.
TOPIC_TYPES: dict[str, str] = {
    DEFLECTIONS: JOINT_STATE,
    TWIST: TWIST_STAMPED,
    **{topic: WRENCH for topic in TRUE_LOAD},
    **{topic: POINT for topic in TRUE_ROAD},
    **{topic: WRENCH for topic in LOAD},
    **{topic: WRENCH for topic in STATIC_LOAD},
    **{topic: POINT for topic in ROAD},
    LTR: FLOAT64,
    LOAD_TRANSFER: VECTOR3_STAMPED,
    STATES: JOINT_STATE,
    DIAGNOSTICS: DIAGNOSTIC_ARRAY,
    FIX: NAVSATFIX,
    **{topic: POINT for topic in LPA},
    WHEEL_LOADS: JOINT_STATE,
    TRUE_WHEEL_LOADS: JOINT_STATE,
    STATIC_WHEEL_LOADS: JOINT_STATE,
    **{topic: VECTOR3_STAMPED for topic in UNIT_LOAD_TRANSFER},
    TRUE_LOAD_TRANSFER_RATIOS: JOINT_STATE,
    **{topic: POINT for topic in ROAD_FUSED},
    IMU: IMU_MSG,
}

# QoS kinds: "Sensor streams use the sensor-data QoS (best effort, keep last); ground truth
# and estimates are reliable."
SENSOR_DATA = 'sensor_data'
RELIABLE = 'reliable'
#: The QoS kind of every topic: the sensor streams (what the truck's sensors publish) are
#: sensor data, everything else reliable.
TOPIC_QOS: dict[str, str] = {
    topic: SENSOR_DATA if topic in (DEFLECTIONS, TWIST, FIX, IMU) else RELIABLE
    for topic in TOPIC_TYPES
}


def static_load_due(stamp_ns: int, last_stamp_ns: int | None) -> bool:
    """Whether the estimate at ``stamp_ns`` publishes the static loads, after the last one
    that did at ``last_stamp_ns`` (None: none yet): a new :data:`STATIC_LOAD_PERIOD_NS`."""
    return last_stamp_ns is None or (stamp_ns // STATIC_LOAD_PERIOD_NS
                                     != last_stamp_ns // STATIC_LOAD_PERIOD_NS)


def qos_kind(topic: str) -> str:
    """The QoS kind of ``topic``: :data:`SENSOR_DATA` or :data:`RELIABLE` (topics not listed
    in INTERFACES.md are reliable)."""
    return TOPIC_QOS.get(topic, RELIABLE)
