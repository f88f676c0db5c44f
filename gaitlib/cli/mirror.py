"""``gaitlib mirror SOURCE --as NAME``."""

from __future__ import annotations

import shlex
from pathlib import Path

import typer

__all__ = ["mirror_command"]


def mirror_command(
    source: str = typer.Argument(..., help="The entry to mirror (a gait of --from)."),
    name: str = typer.Option(..., "--as", help="The new entry's gait: a shipped description that is the mirror "
                             "image of SOURCE's (turn_right of turn_left, sidestep_left of sidestep_right)."),
    source_library: Path | None = typer.Option(
        None, "--from", help="Library that holds SOURCE (default: $GAITLIB_LIBRARY, else the shipped library/)."
    ),
    library: Path | None = typer.Option(
        None, "--library",
        help="Library to write the entry into (default: $GAITLIB_LIBRARY, else your own runs/library, made from the "
        "shipped library on its first write).",
    ),
    replace: bool = typer.Option(
        False, "--replace", help="Replace an entry NAME already there, or write a protected library (the shipped "
        "one, one committed to git): refused without it."
    ),
) -> None:
    """Make a library entry as the left-right mirror image of another: SOURCE's weights with the A1's symmetry folded
    into them (legs FR <-> FL and RR <-> RL, abduction angles, lateral and turning motion negated: docs/skills.md,
    "Mirrored skills"), a policy like any trained one. Nothing is trained; the entry records what it was mirrored
    from, and gets its evaluation as any entry does: gaitlib eval NAME --record."""
    from rich.console import Console

    from gaitlib.cli.preflight import writable_folder
    from gaitlib.gaits import get_gait
    from gaitlib.library import Library, library_status
    from gaitlib.library.layout import default_library_dir
    from gaitlib.library.target import copy_library, writing_target
    from gaitlib.training.mirror import MirrorRequest, check_mirror, mirror_entry

    description = get_gait(name)  # a gait without a description: one line naming the known ones
    target, copy_from = writing_target(library)
    origin = source_library if source_library is not None else default_library_dir()
    writable_folder("--library", target, what="a library folder")
    words = ["gaitlib", "mirror", source, "--as", name, "--from", str(origin), "--library", str(target)]
    request = MirrorRequest(source_library=origin, source=source, library=target, description=description,
                            replace=replace, command=shlex.join(words + (["--replace"] if replace else [])))
    check_mirror(request)  # every refusal before the user library is made
    if copy_from is not None:
        copy_library(copy_from, target)
    entry = mirror_entry(request)
    console = Console(stderr=True)
    console.print(f"wrote {entry}: the mirror image of {origin / source} (no evaluation yet)", soft_wrap=True)
    for problem in library_status(Library(target)).problems:
        console.print(f"next: {problem.line()}", soft_wrap=True)
    console.print(f"evaluate it: gaitlib eval {name} --library {target} --record", soft_wrap=True)
