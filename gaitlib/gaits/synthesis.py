"""From a gait description to a reference clip: foot trajectories planned in the trunk frame, then leg IK.

The trunk moves with level orientation at the constant velocity ``v = (forward_speed, lateral_speed)`` in its
own frame while turning at ``yaw_rate`` ``w`` (a straight line, or a circle of radius ``|v| / |w|``), at
``body_height`` or rising and falling about it (:func:`trunk_height`), straight or swaying (:func:`trunk_sway`).
Each foot has a neutral point below its thigh joint (hip x, hip y plus thigh offset, shifted outward by
``foot_lateral_offset``) on the ground. Leg phase ``psi = (phase - phase_offset) mod 1``:

* stance, ``psi < duty_factor``: the foot stays still in the world, so in the trunk frame it moves with velocity
  ``-(v + w x p)``: without a yaw rate it slides straight back, from ``+D/2`` to ``-D/2`` about the neutral point,
  where ``D = duty_factor * v / stride_frequency``; with one it turns about the trunk's instantaneous centre of
  rotation ``(-v_y, v_x) / w``. The stroke is centred in time on the neutral point (the foot passes it at
  mid-stance), so its touchdown and lift-off points lie symmetrically about it (Raibert 1986, "Legged Robots That
  Balance", MIT Press: the neutral point placement);
* swing: with swing progress ``s`` in [0, 1), the foot moves in the world along a straight line from its lift-off
  to its next touchdown point by the cycloid ``s - sin(2 pi s) / (2 pi)`` of the way (zero velocity at lift-off and
  touchdown; one stride ``v / stride_frequency`` without a yaw rate), and lifts by
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
from gaitlib.rotations import quat_from_yaw

__all__ = ["clip_from_description", "contact_schedule", "foot_trajectory", "trunk_height", "trunk_sway"]

_CROSSING_MARGIN = 0.02  # m, a foot's radius: how near a foot may come to the trunk midline or the other leg's hip
# of its side (choice)
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
    feet = _stance_feet(desc, phase)
    feet_x, feet_y = feet[..., 0], feet[..., 1]
    count = stance.sum(-1)
    centre = (stance * feet_y).sum(-1) / np.maximum(count, 1)
    rank = np.cumsum(stance, axis=-1) * stance  # 1 at the first stance foot, 2 at the second, 0 at the others
    first_x, second_x = (np.where(rank == k, feet_x, 0.0).sum(-1) for k in (1, 2))
    first_y, second_y = (np.where(rank == k, feet_y, 0.0).sum(-1) for k in (1, 2))
    span = second_x - first_x
    line = (count == 2) & (np.abs(span) > 1e-9)
    along = np.clip(-first_x / np.where(line, span, 1.0), 0.0, 1.0)  # where x = 0 lies between the two feet
    return np.where(line, first_y + along * (second_y - first_y), centre)


def _stance_feet(desc: GaitDescription, phase: np.ndarray) -> np.ndarray:
    """(..., 4, 2) trunk-frame x and y of each foot over its stance stroke (the values at swinging legs are not
    used), m."""
    return _neutral_feet(desc)[:, :2] + _stroke(desc, _leg_phase(desc, phase))


def _step(desc: GaitDescription) -> np.ndarray:
    """(2,) trunk displacement per cycle along its own x and y of a gait without yaw rate, m."""
    return np.array([desc.forward_speed, desc.lateral_speed]) / desc.stride_frequency


def _stroke(desc: GaitDescription, psi: np.ndarray) -> np.ndarray:
    """(..., 4, 2) stance foot offset from its neutral point at leg phases ``psi`` (..., 4) in [0, duty), trunk
    frame, m: a straight stroke from ``+D/2`` to ``-D/2``, or, with a yaw rate, the arc about the centre of rotation
    that passes the neutral point at mid-stance (see the module docstring)."""
    duty = desc.duty_factor
    if desc.yaw_rate == 0.0:
        return duty * _step(desc) * (0.5 - psi / duty)[..., None]
    w = desc.yaw_rate
    centre = np.array([-desc.lateral_speed, desc.forward_speed]) / w
    arm = _neutral_feet(desc)[:, :2] - centre  # (4, 2) from the centre of rotation to each neutral point
    return _rotate(arm, -w * (psi - 0.5 * duty) * desc.period) - arm


def _rotate(vectors: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """(..., 2) ``vectors`` turned by ``angle`` (...) rad, counter-clockwise."""
    cos, sin = np.cos(angle), np.sin(angle)
    x, y = vectors[..., 0], vectors[..., 1]
    return np.stack([cos * x - sin * y, sin * x + cos * y], axis=-1)


def _trunk_path(desc: GaitDescription, time: np.ndarray) -> np.ndarray:
    """(..., 2) where the trunk of a gait with a yaw rate is after ``time`` (...) s, in the ground frame it started
    in, m (without sway): an arc of the circle about its centre of rotation."""
    w, v = desc.yaw_rate, np.array([desc.forward_speed, desc.lateral_speed])
    angle = w * np.asarray(time)
    sin, one_minus_cos = np.sin(angle) / w, (1.0 - np.cos(angle)) / w
    return np.stack([sin * v[0] - one_minus_cos * v[1], one_minus_cos * v[0] + sin * v[1]], axis=-1)


def _swing(desc: GaitDescription, s: np.ndarray) -> np.ndarray:
    """(..., 4, 2) swinging foot offset from its neutral point at swing progress ``s`` (..., 4) in [0, 1], trunk
    frame, m: from the lift-off to the touchdown point along a cycloid in the world (see the module docstring)."""
    duty, swing_fraction = desc.duty_factor, 1.0 - desc.duty_factor
    cycloid = (s - np.sin(2.0 * np.pi * s) / (2.0 * np.pi))[..., None]
    if desc.yaw_rate == 0.0:  # world-frame cycloid minus the trunk's own advance, from the back of the stroke
        step = _step(desc)
        return -0.5 * (duty * step) + step * cycloid - swing_fraction * step * s[..., None]
    lift_off, touchdown = _stroke(desc, np.full(4, duty)), _stroke(desc, np.zeros(4))
    neutral = _neutral_feet(desc)[:, :2]
    # In the trunk frame at lift-off: where the foot lands, and where the trunk is (and how turned) meanwhile.
    swing_time = swing_fraction * desc.period
    landing = _trunk_path(desc, swing_time) + _rotate(neutral + touchdown, desc.yaw_rate * swing_time)
    foot = neutral + lift_off + (landing - neutral - lift_off) * cycloid
    elapsed = s * swing_time
    return _rotate(foot - _trunk_path(desc, elapsed), -desc.yaw_rate * elapsed) - neutral


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
    in_stance = psi < duty
    swing_fraction = 1.0 - duty
    s = np.clip((psi - duty) / swing_fraction, 0.0, 1.0) if swing_fraction > 0.0 else np.zeros_like(psi)
    lift = desc.swing_height * 0.5 * (1.0 - np.cos(2.0 * np.pi * s))

    neutral = _neutral_feet(desc)
    offset = np.where(in_stance[..., None], _stroke(desc, psi), _swing(desc, s))
    x = neutral[:, 0] + offset[..., 0]
    y = neutral[:, 1] + offset[..., 1] - trunk_sway(desc, phase)[..., None]
    z = FOOT_RADIUS - trunk_height(desc, phase)[..., None] + np.where(in_stance, 0.0, lift)
    return np.stack([x, y, z], axis=-1)


def clip_from_description(desc: GaitDescription, *, frame_rate: float = 500.0) -> ReferenceClip:
    """One looping cycle of ``desc`` as a reference clip, through the A1's leg inverse kinematics.

    The cycle is stored at about ``frame_rate`` frames per second (rounded to a whole number of frames per
    cycle, at least 16); the trunk starts at x = 0 facing x, advances one stride per cycle and turns by the
    description's :attr:`~gaitlib.gaits.GaitDescription.cycle_yaw`.

    Raises:
        GaitError: a foot target is out of the leg's reach or needs a joint beyond its limits (e.g. the body
            height, stride or turn is too large), or a foot crosses under the trunk into another leg's room
            (the trunk midline, or the other foot of its side fore and aft).
    """
    intervals = max(16, round(desc.period * frame_rate))
    phase = np.arange(intervals + 1) / intervals
    feet = foot_trajectory(desc, phase)
    feet[-1] = feet[0]  # the last frame closes the loop exactly
    _check_feet_apart(desc, feet)
    joint_pos = inverse_kinematics(feet)
    miss = np.abs(forward_kinematics(joint_pos) - feet).max()
    if miss > _REACH_TOLERANCE:
        raise GaitError(f"gait '{desc.name}': a foot target is {miss:.3f} m out of the A1's reach")
    outside = (joint_pos < np.asarray(JOINT_LOWER)) | (joint_pos > np.asarray(JOINT_UPPER))
    if outside.any():
        raise GaitError(f"gait '{desc.name}': the foot trajectories need joint angles beyond the A1's limits")
    root_pos = np.zeros((intervals + 1, 3))
    if desc.yaw_rate == 0.0:
        root_pos[:, 0] = desc.stride_length * phase
        root_pos[:, 1] = desc.lateral_speed / desc.stride_frequency * phase + trunk_sway(desc, phase)
    else:  # the sway is along the turning trunk's own y axis
        yaw, sway = desc.cycle_yaw * phase, trunk_sway(desc, phase)
        left = np.stack([-np.sin(yaw), np.cos(yaw)], axis=-1)  # the trunk's y axis on the ground
        root_pos[:, :2] = _trunk_path(desc, phase * desc.period) + left * sway[:, None]
    root_pos[:, 2] = trunk_height(desc, phase)
    root_quat = quat_from_yaw(desc.cycle_yaw * phase)
    return ReferenceClip.from_frames(
        name=desc.name,
        frame_duration=desc.period / intervals,
        loop=True,
        root_pos=root_pos,
        root_quat=root_quat,
        joint_pos=joint_pos,
        contact=contact_schedule(desc, phase),
        cycle_displacement=np.append(root_pos[-1, :2] - root_pos[0, :2], 0.0),
        cycle_yaw=desc.cycle_yaw,
    )


def _check_feet_apart(desc: GaitDescription, feet: np.ndarray) -> None:
    """Refuse planned feet (frames, 4, 3) in the trunk frame that cross the trunk midline, or reach fore or aft
    past the hip of the other leg of their side, with :data:`_CROSSING_MARGIN` to spare: a turn or sidestep too
    fast for its stride sweeps a foot into another leg's room (the legs would collide; the IK alone does not see
    it). A fast trot's front and hind feet of a side pass close by each other as the hind foot lands where the
    front one lifted, as an animal's do (the shipped trot's come within 1.5 cm), so that is not refused."""
    hips = np.asarray(HIP_OFFSETS)
    side = np.sign(np.asarray(THIGH_OFFSET_Y))  # +1 left legs, -1 right legs
    inward = (side * feet[..., 1]).min()
    if inward < _CROSSING_MARGIN:
        raise GaitError(
            f"gait '{desc.name}': a foot comes {_CROSSING_MARGIN - inward:.3f} m too near or past the trunk midline "
            "(its feet cannot carry this turn or sidestep at this stride: slow it, or step more often)"
        )
    ahead = np.sign(hips[:, 0])  # +1 front legs, -1 rear legs
    reach = (ahead * feet[..., 0]).min() + hips[:, 0].max()  # how far the nearest foot stays short of the other hip
    if reach < _CROSSING_MARGIN:
        raise GaitError(
            f"gait '{desc.name}': a foot reaches {_CROSSING_MARGIN - reach:.3f} m too near or past the hip of the "
            "other leg of its side (its feet cannot carry this motion at this stride: slow it, or step more often)"
        )
