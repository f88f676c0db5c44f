"""Observation layout (design brief section 3) as small pure functions.

Actor observation (158) = state s_t (102) + reference g_t (56):

* s_t: the proprioceptive frame (34) of the current and the two previous control steps, newest first. A frame is
  12 joint angles (rad), projected gravity in the trunk frame (3, unit vector: the orientation), trunk angular
  velocity in the trunk frame (3, rad/s), 4 foot contacts (0/1) and the 12 previous actions.
* g_t: the reference at :data:`REFERENCE_OFFSETS` control steps ahead (t+1, t+2, t+10, t+30: about one second),
  each 12 joint angles (rad), trunk height (m) and forward speed in the heading frame (m/s).

Critic (privileged) extras (14): trunk linear velocity in the trunk frame (3), trunk height (1), gait phase as
sin/cos (2), the world's randomized gravity scale, mass scale, friction, kp/60 and kd (5), push force / 100 N (3).
"""

from __future__ import annotations

import torch

from gaitlib.envs.reference import ReferenceFrame
from gaitlib.envs.rotations import quat_rotate_inverse

__all__ = [
    "ACTOR_OBS_DIM",
    "FRAME_DIM",
    "HISTORY",
    "PRIVILEGED_DIM",
    "REFERENCE_DIM",
    "REFERENCE_OFFSETS",
    "STATE_DIM",
    "layout",
    "privileged_features",
    "proprioceptive_frame",
    "reference_features",
]

FRAME_DIM = 34
"""Size of one proprioceptive frame."""
HISTORY = 3
"""Frames in s_t: current and two past control steps."""
STATE_DIM = FRAME_DIM * HISTORY  # 102
REFERENCE_OFFSETS = (1, 2, 10, 30)
"""Control steps ahead at which the reference is shown to the policy."""
REFERENCE_DIM = 14 * len(REFERENCE_OFFSETS)  # 56
ACTOR_OBS_DIM = STATE_DIM + REFERENCE_DIM  # 158
PRIVILEGED_DIM = 14


def layout() -> dict[str, object]:
    """A description of the observation layout, stored with every trained policy and checked on load."""
    return {
        "frame": ["joint_pos:12", "projected_gravity:3", "ang_vel_trunk:3", "foot_contact:4", "prev_action:12"],
        "history": HISTORY,
        "reference_offsets": list(REFERENCE_OFFSETS),
        "reference_frame": ["joint_pos:12", "root_height:1", "forward_speed:1"],
        "actor_dim": ACTOR_OBS_DIM,
        "privileged_dim": PRIVILEGED_DIM,
    }


def proprioceptive_frame(
    joint_pos: torch.Tensor,
    root_quat: torch.Tensor,
    root_ang_vel: torch.Tensor,
    foot_contact: torch.Tensor,
    prev_action: torch.Tensor,
) -> torch.Tensor:
    """One (N, 34) frame from joint angles (N, 12), orientation (N, 4), trunk-frame angular velocity (N, 3),
    foot contacts (N, 4) and the previous action (N, 12)."""
    down = torch.zeros_like(root_ang_vel)
    down[:, 2] = -1.0
    gravity = quat_rotate_inverse(root_quat, down)
    return torch.cat([joint_pos, gravity, root_ang_vel, foot_contact.float(), prev_action], dim=-1)


def reference_features(frames: list[ReferenceFrame]) -> torch.Tensor:
    """g_t (N, 14 * len(frames)) from the reference at each of the offsets."""
    parts = []
    for f in frames:
        parts += [f.joint_pos, f.root_pos[:, 2:3], f.heading_lin_vel[:, 0:1]]
    return torch.cat(parts, dim=-1)


def privileged_features(
    root_quat: torch.Tensor,
    root_lin_vel: torch.Tensor,
    root_height: torch.Tensor,
    phase: torch.Tensor,
    dynamics: torch.Tensor,
    push_force: torch.Tensor,
) -> torch.Tensor:
    """Critic extras (N, 14): ``dynamics`` (N, 5) is (gravity scale, mass scale, friction, kp, kd)."""
    angle = 2 * torch.pi * phase
    scaled = dynamics / torch.tensor([1.0, 1.0, 1.0, 60.0, 1.0], device=dynamics.device)
    return torch.cat(
        [
            quat_rotate_inverse(root_quat, root_lin_vel),
            root_height.unsqueeze(-1),
            torch.sin(angle).unsqueeze(-1),
            torch.cos(angle).unsqueeze(-1),
            scaled,
            push_force / 100.0,
        ],
        dim=-1,
    )
