"""Leg kinematics of the Unitree A1 (numpy, vectorized over any leading batch shape).

Each leg is hip abduction about the trunk x axis at :data:`~gaitlib.robots.a1.constants.HIP_OFFSETS`, then the
thigh joint about y offset sideways by :data:`~gaitlib.robots.a1.constants.THIGH_OFFSET_Y`, then the calf joint
about y one :data:`~gaitlib.robots.a1.constants.LINK_LENGTH` below it, and the foot (contact-sphere centre, the
MJCF site ``<leg>_foot``) one more link length below the calf joint. Positions are in the trunk frame (x forward,
y left, z up), m; angles in rad, in the joint order of :data:`~gaitlib.robots.a1.constants.JOINT_NAMES`.
"""

from __future__ import annotations

import numpy as np

from gaitlib.errors import UnknownNameError
from gaitlib.robots.a1.constants import HIP_OFFSETS, LEG_NAMES, LINK_LENGTH, NUM_LEGS, THIGH_OFFSET_Y

__all__ = ["forward_kinematics", "inverse_kinematics", "leg_forward_kinematics", "leg_inverse_kinematics"]

_HIPS = np.asarray(HIP_OFFSETS, dtype=np.float64)  # (4, 3)
_THIGH_Y = np.asarray(THIGH_OFFSET_Y, dtype=np.float64)  # (4,)


def _leg_index(leg: str) -> int:
    if leg not in LEG_NAMES:
        raise UnknownNameError("leg", leg, list(LEG_NAMES))
    return LEG_NAMES.index(leg)


def _fk(angles: np.ndarray, hip: np.ndarray, thigh_y: np.ndarray) -> np.ndarray:
    """Foot positions (..., 3) for leg angles (..., 3), hip offsets (..., 3) and thigh offsets (...)."""
    q0, q1, q2 = angles[..., 0], angles[..., 1], angles[..., 2]
    # Leg vector in the abducted hip frame: thigh and calf rotate about y, the thigh joint sits thigh_y sideways.
    px = -LINK_LENGTH * (np.sin(q1) + np.sin(q1 + q2))
    pz = -LINK_LENGTH * (np.cos(q1) + np.cos(q1 + q2))
    c0, s0 = np.cos(q0), np.sin(q0)
    return hip + np.stack([px, c0 * thigh_y - s0 * pz, s0 * thigh_y + c0 * pz], axis=-1)


def _ik(foot: np.ndarray, hip: np.ndarray, thigh_y: np.ndarray) -> np.ndarray:
    """Leg angles (..., 3) putting the feet at ``foot`` (..., 3); knee-backward branch, calf in [-pi, 0]."""
    x, y, z = np.moveaxis(foot - hip, -1, 0)
    # Abduction: (y, z) is (thigh_y, pz) rotated by q0 about x, with the foot below the hip (pz <= 0).
    pz = -np.sqrt(np.maximum(y * y + z * z - thigh_y * thigh_y, 0.0))
    q0 = np.arctan2(z, y) - np.arctan2(pz, thigh_y)
    q0 = (q0 + np.pi) % (2.0 * np.pi) - np.pi
    # Sagittal plane: |(x, pz)| = 2 l cos(q2 / 2) and its direction is q1 + q2 / 2 from straight down.
    cos_q2 = (x * x + pz * pz) / (2.0 * LINK_LENGTH**2) - 1.0
    q2 = -np.arccos(np.clip(cos_q2, -1.0, 1.0))
    q1 = np.arctan2(-x, -pz) - 0.5 * q2
    return np.stack([q0, q1, q2], axis=-1)


def leg_forward_kinematics(leg_angles: np.ndarray, *, leg: str) -> np.ndarray:
    """Foot position of one leg in the trunk frame.

    Args:
        leg_angles: (..., 3) hip abduction, thigh and calf angles, rad.
        leg: leg name, one of :data:`~gaitlib.robots.a1.constants.LEG_NAMES`.

    Returns:
        (..., 3) foot contact-sphere centre in the trunk frame, m.
    """
    i = _leg_index(leg)
    return _fk(np.asarray(leg_angles, dtype=np.float64), _HIPS[i], _THIGH_Y[i])


def leg_inverse_kinematics(foot_pos: np.ndarray, *, leg: str) -> np.ndarray:
    """Leg angles that put one foot at ``foot_pos`` (analytic; knee-backward branch).

    The foot is taken to be below the hip in the abducted leg plane (true of every standing and walking pose).
    For a target the A1 reaches within its joint limits the result is the solution with the calf angle in
    :data:`~gaitlib.robots.a1.constants.CALF_LIMITS`. Targets beyond reach give the fully stretched leg pointing
    at them (callers check with :func:`leg_forward_kinematics` when reach is in doubt).

    Args:
        foot_pos: (..., 3) foot contact-sphere centre in the trunk frame, m.
        leg: leg name, one of :data:`~gaitlib.robots.a1.constants.LEG_NAMES`.

    Returns:
        (..., 3) hip abduction in (-pi, pi], thigh, and calf in [-pi, 0], rad.
    """
    i = _leg_index(leg)
    return _ik(np.asarray(foot_pos, dtype=np.float64), _HIPS[i], _THIGH_Y[i])


def forward_kinematics(joint_pos: np.ndarray) -> np.ndarray:
    """Foot positions of all four legs in the trunk frame.

    Args:
        joint_pos: (..., 12) joint angles in :data:`~gaitlib.robots.a1.constants.JOINT_NAMES` order, rad.

    Returns:
        (..., 4, 3) foot contact-sphere centres in leg order FR, FL, RR, RL, trunk frame, m.
    """
    angles = np.asarray(joint_pos, dtype=np.float64)
    angles = angles.reshape(*angles.shape[:-1], NUM_LEGS, 3)
    return _fk(angles, _HIPS, _THIGH_Y)


def inverse_kinematics(foot_pos: np.ndarray) -> np.ndarray:
    """Joint angles that put all four feet at ``foot_pos`` (see :func:`leg_inverse_kinematics`).

    Args:
        foot_pos: (..., 4, 3) foot contact-sphere centres in leg order, trunk frame, m.

    Returns:
        (..., 12) joint angles in :data:`~gaitlib.robots.a1.constants.JOINT_NAMES` order, rad.
    """
    angles = _ik(np.asarray(foot_pos, dtype=np.float64), _HIPS, _THIGH_Y)
    return angles.reshape(*angles.shape[:-2], NUM_LEGS * 3)
