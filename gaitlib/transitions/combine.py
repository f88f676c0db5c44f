"""Several transition files read as one: how a grown library, or one with a retrained gait, refits on old and new
data together.

Files may hold different gaits (a collection made after a gait was added holds the new pairs); gait indices are
remapped onto the canonical order of the union of their gaits (:func:`~gaitlib.library.store.gait_order`), the
order the transition-net and the TMT index gaits by, whatever order a file was written in. Files must agree on the
latent size, and on every gait they share (same library identity: the same policy), unless the library's current
identities are given: then the samples of a pair whose source or destination policy is not the library's current
one (a gait retrained or removed since) are left out, and the data say so in their note.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from gaitlib.errors import TransitionDataError
from gaitlib.library.layout import gait_order
from gaitlib.transitions.schema import TransitionBatch, TransitionData, TransitionFileInfo, TransitionHeader, read

__all__ = ["read_all"]


def read_all(paths: Sequence[Path], *, current: Mapping[str, str] | None = None) -> TransitionData:
    """Read and merge the committed samples of ``paths``, gaits in canonical order.

    ``current``: gait name -> identity of the library's policies; samples of pairs collected with any other policy
    are left out (and counted in the note). ``None``: every sample is kept, and two files holding different
    policies of one gait are refused.
    """
    if not paths:
        raise TransitionDataError("no transition data files given")
    parts = [read(Path(p)) for p in paths]
    if current is None and len(parts) == 1 and parts[0].header.gaits == gait_order(parts[0].header.gaits):
        return parts[0]
    identities: dict[str, str] = {}
    kept_rows, notes = [], [part.info.note for part in parts if part.info.note]
    for path, part in zip(paths, parts, strict=True):
        header = part.header
        valid = np.ones(len(header.gaits), dtype=bool)
        for i, (gait, identity) in enumerate(zip(header.gaits, header.identities, strict=True)):
            if current is not None:
                valid[i] = current.get(gait) == identity
            elif identities.setdefault(gait, identity) != identity:
                raise TransitionDataError(
                    f"{path} holds samples of another '{gait}' policy than the files before it; they cannot be mixed"
                )
        rows = valid[part.samples.source] & valid[part.samples.dest]
        kept_rows.append(rows)
        if current is not None:
            identities.update((g, i) for g, i, ok in zip(header.gaits, header.identities, valid, strict=True) if ok)
            if not rows.all():
                stale = ", ".join(g for g, ok in zip(header.gaits, valid, strict=True) if not ok)
                notes.append(
                    f"{path}: {int((~rows).sum()):,} samples of pairs with {stale} left out (collected with another "
                    "policy than the library's)"
                )
    if not any(rows.any() for rows in kept_rows):
        raise TransitionDataError(
            f"no sample of {', '.join(map(str, paths))} was collected with the library's current policies"
        )
    latent = {part.header.latent_dim for part in parts}
    if len(latent) != 1:
        raise TransitionDataError(f"the files have different latent sizes {sorted(latent)}; they cannot be mixed")
    gaits = gait_order(identities)
    batches = []
    for part, rows in zip(parts, kept_rows, strict=True):
        remap = np.array([gaits.index(g) if g in identities else -1 for g in part.header.gaits])
        columns = part.samples.select(rows).columns()
        columns["source"] = remap[columns["source"]]
        columns["dest"] = remap[columns["dest"]]
        batches.append(TransitionBatch(**columns))
    header = TransitionHeader(
        gaits=gaits,
        identities=tuple(identities[g] for g in gaits),
        latent_dim=latent.pop(),
        settings=parts[0].header.settings if len(parts) == 1 else {
            "files": [{"path": str(p), "settings": part.header.settings} for p, part in zip(paths, parts, strict=True)]
        },
    )
    samples = TransitionBatch.concatenate(batches)
    info = TransitionFileInfo(
        header, len(samples), [session for part in parts for session in part.info.sessions], "; ".join(notes) or None
    )
    return TransitionData(info, samples)
