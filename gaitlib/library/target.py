"""Where a command that writes a library writes, and whether it may: ``gaitlib train``, ``fit``, ``routes``,
``eval --record``, ``survival fit`` and ``survival catches`` follow one rule.

Nothing a user runs rewrites the shipped library by accident (Isaac Lab, mjlab and legged_gym likewise never write
over what they ship: a run writes its own output, and the user chooses what to use):

- A writing command writes into the library ``--library`` names; without it into ``$GAITLIB_LIBRARY``; without
  that into the user's own library, :data:`USER_LIBRARY`, made on its first write as a copy of the shipped one
  (entries and switching models, published in one step).
- A protected library (the shipped one, one marked as shipped, or one committed to git, such as
  ``library-paper/``: :func:`~gaitlib.library.layout.protection`) is written only on purpose (``--replace``);
  otherwise the command is refused in one line before any work.
- Two writers of one library exclude each other (:func:`library_writer`): the second is refused in one line, and a
  reader sees the old files or the new ones, whole.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
from collections.abc import Iterator
from pathlib import Path

from gaitlib.atomic import check_unlocked, release_lock, take_lock
from gaitlib.errors import GaitlibError
from gaitlib.library.layout import protection, shipped_library_dir
from gaitlib.library.publish import staged_folder
from gaitlib.library.store import Library

__all__ = [
    "USER_LIBRARY",
    "WRITER_LOCK",
    "check_library",
    "check_writable",
    "copy_library",
    "library_writer",
    "measurement_id",
    "writing_target",
]

USER_LIBRARY = Path("runs") / "library"
"""The user's own library, relative to the working folder: where writing commands write by default."""
WRITER_LOCK = ".writer.lock"
"""The lock file inside a library that its writers hold for their whole run."""


def writing_target(library: Path | None) -> tuple[Path, Path | None]:
    """(the library to write into, the library to copy there first): ``library`` if given (never copied into);
    else ``$GAITLIB_LIBRARY``; else :data:`USER_LIBRARY`, a copy of the shipped library when it does not exist."""
    if library is not None:
        return Path(library), None
    if "GAITLIB_LIBRARY" in os.environ:
        return Path(os.environ["GAITLIB_LIBRARY"]), None
    shipped = shipped_library_dir()
    fresh = not USER_LIBRARY.exists() and shipped.is_dir()
    return USER_LIBRARY, shipped if fresh else None


def check_writable(library: Path, *, replace: bool, command: str, what: str) -> None:
    """Refuse, in one line, ``command`` writing ``what`` into a protected library (the shipped one, one marked as
    shipped or committed to git: :func:`~gaitlib.library.layout.protection`) without ``replace``, and a writer
    while another holds the library's lock (checked, not taken: nothing is created)."""
    why = protection(library)
    if why is not None and not replace:
        shipped = "the shipped library" if why == "the shipped library" else f"a protected library ({why})"
        raise GaitlibError(
            f"{command} would rewrite {what} of {shipped}, {library}; it writes to your own library by default "
            f"({USER_LIBRARY}, a copy of the shipped one, or $GAITLIB_LIBRARY), or pass --replace to rewrite this "
            "one on purpose"
        )
    check_unlocked(Path(library) / WRITER_LOCK, writing=_writing(library, command), error=GaitlibError)


def check_library(library: Path, *, command: str) -> None:
    """Refuse, in one line naming the folder, ``command`` writing into a folder that holds no gait entry (not a
    library, or an empty one): what it writes needs a library's policies."""
    if not Library(library).gaits():
        state = "does not exist" if not Path(library).exists() else "holds no gait entry"
        raise GaitlibError(
            f"{command}: {library} is not a library ({state}); give --library a folder of trained gaits, or leave "
            f"it out to write into your own library ({USER_LIBRARY})"
        )


def copy_library(source: Path, destination: Path) -> Path:
    """Copy the entries and switching models of library ``source`` into the new library ``destination``, published
    in one step (a kill leaves no library or the whole copy)."""
    if destination.exists():
        raise GaitlibError(f"{destination} exists already; it is not replaced by a copy of {source}")
    lib = Library(source)
    with staged_folder(destination) as staging:
        for name in [*lib.gaits(), Library.SWITCHING]:
            if (lib.root / name).is_dir():
                shutil.copytree(lib.root / name, staging / name, ignore=shutil.ignore_patterns(".*"))
    return destination


@contextlib.contextmanager
def library_writer(library: Path, *, command: str) -> Iterator[None]:
    """Hold ``library``'s writer lock while the block runs: a second writer (``gaitlib fit``, ``routes``, ``train``'s
    publishing, ``eval --record``, ``survival fit``, ``survival catches``) is refused in one line while one runs; the
    kernel frees the lock however the holder ends."""
    lock = Path(library) / WRITER_LOCK  # take_lock makes the folder of a library's first write
    fd = take_lock(lock, writing=_writing(library, command), error=GaitlibError)
    try:
        yield
    finally:
        release_lock(lock, fd)


def _writing(library: Path, command: str) -> str:
    """What a refused writer's line starts with: the refused command and the library (the holder follows)."""
    return f"{command} refused: library {library}"


def measurement_id(library: Library) -> str:
    """12 hex digits naming what a measurement of ``library`` depends on (its policies and switching models): a
    default output folder that two libraries share only when they hold the same models."""
    key = {"policies": library.identities(), "switching": library.switching_identity()}
    return hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:12]
