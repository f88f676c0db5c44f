"""Several transition files read as one: how a grown library refits on old and new data together.

Files may hold different gaits (a collection made after a gait was added holds the new pairs); gait indices are
remapped onto the canonical order of the union of their gaits (:func:`~gaitlib.training.library.gait_order`), the
order the transition-net and the TMT index gaits by, whatever order a file was written in. Files must agree on every
gait they share (same library identity: the same policy) and on the latent size.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from gaitlib.errors import TransitionDataError
from gaitlib.training.library import gait_order
from gaitlib.transitions.schema import TransitionBatch, TransitionData, TransitionFileInfo, TransitionHeader, read

__all__ = ["read_all"]


def read_all(paths: Sequence[Path]) -> TransitionData:
    """Read and merge the committed samples of ``paths``, gaits in canonical order."""
    if not paths:
        raise TransitionDataError("no transition data files given")
    parts = [read(Path(p)) for p in paths]
    if len(parts) == 1 and parts[0].header.gaits == gait_order(parts[0].header.gaits):
        return parts[0]
    identities: dict[str, str] = {}
    for path, part in zip(paths, parts, strict=True):
        for gait, identity in zip(part.header.gaits, part.header.identities, strict=True):
            if identities.setdefault(gait, identity) != identity:
                raise TransitionDataError(
                    f"{path} holds samples of another '{gait}' policy than the files before it; they cannot be mixed"
                )
    latent = {part.header.latent_dim for part in parts}
    if len(latent) != 1:
        raise TransitionDataError(f"the files have different latent sizes {sorted(latent)}; they cannot be mixed")
    gaits = gait_order(identities)
    batches = []
    for part in parts:
        remap = np.array([gaits.index(g) for g in part.header.gaits])
        columns = part.samples.columns()
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
    notes = [part.info.note for part in parts if part.info.note]
    info = TransitionFileInfo(
        header,
        sum(part.info.count for part in parts),
        [session for part in parts for session in part.info.sessions],
        "; ".join(notes) or None,
    )
    return TransitionData(info, TransitionBatch.concatenate(batches))
