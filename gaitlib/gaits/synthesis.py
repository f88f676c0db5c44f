"""From a gait description to a reference clip: foot trajectories planned in the trunk frame, then leg IK.

The trunk moves at ``forward_speed`` along x with level orientation, at ``body_height`` or rising and falling
about it (:func:`trunk_height`), straight or swaying (:func:`trunk_sway`). Each foot has a neutral
point below its thigh joint (hip x, hip y plus thigh offset, shifted outward by ``foot_lateral_offset``) on the
ground. Leg phase ``psi = (phase - phase_offset) mod 1``:

* stance, ``psi < duty_factor``: the foot stays still in the world, so in the trunk frame it slides backward at
  the forward speed, from ``+d/2`` to ``-d/2`` about the neutral point, where ``d = duty_factor * stride_length``;
* swing: with swing progress ``s`` in [0, 1), the foot moves forward one stride length in the world along a
  cycloid, ``stride_length * (s - sin(2 pi s) / (2 pi))`` (zero velocity at lift-off and touchdown), and lifts by
  ``swing_height * (1 - cos(2 pi s)) / 2`` (apex at mid-swing, zero vertical velocity at both ends).

Foot positions are contact-sphere centres; a foot on the ground has its centre one foot radius above it.
"""

from __future__ import annotations

import functools

import numpy as np

from gaitlib.errors import GaitError
from gaitlib.gaits.clip import ReferenceClip
from gaitlib.gaits.description import GaitDescription
from gaitlib.gaits.kinematics import forward_kinematics, inverse_kinematics
from gaitlib.robots.a1.constants import FOOT_RADIUS, HIP_OFFSETS, JOINT_LOWER, JOINT_UPPER, THIGH_OFFSET_Y

__all__ = ["clip_from_description", "contact_schedule", "foot_trajectory", "trunk_height", "trunk_sway"]

_REACH_TOLERANCE = 1e-6  # m: IK solutions whose feet miss their targets by more than this are out of reach
_GRAVITY = 9.81  # m/s^2: MuJoCo's default gravity, which the A1 model keeps
_SWAY_SAMPLES = 512  # points per cycle at which the sway's periodic boundary problem is solved
_CELL_SAMPLES = 8  # contact samples averaged over each of those points' cells
_BOUNCE_SAMPLES = 512  # points per cycle at which the trunk's vertical motion is integrated


def _leg_phase(desc: GaitDescription, phase: np.ndarray) -> np.ndarray:
    """(..., 4) position of each leg in its own cycle, starting at touchdown, cycles in [0, 1)."""
    return np.mod(np.asarray(phase, dtype=np.float64)[..., None] - np.asarray(desc.phase_offsets), 1.0)


def contact_schedule(desc: GaitDescription, phase: np.ndarray) -> np.ndarray:
    """Planned foot contacts.

    Args:
        desc: the gait.
        phase: (...) gait phase, cycles.

    Returns:
        (..., 4) bool, leg order FR, FL, RR, RL: the foot is in stance.
    """
    return _leg_phase(desc, phase) < desc.duty_factor


def _neutral_feet(desc: GaitDescription) -> np.ndarray:
    """(4, 3) neutral foot points in the trunk frame at z = 0, m (see the module docstring)."""
    thigh_y = np.asarray(THIGH_OFFSET_Y)
    offset = np.stack([np.zeros(4), thigh_y + np.sign(thigh_y) * desc.foot_lateral_offset, np.zeros(4)], axis=-1)
    return np.asarray(HIP_OFFSETS) + offset


def trunk_sway(desc: GaitDescription, phase: np.ndarray) -> np.ndarray:
    """Sideways trunk offset from the straight path, zero unless ``desc.trunk_sway``.

    The trunk is a linear inverted pendulum of height ``body_height`` (Kajita et al. 2001, "The 3D linear inverted
    pendulum mode", IROS) whose zero-moment point ``p`` lies under the stance feet's neutral points:
    ``y'' = (g / body_height) (y - p)`` while a foot is down, ``y'' = 0`` in flight. Its periodic solution over one
    cycle (second differences on a 512-point grid, one linear solve) is the sway: the trunk swings toward the feet
    that bear it, is pushed back toward the other side and is caught by its feet. ``p`` is where the stance feet's
    line runs at the trunk's x (two feet), else their mean lateral position. A pace, whose support line lies
    0.13 m to one side for most of each half cycle, sways 4.4 cm each way; a trot's diagonal line crosses under
    the trunk only at mid-stance and runs up to 11 cm to one side at touchdown and the other at lift-off, so its
    trunk sways 1.4 cm; a pronk, a bound and a stand, whose feet are centred under the trunk, do not sway.

    Args:
        desc: the gait.
        phase: (...) gait phase, cycles.

    Returns:
        (...) offset along the trunk's y axis (to the left), m.
    """
    phase = np.asarray(phase, dtype=np.float64)
    if not desc.trunk_sway:
        return np.zeros_like(phase)
    sway = _sway_cycle(desc)
    grid = np.arange(_SWAY_SAMPLES + 1) / _SWAY_SAMPLES
    return np.interp(np.mod(phase, 1.0), grid, np.append(sway, sway[0]))


@functools.lru_cache(maxsize=32)
def _sway_cycle(desc: GaitDescription) -> np.ndarray:
    """(512,) read-only sway at phases 0, 1/512, ..., m: the periodic pendulum solved once per gait (a clip asks for
    it for its feet and for its trunk)."""
    grid = np.arange(_SWAY_SAMPLES) / _SWAY_SAMPLES
    # Each grid point averages the pendulum over its own cell, so a touchdown between points is not moved onto one.
    cell = grid[:, None] + (np.arange(_CELL_SAMPLES) + 0.5) / (_CELL_SAMPLES * _SWAY_SAMPLES) - 0.5 / _SWAY_SAMPLES
    stance = contact_schedule(desc, cell)  # (points, cell samples, legs)
    centre = _support_centre(desc, cell, stance)
    omega_sq = np.where(stance.any(-1), _GRAVITY / desc.body_height, 0.0)  # 1/s^2; 0 in flight
    stiffness, pull = omega_sq.mean(-1), (omega_sq * centre).mean(-1)  # 1/s^2, m/s^2
    step = desc.period / _SWAY_SAMPLES
    second_difference = (
        np.roll(np.eye(_SWAY_SAMPLES), 1, axis=1)
        + np.roll(np.eye(_SWAY_SAMPLES), -1, axis=1)
        - 2.0 * np.eye(_SWAY_SAMPLES)
    ) / step**2
    sway = np.linalg.solve(second_difference - np.diag(stiffness), -pull)
    sway.setflags(write=False)
    return sway


def trunk_height(desc: GaitDescription, phase: np.ndarray) -> np.ndarray:
    """Height of the trunk-frame origin above the ground, ``body_height`` unless ``desc.trunk_bounce``.

    With the bounce, the trunk moves as a point mass under gravity and the ground's vertical push: each stance foot
    pushes with a half-sine over its stance (the force of a spring-mass leg, Blickhan 1989, "The spring-mass model
    for running and hopping", J. Biomech. 22), all pushes scaled so that over a cycle they carry the weight (the
    impulse rule of Park, Wensing and Kim 2017, "High-speed bounding with the MIT Cheetah 2", IJRR 36(2)). The
    acceleration ``g (push / mean push - 1)`` integrated twice over the cycle (its periodic solution, by Fourier
    series on a 512-point grid), about a mean height of ``body_height``, is the bounce: in flight the trunk falls
    freely; in stance it is caught and thrown up again. Around its 156 ms flights a pronk's trunk moves 5.9 cm from
    lowest to highest; a stand, whose feet never lift and carry the weight evenly, does not move.

    Args:
        desc: the gait.
        phase: (...) gait phase, cycles.

    Returns:
        (...) height, m.
    """
    phase = np.asarray(phase, dtype=np.float64)
    if not desc.trunk_bounce or desc.duty_factor == 1.0:  # feet that never lift push evenly
        return np.full_like(phase, desc.body_height)
    bounce = _bounce_cycle(desc)
    grid = np.arange(_BOUNCE_SAMPLES + 1) / _BOUNCE_SAMPLES
    return desc.body_height + np.interp(np.mod(phase, 1.0), grid, np.append(bounce, bounce[0]))


@functools.lru_cache(maxsize=32)
def _bounce_cycle(desc: GaitDescription) -> np.ndarray:
    """(512,) read-only height about ``body_height`` at phases 0, 1/512, ..., m (see :func:`trunk_height`)."""
    psi = _leg_phase(desc, np.arange(_BOUNCE_SAMPLES) / _BOUNCE_SAMPLES)
    push = np.where(psi < desc.duty_factor, np.sin(np.pi * psi / desc.duty_factor), 0.0).sum(-1)
    accel = _GRAVITY * (push / push.mean() - 1.0)  # m/s^2, zero on average: the feet carry the weight
    spectrum = np.fft.rfft(accel)
    omega = 2.0 * np.pi * np.arange(len(spectrum)) / desc.period  # rad/s of each harmonic
    height = np.zeros_like(spectrum)
    height[1:] = -spectrum[1:] / omega[1:] ** 2  # z'' = a, harmonic by harmonic; the mean (harmonic 0) is 0
    bounce = np.fft.irfft(height, n=_BOUNCE_SAMPLES)
    bounce.setflags(write=False)
    return bounce


def _support_centre(desc: GaitDescription, phase: np.ndarray, stance: np.ndarray) -> np.ndarray:
    """(...) lateral point under the trunk the pendulum is balanced over, m: where the line between two stance feet
    runs at the trunk's x (a diagonal pair's line crosses under the trunk only at mid-stance; the trot's lies up to
    11 cm to one side at touchdown and to the other at lift-off), else the mean of the stance feet's neutral y
    (one, three or four feet; two whose line runs sideways under the trunk; 0 in flight)."""
    feet_x, feet_y = _stance_x(desc, phase), _neutral_feet(desc)[:, 1]
    count = stance.sum(-1)
    centre = (stance * feet_y).sum(-1) / np.maximum(count, 1)
    rank = np.cumsum(stance, axis=-1) * stance  # 1 at the first stance foot, 2 at the second, 0 at the others
    first_x, second_x = (np.where(rank == k, feet_x, 0.0).sum(-1) for k in (1, 2))
    first_y, second_y = (np.where(rank == k, feet_y, 0.0).sum(-1) for k in (1, 2))
    span = second_x - first_x
    line = (count == 2) & (np.abs(span) > 1e-9)
    along = np.clip(-first_x / np.where(line, span, 1.0), 0.0, 1.0)  # where x = 0 lies between the two feet
    return np.where(line, first_y + along * (second_y - first_y), centre)


def _stance_x(desc: GaitDescription, phase: np.ndarray) -> np.ndarray:
    """(..., 4) trunk-frame x of each foot over its stance stroke (from ``+d/2`` to ``-d/2`` about its neutral
    point; the values at swinging legs are not used), m."""
    psi = _leg_phase(desc, phase)
    return _neutral_feet(desc)[:, 0] + desc.duty_factor * desc.stride_length * (0.5 - psi / desc.duty_factor)


def foot_trajectory(desc: GaitDescription, phase: np.ndarray) -> np.ndarray:
    """Planned foot positions in the trunk frame (see the module docstring for the trajectories).

    Args:
        desc: the gait.
        phase: (...) gait phase, cycles.

    Returns:
        (..., 4, 3) foot contact-sphere centres, leg order FR, FL, RR, RL, trunk frame, m.
    """
    psi = _leg_phase(desc, phase)
    duty = desc.duty_factor
    stride = desc.stride_length
    stance_travel = duty * stride
    in_stance = psi < duty
    swing_fraction = 1.0 - duty
    s = np.clip((psi - duty) / swing_fraction, 0.0, 1.0) if swing_fraction > 0.0 else np.zeros_like(psi)
    angle = 2.0 * np.pi * s
    # World-frame cycloid minus the trunk's own advance during the swing, from the back of the stance stroke.
    swing_x = -0.5 * stance_travel + stride * (s - np.sin(angle) / (2.0 * np.pi)) - swing_fraction * stride * s
    lift = desc.swing_height * 0.5 * (1.0 - np.cos(angle))

    neutral = _neutral_feet(desc)
    x = np.where(in_stance, _stance_x(desc, phase), neutral[:, 0] + swing_x)
    y = neutral[:, 1] - trunk_sway(desc, phase)[..., None]
    z = FOOT_RADIUS - trunk_height(desc, phase)[..., None] + np.where(in_stance, 0.0, lift)
    return np.stack([x, y, z], axis=-1)


def clip_from_description(desc: GaitDescription, *, frame_rate: float = 500.0) -> ReferenceClip:
    """One looping cycle of ``desc`` as a reference clip, through the A1's leg inverse kinematics.

    The cycle is stored at about ``frame_rate`` frames per second (rounded to a whole number of frames per
    cycle, at least 16); the trunk starts at x = 0 and advances one stride length per cycle.

    Raises:
        GaitError: a foot target is out of the leg's reach or needs a joint beyond its limits (e.g. the body
            height or stride is too large).
    """
    intervals = max(16, round(desc.period * frame_rate))
    phase = np.arange(intervals + 1) / intervals
    feet = foot_trajectory(desc, phase)
    feet[-1] = feet[0]  # the last frame closes the loop exactly
    joint_pos = inverse_kinematics(feet)
    miss = np.abs(forward_kinematics(joint_pos) - feet).max()
    if miss > _REACH_TOLERANCE:
        raise GaitError(f"gait '{desc.name}': a foot target is {miss:.3f} m out of the A1's reach")
    outside = (joint_pos < np.asarray(JOINT_LOWER)) | (joint_pos > np.asarray(JOINT_UPPER))
    if outside.any():
        raise GaitError(f"gait '{desc.name}': the foot trajectories need joint angles beyond the A1's limits")
    root_pos = np.zeros((intervals + 1, 3))
    root_pos[:, 0] = desc.stride_length * phase
    root_pos[:, 1] = trunk_sway(desc, phase)
    root_pos[:, 2] = trunk_height(desc, phase)
    root_quat = np.zeros((intervals + 1, 4))
    root_quat[:, 0] = 1.0
    return ReferenceClip.from_frames(
        name=desc.name,
        frame_duration=desc.period / intervals,
        loop=True,
        root_pos=root_pos,
        root_quat=root_quat,
        joint_pos=joint_pos,
        contact=contact_schedule(desc, phase),
        cycle_displacement=np.array([desc.stride_length, 0.0, 0.0]),
    )
