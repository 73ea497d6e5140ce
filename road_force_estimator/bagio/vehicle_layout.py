"""Which deflection joints a front-axle reader takes from a drive bag: the front axle's, also
in an articulated drive (INTERFACES.md "The whole vehicle": a front-axle tool reads an
articulated drive).

A front-axle drive names ``left_suspension``, ``right_suspension``, ``roll``. An articulated
one names ``<axle>_left_suspension``, ``<axle>_right_suspension`` for every instrumented axle,
``tractor_roll`` and ``trailer_roll``: a front-axle tool then reads the front axle's two
deflections and the tractor's roll (the front axle of the 4-DOF model is the tractor's
front axle), named in the bag's ``custom_data`` by ``simulate_bag``; in a bag without it (a
recording of the nodes) the first axle of the message, which is the front axle whenever it
is instrumented (the contract lists the axles front first). An articulated drive whose front
axle has no deflection sensors is refused: a front-axle tool has nothing to read.
"""
from __future__ import annotations

from typing import Mapping, Sequence

from road_force_estimator.bagio.errors import BagReadError
from road_force_estimator.interfaces import DEFLECTION_JOINTS, TRACTOR_ROLL_JOINT

__all__ = ['MODEL_KEY', 'FRONT_JOINTS_KEY', 'STATIC_KEY', 'WHEELS_KEY', 'AXLES_KEY',
           'is_articulated', 'front_axle_joints']

#: custom_data keys of an articulated drive.
MODEL_KEY = 'road_force_estimator.vehicle_model'
FRONT_JOINTS_KEY = 'road_force_estimator.front_axle_joints'
STATIC_KEY = 'road_force_estimator.static_wheel_loads_n'
WHEELS_KEY = 'road_force_estimator.wheels'
AXLES_KEY = 'road_force_estimator.axle_bodies'
_LEFT = '_left_suspension'


def is_articulated(custom_data: Mapping[str, str]) -> bool:
    """A bag's ``custom_data`` says it is an articulated drive."""
    return custom_data.get(MODEL_KEY) == 'articulated'


def front_axle_joints(custom_data: Mapping[str, str],
                      names: Sequence[str] | None) -> tuple[tuple[str, str, str], str]:
    """The three joints a front-axle reader maps to (q_1, q_2, phi), and a note ('' for a
    front-axle drive) saying what was read.

    ``names``: the joint names of the bag's first ``/suspension/deflections`` (None if
    unknown).

    Raises
    ------
    BagReadError
        An articulated drive whose front axle has no deflection sensors.
    """
    names = tuple(names or ())
    if set(DEFLECTION_JOINTS) <= set(names):
        return DEFLECTION_JOINTS, ''
    if is_articulated(custom_data):
        joints = tuple(j for j in custom_data.get(FRONT_JOINTS_KEY, '').split(',') if j)
        if len(joints) != 3:
            raise BagReadError('an articulated drive whose front axle has no deflection '
                               'sensors: a front-axle tool has nothing to estimate '
                               '(vehicle.axle.<front>.instrumented is false)')
        return joints, _note(joints, len([n for n in names if n.endswith(_LEFT)]), '')
    if TRACTOR_ROLL_JOINT in names:
        left = [n for n in names if n.endswith(_LEFT)]
        if left:
            axle = left[0][:-len(_LEFT)]
            joints = (left[0], f'{axle}_right_suspension', TRACTOR_ROLL_JOINT)
            return joints, _note(joints, len(left), ' (the first axle of the message: the '
                                                    'front axle when it is instrumented)')
    return DEFLECTION_JOINTS, ''


def _note(joints, axles: int, how: str) -> str:
    return (f'an articulated drive ({axles} instrumented axles): the front axle estimated '
            f'from {", ".join(joints)}{how} with the front-axle model of the parameters '
            f'(its pitch coupling, beam axle and the other axles are not in that model)')
