"""Unitree A1 constants: the one place every other module takes the robot's numbers from.

Each number cites its source: ``facts`` is Unitree's public A1 description (the URDF in
github.com/unitreerobotics/unitree_ros, ``robots/a1_description``), as also used by MuJoCo Menagerie
(github.com/google-deepmind/mujoco_menagerie, ``unitree_a1``) and motion_imitation
(github.com/erwincoumans/motion_imitation); ``paper`` is Christmann et al., Table 1; ``choice`` is gaitlib's own,
with the reason beside it. Units are SI (m, kg, rad, N·m, s). Body frame: x forward, y left, z up.
"""

from __future__ import annotations

from pathlib import Path

__all__ = [
    "ABDUCTION_LIMITS",
    "CALF_LIMITS",
    "CONTROL_HZ",
    "DEFAULT_JOINT_POS",
    "FOOT_FRICTION",
    "FOOT_NAMES",
    "FOOT_RADIUS",
    "HIP_OFFSETS",
    "JOINT_LOWER",
    "JOINT_NAMES",
    "JOINT_UPPER",
    "KD_DEFAULT",
    "KD_RANGE",
    "KP_DEFAULT",
    "KP_RANGE",
    "LEG_NAMES",
    "LINK_LENGTH",
    "MIRROR_AXIAL",
    "MIRROR_JOINTS",
    "MIRROR_JOINT_SIGNS",
    "MIRROR_LEGS",
    "MIRROR_PART_SIGNS",
    "MIRROR_QUAT",
    "MIRROR_VECTOR",
    "MJCF_PATH",
    "NUM_JOINTS",
    "NUM_LEGS",
    "PHYSICS_DT",
    "STANDING_HEIGHT",
    "SUBSTEPS",
    "THIGH_LIMITS",
    "THIGH_OFFSET_Y",
    "TORQUE_LIMIT",
    "TOTAL_MASS",
    "TRUNK_BODY",
]

MJCF_PATH: Path = Path(__file__).with_name("a1.xml")
"""The project's own A1 MJCF (primitive collision shapes, position actuators, foot contact sensors)."""

LEG_NAMES: tuple[str, ...] = ("FR", "FL", "RR", "RL")  # facts: leg order used everywhere
NUM_LEGS: int = 4
JOINT_NAMES: tuple[str, ...] = tuple(
    f"{leg}_{part}_joint" for leg in LEG_NAMES for part in ("hip", "thigh", "calf")
)  # facts: per leg (hip abduction, thigh, calf)
NUM_JOINTS: int = 12
FOOT_NAMES: tuple[str, ...] = tuple(f"{leg}_foot" for leg in LEG_NAMES)  # MJCF body, geom and site names
TRUNK_BODY: str = "trunk"

# Kinematics (facts).
HIP_OFFSETS: tuple[tuple[float, float, float], ...] = (
    (0.183, -0.047, 0.0),  # FR hip joint in the trunk frame
    (0.183, 0.047, 0.0),  # FL
    (-0.183, -0.047, 0.0),  # RR
    (-0.183, 0.047, 0.0),  # RL
)
THIGH_OFFSET_Y: tuple[float, ...] = (-0.08505, 0.08505, -0.08505, 0.08505)  # thigh joint from hip joint, y
LINK_LENGTH: float = 0.2  # thigh and calf length, m
FOOT_RADIUS: float = 0.02  # contact sphere radius, m
FOOT_FRICTION: float = 0.8  # facts: sliding friction of the feet and the ground (the MJCF's geom friction)

# Joint limits, rad (facts).
ABDUCTION_LIMITS: tuple[float, float] = (-0.802851, 0.802851)
THIGH_LIMITS: tuple[float, float] = (-1.0472, 4.18879)
CALF_LIMITS: tuple[float, float] = (-2.69653, -0.916298)
JOINT_LOWER: tuple[float, ...] = (ABDUCTION_LIMITS[0], THIGH_LIMITS[0], CALF_LIMITS[0]) * NUM_LEGS
JOINT_UPPER: tuple[float, ...] = (ABDUCTION_LIMITS[1], THIGH_LIMITS[1], CALF_LIMITS[1]) * NUM_LEGS

DEFAULT_JOINT_POS: tuple[float, ...] = (0.0, 0.9, -1.8) * NUM_LEGS  # facts: default standing pose, rad
STANDING_HEIGHT: float = 0.2686  # trunk height with DEFAULT_JOINT_POS and feet on the ground (forward kinematics), m
TOTAL_MASS: float = 12.453  # facts: sum of the link masses, kg

# Actuation.
TORQUE_LIMIT: float = 33.5  # facts: motor torque limit per joint, N·m
KP_RANGE: tuple[float, float] = (45.0, 75.0)  # paper Table 1: PD stiffness, N·m/rad
KD_RANGE: tuple[float, float] = (0.9, 1.8)  # paper Table 1: PD damping, N·m·s/rad
KP_DEFAULT: float = 60.0  # choice: middle of KP_RANGE, used when nothing is randomized
KD_DEFAULT: float = 1.35  # choice: middle of KD_RANGE

# Timing.
CONTROL_HZ: float = 30.0  # paper: policy rate, Hz
SUBSTEPS: int = 8  # choice: physics steps per control step
PHYSICS_DT: float = 1.0 / (CONTROL_HZ * SUBSTEPS)  # 1/240 s, as in the MJCF <option timestep>

# Left-right symmetry: the reflection y -> -y of the trunk frame (its x-z plane), which maps the A1 onto itself
# (facts: HIP_OFFSETS and THIGH_OFFSET_Y differ in the sign of y alone between a leg and its mirror, and so do the
# MJCF's leg bodies, their inertial frames and their joint ranges; a1.xml). Not quite: the trunk's centre of mass sits
# 4.1 mm to the left (y = 0.0041 m) and its inertia has small products (a1.xml's trunk <inertial>, from Unitree's
# URDF), which the reflection moves to the right; a mirrored policy meets that difference.
MIRROR_VECTOR: tuple[float, float, float] = (1.0, -1.0, 1.0)
"""Signs that reflect a vector (a position, velocity, force, gravity) in the x-z plane: y negated."""
MIRROR_AXIAL: tuple[float, float, float] = (-1.0, 1.0, -1.0)
"""Signs that reflect an axial vector (an angular velocity, a rotation vector): a reflection reverses the sense of
rotation, so the components about x and z change sign and the one about y (normal to the plane) keeps it."""
MIRROR_QUAT: tuple[float, float, float, float] = (1.0, -1.0, 1.0, -1.0)
"""Signs that reflect a (w, x, y, z) orientation, trunk to world, in the x-z plane (R -> S R S, S = diag(1, -1,
1)): the rotation axis reflects as an axial vector, the angle stays."""
MIRROR_LEGS: tuple[int, ...] = (1, 0, 3, 2)
"""The leg whose mirror image each leg of LEG_NAMES is: FR <-> FL, RR <-> RL (HIP_OFFSETS)."""
MIRROR_PART_SIGNS: tuple[float, float, float] = (-1.0, 1.0, 1.0)
"""Per leg (hip abduction, thigh, calf): the sign a joint angle takes in its mirror joint. a1.xml: every abduction
joint turns about the trunk's x axis, which lies in the plane, so the mirror image turns the other way (-1); the
thigh and calf joints turn about y, normal to the plane, so the mirror image turns the same way (+1). Each joint's
range is symmetric under it (ABDUCTION_LIMITS is, and thigh and calf keep their own)."""
MIRROR_JOINTS: tuple[int, ...] = tuple(3 * MIRROR_LEGS[j // 3] + j % 3 for j in range(NUM_JOINTS))
"""The joint of JOINT_NAMES whose mirror image each joint is: its leg's mirror, the same part."""
MIRROR_JOINT_SIGNS: tuple[float, ...] = MIRROR_PART_SIGNS * NUM_LEGS
"""Per joint of JOINT_NAMES: mirrored angle (or velocity, or action) = this sign x the mirror joint's."""
