"""The one writer of a transition file (layout in :mod:`gaitlib.transitions.schema`).

:func:`open_writer` takes an exclusive lock on ``PATH.lock`` for the life of the writer (a second writer is
refused in one line naming the holder's process id), checks an existing file completely, and removes what a killed
writer left (part files no index lists, temporaries). Each :meth:`TransitionWriter.append` writes one new part,
then replaces the index that lists it, so a kill at any moment loses at most the batch being written. Whenever
the last :data:`FAN_IN` parts are of one size tier (a tier spans a factor of :data:`FAN_IN` in rows) they are
merged into one new part (up to :data:`MAX_MERGED_ROWS` samples), committed the same way, and the merged parts
removed: a 2e6-sample collection in batches of 256 ends with a few dozen files.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import signal
import threading
from collections.abc import Iterator
from datetime import UTC, datetime
from pathlib import Path

import h5py
import numpy as np

import gaitlib
from gaitlib.atomic import release_lock, stale_temporaries, take_lock
from gaitlib.errors import TransitionDataError
from gaitlib.transitions import schema
from gaitlib.transitions.explicit import EXPLICIT_DIM
from gaitlib.transitions.records import COLUMNS, TransitionBatch, TransitionHeader

__all__ = ["FAN_IN", "MAX_MERGED_ROWS", "TransitionWriter", "lock_path", "open_writer"]

FAN_IN = 16
"""Parts of one size tier merged into one."""
MAX_MERGED_ROWS = 1 << 17
"""Largest part a merge makes, samples (about 47 MB uncompressed with 16-dim latents)."""
_COMMITTED = ("source", "dest", "success", "chunk")
"""Columns a writer keeps of the samples committed before it opened."""


def lock_path(path: Path) -> Path:
    """The lock file of the transition file ``path`` (holds the writer's process id while it runs)."""
    return Path(path).with_name(Path(path).name + ".lock")


class TransitionWriter:
    """A transition file open for appending (a context manager that releases the lock)."""

    def __init__(self, path: Path, index: schema.TransitionIndex, committed: dict[str, np.ndarray], note: str | None,
                 lock: int) -> None:
        self.path = path
        self.committed = committed
        """``source``, ``dest``, ``success`` and ``chunk`` of the samples committed before this writer opened."""
        self.note = note
        """What opening removed (leftovers of an interrupted run), else ``None``."""
        self._index = index
        self._sessions: list[dict] = []
        self._lock: int | None = lock

    @property
    def count(self) -> int:
        """Committed samples."""
        return self._index.count

    @property
    def next_chunk(self) -> int:
        """``chunk`` index of the next batch (one more than the last committed one)."""
        chunks = self.committed["chunk"]
        return int(chunks[-1]) + 1 if len(chunks) else 0

    def record_session(self, session: dict) -> None:
        """Add a collection run's record (JSON-able: seed, first chunk, samples at start, ...) to ``sessions``; it is
        committed with the next batch (a run that commits no sample leaves no record)."""
        self._sessions.append(json.loads(json.dumps(session)))

    def append(self, batch: TransitionBatch) -> int:
        """Commit ``batch`` (one new part, then the index); returns the new sample count. Ctrl-C waits until the
        batch is committed."""
        latent_dim = self._index.header.latent_dim
        if batch.latent.shape[1:] != (latent_dim,) or batch.explicit.shape[1:] != (EXPLICIT_DIM,):
            raise TransitionDataError(
                f"batch has latent {batch.latent.shape[1:]} and explicit {batch.explicit.shape[1:]}, "
                f"the file holds ({latent_dim},) and ({EXPLICIT_DIM},)"
            )
        gaits = len(self._index.header.gaits)
        if len(batch) and not (0 <= min(batch.source.min(), batch.dest.min()) <= max(batch.source.max(),
                                                                                        batch.dest.max()) < gaits):
            raise TransitionDataError(f"batch has gait indices outside the file's {gaits} gaits")
        if len(batch):
            with _sigint_deferred():
                try:
                    self._commit((*self._index.parts, schema.write_part(self.path, batch, start=self.count)))
                    self._merge()
                except OSError as error:  # a full disk, a folder gone read-only
                    reason = (error.strerror or str(error)).lower()
                    raise TransitionDataError(
                        f"could not write {error.filename or self.path}: {reason}; the {self.count:,} samples "
                        "committed before are kept: free space and rerun to resume"
                    ) from None
        return self.count

    def close(self) -> None:
        """Release the lock (idempotent)."""
        if self._lock is not None:
            _unlock(self.path, self._lock)
            self._lock = None

    def __enter__(self) -> TransitionWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _commit(self, parts: tuple[schema.Part, ...]) -> None:
        index = dataclasses.replace(
            self._index, parts=parts, sessions=(*self._index.sessions, *self._sessions),
            count=sum(p.rows for p in parts),
        )
        schema.write_index(self.path, index)
        self._index, self._sessions = index, []

    def _merge(self) -> None:
        """Merge the last :data:`FAN_IN` parts while they are of one tier (see the module doc)."""
        parts = self._index.parts
        while len(parts) >= FAN_IN:
            tail = parts[-FAN_IN:]
            rows = sum(p.rows for p in tail)
            if len({_tier(p.rows) for p in tail}) > 1 or rows > MAX_MERGED_ROWS:
                return
            read = [schema.read_part(self.path, p, self._index.header) for p in tail]
            batch = TransitionBatch(**{name: np.concatenate([r[name] for r in read]) for name in COLUMNS})
            parts = (*parts[:-FAN_IN], schema.write_part(self.path, batch, start=self.count - rows))
            self._commit(parts)
            for part in tail:
                (schema.parts_folder(self.path) / part.file).unlink(missing_ok=True)


def open_writer(path: Path, *, header: TransitionHeader) -> TransitionWriter:
    """Lock ``path`` and open it for appending samples of ``header`` (a new file is written at the first commit).

    Raises a one-line :class:`TransitionDataError` if another process writes ``path``, if ``path`` exists and is not
    a sound transition file (see :func:`~gaitlib.transitions.schema.scan`; it is never changed then), or holds
    other gaits, library identities, latent size or settings.
    """
    path = Path(path)
    lock = _lock(path)
    try:
        if path.exists() or path.is_symlink():
            index, committed = schema.scan(path, keep=_COMMITTED)
            schema.compare_header(index.header, header, path)
        else:
            index = schema.TransitionIndex(
                header=header, parts=(), sessions=(), provenance=_provenance(), count=0
            )
            committed = {name: np.zeros(0, dtype=COLUMNS[name].dtype) for name in _COMMITTED}
        return TransitionWriter(path, index, committed, _clean(path, index), lock)
    except BaseException:
        _unlock(path, lock)
        raise


# ---------------------------------------------------------------------------------------------------- internals
def _tier(rows: int) -> int:
    return (rows.bit_length() - 1) // (FAN_IN.bit_length() - 1)


def _provenance() -> dict:
    versions = {"gaitlib": gaitlib.__version__, "h5py": h5py.__version__, "hdf5": h5py.version.hdf5_version,
                "numpy": np.__version__}
    return {"created_by": json.dumps(versions), "created": datetime.now(UTC).isoformat(timespec="seconds")}


def _clean(path: Path, index: schema.TransitionIndex) -> str | None:
    """Remove what killed writers left: temporaries and parts that the index does not list."""
    folder = schema.parts_folder(path)
    stale = stale_temporaries(path)
    if folder.is_dir():
        listed = {p.file for p in index.parts}
        stale += [p for p in folder.glob("part-*.h5") if p.name not in listed]
        stale += list(folder.glob(".part-*.tmp.h5"))
    for file in stale:
        file.unlink(missing_ok=True)
    return f"{path}: removed {len(stale)} uncommitted files left by an interrupted run" if stale else None


def _lock(path: Path) -> int:
    """Take the exclusive lock of ``path`` (without waiting); one line naming the holder if it is taken."""
    return take_lock(lock_path(path), writing=str(path), error=TransitionDataError)


def _unlock(path: Path, fd: int) -> None:
    release_lock(lock_path(path), fd)


@contextlib.contextmanager
def _sigint_deferred() -> Iterator[None]:
    """Hold back Ctrl-C (in the main thread) until the block is done, then raise it."""
    previous = signal.getsignal(signal.SIGINT)
    if threading.current_thread() is not threading.main_thread() or previous is None:
        yield
        return
    caught = []
    signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if caught:
        raise KeyboardInterrupt
