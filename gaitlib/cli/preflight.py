"""What every command checks before its first simulated step: the options it was given that contradict each other,
every path it will write, every optional package it will need and every lock it will take.

A refusal is one line, ``gaitlib: error: ...`` with exit code 2, and nothing is created or written: a command that
would fail at its end (a plot into a folder that cannot be made, a video without imageio, a library that is a
file, a library another process writes) fails before its work instead (``docs/failures.md``, "Bad input").
"""

from __future__ import annotations

import importlib.util
import os
import tempfile
from collections.abc import Iterable, Mapping
from pathlib import Path

import typer

from gaitlib.cli.options import OptionError

__all__ = [
    "apart",
    "given",
    "library_input",
    "needs_module",
    "no_effect",
    "plot_and_video",
    "writable_file",
    "writable_folder",
    "writing_library",
]


def given(ctx: typer.Context, name: str) -> bool:
    """Whether the parameter ``name`` (its Python name, ``kick_max``) of the command running in ``ctx`` was given on
    the command line (or by the environment), not left at its default."""
    source = ctx.get_parameter_source(name)
    return source is not None and source.name not in ("DEFAULT", "DEFAULT_MAP")


def _flag(ctx: typer.Context, name: str) -> str:
    """The option's own spelling (``--kick-max``) of the parameter ``name``."""
    return next(param.opts[0] for param in ctx.command.params if param.name == name)


def no_effect(ctx: typer.Context, names: Iterable[str], *, when: bool, because: str) -> None:
    """Refuse the options ``names`` (parameter names) given to the command running in ``ctx`` although, ``when``
    this holds, they change nothing (``because`` says why, e.g. ``with --push-kind force (its pushes are forces, not
    kicks)``): a run records the options it ran with, and one it ignored would be recorded as if it had run."""
    if not when:
        return
    flags = [_flag(ctx, name) for name in names if given(ctx, name)]
    if flags:
        them = "it" if len(flags) == 1 else "them"
        raise OptionError(f"{', '.join(flags)} {'has' if len(flags) == 1 else 'have'} no effect {because}: "
                          f"leave {them} out")


def writable_file(option: str, path: Path) -> Path:
    """``path`` if a file can be written there: a name that is not empty and not a folder, in a folder that exists
    and can be written, or can be made (its nearest existing parent a writable folder, tried by making a file or a
    folder there and removing it); one line otherwise. Nothing is left behind."""
    if not str(path).strip() or path.is_dir():
        raise OptionError(f"{option} must name a file, got '{path}'" + (" (a folder)" if path.is_dir() else ""))
    _creatable(option, path.parent, of=path)
    return path


def writable_folder(option: str, path: Path, *, what: str = "a folder") -> Path:
    """``path`` if it is a writable folder, or one that can be made; one line naming ``what`` otherwise (``--library
    x`` that is a file: ``--library x is a file, not a library folder``). Nothing is left behind."""
    if path.exists() and not path.is_dir():
        raise OptionError(f"{option} {path} is a file, not {what}")
    _creatable(option, path, of=path)
    return path


def plot_and_video(plot: Path, video: Path | None, *, inputs: Mapping[str, Path | None] | None = None,
                   library: Path | None = None) -> None:
    """``--plot`` and ``--video`` (when given) writable, apart from each other, from the command's input files
    ``inputs`` and from the ``library`` it reads (``None``: the default one) (:func:`apart`), and the packages
    ``--video`` needs installed (``gaitlib run``, ``drive``)."""
    apart({"--plot": plot, "--video": video}, files=inputs or {}, folders=library_input(library))
    writable_file("--plot", plot)
    if video is not None:
        writable_file("--video", video)
        needs_module("--video", ("imageio", "imageio_ffmpeg"), install="pip install 'gaitlib[video]'")


def apart(outputs: Mapping[str, Path | None], *, files: Mapping[str, Path | None],
          folders: Mapping[str, Path | None]) -> None:
    """Refuse an output (option -> path; ``None``: not written) that would overwrite one of the command's input
    ``files`` or ``folders`` (option, or a description such as ``the library``, -> its path), lie inside an input
    folder, or be another output: paths compared as the file system resolves them (the working folder, ``..``,
    symbolic links; a hard link to an existing input too)."""
    seen: dict[str, str] = {}
    for option, path in outputs.items():
        if path is None:
            continue
        where = os.path.realpath(path)
        for source, read in {**files, **folders}.items():
            if read is None:
                continue
            if _same(path, read):
                raise OptionError(f"{option} {path} is the input {source} {read}: writing it would replace what the "
                                  f"command reads; give {option} another path")
            if source in folders and Path(where).is_relative_to(os.path.realpath(read)):
                raise OptionError(f"{option} {path} lies in {source} {read}, which the command reads; give "
                                  f"{option} a path outside it")
        if where in seen:
            raise OptionError(f"{seen[where]} and {option} both name {path}; give each its own path")
        seen[where] = option


def library_input(library: Path | None) -> dict[str, Path]:
    """The library a command reads (``--library``, or the default one) as an input folder of :func:`apart`."""
    from gaitlib.library.layout import default_library_dir

    return {"--library": library} if library is not None else {"the library": default_library_dir()}


def _same(a: Path, b: Path) -> bool:
    """Whether ``a`` and ``b`` name one file: one resolved path, or one file on disk (a hard link)."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist: not the same
        return False


def writing_library(library: Path | None, *, replace: bool, command: str, what: str) -> tuple[Path, Path | None]:
    """(the library ``command`` writes ``what`` into, the library to copy there first:
    :func:`~gaitlib.library.target.writing_target`), after refusing a target that is a file or cannot be made, and
    one that is protected without ``replace`` or held by another writer
    (:func:`~gaitlib.library.target.check_writable`)."""
    from gaitlib.library.target import check_writable, writing_target

    target, copy_from = writing_target(library)
    writable_folder("--library", target, what="a library folder")
    check_writable(target, replace=replace, command=command, what=what)
    return target, copy_from


def _creatable(option: str, folder: Path, *, of: Path) -> None:
    """Refuse ``option`` (which writes ``of``) when ``folder`` cannot be made or written: a file on its way, or its
    nearest existing folder not writable."""
    existing = Path(os.path.abspath(folder))
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        raise OptionError(f"{option} {of} cannot be written: {existing} is a file, not a folder")
    if not os.access(existing, os.W_OK | os.X_OK) or not _tried(existing):
        raise OptionError(f"{option} {of} cannot be written: the folder {existing} is not writable")


def _tried(folder: Path) -> bool:
    """Whether a file can be made in ``folder``, tried (a file system that refuses what its permissions allow:
    ``/proc``, a read-only mount for root), the file removed at once."""
    try:
        handle, name = tempfile.mkstemp(prefix=".gaitlib-try-", dir=folder)
    except OSError:
        return False
    os.close(handle)
    os.unlink(name)
    return True


def needs_module(option: str, modules: Iterable[str], *, install: str) -> None:
    """Refuse ``option`` when one of the optional packages ``modules`` it needs is not installed (``install``: the
    command that installs them)."""
    missing = [name for name in modules if importlib.util.find_spec(name) is None]
    if missing:
        raise OptionError(f"{option} needs {' and '.join(missing)}, which {'is' if len(missing) == 1 else 'are'} not "
                          f"installed: {install}")
