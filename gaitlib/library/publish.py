"""Publishing a folder in one step: a library entry or the switching models are written into a hidden staging
folder and then swapped into place, so that a reader, or a process killed at any moment, finds the old folder or
the new one, never neither and never a mix.

On Linux the swap is ``renameat2(RENAME_EXCHANGE)`` (one system call: atomic); the staging folder then holds the
old version and is removed. Where the system cannot exchange, the old folder is renamed to ``.<name>.old`` and
the new one renamed into place; a kill between the two renames leaves ``<name>`` missing, and :func:`recover`
(which the library calls before it lists or writes) puts the old folder back. Writers of one folder take an
exclusive lock (``.<name>.lock`` beside it) and remove what killed writers left (``.<name>.*`` folders).

A folder may be a symbolic link to another library's (a grown library holds its first gaits so): publishing
replaces the link itself with a folder of its own, and the folder it pointed to is never written or removed.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import os
import shutil
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

from gaitlib.atomic import fsync_folder, release_lock, take_lock
from gaitlib.errors import GaitlibError

__all__ = ["exchange", "recover", "staged_folder"]

_AT_FDCWD = -100
_RENAME_EXCHANGE = 2
"""From ``linux/fs.h``; see rename(2)."""


def exchange(a: Path, b: Path) -> bool:
    """Swap the paths ``a`` and ``b`` atomically; ``False`` (nothing done) where the system cannot."""
    if sys.platform != "linux":
        return False
    libc = ctypes.CDLL(None, use_errno=True)
    renameat2 = getattr(libc, "renameat2", None)  # glibc >= 2.28
    if renameat2 is None:
        return False
    renameat2.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    if renameat2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.ENOSYS, errno.EINVAL, errno.EOPNOTSUPP):  # kernel or file system without exchange
        return False
    raise OSError(code, os.strerror(code), str(a))


def recover(final: Path) -> None:
    """Undo a kill between the fallback's two renames: ``.<name>.old`` back to ``<name>`` if that is missing."""
    old = final.with_name(f".{final.name}.old")
    if old.is_dir() and not final.exists() and not final.is_symlink():
        os.rename(old, final)


@contextlib.contextmanager
def staged_folder(final: Path) -> Iterator[Path]:
    """Yield an empty hidden staging folder beside ``final`` to fill; on success it replaces ``final`` in one step,
    on any exception it is removed and ``final`` is left as it was. Holds ``final``'s writer lock throughout."""
    final.parent.mkdir(parents=True, exist_ok=True)
    with _writer_lock(final):
        recover(final)
        for leftover in final.parent.glob(f".{final.name}.*"):
            if leftover.is_dir():  # a staging or old folder of a killed writer (the lock says none is running)
                _remove(leftover, ignore_errors=True)
        staging = Path(tempfile.mkdtemp(prefix=f".{final.name}.", dir=final.parent))
        try:
            staging.chmod(0o755)  # mkdtemp makes it private; library folders are meant to be shared
            yield staging
            _fsync_tree(staging)
            _swap_in(staging, final)
        except OSError as error:  # a full disk: name the file of the folder being published, not the staging one
            shutil.rmtree(staging, ignore_errors=True)
            if error.errno is None:  # not the system's: its own message says what happened
                raise
            if error.filename is None:  # a write to an open file: the folder is what was being written
                raise OSError(error.errno, error.strerror, str(final)) from error
            if not Path(error.filename).is_relative_to(staging):
                raise
            named = final / Path(error.filename).relative_to(staging)
            raise OSError(error.errno, error.strerror, str(named)) from error
        except BaseException:
            shutil.rmtree(staging, ignore_errors=True)
            raise


def _swap_in(staging: Path, final: Path) -> None:
    if not final.exists() and not final.is_symlink():
        os.rename(staging, final)
    elif exchange(staging, final):
        _remove(staging)  # it now holds the old version
    else:
        old = final.with_name(f".{final.name}.old")
        os.rename(final, old)
        os.rename(staging, final)
        _remove(old)
    fsync_folder(final.parent)


def _remove(folder: Path, *, ignore_errors: bool = False) -> None:
    """Remove an old version: a folder with what it holds; a link, only the link (never the folder it points to)."""
    if folder.is_symlink():
        with contextlib.suppress(OSError) if ignore_errors else contextlib.nullcontext():
            folder.unlink()
    else:
        shutil.rmtree(folder, ignore_errors=ignore_errors)


@contextlib.contextmanager
def _writer_lock(final: Path) -> Iterator[None]:
    lock = final.with_name(f".{final.name}.lock")
    fd = take_lock(lock, writing=str(final), error=GaitlibError)
    try:
        yield
    finally:
        release_lock(lock, fd)


def _fsync_tree(folder: Path) -> None:
    """Flush the files of ``folder`` and the folder itself to disk (a crash of the machine, not only of the
    process, then also leaves the old or the new version)."""
    for path in folder.iterdir():
        if path.is_file():
            fd = os.open(path, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
    fsync_folder(folder)
