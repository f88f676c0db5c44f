"""Atomic file writes: the one way gaitlib writes a result file, so that a crash, Ctrl-C or a full disk never
leaves a half-written file where a good one (or none) was; the one writer lock, so that two processes never
write the same result; and the one reader of gaitlib's versioned JSON files."""

from __future__ import annotations

import contextlib
import fcntl
import glob
import hashlib
import json
import math
import os
import shlex
import sys
import tempfile
import time
from collections.abc import Iterator, Mapping
from pathlib import Path

from gaitlib.errors import GaitlibError

__all__ = [
    "CHECKSUM_KEY",
    "atomic_path",
    "check_unlocked",
    "command_line",
    "file_sha256",
    "fsync_folder",
    "json_checksum",
    "json_text",
    "null_for_nan",
    "read_json",
    "release_lock",
    "save_figure",
    "stale_temporaries",
    "take_lock",
    "torch_bytes",
    "write_bytes",
    "write_json",
]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def fsync_folder(folder: Path) -> None:
    """Flush ``folder``'s entries (names created, renamed or removed in it) to disk."""
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_path(path: Path, *, durable: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` to write; on success it replaces ``path`` (with the usual
    permissions, 0666 minus the umask), on any exception it is removed and ``path`` is left as it was.

    ``durable``: the written data are flushed to disk before the rename and the rename after it, so that a power
    loss (not only a killed process) leaves the old or the new file, and what follows is ordered after it.
    A process killed in between leaves a temporary (see :func:`stale_temporaries`)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=f".tmp{path.suffix}", dir=path.parent)
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~_umask())
        if durable:
            with open(tmp, "rb") as handle:
                os.fsync(handle.fileno())
        os.replace(tmp, path)
    except OSError as error:  # a full disk: name the file being written, not the temporary (or nothing)
        tmp.unlink(missing_ok=True)
        if error.filename not in (None, str(tmp), tmp):
            raise
        raise OSError(error.errno, error.strerror, str(path)) from error
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    if durable:
        fsync_folder(path.parent)


def torch_bytes(payload: object) -> bytes:
    """``payload`` as ``torch.save`` writes it, made in memory (then written with :func:`write_bytes`: torch's own
    file writer fails on a full disk with a multi-line ``RuntimeError`` that names no file)."""
    import io

    import torch

    buffer = io.BytesIO()
    torch.save(payload, buffer)
    return buffer.getvalue()


def write_bytes(path: Path, data: bytes, *, durable: bool = False) -> Path:
    """Write ``data`` to ``path`` atomically (:func:`atomic_path`). Files that a C library would write itself (HDF5,
    torch) are made in memory and written with this: a full disk then fails Python's own write, one ``OSError``
    naming ``path``, and leaves no half-closed handle inside the C library (HDF5 crashes at exit on one)."""
    with atomic_path(path, durable=durable) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def stale_temporaries(path: Path) -> list[Path]:
    """The temporaries :func:`atomic_path` left beside ``path`` when a process was killed while writing it (remove
    them only while no other process can be writing ``path``)."""
    path = Path(path)
    return sorted(path.parent.glob(f".{glob.escape(path.name)}.*.tmp{glob.escape(path.suffix)}"))


def file_sha256(path: Path) -> str:
    """SHA-256 of the bytes of the file ``path``, read in blocks (what ``sha256sum`` prints)."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def json_checksum(payload: Mapping[str, object]) -> str:
    """SHA-256 of ``payload`` less its ``checksum`` key, as canonical JSON (sorted keys, no spaces): what a JSON file
    of gaitlib's carries under ``checksum``, so that a changed value (a flipped bit) is refused, not used."""
    body = {key: value for key, value in payload.items() if key != CHECKSUM_KEY}
    return hashlib.sha256(json.dumps(body, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


CHECKSUM_KEY = "checksum"
"""The key of a JSON object's own checksum (:func:`json_checksum`)."""


def write_json(path: Path, payload: object, *, indent: int | None = 2, checksum: bool = False) -> Path:
    """Write ``payload`` as JSON to ``path`` atomically; ``checksum``: with its :func:`json_checksum` added.

    JSON has no nan or infinity (RFC 8259, section 6): a payload holding one is refused with a
    :class:`~gaitlib.errors.GaitlibError` naming where, before anything is written (``path`` keeps what it held),
    instead of a file that strict readers (``jq``, browsers) cannot parse."""
    where = _non_finite(payload, "")
    if where is not None:
        raise GaitlibError(f"refusing to write {path}: {where or 'the value'} is not a finite number (JSON has none)")
    if checksum:
        payload = dict(payload) | {CHECKSUM_KEY: json_checksum(payload)}
    with atomic_path(path) as tmp, open(tmp, "w") as handle:
        json.dump(payload, handle, indent=indent, allow_nan=False)
        handle.write("\n")
    return Path(path)


def json_text(payload: object) -> str:
    """``payload`` as one line of strict JSON, what a command's ``--json`` prints: an undefined number (nan: an
    empty cell's rate) as null (:func:`null_for_nan`), an infinity refused as :func:`write_json` refuses it."""
    payload = null_for_nan(payload)
    where = _non_finite(payload, "")
    if where is not None:
        raise GaitlibError(f"refusing to print JSON: {where or 'the value'} is not a finite number (JSON has none)")
    return json.dumps(payload, allow_nan=False)


def null_for_nan(value: object) -> object:
    """``value`` with every nan float (an undefined number: an empty bin's or cell's rate) as ``None``, JSON's
    null; mappings become dicts and sequences lists."""
    if isinstance(value, float) and math.isnan(value):
        return None
    if isinstance(value, Mapping):
        return {key: null_for_nan(v) for key, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [null_for_nan(v) for v in value]
    return value


def _non_finite(value: object, where: str) -> str | None:
    """The key path (``a.b[2]``) of the first non-finite float in ``value``, ``None`` if there is none."""
    if isinstance(value, float):
        return None if math.isfinite(value) else where
    if isinstance(value, Mapping):
        found = (_non_finite(v, f"{where}.{k}" if where else str(k)) for k, v in value.items())
    elif isinstance(value, (list, tuple)):
        found = (_non_finite(v, f"{where}[{i}]") for i, v in enumerate(value))
    else:
        return None
    return next((w for w in found if w is not None), None)


def read_json(path: Path, *, header: Mapping[str, object], what: str, error: type[Exception]) -> dict:
    """The JSON object in ``path`` (which exists) whose ``format`` and ``format_version`` are ``header``'s and whose
    ``checksum`` matches its content (returned without it); raises ``error`` with one line otherwise. ``what`` names
    the kind of file with its article (``"a gaitlib TMT"``)."""
    try:
        payload = json.loads(Path(path).read_text())
    except (OSError, ValueError) as failure:
        raise error(f"{path} is not readable as {what} ({type(failure).__name__})") from failure
    if not isinstance(payload, dict) or payload.get("format") != header["format"]:
        raise error(f"{path} is not {what}")
    if payload.get("format_version") != header["format_version"]:
        raise error(
            f"{path} is {what} of format version {payload.get('format_version')}; "
            f"this gaitlib reads version {header['format_version']}"
        )
    if payload.pop(CHECKSUM_KEY, None) != json_checksum(payload):
        raise error(f"{path} is damaged: its content does not match its checksum")
    return payload


def save_figure(fig, path: Path, *, dpi: int = 110) -> Path:
    """Save the matplotlib figure ``fig`` as a PNG at ``path`` atomically, then close it."""
    import matplotlib.pyplot as plt

    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=dpi, format="png")
    finally:
        plt.close(fig)
    return Path(path)


def take_lock(lock: Path, *, writing: str, error: type[Exception]) -> int:
    """Take the exclusive writer lock ``lock`` (a file, created if needed) without waiting, write this process's
    id and command line into it and return its descriptor; if another process holds it, raise ``error("<writing>
    is being written by process N (its command)")``. The kernel releases the lock when the holder exits, however
    it exits."""
    lock.parent.mkdir(parents=True, exist_ok=True)
    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _holder(fd)
            os.close(fd)
            raise error(f"{writing} is being written by {holder}") from None
        with contextlib.suppress(FileNotFoundError):
            if os.path.samestat(os.fstat(fd), os.stat(lock)):
                break
        os.close(fd)  # its last holder removed it after we opened it: take the one there now
    os.ftruncate(fd, 0)
    os.write(fd, f"{os.getpid()}\n{command_line()}\n".encode())
    return fd


def check_unlocked(lock: Path, *, writing: str, error: type[Exception]) -> None:
    """Refuse as :func:`take_lock` would, without taking the lock or creating anything: what a command checks
    before its work when it takes the lock only at the end (``gaitlib train`` publishing its entry)."""
    try:
        fd = os.open(lock, os.O_RDONLY)
    except (FileNotFoundError, NotADirectoryError):
        return  # a held lock's file exists: its holder removes it only when it releases it
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        raise error(f"{writing} is being written by {_holder(fd)}") from None
    finally:
        os.close(fd)


def release_lock(lock: Path, fd: int) -> None:
    """Release a lock taken with :func:`take_lock` (the lock file is removed)."""
    lock.unlink(missing_ok=True)
    os.close(fd)


def _holder(fd: int) -> str:
    """Who holds the lock open as ``fd``: ``process N (its command line)`` (it writes both right after taking
    it)."""
    pid = ""
    for _ in range(20):
        pid, _, command = os.pread(fd, 4096, 0).decode(errors="replace").partition("\n")
        if pid.isdigit() and command.endswith("\n"):
            return f"process {pid} ({command.strip()})"
        time.sleep(0.05)
    return f"process {pid}" if pid.isdigit() else "another process"


def command_line() -> str:
    """This process's command line as one line (``gaitlib fit --data t.h5``; the program by its file name), at most
    300 characters."""
    try:
        with open(f"/proc/{os.getpid()}/cmdline", "rb") as handle:
            argv = [a.decode(errors="replace") for a in handle.read().split(b"\0")[:-1]]
    except OSError:
        argv = list(sys.argv)
    if argv:
        argv[0] = os.path.basename(argv[0])
    line = shlex.join(argv).replace("\n", " ")
    return line if len(line) <= 300 else line[:297] + "..."

