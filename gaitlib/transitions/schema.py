"""The HDF5 file of transition samples: one versioned, self-describing schema, appendable and crash-tolerant.

Layout (schema ``gaitlib.transitions``, version :data:`SCHEMA_VERSION`): one row per sample in each of the
datasets of :data:`COLUMNS` (all chunked, gzip-compressed with shuffle and Fletcher-32 checksums, resizable along
rows; each carries ``description`` and ``units`` attributes). ``L`` is the source actors' latent size (the file
attribute ``latent_dim``), ``E`` = 66 the explicit state (layout in the attribute ``explicit_layout``).

File attributes:

* ``schema`` (str), ``schema_version`` (int): what this file is; anything else is refused.
* ``gaits`` (str list): gait names; ``source``/``dest`` index it. ``library_identities`` (str list, same order):
  SHA-256 of each library entry's weights, so samples never mix policies.
* ``latent_dim`` (int), ``explicit_layout`` (JSON), ``settings`` (JSON: everything that defines how samples are
  drawn; a resumed collection must use the same), ``sessions`` (JSON list: one record per collection run with its
  seed and where it started), ``created_by`` (JSON versions), ``created`` (UTC ISO time).
* ``count`` (int): samples committed. :func:`append` writes every dataset, then ``count``, then flushes; rows past
  ``count`` (left by a crash mid-append) are ignored by readers and cut off by :func:`open_for_append`.
"""

from __future__ import annotations

import contextlib
import json
import signal
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import h5py
import numpy as np

import gaitlib
from gaitlib.atomic import atomic_path
from gaitlib.errors import TransitionDataError
from gaitlib.transitions.explicit import EXPLICIT_DIM, EXPLICIT_LAYOUT
from gaitlib.transitions.records import (
    COLUMNS,
    Column,
    TransitionBatch,
    TransitionData,
    TransitionFileInfo,
    TransitionHeader,
)

__all__ = [
    "COLUMNS",
    "SCHEMA_NAME",
    "SCHEMA_VERSION",
    "AppendTarget",
    "Column",
    "TransitionBatch",
    "TransitionData",
    "TransitionFileInfo",
    "TransitionHeader",
    "append",
    "create",
    "open_for_append",
    "read",
    "record_session",
    "validate",
]

SCHEMA_NAME = "gaitlib.transitions"
"""Value of the ``schema`` file attribute."""
SCHEMA_VERSION = 1
"""Version of this layout; files of another version are refused."""


@dataclass
class AppendTarget:
    """A file opened for appending (a context manager that closes it)."""

    file: h5py.File
    count: int
    """Samples present when it was opened (after any repair)."""
    note: str | None
    """What :func:`open_for_append` repaired, else ``None``."""

    def close(self) -> None:
        self.file.close()

    def __enter__(self) -> AppendTarget:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def create(path: Path, *, gaits: list[str], identities: list[str], latent_dim: int, settings: dict) -> None:
    """Create an empty transition file at ``path`` (written beside it, then renamed into place).

    Raises :class:`TransitionDataError` if ``path`` exists or the arguments are inconsistent.
    """
    path = Path(path)
    if path.exists():
        raise TransitionDataError(f"{path} already exists; open it for appending or choose another path")
    if len(gaits) != len(identities) or len(set(gaits)) != len(gaits) or not 2 <= len(gaits) <= 127:
        raise TransitionDataError(f"need 2-127 distinct gaits with one identity each, got {gaits} / {identities}")
    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w") as f:
            f.attrs["schema"] = SCHEMA_NAME
            f.attrs["schema_version"] = SCHEMA_VERSION
            f.attrs["gaits"] = np.array(gaits, dtype=h5py.string_dtype())
            f.attrs["library_identities"] = np.array(identities, dtype=h5py.string_dtype())
            f.attrs["latent_dim"] = int(latent_dim)
            f.attrs["explicit_layout"] = json.dumps(EXPLICIT_LAYOUT)
            f.attrs["settings"] = json.dumps(settings, sort_keys=True)
            f.attrs["sessions"] = "[]"
            f.attrs["created_by"] = json.dumps(
                {
                    "gaitlib": gaitlib.__version__,
                    "h5py": h5py.__version__,
                    "hdf5": h5py.version.hdf5_version,
                    "numpy": np.__version__,
                }
            )
            f.attrs["created"] = datetime.now(timezone.utc).isoformat(timespec="seconds")
            f.attrs["count"] = 0
            for name, column in COLUMNS.items():
                width = _width(column, latent_dim)
                row_bytes = np.dtype(column.dtype).itemsize * int(np.prod(width))
                rows = int(np.clip(2**18 // row_bytes, 64, 4096))
                ds = f.create_dataset(
                    name,
                    shape=(0, *width),
                    maxshape=(None, *width),
                    dtype=column.dtype,
                    chunks=(rows, *width),
                    compression="gzip",
                    compression_opts=4,
                    shuffle=True,
                    fletcher32=True,
                )
                ds.attrs["description"] = column.description
                ds.attrs["units"] = column.units


def open_for_append(path: Path, *, expect: TransitionHeader) -> AppendTarget:
    """Open an existing file for appending after checking it against ``expect``.

    Rows left past the committed count by an interrupted append are cut off (the returned ``note`` says so).
    Raises :class:`TransitionDataError` for an unreadable or foreign file, another schema version, other gaits,
    library identities, latent size or settings.
    """
    path = Path(path)
    f = _open(path, "r+")
    try:
        header, count, lengths, _ = _inspect(f, path)
        _compare(header, expect, path)
        note = None
        if any(n != count for n in lengths.values()):
            extra = max(lengths.values()) - count
            for name in COLUMNS:
                f[name].resize(count, axis=0)
            f.flush()
            note = f"{path}: cut {extra} uncommitted rows left by an interrupted append; {count} samples kept"
        return AppendTarget(file=f, count=count, note=note)
    except BaseException:
        f.close()
        raise


def append(file: h5py.File, batch: TransitionBatch) -> int:
    """Append ``batch``, commit and flush; returns the new sample count. Ctrl-C waits until the batch is on disk."""
    count = int(file.attrs["count"])
    latent_dim = int(file.attrs["latent_dim"])
    if batch.latent.shape[1:] != (latent_dim,) or batch.explicit.shape[1:] != (EXPLICIT_DIM,):
        raise TransitionDataError(
            f"batch has latent {batch.latent.shape[1:]} and explicit {batch.explicit.shape[1:]}, "
            f"the file holds ({latent_dim},) and ({EXPLICIT_DIM},)"
        )
    total = count + len(batch)
    with _sigint_deferred():
        for name, values in batch.columns().items():
            ds = file[name]
            ds.resize(total, axis=0)
            ds[count:total] = values
        file.attrs["count"] = total
        file.flush()
    return total


def record_session(file: h5py.File, session: dict) -> None:
    """Add a collection run's record (JSON-able: seed, first chunk, samples at start, ...) to ``sessions``."""
    sessions = json.loads(file.attrs["sessions"])
    sessions.append(session)
    file.attrs["sessions"] = json.dumps(sessions)
    file.flush()


def validate(path: Path) -> TransitionFileInfo:
    """Check ``path`` completely (attributes, datasets, every committed row readable).

    Raises a one-line :class:`TransitionDataError` for: a missing file, a file that is not HDF5, a truncated or
    corrupt file, HDF5 that is not transition data, another schema version, missing or malformed datasets,
    datasets shorter than the committed count.
    """
    path = Path(path)
    with _open(path, "r") as f:
        header, count, lengths, sessions = _inspect(f, path)
        step = 1 << 16
        for name in COLUMNS:
            for start in range(0, count, step):
                _read_rows(f, name, start, min(count, start + step), path)
        return TransitionFileInfo(header, count, sessions, _tail_note(lengths, count, path))


def read(path: Path) -> TransitionData:
    """Read the committed samples of ``path`` (checked as by :func:`validate`)."""
    path = Path(path)
    with _open(path, "r") as f:
        header, count, lengths, sessions = _inspect(f, path)
        columns = {name: _read_rows(f, name, 0, count, path) for name in COLUMNS}
    info = TransitionFileInfo(header, count, sessions, _tail_note(lengths, count, path))
    return TransitionData(info, TransitionBatch(**columns))


# ---------------------------------------------------------------------------------------------------- internals
def _width(column: Column, latent_dim: int) -> tuple[int, ...]:
    return {None: (), "latent": (latent_dim,), "explicit": (EXPLICIT_DIM,)}[column.width]


def _first_line(error: BaseException) -> str:
    text = str(error).strip()
    return text.splitlines()[0] if text else type(error).__name__


def _open(path: Path, mode: str) -> h5py.File:
    if not path.is_file():
        raise TransitionDataError(f"no transition file at {path}")
    try:
        return h5py.File(path, mode)
    except OSError as error:
        if not h5py.is_hdf5(path):
            raise TransitionDataError(f"{path} is not an HDF5 file") from error
        raise TransitionDataError(f"{path} is a corrupt or truncated HDF5 file ({_first_line(error)})") from error


def _read_rows(f: h5py.File, name: str, start: int, stop: int, path: Path) -> np.ndarray:
    try:
        return f[name][start:stop]
    except (OSError, ValueError) as error:
        raise TransitionDataError(
            f"{path} is corrupt or truncated: dataset '{name}' rows {start}-{stop} unreadable ({_first_line(error)})"
        ) from error


def _text_list(values: object) -> tuple[str, ...]:
    return tuple(v.decode() if isinstance(v, bytes) else str(v) for v in np.atleast_1d(values))


def _inspect(f: h5py.File, path: Path) -> tuple[TransitionHeader, int, dict[str, int], list[dict]]:
    """Header, committed count, dataset lengths and sessions of an open file; raises on anything malformed."""
    try:
        attrs = dict(f.attrs)
    except (OSError, RuntimeError) as error:
        raise TransitionDataError(f"{path} is corrupt or truncated ({_first_line(error)})") from error
    schema = attrs.get("schema")
    schema = schema.decode() if isinstance(schema, bytes) else schema
    if schema != SCHEMA_NAME:
        what = "no 'schema' attribute" if schema is None else f"schema '{schema}'"
        raise TransitionDataError(f"{path} is an HDF5 file but not gaitlib transition data ({what})")
    version = attrs.get("schema_version")
    if version != SCHEMA_VERSION:
        raise TransitionDataError(
            f"{path} has transition schema version {version}; this gaitlib reads version {SCHEMA_VERSION}"
        )
    try:
        header = TransitionHeader(
            gaits=_text_list(attrs["gaits"]),
            identities=_text_list(attrs["library_identities"]),
            latent_dim=int(attrs["latent_dim"]),
            settings=json.loads(attrs["settings"]),
        )
        count = int(attrs["count"])
        sessions = json.loads(attrs["sessions"])
    except (KeyError, TypeError, ValueError) as error:
        raise TransitionDataError(f"{path} is damaged: file attribute missing or malformed ({error})") from error
    lengths = {}
    for name, column in COLUMNS.items():
        try:
            ds = f[name]
            shape, dtype = ds.shape, ds.dtype
        except (KeyError, OSError) as error:
            raise TransitionDataError(f"{path} is damaged: dataset '{name}' missing or unreadable") from error
        width = _width(column, header.latent_dim)
        if shape[1:] != width or dtype != np.dtype(column.dtype):
            raise TransitionDataError(
                f"{path} is damaged: dataset '{name}' is {dtype} {shape}, expected {column.dtype} (n, {width})"
            )
        lengths[name] = shape[0]
    short = {name: n for name, n in lengths.items() if n < count}
    if short:
        name, n = next(iter(short.items()))
        raise TransitionDataError(
            f"{path} has inconsistent dataset lengths: {count} samples committed but '{name}' has {n} rows"
        )
    return header, count, lengths, sessions


def _tail_note(lengths: dict[str, int], count: int, path: Path) -> str | None:
    extra = max(lengths.values()) - count
    if extra == 0:
        return None
    return f"{path}: {extra} uncommitted rows from an interrupted append are ignored"


def _compare(found: TransitionHeader, expect: TransitionHeader, path: Path) -> None:
    if found.gaits != tuple(expect.gaits):
        raise TransitionDataError(f"{path} holds gaits {list(found.gaits)}, not {list(expect.gaits)}")
    changed = [g for g, a, b in zip(found.gaits, found.identities, expect.identities, strict=True) if a != b]
    if changed:
        raise TransitionDataError(
            f"{path} was collected with other library policies for {', '.join(changed)} "
            "(library identities differ); write to a new file"
        )
    if found.latent_dim != expect.latent_dim:
        raise TransitionDataError(f"{path} holds latents of size {found.latent_dim}, not {expect.latent_dim}")
    wanted = json.loads(json.dumps(expect.settings, sort_keys=True))
    if found.settings != wanted:
        keys = sorted(k for k in set(found.settings) | set(wanted) if found.settings.get(k) != wanted.get(k))
        diffs = ", ".join(f"{k}: {found.settings.get(k)!r} in the file, {wanted.get(k)!r} now" for k in keys)
        raise TransitionDataError(f"{path} was collected with other settings ({diffs}); write to a new file")


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
