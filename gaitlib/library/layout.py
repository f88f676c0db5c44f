"""Where libraries are and the names and orders every file agrees on: the shipped and default library folders,
the canonical gait order, ordered pairs, the commands of a first fit, and the identity check of files made for a
library's policies. No heavy imports: everything that names a library's gaits or files uses these."""

from __future__ import annotations

import os
import subprocess
from collections.abc import Iterable, Mapping
from pathlib import Path

from gaitlib.defaults import Falls
from gaitlib.errors import TransitionDataError

__all__ = [
    "PACKAGED_LIBRARY",
    "SHIPPED_MARKER",
    "check_identities",
    "default_library_dir",
    "first_fit",
    "gait_order",
    "is_shipped",
    "merged_fit",
    "ordered_pairs",
    "protection",
    "shipped_library_dir",
]


PACKAGED_LIBRARY = "shipped"
"""The folder of ``gaitlib/library/`` that holds the shipped library in a wheel (the build copies ``library/``
there: ``setup.py``)."""


def shipped_library_dir() -> Path:
    """The library that ships with gaitlib, by one rule: run from a source checkout (the folder holding the
    ``gaitlib`` package also holds ``pyproject.toml``), the checkout's ``library/``; installed from a wheel (or by
    ``pip install .``), the copy the build put inside the package, ``gaitlib/library/shipped/``
    (:data:`PACKAGED_LIBRARY`)."""
    here = Path(__file__).resolve().parent
    checkout = here.parents[1]
    if (checkout / "pyproject.toml").is_file():
        return checkout / "library"
    return here / PACKAGED_LIBRARY


def default_library_dir() -> Path:
    """The library commands read by default: ``$GAITLIB_LIBRARY`` if set, else the shipped one
    (:func:`shipped_library_dir`). Training writes elsewhere by default (:mod:`gaitlib.training.target`)."""
    if "GAITLIB_LIBRARY" in os.environ:
        return Path(os.environ["GAITLIB_LIBRARY"])
    return shipped_library_dir()


def is_shipped(root: Path | str) -> bool:
    """Whether ``root`` is the shipped library (:func:`shipped_library_dir`), under whatever path it is named."""
    try:
        return Path(root).resolve() == shipped_library_dir().resolve()
    except OSError:
        return False


SHIPPED_MARKER = ".gaitlib-shipped"
"""A file at a library's root that marks it as shipped data (its content is free text): such a library is written
only with ``--replace``, wherever it lies and whatever its folder's name. Copies made by gaitlib leave it out (a
user's own library is never marked)."""


def protection(root: Path | str) -> str | None:
    """Why the library ``root`` is written only with ``--replace``, ``None`` if it is not protected: the shipped
    library, one marked as shipped (:data:`SHIPPED_MARKER`), or one with a file tracked by git in the checkout it
    lives in (``library-paper/``, ``library-switch-start/``: committed results)."""
    root = Path(root)
    if is_shipped(root):
        return "the shipped library"
    if (root / SHIPPED_MARKER).is_file():
        return f"marked as shipped ({SHIPPED_MARKER})"
    if not root.is_dir():
        return None
    try:
        tracked = subprocess.run(["git", "-C", str(root), "ls-files", "--", "."], capture_output=True, text=True,
                                 timeout=30, check=False)
    except (OSError, subprocess.SubprocessError):  # no git: only the marker protects
        return None
    return "committed to git" if tracked.returncode == 0 and tracked.stdout.strip() else None


def gait_order(names: Iterable[str]) -> tuple[str, ...]:
    """The canonical order of a set of gaits (names sorted, each once): the one order every file indexes gaits by."""
    return tuple(sorted(set(names)))


def ordered_pairs(gaits: Iterable[str]) -> list[str]:
    """Every ordered pair ``"m-n"`` of ``gaits`` (sources, then destinations, in the order given)."""
    names = list(gaits)
    return [f"{m}-{n}" for m in names for n in names if m != n]


def first_fit(root: Path) -> tuple[str, str]:
    """The commands that make a library's first switching models: collect every pair, then fit."""
    data = Path("data") / f"{Path(root).name}.h5"
    return (
        f"gaitlib collect --library {root} --samples 2e5 --out {data}",
        f"gaitlib fit --library {root} --data {data}",
    )


def check_identities(recorded: Mapping[str, str], current: Mapping[str, str], *, what: str) -> None:
    """Refuse, with one line naming ``what``, a file (transition data, a transition-net, a TMT) made for other
    policies than the current ones: ``recorded`` is gait name -> identity as the file holds them, ``current`` the
    library's. Every recorded gait must be present with the same identity
    (:class:`~gaitlib.errors.TransitionDataError` otherwise)."""
    for gait, identity in recorded.items():
        if gait not in current:
            raise TransitionDataError(f"{what} needs gait '{gait}', which the library does not hold")
        if current[gait] != identity:
            raise TransitionDataError(
                f"{what} was made for another '{gait}' policy than the library's (identities differ); gaitlib "
                "library lists the stale pairs and the commands that collect and fit them again"
            )


def merged_fit(kept_falls: str, new_falls: str, kept: Mapping[str, str], new: Mapping[str, str], *,
               what: str) -> tuple[Falls, dict[str, str]]:
    """The definition of a fall and the identities (gait name -> identity) of two fits' models of one kind merged
    into one (``gaitlib fit --extend``): ``kept_falls``/``new_falls`` each fit's definition, ``kept``/``new`` its
    identities. Refused in one line naming ``what`` (e.g. ``"TMT"``) where the definitions differ or a gait's
    policies do (:class:`~gaitlib.errors.TransitionDataError`)."""
    falls = {Falls(kept_falls), Falls(new_falls)}
    if len(falls) != 1:
        raise TransitionDataError(f"the kept {what} and the new one follow different definitions of a fall "
                                  f"({', '.join(sorted(falls))}); they cannot be merged")
    identities = dict(kept)
    for gait, identity in new.items():
        if identities.setdefault(gait, identity) != identity:
            raise TransitionDataError(f"the kept {what} and the new one hold different '{gait}' policies")
    return falls.pop(), identities
