"""Motion-imitation reward (Peng et al. 2020, "Learning Agile Robotic Locomotion Skills by Imitating Animals"):
terms declared once, as (name, error, weight, scale), in :data:`IMITATION_REWARD`.

Each term is ``exp(-scale * error)`` in [0, 1], its error computed from the robot's readings and its reference;
the reward is the weighted sum. Adding a term is one error function and one line in the declaration. All tensors
are batched over N worlds; errors are taken in each robot's heading frame where a frame matters.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import torch

from gaitlib.envs.reference import ReferenceFrame
from gaitlib.rotations import quat_angle_between, quat_from_yaw, quat_rotate_inverse, yaw_of
from gaitlib.sim import SimState

__all__ = [
    "IMITATION_REWARD",
    "RewardTerm",
    "end_effector_error",
    "joint_velocity_error",
    "pose_error",
    "reward",
    "root_pose_error",
    "root_velocity_error",
]


@dataclass(frozen=True)
class RewardTerm:
    """One imitation reward term, ``weight * exp(-scale * error)``."""

    name: str
    """Logged as ``/reward/<name>``."""
    error: Callable[[SimState, ReferenceFrame], torch.Tensor]
    """(N,) non-negative tracking error of each world."""
    weight: float
    """Share of the term in the reward (the weights of a reward sum to 1)."""
    scale: float
    """Sharpness, per unit of the error."""


def pose_error(s: SimState, ref: ReferenceFrame) -> torch.Tensor:
    """sum_j (q_ref - q)^2, joint angles in rad."""
    return (ref.joint_pos - s.joint_pos).square().sum(-1)


def joint_velocity_error(s: SimState, ref: ReferenceFrame) -> torch.Tensor:
    """sum_j (qd_ref - qd)^2, joint velocities in rad/s."""
    return (ref.joint_vel - s.joint_vel).square().sum(-1)


def end_effector_error(s: SimState, ref: ReferenceFrame, *, height_weight: float) -> torch.Tensor:
    """sum_feet (dx^2 + dy^2 + height_weight dz^2) of the feet relative to the trunk in the robot's heading frame,
    m^2."""
    heading = quat_from_yaw(yaw_of(s.root_quat)).unsqueeze(1)
    feet = quat_rotate_inverse(heading, s.foot_pos - s.root_pos.unsqueeze(1))
    error = (ref.foot_pos_heading - feet).square()
    return (error[..., 0] + error[..., 1] + height_weight * error[..., 2]).sum(-1)


def root_pose_error(s: SimState, ref: ReferenceFrame, *, rotation_weight: float) -> torch.Tensor:
    """|p_ref - p|^2 (m^2) + rotation_weight * angle^2 (rad^2) of the trunk."""
    angle = quat_angle_between(s.root_quat, ref.root_quat)
    return (ref.root_pos - s.root_pos).square().sum(-1) + rotation_weight * angle.square()


def root_velocity_error(s: SimState, ref: ReferenceFrame, *, angular_weight: float) -> torch.Tensor:
    """|v_ref - v|^2 ((m/s)^2, world frame) + angular_weight |w_ref - w|^2 ((rad/s)^2, trunk frame)."""
    linear = (ref.root_lin_vel - s.root_lin_vel).square().sum(-1)
    return linear + angular_weight * (ref.root_ang_vel - s.root_ang_vel).square().sum(-1)


IMITATION_REWARD: tuple[RewardTerm, ...] = (
    RewardTerm("pose", pose_error, 0.5, 5.0),
    RewardTerm("joint_velocity", joint_velocity_error, 0.05, 0.1),
    RewardTerm("end_effector", partial(end_effector_error, height_weight=3.0), 0.2, 40.0),
    RewardTerm("root_pose", partial(root_pose_error, rotation_weight=0.5), 0.15, 20.0),
    RewardTerm("root_velocity", partial(root_velocity_error, angular_weight=0.1), 0.1, 2.0),
)
"""The paper's terms, weights and scales (Peng et al. 2020, as in Christmann et al.)."""


def reward(
    terms: tuple[RewardTerm, ...], s: SimState, ref: ReferenceFrame
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """The reward (N,) and each term's value (N,) in [0, 1], by name."""
    values = {t.name: torch.exp(-t.scale * t.error(s, ref)) for t in terms}
    return sum(t.weight * values[t.name] for t in terms), values
