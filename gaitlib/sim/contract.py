"""The simulation backend contract: a batch of N independent robot worlds advanced one control period at a time.

Every backend (``mujoco``: MuJoCo C on CPU threads; ``newton``: Newton + mujoco_warp on GPU or CPU) implements
:class:`SimBackend` for the same MJCF and the same physics, so anything above this module is backend-agnostic.

Conventions for every tensor (``N`` = number of worlds, ``k`` = number of selected worlds, ``J`` = joints,
``F`` = feet):

* ``torch.float32`` on :attr:`SimBackend.device` (indices ``torch.long``, flags ``torch.bool``); SI units.
* World frame: z up, gravity along -z. Quaternions are ``(w, x, y, z)`` and rotate trunk-frame vectors into the
  world frame.
* Joint tensors follow :attr:`gaitlib.robots.RobotSpec.joint_names`; foot tensors follow ``foot_names``.
* PD law applied at every physics substep: ``tau = clip(kp * (q_target - q) - kd * qd, -tau_max, tau_max)``,
  with ``q_target`` clipped to the joint range (the MJCF actuators' ``ctrlrange``), times the robot's
  ``motor_strength`` (1 unless a deployment gap is simulated; the ``mujoco`` backend alone supports other values,
  and robots adapted from another MJCF, :mod:`gaitlib.robots.variant`).

Readings (:meth:`SimBackend.state`) are taken after the last physics substep; contact flags and foot positions
come from that substep's collision pass (at most one physics step, 1/240 s, old).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import torch

from gaitlib.robots import RobotSpec

__all__ = ["KinematicState", "SimBackend", "SimState", "standing_state"]


@dataclass
class KinematicState:
    """Generalized position and velocity of k robots: what :meth:`SimBackend.reset` takes."""

    root_pos: torch.Tensor
    """(k, 3) trunk frame origin in the world frame, m."""
    root_quat: torch.Tensor
    """(k, 4) trunk orientation (w, x, y, z), trunk to world."""
    root_lin_vel: torch.Tensor
    """(k, 3) linear velocity of the trunk frame origin, world frame, m/s."""
    root_ang_vel: torch.Tensor
    """(k, 3) angular velocity of the trunk, trunk frame, rad/s."""
    joint_pos: torch.Tensor
    """(k, J) joint angles, rad."""
    joint_vel: torch.Tensor
    """(k, J) joint velocities, rad/s."""


@dataclass
class SimState(KinematicState):
    """Everything a backend reports about its N worlds after a step."""

    foot_contact: torch.Tensor
    """(N, F) bool: the foot touches the ground."""
    foot_pos: torch.Tensor
    """(N, F, 3) foot contact-sphere centres in the world frame, m."""
    body_contact: torch.Tensor
    """(N,) bool: some robot geometry other than a foot, or than one of the robot's ``stance_contact_geoms``, touches
    the ground (a leg's touch, or the trunk's)."""
    trunk_contact: torch.Tensor
    """(N,) bool: a geometry of the trunk body itself touches the ground (a fall by any definition)."""


def standing_state(robot: RobotSpec, num: int, *, device: torch.device | str = "cpu") -> KinematicState:
    """``num`` copies of the robot at rest in its default pose with its feet on the ground at the origin."""
    zeros3 = torch.zeros(num, 3, device=device)
    root_pos = zeros3.clone()
    root_pos[:, 2] = robot.standing_height
    quat = torch.zeros(num, 4, device=device)
    quat[:, 0] = 1.0
    joint_pos = torch.tensor(robot.default_joint_pos, dtype=torch.float32, device=device).repeat(num, 1)
    return KinematicState(
        root_pos=root_pos,
        root_quat=quat,
        root_lin_vel=zeros3.clone(),
        root_ang_vel=zeros3.clone(),
        joint_pos=joint_pos,
        joint_vel=torch.zeros_like(joint_pos),
    )


class SimBackend(ABC):
    """A batch of ``num_worlds`` independent copies of one robot on flat ground.

    A new backend holds every world in :func:`standing_state` with the robot's default PD gains, unit gravity
    and mass scales, the MJCF's ground friction and no external force.
    """

    name: str
    """Registry name of the backend."""
    robot: RobotSpec
    """The robot every world holds."""
    num_worlds: int
    """Number of worlds N."""
    device: torch.device
    """Where every tensor this backend takes and returns lives."""

    @property
    def control_dt(self) -> float:
        """Duration of one :meth:`step`, s."""
        return 1.0 / self.robot.control_hz

    @property
    def substeps(self) -> int:
        """Physics steps per :meth:`step`."""
        return self.robot.substeps

    @abstractmethod
    def reset(self, world_ids: torch.Tensor, state: KinematicState) -> None:
        """Put worlds ``world_ids`` (k,) into ``state`` (k rows), set their PD targets to ``state.joint_pos``
        and clear their external forces and solver warm start. Other worlds are left bit-identical."""

    @abstractmethod
    def set_pd_targets(self, targets: torch.Tensor) -> None:
        """Set the joint position targets (N, J), rad, held until the next call. Raises
        :class:`~gaitlib.errors.SimulationError` on non-finite targets."""

    @abstractmethod
    def set_pd_gains(self, world_ids: torch.Tensor, kp: torch.Tensor, kd: torch.Tensor) -> None:
        """Set PD stiffness ``kp`` (k, J), N·m/rad, and damping ``kd`` (k, J), N·m·s/rad, of worlds ``world_ids``."""

    @abstractmethod
    def set_dynamics(
        self,
        world_ids: torch.Tensor,
        *,
        gravity_scale: torch.Tensor,
        mass_scale: torch.Tensor,
        friction: torch.Tensor,
    ) -> None:
        """Per-world domain randomization of worlds ``world_ids`` (k,), each argument (k,), relative to the MJCF:
        ``gravity_scale`` multiplies gravity, ``mass_scale`` multiplies every robot link's mass and inertia,
        ``friction`` is the sliding friction coefficient of every robot-ground contact."""

    @abstractmethod
    def set_trunk_force(self, world_ids: torch.Tensor, force: torch.Tensor) -> None:
        """Apply ``force`` (k, 3), N, world frame, at the trunk's centre of mass of worlds ``world_ids`` from the
        next step on, until changed (a zero force removes it) or the world is reset."""

    @abstractmethod
    def step(self) -> torch.Tensor:
        """Advance every world by one control period (``substeps`` physics steps).

        Returns ``diverged`` (N,) bool: worlds whose physics went non-finite or unstable during this step. Each
        such world is put back into the state of its last :meth:`reset` (or :func:`standing_state`) before this
        returns, so no NaN ever reaches :meth:`state`; the caller decides what the divergence means (an
        environment ends the episode).
        """

    @abstractmethod
    def state(self) -> SimState:
        """Readings of all N worlds after the last :meth:`step` or :meth:`reset`."""

    def close(self) -> None:  # noqa: B027 - optional hook
        """Release threads, devices and buffers; the backend is unusable afterwards."""
