"""Per-world reference motion: which gait each world imitates, its phase, and where the reference is anchored.

The reference of a world is its gait's clip placed in the world by a planar transform (an xy offset and a yaw)
chosen when the world starts or switches, so that the reference begins where the robot stands and faces.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch

from gaitlib.gaits import ClipFrame, ReferenceClip
from gaitlib.gaits.clip import clip_bank
from gaitlib.rotations import quat_from_yaw, quat_multiply, quat_rotate, quat_rotate_inverse, yaw_of
from gaitlib.sim import KinematicState

__all__ = ["ReferenceFrame", "ReferenceTracker"]


@dataclass
class ReferenceFrame(KinematicState):
    """Reference quantities of N worlds in the world frame (see :class:`~gaitlib.gaits.ClipFrame`): a kinematic state
    (where reference state initialization puts a robot) and what the observations and rewards compare."""

    heading_lin_vel: torch.Tensor
    """(N, 3) linear velocity in the reference's heading frame, m/s (x: forward speed)."""
    foot_pos_heading: torch.Tensor
    """(N, F, 3) feet relative to the trunk in the heading frame, m."""
    contact: torch.Tensor
    """(N, F) bool."""


class ReferenceTracker:
    """Gait index, unwrapped phase and anchor of each of N worlds; reads their references at any time offset."""

    def __init__(self, clips: list[ReferenceClip], num_worlds: int, device: torch.device) -> None:
        self.clips = clips
        self._bank = clip_bank(tuple(clips), torch.device(device))
        self.device = device
        self.gait = torch.zeros(num_worlds, dtype=torch.long, device=device)
        """(N,) index into ``clips`` of the gait each world imitates."""
        self.phase = torch.zeros(num_worlds, device=device)
        """(N,) unwrapped phase in cycles (its fractional part is the gait phase)."""
        self._offset = torch.zeros(num_worlds, 3, device=device)  # anchor translation (z stays 0), m
        self._yaw = torch.zeros(num_worlds, device=device)  # anchor rotation about z, rad
        self._rate = torch.tensor([c.phase_rate for c in clips], device=device)

    @property
    def rate(self) -> torch.Tensor:
        """(G,) how fast each gait's phase advances, cycles per second (the inverse of its clip's period)."""
        return self._rate

    @property
    def wrapped_phase(self) -> torch.Tensor:
        """(N,) phase in [0, 1)."""
        return torch.remainder(self.phase, 1.0)

    def advance(self, dt: float) -> torch.Tensor:
        """Move every world's phase on by ``dt`` seconds; return the (N,) bool mask of the worlds whose phase passed
        the start of a cycle."""
        before = torch.floor(self.phase)
        self.phase += dt * self._rate[self.gait]
        return torch.floor(self.phase) > before

    def sync_position(self, world_ids: torch.Tensor, root_pos: torch.Tensor) -> None:
        """Move the anchor of ``world_ids`` horizontally so that the reference's trunk is at the robot's ``root_pos``
        (k, 3) now; its heading stays (Peng et al.'s cycle sync, ``_sync_ref_origin`` with the root position only)."""
        clip = self._clip_frames(self.gait[world_ids], self.phase[world_ids])
        self._anchor(world_ids, self._yaw[world_ids], clip.root_pos, root_pos)

    def start(
        self,
        world_ids: torch.Tensor,
        gait: torch.Tensor,
        phase: torch.Tensor,
        root_pos: torch.Tensor,
        root_quat: torch.Tensor,
    ) -> None:
        """Make ``world_ids`` imitate ``gait`` (k,) from ``phase`` (k,) on, anchored so that the reference's trunk
        is at the robot's ``root_pos`` (k, 3) (horizontally) and faces the robot's heading (``root_quat`` (k, 4))."""
        self.gait[world_ids] = gait
        self.phase[world_ids] = phase
        clip = self._clip_frames(gait, phase)
        self._anchor(world_ids, yaw_of(root_quat) - yaw_of(clip.root_quat), clip.root_pos, root_pos)

    def _anchor(self, world_ids: torch.Tensor, yaw: torch.Tensor, clip_root_pos: torch.Tensor,
                root_pos: torch.Tensor) -> None:
        """Anchor ``world_ids`` turned by ``yaw`` (k,) rad so that the clip's trunk at ``clip_root_pos`` (k, 3) lies
        horizontally at ``root_pos`` (k, 3)."""
        offset = root_pos - quat_rotate(quat_from_yaw(yaw), clip_root_pos)
        offset[:, 2] = 0.0
        self._offset[world_ids] = offset
        self._yaw[world_ids] = yaw

    def frame(self, dt: float = 0.0, world_ids: torch.Tensor | None = None) -> ReferenceFrame:
        """The reference ``dt`` seconds ahead of the current phase, for all worlds or ``world_ids``."""
        ids = slice(None) if world_ids is None else world_ids
        gait = self.gait[ids]
        return self._frame(gait, self.phase[ids] + dt * self._rate[gait], self._offset[ids], self._yaw[ids])

    def joint_pos(self, dt: float) -> torch.Tensor:
        """(N, 12) the reference's joint angles ``dt`` seconds ahead, rad: ``frame(dt).joint_pos``, without the
        trunk's and feet's placement (what an action is added to, every control step)."""
        return self._clip_frames(self.gait, self.phase + dt * self._rate[self.gait]).joint_pos

    def frames(self, dts: Sequence[float]) -> list[ReferenceFrame]:
        """The references ``dts`` seconds ahead of the current phase, for all worlds: the same as
        ``[frame(dt) for dt in dts]``, in one read of the clips (per control step, most of an environment's own
        time at a few worlds is spent reading references)."""
        n, k = len(self.gait), len(dts)
        gait = self.gait.repeat(k)
        ahead = torch.tensor(dts, dtype=self.phase.dtype, device=self.device).repeat_interleave(n)
        whole = self._frame(gait, self.phase.repeat(k) + ahead * self._rate[gait], self._offset.repeat(k, 1),
                            self._yaw.repeat(k))
        fields = whole.__dataclass_fields__
        return [ReferenceFrame(**{f: getattr(whole, f)[i * n:(i + 1) * n] for f in fields}) for i in range(k)]

    def _frame(self, gait: torch.Tensor, phase: torch.Tensor, offset: torch.Tensor, yaw: torch.Tensor
               ) -> ReferenceFrame:
        """The reference of rows imitating ``gait`` at ``phase``, anchored by ``offset`` (rows, 3) and ``yaw``."""
        clip = self._clip_frames(gait, phase)
        anchor = quat_from_yaw(yaw)
        heading = quat_from_yaw(yaw_of(clip.root_quat))
        rel_feet = clip.foot_pos_world - clip.root_pos.unsqueeze(1)
        return ReferenceFrame(
            root_pos=offset + quat_rotate(anchor, clip.root_pos),
            root_quat=quat_multiply(anchor, clip.root_quat),
            root_lin_vel=quat_rotate(anchor, clip.root_lin_vel),
            root_ang_vel=clip.root_ang_vel,
            heading_lin_vel=quat_rotate_inverse(heading, clip.root_lin_vel),
            joint_pos=clip.joint_pos,
            joint_vel=clip.joint_vel,
            foot_pos_heading=quat_rotate_inverse(heading.unsqueeze(1), rel_feet),
            contact=clip.contact,
        )

    def _clip_frames(self, gait: torch.Tensor, phase: torch.Tensor) -> ClipFrame:
        """Clip frames of each world's own gait (one read of the clips, whatever the gaits present)."""
        return self._bank.frame(gait, phase)
