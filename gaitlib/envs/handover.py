"""Handover states: what a policy inherits when the meta-controller switches to it (switch-start training).

A switch leaves the destination policy with the robot as the source gait left it: its joints, trunk and
velocities, and the actor's observation history (the last frames and the source policy's previous actions), while
the reference is re-anchored where the robot stands and faces (:meth:`ImitationEnv.switch`). A
:class:`HandoverStates` holds such states, recorded while library gaits ran (:mod:`gaitlib.transitions.states`),
so that training can start a share of its episodes from them (:meth:`ImitationEnv.hand_over`): the destination
policy learns to take over from the states it will really be handed, not only from its own reference (reference
state initialization). The Expert Composer Policy (Christmann, Luo, Chen, ICRA 2024, arXiv:2403.11412) observes
that a destination expert fails where the current state is outside the distribution it learned; switch-start
training widens that distribution inside each expert.

States are stored heading-free: the trunk's yaw is removed (its position is the origin at its height, its velocity
turned with it), which changes nothing the policy sees, since every observation is in the trunk or heading frame
and the reference follows the robot's heading.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import math
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gaitlib.atomic import atomic_path
from gaitlib.checks import (
    GAIT_NAME,
    RANDOMIZATION,
    SHA256,
    check_content,
    items,
    number,
    plain,
    record,
    span,
    table,
    text,
)
from gaitlib.envs import observations as obs_fn
from gaitlib.errors import GaitlibError

__all__ = ["ARRAYS", "FORMAT", "LIMITS", "PUSH_ARRAYS", "HandoverStates", "load_states"]

FORMAT = {"format": "gaitlib.handover_states", "format_version": 1}
"""Header of a handover-states file (``.npz``: the arrays, and ``meta``, a JSON string)."""

ARRAYS = ("source", "phase", "root_height", "root_quat", "root_lin_vel", "root_ang_vel", "joint_pos", "joint_vel",
          "history", "last_reading", "action", "targets")
"""The per-state arrays, in file order."""

PUSH_ARRAYS = ("push_force", "push_steps")
"""The arrays of the push under way at each state, which a file recorded under single shoves holds (``gaitlib
states --shove-max``) and a file without them does not: a hand-over continues the push (both or neither)."""


@dataclass(frozen=True)
class HandoverStates:
    """S recorded states (numpy arrays, first axis S) and what they were recorded with."""

    gaits: tuple[str, ...]
    """Gaits of the library they were recorded in (``source`` indexes them)."""
    identities: dict[str, str]
    """Gait -> identity of the policy that ran it."""
    settings: dict
    """How they were recorded (worlds, pushes, warm-up, seed, randomization)."""
    source: np.ndarray
    """(S,) index into :attr:`gaits` of the gait that ran."""
    phase: np.ndarray
    """(S,) its phase at the moment recorded, cycles in [0, 1)."""
    root_height: np.ndarray
    """(S,) trunk height, m."""
    root_quat: np.ndarray
    """(S, 4) trunk orientation with its yaw removed (w, x, y, z)."""
    root_lin_vel: np.ndarray
    """(S, 3) trunk velocity in the yaw-free frame, m/s."""
    root_ang_vel: np.ndarray
    """(S, 3) trunk angular velocity, trunk frame, rad/s."""
    joint_pos: np.ndarray
    """(S, J) joint angles, rad."""
    joint_vel: np.ndarray
    """(S, J) joint velocities, rad/s."""
    history: np.ndarray
    """(S, HISTORY, FRAME_DIM) the observed frames the actor reads, newest first (latency and noise included)."""
    last_reading: np.ndarray
    """(S, FRAME_DIM) the clean frame of the last step (the next frame's latency interpolates from it)."""
    action: np.ndarray
    """(S, J) the source policy's last action (after clipping), action units."""
    targets: np.ndarray
    """(S, D, J) PD targets of the last D steps, newest first, rad (what a delayed servo still has to apply)."""
    push_force: np.ndarray | None = None
    """(S, 3) the push on the trunk under way when the state was taken, in the yaw-free frame, N (0: none); ``None``:
    the file records no pushes, and a hand-over starts none (:data:`PUSH_ARRAYS`)."""
    push_steps: np.ndarray | None = None
    """(S,) the control steps that push still lasts after the state (0: none), a whole number as a float."""

    @property
    def arrays(self) -> tuple[str, ...]:
        """The per-state arrays these states hold: :data:`ARRAYS`, then :data:`PUSH_ARRAYS` where recorded."""
        return ARRAYS + (PUSH_ARRAYS if self.push_force is not None else ())

    def __len__(self) -> int:
        return len(self.source)

    def rows(self, exclude: str | None = None) -> np.ndarray:
        """Indices of the states recorded while a gait other than ``exclude`` ran."""
        keep = np.ones(len(self), dtype=bool)
        if exclude is not None and exclude in self.gaits:
            keep &= self.source != self.gaits.index(exclude)
        return np.flatnonzero(keep)

    def select(self, rows: np.ndarray) -> HandoverStates:
        """The states ``rows``."""
        return dataclasses.replace(self, **{name: getattr(self, name)[rows] for name in self.arrays})

    def save(self, path: Path) -> Path:
        """Write the states to ``path`` (``.npz``), atomically."""
        meta = FORMAT | {"gaits": list(self.gaits), "identities": self.identities, "settings": self.settings}
        with atomic_path(Path(path)) as tmp, open(tmp, "wb") as handle:
            np.savez(handle, meta=np.array(json.dumps(meta)), **{name: getattr(self, name) for name in self.arrays})
        return Path(path)


def load_states(path: Path) -> tuple[HandoverStates, str]:
    """The states in ``path`` and the file's SHA-256; a one-line :class:`GaitlibError` for a missing, foreign or
    damaged file: one whose header, gaits, identities or settings are not of the format, or whose arrays are
    missing, of the wrong shape or type, not finite or out of their physical range (:data:`LIMITS`)."""
    path = Path(path)
    try:
        data = path.read_bytes()  # read once: the checksum is of the bytes loaded
        with np.load(io.BytesIO(data), allow_pickle=False) as npz:
            names = set(npz.files)
            meta = json.loads(str(npz["meta"]))
            arrays = {name: npz[name] for name in ARRAYS + PUSH_ARRAYS if name in names}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as error:  # the zip's CRC-32 catches flips
        raise GaitlibError(f"{path} is not a readable handover-states file ({type(error).__name__})") from None
    if not isinstance(meta, dict) or {k: meta.get(k) for k in FORMAT} != FORMAT:
        raise GaitlibError(f"{path} is not a gaitlib handover-states file of format version 1")
    damaged = f"{path} is damaged: "
    for name in ARRAYS:
        if name not in arrays:
            raise GaitlibError(f"{damaged}array {name} is missing")
    unknown = sorted(names - set(ARRAYS + PUSH_ARRAYS) - {"meta"})
    if unknown:
        raise GaitlibError(f"{damaged}array {unknown[0]} is not one of a handover-states file")
    if len(set(PUSH_ARRAYS) & names) == 1:
        raise GaitlibError(f"{damaged}it holds one of the arrays {' and '.join(PUSH_ARRAYS)} without the other")
    check_content(meta, _META, error=GaitlibError, prefix=damaged)
    gaits = tuple(meta["gaits"])
    if set(meta["identities"]) != set(gaits):
        raise GaitlibError(f"{damaged}identities name {', '.join(sorted(meta['identities']))}, the file's gaits are "
                           f"{', '.join(gaits)}")
    _check_arrays(arrays, len(gaits), damaged)
    states = HandoverStates(gaits, dict(meta["identities"]), dict(meta["settings"]), **arrays)
    return states, hashlib.sha256(data).hexdigest()


_META = record({
    "format": text(), "format_version": number(whole=True),
    "gaits": items(GAIT_NAME, low=1, unique=True, ordered=True),
    "identities": table(GAIT_NAME, SHA256, low=1),
    "settings": record(
        {
            "per_gait": number(1, 1e8, whole=True), "push_max": number(0, 2000, unit="N"),
            "num_worlds": number(1, 65536, whole=True), "warmup_s": number(0, 600, unit="s"),
            "spacing_s": number(0, 600, low_open=True, unit="s"), "backend": text(("mujoco", "newton")),
            "seed": number(0, 2**32 - 1, whole=True),
        },
        {"push_interval_s": span(0, 600, unit="s"), "randomization": RANDOMIZATION, "recorded": text()},
        extra=plain(),
    ),
})
"""The schema of a handover-states file's ``meta`` (:class:`HandoverStates`, :class:`~gaitlib.transitions.states.
StatesConfig`); ``source`` indexes ``gaits``, which are in canonical (sorted) order."""

_JOINTS = next(f.width for f in obs_fn.FRAME if f.name == "joint_pos")
"""J: joints of the robot the frames describe (the A1's 12)."""

QUAT_TOLERANCE = 1e-3
"""How far the norm of a stored ``root_quat`` may be from 1 (float32 rounding is about 1e-7)."""

LIMITS = {
    "phase": (0.0, 1.0, "cycles"),
    "root_quat": (-1.0 - QUAT_TOLERANCE, 1.0 + QUAT_TOLERANCE, "(a unit quaternion's components)"),
    "root_height": (0.0, 2.0, "m"),
    "root_lin_vel": (-100.0, 100.0, "m/s"),
    "root_ang_vel": (-1000.0, 1000.0, "rad/s"),
    "joint_pos": (-2 * math.pi, 2 * math.pi, "rad"),
    "joint_vel": (-1000.0, 1000.0, "rad/s"),
    "history": (-1000.0, 1000.0, "(observation units)"),
    "last_reading": (-1000.0, 1000.0, "(observation units)"),
    "action": (-100.0, 100.0, "action units"),
    "targets": (-2 * math.pi, 2 * math.pi, "rad"),
    "push_force": (-1e5, 1e5, "N"),
    "push_steps": (0.0, 1e4, "control steps"),
}
"""Array -> (lowest, highest, unit) of each of its values: a physical range (a trunk between the ground and 2 m, a
joint within a turn either way) or a sanity bound far beyond what a robot that runs reaches. A root height of 0 is
refused too (the trunk is above the ground), and ``root_quat`` must be a unit quaternion within
:data:`QUAT_TOLERANCE`."""

MAX_DELAY_LINE = 32
"""Most PD targets a state may carry in ``targets`` (the delay line: the trained action delay plus one)."""


def _check_arrays(arrays: dict[str, np.ndarray], num_gaits: int, damaged: str) -> None:
    """Shapes, types, finiteness and ranges of the per-state arrays (``damaged`` opens each one-line refusal)."""
    source = arrays["source"]
    if source.ndim != 1 or len(source) == 0 or source.dtype.kind not in "iu":
        raise GaitlibError(f"{damaged}source must be a list of gait indices (integers), got {source.dtype} of "
                           f"shape {source.shape}")
    count, targets = len(source), arrays["targets"]
    if targets.ndim != 3 or not 1 <= targets.shape[1] <= MAX_DELAY_LINE:
        raise GaitlibError(f"{damaged}targets must have shape (S, D, J) with D in [1, {MAX_DELAY_LINE}], got "
                           f"{targets.shape}")
    shapes = {
        "phase": (), "root_height": (), "root_quat": (4,), "root_lin_vel": (3,), "root_ang_vel": (3,),
        "joint_pos": (_JOINTS,), "joint_vel": (_JOINTS,), "history": (obs_fn.HISTORY, obs_fn.FRAME_DIM),
        "last_reading": (obs_fn.FRAME_DIM,), "action": (_JOINTS,), "targets": (targets.shape[1], _JOINTS),
    } | ({"push_force": (3,), "push_steps": ()} if "push_force" in arrays else {})
    for name, trailing in shapes.items():
        values = arrays[name]
        if values.shape != (count, *trailing):
            raise GaitlibError(f"{damaged}{name} must have shape {(count, *trailing)} ({count} states, "
                               f"{_JOINTS} joints, frames of {obs_fn.FRAME_DIM}), got {values.shape}")
        if values.dtype.kind != "f":
            raise GaitlibError(f"{damaged}{name} must hold floating-point numbers, got {values.dtype}")
        low, high, unit = LIMITS[name]
        finite = np.isfinite(values)
        inside = finite & (values >= low) & (values <= high) & ((values > 0) if name == "root_height" else True)
        if not inside.all():
            state = int(np.argwhere(~inside)[0][0])
            what = "is not finite" if not finite[state].all() else f"lies outside [{low:g}, {high:g}] {unit}"
            raise GaitlibError(f"{damaged}{name} of state {state} {what}")
    norms = np.linalg.norm(arrays["root_quat"].astype(np.float64), axis=1)
    off = np.flatnonzero(np.abs(norms - 1) > QUAT_TOLERANCE)
    if len(off):
        raise GaitlibError(f"{damaged}root_quat of state {off[0]} is not a unit quaternion (norm {norms[off[0]]:.6g})")
    wrong = np.flatnonzero((source < 0) | (source >= num_gaits))
    if len(wrong):
        raise GaitlibError(f"{damaged}source of state {wrong[0]} is gait index {source[wrong[0]]}, the file lists "
                           f"{num_gaits} gaits")
