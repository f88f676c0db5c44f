"""Reference clips: a robot motion stored as frames on a uniform phase grid, read back at any phase.

A clip holds ``K + 1`` frames at phases ``k / K`` (k = 0..K), so the first and last frames bracket the whole clip.
A looping clip repeats with period :attr:`ReferenceClip.period`: its last frame is its first frame turned by
:attr:`ReferenceClip.cycle_yaw` about the vertical through the first frame's trunk and shifted by
:attr:`ReferenceClip.cycle_displacement`, so joint angles and velocities wrap seamlessly and the trunk advances
(and turns) by that much per cycle. Cycle k's frames are cycle 0's turned by ``k * cycle_yaw`` about that vertical
and shifted by the displacements of the cycles before, each turned by its own cycle's yaw:
``sum_{i<k} Rz(i * cycle_yaw) cycle_displacement`` (a trunk that turns runs on a circle and comes back). A
non-looping clip holds its end frames outside [0, 1].

Frames are linearly interpolated (the orientation by normalized linear interpolation); contact flags come from
the nearest frame. Units SI; the world frame is z up; quaternions are (w, x, y, z), trunk to world.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import torch

from gaitlib.gaits.kinematics import forward_kinematics
from gaitlib.robots.a1.constants import NUM_JOINTS, NUM_LEGS
from gaitlib.rotations import quat_conjugate, quat_from_yaw, quat_multiply, quat_rotate, quat_to_rotation_vector

__all__ = ["ClipBank", "ClipFrame", "ReferenceClip", "clip_bank"]


@dataclass
class ClipFrame:
    """Reference quantities of N robots, each at its own phase (``torch.float32`` unless noted)."""

    root_pos: torch.Tensor
    """(N, 3) trunk position in the world frame, m, counting whole cycles of a looping clip."""
    root_quat: torch.Tensor
    """(N, 4) trunk orientation (w, x, y, z), trunk to world."""
    root_lin_vel: torch.Tensor
    """(N, 3) trunk linear velocity in the world frame, m/s."""
    root_ang_vel: torch.Tensor
    """(N, 3) trunk angular velocity in the trunk frame, rad/s."""
    joint_pos: torch.Tensor
    """(N, 12) joint angles in :data:`~gaitlib.robots.a1.constants.JOINT_NAMES` order, rad."""
    joint_vel: torch.Tensor
    """(N, 12) joint velocities, rad/s."""
    foot_pos_local: torch.Tensor
    """(N, 4, 3) foot contact-sphere centres in the trunk frame, leg order FR, FL, RR, RL, m."""
    foot_pos_world: torch.Tensor
    """(N, 4, 3) foot contact-sphere centres in the world frame, m."""
    contact: torch.Tensor
    """(N, 4) ``torch.bool``: the foot is on the ground."""

    @property
    def root_height(self) -> torch.Tensor:
        """(N,) trunk height above the ground, m."""
        return self.root_pos[:, 2]


# Columns of the interpolation table, in order, with their per-frame widths.
_TABLE_FIELDS = (
    ("root_pos", 3),
    ("root_quat", 4),
    ("root_lin_vel", 3),
    ("root_ang_vel", 3),
    ("joint_pos", NUM_JOINTS),
    ("joint_vel", NUM_JOINTS),
    ("foot_pos_local", NUM_LEGS * 3),
    ("foot_pos_world", NUM_LEGS * 3),
)


@dataclass(frozen=True, kw_only=True, eq=False)
class ReferenceClip:
    """A reference motion of the A1 as ``K + 1`` frames on the phase grid ``k / K`` (arrays are read-only).

    Build one with :meth:`from_frames` (velocities, feet and the orientation table are derived there), from a gait
    description with :func:`gaitlib.gaits.clip_from_description`, or from a motion file with
    :func:`gaitlib.gaits.load_motion_file`; read it at any phase with :meth:`frame`.
    """

    name: str
    """Where the clip came from: the gait name or the motion file's stem."""
    frame_duration: float
    """Time between consecutive frames, s."""
    loop: bool
    """Whether the clip repeats (phase wraps) or holds its end frames (phase clamps to [0, 1])."""
    root_pos: np.ndarray
    """(K+1, 3) trunk position in the world frame, m."""
    root_quat: np.ndarray
    """(K+1, 4) trunk orientation (w, x, y, z), consecutive frames in the same hemisphere."""
    root_lin_vel: np.ndarray
    """(K+1, 3) trunk linear velocity in the world frame, m/s."""
    root_ang_vel: np.ndarray
    """(K+1, 3) trunk angular velocity in the trunk frame, rad/s."""
    joint_pos: np.ndarray
    """(K+1, 12) joint angles, rad."""
    joint_vel: np.ndarray
    """(K+1, 12) joint velocities, rad/s."""
    foot_pos_local: np.ndarray
    """(K+1, 4, 3) foot contact-sphere centres in the trunk frame, m."""
    foot_pos_world: np.ndarray
    """(K+1, 4, 3) foot contact-sphere centres in the world frame, m."""
    contact: np.ndarray
    """(K+1, 4) bool: the foot is on the ground."""
    cycle_displacement: np.ndarray
    """(3,) world-frame trunk displacement over cycle 0 of a looping clip, last frame's trunk minus first's, m
    (zero for a non-looping clip; z is 0)."""
    cycle_yaw: float = 0.0
    """Trunk turn per cycle of a looping clip, rad, counter-clockwise, in (-pi, pi) (0 for a non-looping clip)."""
    _tables: dict[torch.device, tuple[torch.Tensor, ...]] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        frames = self.root_pos.shape[0]
        if frames < (3 if self.loop else 2) or self.frame_duration <= 0.0:
            raise ValueError("a reference clip needs 2 frames (3 if looping) and a positive frame duration")
        shapes = {
            "root_pos": (frames, 3),
            "root_quat": (frames, 4),
            "root_lin_vel": (frames, 3),
            "root_ang_vel": (frames, 3),
            "joint_pos": (frames, NUM_JOINTS),
            "joint_vel": (frames, NUM_JOINTS),
            "foot_pos_local": (frames, NUM_LEGS, 3),
            "foot_pos_world": (frames, NUM_LEGS, 3),
            "contact": (frames, NUM_LEGS),
            "cycle_displacement": (3,),
        }
        for name, shape in shapes.items():
            array = np.array(getattr(self, name), dtype=bool if name == "contact" else np.float64)
            if array.shape != shape:
                raise ValueError(f"reference clip field {name} has shape {array.shape}, expected {shape}")
            array.setflags(write=False)
            object.__setattr__(self, name, array)
        turn = self.cycle_yaw
        if isinstance(turn, bool) or not isinstance(turn, (int, float)) or not abs(turn) < math.pi:
            raise ValueError(f"a clip's cycle_yaw must be a number of rad in (-pi, pi), got {turn!r}")
        if turn != 0.0 and not self.loop:
            raise ValueError("only a looping clip turns per cycle (cycle_yaw must be 0)")
        object.__setattr__(self, "cycle_yaw", float(turn))

    @classmethod
    def from_frames(
        cls,
        *,
        name: str,
        frame_duration: float,
        loop: bool,
        root_pos: np.ndarray,
        root_quat: np.ndarray,
        joint_pos: np.ndarray,
        contact: np.ndarray,
        cycle_displacement: np.ndarray | None = None,
        cycle_yaw: float = 0.0,
    ) -> ReferenceClip:
        """Build a clip from poses, deriving velocities by central finite differences and feet by kinematics.

        Args:
            name: see :attr:`name`.
            frame_duration: time between frames, s.
            loop: see :attr:`loop`. A looping clip's last frame must be its first pose, turned by ``cycle_yaw``
                and displaced by ``cycle_displacement`` (the module docstring); differences then wrap around the
                seam.
            root_pos: (K+1, 3) trunk positions, world frame, m.
            root_quat: (K+1, 4) trunk orientations (w, x, y, z); normalized here.
            joint_pos: (K+1, 12) joint angles, rad.
            contact: (K+1, 4) bool foot contacts.
            cycle_displacement: (3,) trunk displacement over cycle 0, m; defaults to zero.
            cycle_yaw: trunk turn per cycle, rad; defaults to zero.
        """
        root_pos = np.asarray(root_pos, dtype=np.float64)
        joint_pos = np.asarray(joint_pos, dtype=np.float64)
        quat = np.asarray(root_quat, dtype=np.float64)
        quat = quat / np.linalg.norm(quat, axis=-1, keepdims=True)
        for k in range(1, quat.shape[0]):  # same hemisphere as the previous frame, for interpolation
            if np.dot(quat[k], quat[k - 1]) < 0.0:
                quat[k] = -quat[k]
        displacement = np.zeros(3) if cycle_displacement is None else np.asarray(cycle_displacement, np.float64)
        if not loop:
            displacement, cycle_yaw = np.zeros(3), 0.0

        prev, nxt, span = _neighbours(len(root_pos), frame_duration, loop=loop)
        lin_vel = (root_pos[nxt] - root_pos[prev]) / span
        before, after = quat[prev], quat[nxt]
        if loop:
            # The seam frames' outer neighbours lie in the cycles before and after: the step before the first frame
            # is the step before the last turned back by a cycle's yaw, the step after the last frame the step after
            # the first turned on by it (without yaw: both just one displacement further).
            step_in, step_out = root_pos[-2] - root_pos[-1], root_pos[1] - root_pos[0]
            seam = displacement + np.stack(
                [step_in - _turn(step_in, -cycle_yaw), _turn(step_out, cycle_yaw) - step_out]
            )
            lin_vel[[0, -1]] += seam / span[[0, -1]]
            if cycle_yaw != 0.0:
                before[0] = quat_multiply(quat_from_yaw(np.float64(-cycle_yaw)), quat[-2])
                after[-1] = quat_multiply(quat_from_yaw(np.float64(cycle_yaw)), quat[1])
        ang_vel = quat_to_rotation_vector(quat_multiply(quat_conjugate(before), after)) / span
        joint_vel = (joint_pos[nxt] - joint_pos[prev]) / span
        feet_local = forward_kinematics(joint_pos)
        feet_world = root_pos[:, None, :] + quat_rotate(quat[:, None, :], feet_local)
        return cls(
            name=name,
            frame_duration=float(frame_duration),
            loop=loop,
            root_pos=root_pos,
            root_quat=quat,
            root_lin_vel=lin_vel,
            root_ang_vel=ang_vel,
            joint_pos=joint_pos,
            joint_vel=joint_vel,
            foot_pos_local=feet_local,
            foot_pos_world=feet_world,
            contact=contact,
            cycle_displacement=displacement,
            cycle_yaw=cycle_yaw,
        )

    @property
    def num_frames(self) -> int:
        """Number of stored frames, K + 1."""
        return self.root_pos.shape[0]

    @property
    def period(self) -> float:
        """Duration of the clip (one cycle of a looping clip), s."""
        return self.frame_duration * (self.num_frames - 1)

    @property
    def phase_rate(self) -> float:
        """Phase advance per second, cycles/s (``1 / period``)."""
        return 1.0 / self.period

    def frame(self, phase: torch.Tensor) -> ClipFrame:
        """Interpolated reference at each of N phases, on ``phase.device``.

        Args:
            phase: (N,) phase in cycles. A looping clip wraps it (a phase of 2.25 is a quarter into the third
                cycle, with the trunk two cycle displacements further on, and turned by two cycle yaws); a
                non-looping clip clamps it to [0, 1].

        Returns:
            The :class:`ClipFrame` of the N phases.
        """
        gait = torch.zeros(phase.shape[0], dtype=torch.long, device=phase.device)
        return clip_bank((self,), phase.device).frame(gait, phase)

    def _device_tables(self, device: torch.device) -> tuple[torch.Tensor, ...]:
        """The float32 frame table (K+1, 61), contact table (K+1, 4), displacement (3,) and turn (6,) on ``device``:
        the cycle yaw (rad), the pivot (the first frame's trunk on the ground, m) and the turning sum's factor
        ``d / (1 - e^{i yaw})`` as (real, imaginary), m."""
        if device not in self._tables:
            rows = np.concatenate([getattr(self, n).reshape(self.num_frames, w) for n, w in _TABLE_FIELDS], axis=1)
            d = complex(*self.cycle_displacement[:2])
            circle = d / (1.0 - complex(math.cos(self.cycle_yaw), math.sin(self.cycle_yaw))) if self.cycle_yaw else 0j
            pivot = (*self.root_pos[0, :2], 0.0)
            self._tables[device] = (
                torch.tensor(rows, dtype=torch.float32, device=device),
                torch.tensor(self.contact, device=device),
                torch.tensor(self.cycle_displacement, dtype=torch.float32, device=device),
                torch.tensor([self.cycle_yaw, *pivot, circle.real, circle.imag], dtype=torch.float32, device=device),
            )
        return self._tables[device]


class ClipBank:
    """Several clips read as one: every row of a batch at its own clip and phase, in one interpolation whatever the
    number of clips among the rows (per control step at a few worlds, reading references is most of an
    environment's own time, and a read per clip would multiply it). Build one with :func:`clip_bank`."""

    def __init__(self, clips: tuple[ReferenceClip, ...], device: torch.device) -> None:
        tables = [clip._device_tables(device) for clip in clips]
        frames = [clip.num_frames for clip in clips]
        self._table = torch.cat([t[0] for t in tables])  # (sum of K+1, 61): the clips' frame tables one after another
        self._contact = torch.cat([t[1] for t in tables])
        self._start = torch.tensor([sum(frames[:i]) for i in range(len(clips))], device=device)  # first row per clip
        self._intervals = torch.tensor([k - 1 for k in frames], device=device)  # K per clip
        self._loop = torch.tensor([clip.loop for clip in clips], device=device)
        self._displacement = torch.stack([t[2] for t in tables])  # (G, 3), m
        self._turn = torch.stack([t[3] for t in tables])  # (G, 6): see ReferenceClip._device_tables
        self._turning = torch.tensor([clip.cycle_yaw != 0.0 for clip in clips], device=device)
        self._any_turning = bool(self._turning.any())
        self._one = len(clips) == 1

    def _of(self, gait: torch.Tensor) -> Callable[[torch.Tensor], torch.Tensor]:
        """Each row's value of a per-clip table (G, ...): one clip's (1, ...) row broadcasts, unread per row."""
        return (lambda table: table) if self._one else (lambda table: table[gait])

    def frame(self, gait: torch.Tensor, phase: torch.Tensor) -> ClipFrame:
        """Each of N rows at its clip's index ``gait`` (N,) and its ``phase`` (N,) in cycles: row for row what that
        clip's :meth:`ReferenceClip.frame` gives (the same operations; a batch's last bits may follow the vector
        width of torch's CPU loops, so tests hold it to float32's relative 1e-6)."""
        phase = phase.to(torch.float32)
        of = self._of(gait)
        loop, intervals = of(self._loop), of(self._intervals)
        cycles = torch.where(loop, torch.floor(phase), 0.0)
        fraction = torch.where(loop, phase - cycles, phase.clamp(0.0, 1.0))
        position = fraction * intervals.to(torch.float32)
        lower = torch.minimum(position.floor().long().clamp(min=0), intervals - 1)
        weight = (position - lower).unsqueeze(-1)
        at = of(self._start) + lower
        row = self._table[at] * (1.0 - weight) + self._table[at + 1] * weight
        values = dict(zip((n for n, _ in _TABLE_FIELDS), row.split([w for _, w in _TABLE_FIELDS], dim=-1),
                          strict=True))
        count = phase.shape[0]
        root_quat = torch.nn.functional.normalize(values["root_quat"], dim=-1)
        root_pos, root_lin_vel = values["root_pos"], values["root_lin_vel"]
        foot_pos_world = values["foot_pos_world"].reshape(count, NUM_LEGS, 3)
        shift = cycles.unsqueeze(-1) * of(self._displacement)
        moved_root, moved_feet = root_pos + shift, foot_pos_world + shift.unsqueeze(1)
        if self._any_turning:  # turned by k cycle yaws about the first frame's trunk, shifted by the turned
            # displacements before: sum_{i<k} Rz(i yaw) d = c (1 - e^{i k yaw}) in the complex plane,
            # c = d / (1 - e^{i yaw})
            rows = self._turning[gait].nonzero().squeeze(1)
            turn, k = self._turn[gait[rows]], cycles[rows]
            yaw, pivot, circle = turn[:, 0], turn[:, 1:4], turn[:, 4:6]
            spin = quat_from_yaw(k * yaw)
            cos, sin = torch.cos(k * yaw), torch.sin(k * yaw)
            shift = torch.stack([circle[:, 0] * (1.0 - cos) + circle[:, 1] * sin,
                                 circle[:, 1] * (1.0 - cos) - circle[:, 0] * sin, torch.zeros_like(cos)], dim=-1)
            shift = shift + pivot
            moved_root[rows] = quat_rotate(spin, root_pos[rows] - pivot) + shift
            feet = foot_pos_world[rows] - pivot.unsqueeze(1)
            moved_feet[rows] = quat_rotate(spin.unsqueeze(1), feet) + shift.unsqueeze(1)
            root_quat[rows] = quat_multiply(spin, root_quat[rows])
            root_lin_vel = root_lin_vel.clone()
            root_lin_vel[rows] = quat_rotate(spin, root_lin_vel[rows])
        nearest = torch.minimum(position.round().long().clamp(min=0), intervals)
        return ClipFrame(
            root_pos=moved_root,
            root_quat=root_quat,
            root_lin_vel=root_lin_vel,
            root_ang_vel=values["root_ang_vel"],
            joint_pos=values["joint_pos"],
            joint_vel=values["joint_vel"],
            foot_pos_local=values["foot_pos_local"].reshape(count, NUM_LEGS, 3),
            foot_pos_world=moved_feet,
            contact=self._contact[of(self._start) + nearest],
        )


@functools.lru_cache(maxsize=32)
def clip_bank(clips: tuple[ReferenceClip, ...], device: torch.device) -> ClipBank:
    """The :class:`ClipBank` of ``clips`` on ``device``, built once (a guard builds a reference tracker on the same
    clips every control step)."""
    return ClipBank(clips, device)


def _turn(vector: np.ndarray, yaw: float) -> np.ndarray:
    """(3,) ``vector`` turned by ``yaw`` rad about z (itself, exactly, for a yaw of 0)."""
    cos, sin = math.cos(yaw), math.sin(yaw)
    return np.array([cos * vector[0] - sin * vector[1], sin * vector[0] + cos * vector[1], vector[2]])


def _neighbours(frames: int, frame_duration: float, *, loop: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Indices of the previous and next frames for central differences and the time between them, s.

    A looping clip's first and last frames are the same pose, so their outer neighbours are the second and the
    second-to-last frames; a non-looping clip uses one-sided differences at its ends.
    """
    index = np.arange(frames)
    last = frames - 1
    if loop:
        prev = np.where(index == 0, last - 1, index - 1)
        nxt = np.where(index == last, 1, index + 1)
        span = np.full(frames, 2.0 * frame_duration)
    else:
        prev = np.maximum(index - 1, 0)
        nxt = np.minimum(index + 1, last)
        span = (nxt - prev) * frame_duration
    return prev, nxt, span[:, None]
