"""Observation layout (docs/deploying.md): one declaration of every field, from which every width, slice and
scale is derived, and the small pure functions that fill it.

Actor observation (158) = state s_t (102) + reference g_t (56):

* s_t: the proprioceptive :data:`FRAME` (34) of the current and the two previous control steps, newest first: joint
  angles (rad), projected gravity in the trunk frame (unit vector: the orientation), trunk angular velocity in the
  trunk frame (rad/s), foot contacts (0/1) and the previous actions.
* g_t: the :data:`REFERENCE_FRAME` (14) at :data:`REFERENCE_OFFSETS` control steps ahead (t+1, t+2, t+10, t+30:
  about one second): joint angles (rad), trunk height (m) and forward speed in the heading frame (m/s).
* with :attr:`ObservationConfig.heading` (the default), one more value, :data:`HEADING`: the reference trunk's yaw
  minus the robot's, rad (159 in all). Without it the layout is the 158 values of gaitlib 0.1's libraries, which
  still load.

Critic (privileged) extras, :data:`PRIVILEGED` (14): trunk linear velocity in the trunk frame, trunk height, gait
phase as sin/cos, the world's randomized :data:`DYNAMICS` (gravity scale, mass scale, friction, kp in units of the
robot's default stiffness, kd) and the push force in units of 100 N; with
:attr:`ObservationConfig.critic_delay`, one more, :data:`DELAY`: the control steps every action of the world waits.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import torch

from gaitlib.envs.reference import ReferenceFrame
from gaitlib.robots.a1.constants import KP_DEFAULT, NUM_JOINTS, NUM_LEGS
from gaitlib.rotations import quat_rotate_inverse, yaw_of

__all__ = [
    "ACTOR_OBS_DIM",
    "DYNAMICS",
    "FRAME",
    "FRAME_DIM",
    "HEADING",
    "HISTORY",
    "PRIVILEGED",
    "PRIVILEGED_DIM",
    "REFERENCE_DIM",
    "REFERENCE_FRAME",
    "REFERENCE_OFFSETS",
    "SENSED",
    "STATE_DIM",
    "Field",
    "ObservationBatch",
    "ObservationConfig",
    "heading_error",
    "layout",
    "observation_config",
    "privileged_features",
    "proprioceptive_frame",
    "reference_features",
    "width",
]


class Field(NamedTuple):
    """One named block of an observation vector."""

    name: str
    width: int
    """Number of values."""
    unit: float = 1.0
    """The observation holds the quantity divided by this (in the quantity's SI unit)."""


def width(fields: tuple[Field, ...]) -> int:
    """Number of values of a sequence of fields."""
    return sum(f.width for f in fields)


def _assemble(fields: tuple[Field, ...], parts: dict[str, torch.Tensor]) -> torch.Tensor:
    """Concatenate ``parts`` (name -> (N, width)) in the order of ``fields``, each divided by its unit."""
    return torch.cat([parts[f.name] if f.unit == 1.0 else parts[f.name] / f.unit for f in fields], dim=-1)


FRAME: tuple[Field, ...] = (
    Field("joint_pos", NUM_JOINTS),
    Field("projected_gravity", 3),
    Field("ang_vel_trunk", 3),
    Field("foot_contact", NUM_LEGS),
    Field("prev_action", NUM_JOINTS),
)
"""One proprioceptive frame."""
FRAME_DIM = width(FRAME)  # 34
SENSED = slice(0, FRAME_DIM - FRAME[-1].width)
"""The values of a frame that sensors read (all but the previous actions, which are known exactly)."""
HISTORY = 3
"""Frames in s_t: current and two past control steps."""
STATE_DIM = FRAME_DIM * HISTORY  # 102
REFERENCE_FRAME: tuple[Field, ...] = (
    Field("joint_pos", NUM_JOINTS),
    Field("root_height", 1),
    Field("forward_speed", 1),
)
"""The reference at one offset."""
REFERENCE_OFFSETS = (1, 2, 10, 30)
"""Control steps ahead at which the reference is shown to the policy."""
REFERENCE_DIM = width(REFERENCE_FRAME) * len(REFERENCE_OFFSETS)  # 56
ACTOR_OBS_DIM = STATE_DIM + REFERENCE_DIM  # 158
"""State and reference: the actor observation without :data:`HEADING`."""
HEADING: tuple[Field, ...] = (Field("heading_error", 1),)
"""The heading error after the reference, when :attr:`ObservationConfig.heading`: without it the heading is
unobservable (gravity and angular velocity do not hold it), so no policy can hold a heading."""
DYNAMICS: tuple[Field, ...] = (
    Field("gravity_scale", 1),
    Field("mass_scale", 1),
    Field("friction", 1),
    Field("kp", 1, KP_DEFAULT),
    Field("kd", 1),
)
"""The randomized parameters the critic sees, in :class:`~gaitlib.envs.randomization.WorldParameters` names."""
PRIVILEGED: tuple[Field, ...] = (
    Field("lin_vel_trunk", 3),
    Field("root_height", 1),
    Field("phase_sin", 1),
    Field("phase_cos", 1),
    *DYNAMICS,
    Field("push_force", 3, 100.0),  # N
)
"""Critic extras."""
PRIVILEGED_DIM = width(PRIVILEGED)  # 14
DELAY: tuple[Field, ...] = (Field("action_delay", 1),)
"""The critic's extra with :attr:`ObservationConfig.critic_delay`: the world's action delay, control steps."""


@dataclass(frozen=True, kw_only=True)
class ObservationConfig:
    """The options of the actor observation; every policy of a library shares them."""

    heading: bool = True
    """End the actor observation with :data:`HEADING` (159 values); ``False`` is gaitlib 0.1's 158-value layout."""
    critic_delay: bool = False
    """End the critic's extras with :data:`DELAY`, the world's action delay (privileged: the actor does not see it;
    a training lever, :mod:`gaitlib.training.recipe`)."""

    @property
    def policy(self) -> tuple[Field, ...]:
        """The fields of the actor observation in order: :data:`FRAME` for each of the :data:`HISTORY` frames (newest
        first), :data:`REFERENCE_FRAME` for each of the :data:`REFERENCE_OFFSETS`, then :data:`HEADING` where
        :attr:`heading`."""
        return FRAME * HISTORY + REFERENCE_FRAME * len(REFERENCE_OFFSETS) + (HEADING if self.heading else ())

    @property
    def privileged(self) -> tuple[Field, ...]:
        """The critic's extras."""
        return PRIVILEGED + (DELAY if self.critic_delay else ())

    @property
    def privileged_dim(self) -> int:
        """Width of the critic's extras."""
        return width(self.privileged)

    @property
    def actor_dim(self) -> int:
        """Width of the actor observation."""
        return ACTOR_OBS_DIM + (width(HEADING) if self.heading else 0)


@dataclass(frozen=True, slots=True)
class ObservationBatch:
    """The observations of N worlds: what each actor reads and what each critic reads beside it. Indexing by rows
    (``obs[ids]``: indices, a mask or a slice) gives those worlds' observations."""

    policy: torch.Tensor
    """(N, :attr:`ObservationConfig.actor_dim`) the actor's observation."""
    privileged: torch.Tensor
    """(N, :attr:`ObservationConfig.privileged_dim`) the critic's extras; the critic reads ``policy`` then these."""

    def __len__(self) -> int:
        return len(self.policy)

    def __getitem__(self, rows: torch.Tensor | slice) -> ObservationBatch:
        return ObservationBatch(policy=self.policy[rows], privileged=self.privileged[rows])


def layout(cfg: ObservationConfig = ObservationConfig()) -> dict[str, object]:
    """A description of the observation layout, stored with every trained policy and checked on load."""
    described: dict[str, object] = {
        "frame": [f"{f.name}:{f.width}" for f in FRAME],
        "history": HISTORY,
        "reference_offsets": list(REFERENCE_OFFSETS),
        "reference_frame": [f"{f.name}:{f.width}" for f in REFERENCE_FRAME],
        "actor_dim": cfg.actor_dim,
        "privileged_dim": cfg.privileged_dim,
    }
    if cfg.heading:
        described["heading"] = [f"{f.name}:{f.width}" for f in HEADING]
    if cfg.critic_delay:
        described["critic_delay"] = [f"{f.name}:{f.width}" for f in DELAY]
    return described


def observation_config(described: object) -> ObservationConfig | None:
    """The options whose :func:`layout` is ``described`` (as stored with a policy); ``None`` if no options of this
    gaitlib give it."""
    for heading in (True, False):
        for critic_delay in (False, True):
            cfg = ObservationConfig(heading=heading, critic_delay=critic_delay)
            if described == layout(cfg):
                return cfg
    return None


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
    parts = {
        "joint_pos": joint_pos,
        "projected_gravity": quat_rotate_inverse(root_quat, down),
        "ang_vel_trunk": root_ang_vel,
        "foot_contact": foot_contact.float(),
        "prev_action": prev_action,
    }
    return _assemble(FRAME, parts)


def reference_features(frames: list[ReferenceFrame]) -> torch.Tensor:
    """g_t (N, 14 * len(frames)) from the reference at each of the offsets."""
    parts = [
        {"joint_pos": f.joint_pos, "root_height": f.root_pos[:, 2:3], "forward_speed": f.heading_lin_vel[:, 0:1]}
        for f in frames
    ]
    return torch.cat([_assemble(REFERENCE_FRAME, p) for p in parts], dim=-1)


def heading_error(root_quat: torch.Tensor, ref_root_quat: torch.Tensor) -> torch.Tensor:
    """(N, 1) yaw of the reference trunk ``ref_root_quat`` (N, 4) minus yaw of the trunk ``root_quat`` (N, 4), wrapped
    to [-pi, pi), rad: positive when the robot must turn left to face the reference's way."""
    error = yaw_of(ref_root_quat) - yaw_of(root_quat)
    return (torch.remainder(error + torch.pi, 2 * torch.pi) - torch.pi).unsqueeze(-1)


def privileged_features(
    root_quat: torch.Tensor,
    root_lin_vel: torch.Tensor,
    root_height: torch.Tensor,
    phase: torch.Tensor,
    dynamics: torch.Tensor,
    push_force: torch.Tensor,
    action_delay: torch.Tensor | None = None,
) -> torch.Tensor:
    """Critic extras (N, 14): ``dynamics`` (N, 5) holds the :data:`DYNAMICS` in their SI units, ``push_force``
    (N, 3) is in N; with ``action_delay`` (N,) control steps, :data:`DELAY` after them (N, 15)."""
    angle = 2 * torch.pi * phase
    parts = {
        "lin_vel_trunk": quat_rotate_inverse(root_quat, root_lin_vel),
        "root_height": root_height.unsqueeze(-1),
        "phase_sin": torch.sin(angle).unsqueeze(-1),
        "phase_cos": torch.cos(angle).unsqueeze(-1),
        "push_force": push_force,
    }
    parts |= {f.name: dynamics[:, i : i + 1] for i, f in enumerate(DYNAMICS)}
    if action_delay is None:
        return _assemble(PRIVILEGED, parts)
    return _assemble(PRIVILEGED + DELAY, parts | {"action_delay": action_delay.float().unsqueeze(-1)})
