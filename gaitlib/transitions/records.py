"""Transition samples in memory: the per-sample columns (:data:`COLUMNS`, the datasets of a transition file), a
batch of samples, and what a file's samples belong to (:class:`TransitionHeader`)."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from gaitlib.defaults import Falls

__all__ = [
    "COLUMNS",
    "Column",
    "TransitionBatch",
    "TransitionData",
    "TransitionFileInfo",
    "TransitionHeader",
    "content_sha256",
]


@dataclass(frozen=True)
class Column:
    """One per-sample dataset."""

    dtype: str
    """numpy dtype name."""
    width: str | None
    """``None`` for a scalar per row, ``"latent"`` for (L,), ``"explicit"`` for (E,)."""
    units: str
    """SI units (``"1"`` for dimensionless, ``"index"``, ``"cycles"``)."""
    description: str
    """What the value is."""


COLUMNS: dict[str, Column] = {
    "source": Column("int8", None, "index", "source gait m: index into the file attribute 'gaits'"),
    "dest": Column("int8", None, "index", "destination gait n: index into the file attribute 'gaits'"),
    "latent": Column("float32", "latent", "1", "psi_m: source actor's last hidden layer just before the switch"),
    "phase_source": Column("float32", None, "cycles", "phi_m: source reference phase at the switch, in [0, 1)"),
    "phase_dest": Column("float32", None, "cycles", "phi_n: destination phase switched to, in [0, 1)"),
    "explicit": Column("float32", "explicit", "mixed", "source's explicit state at the switch (explicit_layout)"),
    "value_source": Column("float32", None, "1", "source critic value before the switch"),
    "value_dest": Column("float32", None, "1", "destination critic value on the observation right after the switch"),
    "push_force": Column("float32", None, "N", "largest push magnitude of the source run before the switch (0: none)"),
    "success": Column("uint8", None, "1", "alpha: 1 if no fall (trunk definition: the trunk too low, tilted or on the "
                      "ground) from the request until the horizon after the switch"),
    "switch_time": Column("float32", None, "s", "time of the switch since the world's episode start"),
    "world": Column("int32", None, "index", "world that produced the sample"),
    "chunk": Column("int32", None, "index", "write batch (counted over all collection runs of the file)"),
    "fall_after": Column("float32", None, "s", "time from the switch to the fall; inf: up over the whole horizon"),
    "success_contact": Column("uint8", None, "1", "alpha by the contact definition: 1 if, besides, no non-foot body "
                              "touched the ground from the request until the horizon after the switch"),
    "longest_touch": Column("float32", None, "s", "longest unbroken touch of a non-foot body on the ground from the "
                            "request until the horizon after the switch (0: none)"),
}
"""The per-sample datasets, in file order."""


@dataclass
class TransitionBatch:
    """Samples as numpy arrays, one row each; field names, dtypes and meanings are those of :data:`COLUMNS`."""

    source: np.ndarray
    dest: np.ndarray
    latent: np.ndarray
    """(n, L)."""
    phase_source: np.ndarray
    phase_dest: np.ndarray
    explicit: np.ndarray
    """(n, E)."""
    value_source: np.ndarray
    value_dest: np.ndarray
    push_force: np.ndarray
    success: np.ndarray
    switch_time: np.ndarray
    world: np.ndarray
    chunk: np.ndarray
    fall_after: np.ndarray | None = None
    """``None``: not recorded (all nan)."""
    success_contact: np.ndarray | None = None
    """``None``: no touch recorded (``success`` by both definitions)."""
    longest_touch: np.ndarray | None = None
    """``None``: no touch recorded (all 0)."""

    def __post_init__(self) -> None:
        if self.fall_after is None:
            self.fall_after = np.full(len(self.source), np.nan)
        if self.success_contact is None:
            self.success_contact = np.array(self.success, copy=True)
        if self.longest_touch is None:
            self.longest_touch = np.zeros(len(self.source))
        for name, column in COLUMNS.items():
            setattr(self, name, np.asarray(getattr(self, name), dtype=column.dtype))
        lengths = {len(getattr(self, name)) for name in COLUMNS}
        if len(lengths) != 1:
            raise ValueError(f"transition batch columns have different lengths: {sorted(lengths)}")

    def __len__(self) -> int:
        return len(self.source)

    def pairs(self) -> list[tuple[int, int]]:
        """The ordered pairs (source, destination gait indices) that have samples, sorted."""
        return sorted(set(zip(self.source.tolist(), self.dest.tolist(), strict=True)))

    def columns(self) -> dict[str, np.ndarray]:
        """Column name -> array, in :data:`COLUMNS` order."""
        return {name: getattr(self, name) for name in COLUMNS}

    def labelled(self, falls: Falls) -> TransitionBatch:
        """These samples with ``success`` the outcome by the definition of a fall ``falls`` (``trunk``: as stored;
        ``contact``: ``success_contact``), for whatever reads ``success`` (fits, calibration, TMT, maps)."""
        if falls != Falls.CONTACT:
            return self
        return TransitionBatch(**(self.columns() | {"success": self.success_contact}))

    def select(self, index: np.ndarray | slice) -> TransitionBatch:
        """Rows ``index`` of every column."""
        return TransitionBatch(**{name: values[index] for name, values in self.columns().items()})

    @staticmethod
    def concatenate(batches: list[TransitionBatch]) -> TransitionBatch:
        """The rows of ``batches`` in order (at least one batch)."""
        return TransitionBatch(**{name: np.concatenate([getattr(b, name) for b in batches]) for name in COLUMNS})


@dataclass(frozen=True, kw_only=True)
class TransitionHeader:
    """What a file's samples belong to: a resumed collection must match it exactly."""

    gaits: tuple[str, ...]
    """Gait names; sample gait indices refer to this order."""
    identities: tuple[str, ...]
    """SHA-256 of each gait's library entry, same order."""
    latent_dim: int
    """L: size of the source actors' last hidden layer."""
    settings: dict
    """JSON-able collection settings (horizon, warm-up, pushes, backend, seed, pairs, ...)."""


@dataclass(frozen=True)
class TransitionFileInfo:
    """A checked file."""

    header: TransitionHeader
    count: int
    """Committed samples."""
    sessions: list[dict]
    """One record per collection run (seed, first chunk, samples at its start, ...)."""
    note: str | None
    """What was noticed but tolerated (uncommitted rows after an interrupted append), else ``None``."""
    files: tuple[tuple[str, str], ...] = ()
    """(path, content SHA-256) of each transition file read, in order: the content is the SHA-256 of the committed
    parts' digests (each the SHA-256 of a part file's bytes, which every read checks), one per line, so it is the
    same for one file read under two names, through a hard link or as a copy (:func:`content_sha256`)."""


def content_sha256(part_digests: tuple[str, ...]) -> str:
    """The identity of a transition file's committed samples from its parts' SHA-256 digests, in sample order."""
    return hashlib.sha256("\n".join(part_digests).encode()).hexdigest()


@dataclass(frozen=True)
class TransitionData:
    """A whole file read into memory."""

    info: TransitionFileInfo
    samples: TransitionBatch

    @property
    def header(self) -> TransitionHeader:
        """The file's gaits, identities, latent size and settings."""
        return self.info.header

    def labelled(self, falls: Falls) -> TransitionData:
        """This data labelled by the definition of a fall ``falls`` (:meth:`TransitionBatch.labelled`)."""
        return TransitionData(self.info, self.samples.labelled(falls))
