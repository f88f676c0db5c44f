"""Where ``gaitlib train`` writes, and what it may replace there.

Training never silently replaces a gait that other artefacts depend on (Isaac Lab, mjlab and legged_gym likewise
never write over what they ship: a run writes its own output, and the user chooses what to use):

- By default a trained gait goes into the user's own library (:mod:`gaitlib.library.target`, the rule of every
  command that writes a library), made on its first write as a copy of the shipped library (entries and switching
  models), so that a retrained gait joins gaits it can switch with at once and only its own pairs need new
  transition data.
- A protected library (the shipped one, one marked as shipped, one committed to git) is written only on purpose
  (``--replace``), a new gait included; a library another process writes is refused before training starts.
- The tests' preset (``tiny``: it learns nothing) writes only into a library whose every entry it trained.
- Replacing an entry of any other library is allowed, and said: before training starts, which pairs of its
  switching models the new policy leaves stale (``gaitlib library`` then prints the commands that fix them).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from gaitlib.errors import GaitlibError
from gaitlib.library.layout import ordered_pairs
from gaitlib.library.store import Library
from gaitlib.library.target import check_writable

__all__ = ["TEST_PRESET", "TrainTarget", "check_target"]

TEST_PRESET = "tiny"
"""The preset that exists for tests: refused in a library holding an entry it did not train."""


@dataclass(frozen=True)
class TrainTarget:
    """The library a training run writes into, and what it found there before any work."""

    library: Path
    """The library folder the entry is written into."""
    copy_from: Path | None
    """A library to copy into :attr:`library` before the entry is written (it does not exist yet), else ``None``."""
    notes: tuple[str, ...]
    """What the run will change beyond its own entry (stale pairs), one line each."""


def check_target(library: Path, gait: str, *, preset: str, replace: bool, copy_from: Path | None = None,
                 states: Path | None = None) -> TrainTarget:
    """Refuse, before any work, a run that would write a protected library without ``replace``, write a library
    another process writes now, or put the tests' preset among trained gaits; otherwise say which switching pairs the
    new entry will leave stale, and, when the handover ``states`` were recorded with other policies than the
    library's, whose they are."""
    lib = Library(copy_from if copy_from is not None else library)
    names = lib.gaits()
    if copy_from is None:  # a protected library only with --replace; no other writer of it now
        check_writable(library, replace=replace, command="gaitlib train", what=f"the entry {gait}")
    if preset == TEST_PRESET:
        trained = [n for n in names if n != gait and _preset(lib, n) != TEST_PRESET]
        if trained or (gait in names and _preset(lib, gait) != TEST_PRESET):
            raise GaitlibError(
                f"the '{TEST_PRESET}' preset is for tests (it learns nothing) and writes only into a library of its "
                f"own; {library} holds trained gaits ({', '.join(names)}): pass --library with a new folder"
            )
    notes = []
    if gait in names and lib.switching_dir.is_dir():
        stale = [p for p in ordered_pairs(names) if gait in p.split("-")]
        notes.append(
            f"replacing {Path(library) / gait}: the switching models there were fitted on the old {gait}, so pairs "
            f"{', '.join(stale)} will need new transition data (gaitlib library --library {library} says how)"
        )
    if states is not None:
        from gaitlib.envs.handover import load_states

        recorded, _ = load_states(states)
        current = lib.identities()
        other = sorted(g for g, identity in recorded.identities.items() if g != gait and current.get(g) != identity)
        if other:
            notes.append(
                f"the handover states in {states} come from policies that are not {library}'s: {', '.join(other)} "
                f"({'gaits it lacks or ' if set(other) - set(current) else ''}other policies of these gaits); the new "
                f"{gait} learns to take over from those"
            )
    return TrainTarget(Path(library), copy_from, tuple(notes))


def _preset(lib: Library, name: str) -> str | None:
    """The preset entry ``name`` was trained with, as its metadata records it (``None``: unreadable)."""
    try:
        return json.loads((lib.root / name / "metadata.json").read_text())["training"]["preset"]["name"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
