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
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gaitlib.atomic import atomic_path
from gaitlib.errors import GaitlibError

__all__ = ["FORMAT", "HandoverStates", "load_states"]

FORMAT = {"format": "gaitlib.handover_states", "format_version": 1}
"""Header of a handover-states file (``.npz``: the arrays, and ``meta``, a JSON string)."""

ARRAYS = ("source", "phase", "root_height", "root_quat", "root_lin_vel", "root_ang_vel", "joint_pos", "joint_vel",
          "history", "last_reading", "action", "targets")
"""The per-state arrays, in file order."""


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
        return dataclasses.replace(self, **{name: getattr(self, name)[rows] for name in ARRAYS})

    def save(self, path: Path) -> Path:
        """Write the states to ``path`` (``.npz``), atomically."""
        meta = FORMAT | {"gaits": list(self.gaits), "identities": self.identities, "settings": self.settings}
        with atomic_path(Path(path)) as tmp, open(tmp, "wb") as handle:
            np.savez(handle, meta=np.array(json.dumps(meta)), **{name: getattr(self, name) for name in ARRAYS})
        return Path(path)


def load_states(path: Path) -> tuple[HandoverStates, str]:
    """The states in ``path`` and the file's SHA-256; a one-line :class:`GaitlibError` for a missing, foreign,
    damaged or non-finite file."""
    path = Path(path)
    try:
        data = path.read_bytes()  # read once: the checksum is of the bytes loaded
        with np.load(io.BytesIO(data), allow_pickle=False) as npz:
            meta = json.loads(str(npz["meta"]))
            arrays = {name: npz[name] for name in ARRAYS}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as error:  # the zip's CRC-32 catches flips
        raise GaitlibError(f"{path} is not a readable handover-states file ({type(error).__name__})") from None
    if not isinstance(meta, dict) or {k: meta.get(k) for k in FORMAT} != FORMAT:
        raise GaitlibError(f"{path} is not a gaitlib handover-states file of format version 1")
    count = len(arrays["source"])
    gaits = tuple(meta.get("gaits", ()))
    if count == 0 or any(len(a) != count for a in arrays.values()):
        raise GaitlibError(f"{path} is damaged: its arrays hold different numbers of states (or none)")
    source = arrays["source"]
    if not all(np.isfinite(a).all() for a in arrays.values()) or source.min() < 0 or source.max() >= len(gaits):
        raise GaitlibError(f"{path} is damaged: a state is not finite, or names a gait the file does not list")
    states = HandoverStates(gaits, dict(meta["identities"]), dict(meta["settings"]), **arrays)
    return states, hashlib.sha256(data).hexdigest()
