"""Motion-imitation reward (Peng et al. 2020): small pure functions, weights and scales kept in RewardConfig.

Each term is ``exp(-scale * error)`` in [0, 1]; the reward is the weighted sum. All tensors are batched over N
worlds; errors are computed in each robot's heading frame where a frame matters.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

__all__ = [
    "RewardConfig",
    "end_effector_reward",
    "joint_velocity_reward",
    "pose_reward",
    "root_pose_reward",
    "root_velocity_reward",
]


@dataclass(frozen=True, kw_only=True)
class RewardConfig:
    """Weights and scales of the imitation reward terms (Peng et al. 2020, as in the paper)."""

    pose_weight: float = 0.5
    pose_scale: float = 5.0
    joint_velocity_weight: float = 0.05
    joint_velocity_scale: float = 0.1
    end_effector_weight: float = 0.2
    end_effector_scale: float = 40.0
    end_effector_height_weight: float = 3.0
    """Weight of the vertical foot error against the horizontal one."""
    root_pose_weight: float = 0.15
    root_pose_scale: float = 20.0
    root_rotation_weight: float = 0.5
    """Weight of the squared orientation error (rad^2) against the squared position error (m^2)."""
    root_velocity_weight: float = 0.1
    root_velocity_scale: float = 2.0
    root_angular_velocity_weight: float = 0.1
    """Weight of the squared angular velocity error against the squared linear velocity error."""

    def terms(self) -> dict[str, float]:
        """Term name -> weight."""
        return {
            "pose": self.pose_weight,
            "joint_velocity": self.joint_velocity_weight,
            "end_effector": self.end_effector_weight,
            "root_pose": self.root_pose_weight,
            "root_velocity": self.root_velocity_weight,
        }


def pose_reward(joint_pos: torch.Tensor, ref_joint_pos: torch.Tensor, *, scale: float) -> torch.Tensor:
    """exp(-scale * sum_j (q_ref - q)^2); joint angles (N, J) in rad."""
    return torch.exp(-scale * (ref_joint_pos - joint_pos).square().sum(-1))


def joint_velocity_reward(joint_vel: torch.Tensor, ref_joint_vel: torch.Tensor, *, scale: float) -> torch.Tensor:
    """exp(-scale * sum_j (qd_ref - qd)^2); joint velocities (N, J) in rad/s."""
    return torch.exp(-scale * (ref_joint_vel - joint_vel).square().sum(-1))


def end_effector_reward(
    foot_pos: torch.Tensor, ref_foot_pos: torch.Tensor, *, scale: float, height_weight: float
) -> torch.Tensor:
    """exp(-scale * sum_feet (dx^2 + dy^2 + height_weight dz^2)); feet (N, F, 3) relative to the trunk, heading
    frame, m."""
    error = (ref_foot_pos - foot_pos).square()
    weighted = error[..., 0] + error[..., 1] + height_weight * error[..., 2]
    return torch.exp(-scale * weighted.sum(-1))


def root_pose_reward(
    root_pos: torch.Tensor,
    ref_root_pos: torch.Tensor,
    rotation_error: torch.Tensor,
    *,
    scale: float,
    rotation_weight: float,
) -> torch.Tensor:
    """exp(-scale * (|p_ref - p|^2 + rotation_weight * angle^2)); positions (N, 3) m, ``rotation_error`` (N,) rad."""
    return torch.exp(-scale * ((ref_root_pos - root_pos).square().sum(-1) + rotation_weight * rotation_error.square()))


def root_velocity_reward(
    lin_vel: torch.Tensor,
    ref_lin_vel: torch.Tensor,
    ang_vel: torch.Tensor,
    ref_ang_vel: torch.Tensor,
    *,
    scale: float,
    angular_weight: float,
) -> torch.Tensor:
    """exp(-scale * (|v_ref - v|^2 + angular_weight |w_ref - w|^2)); (N, 3) m/s and rad/s in one common frame."""
    error = (ref_lin_vel - lin_vel).square().sum(-1) + angular_weight * (ref_ang_vel - ang_vel).square().sum(-1)
    return torch.exp(-scale * error)
