"""Robot registry: a robot is an MJCF file plus the few facts the simulator needs to drive it.

Adding a robot means writing its MJCF and constants module under ``gaitlib/robots/<name>/`` and calling
:func:`register_robot` with a :class:`RobotSpec` (see ``docs/robot.md``). Another MJCF of the A1 (MuJoCo Menagerie's,
say) becomes a robot at run time through :func:`gaitlib.robots.variant.load_variant`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gaitlib.registry import Registry

__all__ = ["RobotSpec", "get_robot", "register_robot"]


@dataclass(frozen=True, kw_only=True)
class RobotSpec:
    """What a simulation backend needs to know about a legged robot described by an MJCF file."""

    name: str
    """Registry name, e.g. ``"a1"``."""
    mjcf_path: Path
    """MJCF with a free-jointed trunk, one position actuator per joint, a plane named ``floor`` and one foot
    geom and site per leg named as in :attr:`foot_names`."""
    joint_names: tuple[str, ...]
    """Actuated hinge joints in the order used by every tensor (the actuators follow the same order)."""
    foot_names: tuple[str, ...]
    """Foot body, geom and site names (one per leg), in leg order."""
    trunk_body: str
    """Name of the free-floating base body that pushes are applied to."""
    default_joint_pos: tuple[float, ...]
    """Standing pose, rad, in joint order."""
    joint_lower: tuple[float, ...]
    """Lower joint limits, rad, in joint order."""
    joint_upper: tuple[float, ...]
    """Upper joint limits, rad, in joint order."""
    standing_height: float
    """Trunk height above the ground in the standing pose, m."""
    torque_limit: float
    """Symmetric motor torque limit, N·m."""
    kp_default: float
    """PD stiffness used when no per-world gain is set, N·m/rad."""
    kd_default: float
    """PD damping used when no per-world gain is set, N·m·s/rad."""
    control_hz: float
    """Control (policy) rate, Hz."""
    substeps: int
    """Physics steps per control step; the MJCF timestep must equal 1 / (control_hz * substeps)."""
    build_model: Callable[[], Any] | None = None
    """Returns the compiled ``mujoco.MjModel`` to simulate instead of compiling :attr:`mjcf_path` (a model adapted in
    memory from another MJCF, :mod:`gaitlib.robots.variant`); ``None``: :attr:`mjcf_path` is the model itself."""
    stance_contact_geoms: tuple[str, ...] = ()
    """Non-foot geoms whose ground contact is normal stance, not a fall (on MuJoCo Menagerie's A1 the lower calf
    capsules reach the foot centre and touch the ground when the soft feet sink); each has a contact sensor
    ``<geom>_contact`` against the floor like the feet'. Empty for gaitlib's own A1."""
    motor_strength: float = 1.0
    """The motors deliver this multiple of the PD law's torque, its limit included: ``tau = motor_strength *
    clip(kp (q* - q) - kd qd, -torque_limit, torque_limit)`` (a deployment gap; 1: as modelled)."""

    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    @property
    def num_feet(self) -> int:
        return len(self.foot_names)


_ROBOTS: Registry[RobotSpec] = Registry("robot")


def register_robot(spec: RobotSpec) -> None:
    """Add ``spec`` to the registry under ``spec.name`` (replacing any robot of that name)."""
    _ROBOTS.register(spec.name, spec)


def get_robot(name: str = "a1") -> RobotSpec:
    """Return the registered robot called ``name``; raises :class:`~gaitlib.errors.UnknownNameError` for an unknown
    name."""
    return _ROBOTS.get(name)


def _register_a1() -> None:
    from gaitlib.robots.a1 import constants as c

    register_robot(
        RobotSpec(
            name="a1",
            mjcf_path=c.MJCF_PATH,
            joint_names=c.JOINT_NAMES,
            foot_names=c.FOOT_NAMES,
            trunk_body=c.TRUNK_BODY,
            default_joint_pos=c.DEFAULT_JOINT_POS,
            joint_lower=c.JOINT_LOWER,
            joint_upper=c.JOINT_UPPER,
            standing_height=c.STANDING_HEIGHT,
            torque_limit=c.TORQUE_LIMIT,
            kp_default=c.KP_DEFAULT,
            kd_default=c.KD_DEFAULT,
            control_hz=c.CONTROL_HZ,
            substeps=c.SUBSTEPS,
        )
    )


_register_a1()
