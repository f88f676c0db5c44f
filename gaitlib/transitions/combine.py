"""Several transition files read as one: how a grown library, or one with a retrained gait, refits on old and new
data together.

Files may hold different gaits (a collection made after a gait was added holds the new pairs); gait indices are
remapped onto the canonical order of the union of their gaits (:func:`~gaitlib.library.store.gait_order`), the
order the transition-net and the TMT index gaits by, whatever order a file was written in. Files must agree on the
latent size, and on every gait they share (same library identity: the same policy), unless the library's current
identities are given: then the samples of a pair whose source or destination policy is not the library's current
one (a gait retrained or removed since) are left out, and the data say so in their note.

The same samples are counted once, whatever the files are called: a file given twice, through a hard link or as a
copy holds the same committed parts (the same content SHA-256,
:attr:`~gaitlib.transitions.records.TransitionFileInfo.files`) and is read once; a sample of a later file that is
byte for byte a sample of an earlier one (two collections with the same seed and settings draw the same samples) is
left out. The note names each such file, the file it repeats and how many samples were left out.

A budget of ``per_pair`` keeps the first samples of each ordered pair of each file, in file order (the order they
were collected in), as a shorter collection with the same seed would hold them: the budget of a new pair is read
from nets fitted on such nested subsets (``docs/transitions.md``, "The switch-success budget").
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from gaitlib.defaults import Falls
from gaitlib.errors import TransitionDataError
from gaitlib.library.layout import gait_order
from gaitlib.transitions.schema import TransitionBatch, TransitionData, TransitionFileInfo, TransitionHeader, read

__all__ = ["pairs_that_fell", "read_all"]


def read_all(paths: Sequence[Path], *, current: Mapping[str, str] | None = None,
             per_pair: int | None = None) -> TransitionData:
    """Read and merge the committed samples of ``paths``, gaits in canonical order.

    ``per_pair``: keep at most the first this many samples of each ordered pair of each file (module doc; ``None``:
    every sample).

    ``current``: gait name -> identity of the library's policies; samples of pairs collected with any other policy
    are left out (and counted in the note). ``None``: every sample is kept, and two files holding different
    policies of one gait are refused.
    """
    if not paths:
        raise TransitionDataError("no transition data files given")
    parts = [read(Path(p)) for p in paths]
    if per_pair is not None and per_pair < 1:
        raise ValueError(f"per_pair must be at least 1, got {per_pair}")
    if (current is None and per_pair is None and len(parts) == 1
            and parts[0].header.gaits == gait_order(parts[0].header.gaits)):
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
    repeats, repeated = _repeats(paths, parts)
    kept_rows = [rows & ~again for rows, again in zip(kept_rows, repeats, strict=True)]
    notes += repeated
    if per_pair is not None:
        kept_rows = [_first_per_pair(part.samples, rows, per_pair) for part, rows in zip(parts, kept_rows, strict=True)]
        notes.append(f"the first {per_pair:,} samples of each ordered pair of each file kept")
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
        header, len(samples), [session for part in parts for session in part.info.sessions], "; ".join(notes) or None,
        tuple(file for part in parts for file in part.info.files),
    )
    return TransitionData(info, samples)


def pairs_that_fell(path: Path, *, current: Mapping[str, str], falls: Falls) -> tuple[tuple[str, str], ...]:
    """The ordered pairs, as (source, destination) names in the file's order, in which at least one switch of the
    transition file ``path`` fell (labels by ``falls``): a short screen's pairs that need a full collection, where a
    pair whose every screened switch stayed up does not (``docs/transitions.md``, "Growing by extension"). Samples of
    pairs collected with other policies than ``current``'s (gait name -> library identity) are left out, as
    :func:`read_all` leaves them."""
    data = read_all([path], current=current).labelled(falls)
    samples, gaits = data.samples, data.header.gaits
    failed = ~samples.success.astype(bool)
    fell = sorted(set(zip(samples.source[failed].tolist(), samples.dest[failed].tolist(), strict=True)))
    return tuple((gaits[m], gaits[n]) for m, n in fell)


def _first_per_pair(samples: TransitionBatch, rows: np.ndarray, count: int) -> np.ndarray:
    """``rows`` (a mask over ``samples``) with only the first ``count`` kept samples of each ordered pair, in file
    order."""
    index = np.flatnonzero(rows)
    pair = samples.source[index].astype(np.int64) * (int(samples.dest.max(initial=0)) + 1) + samples.dest[index]
    order = np.argsort(pair, kind="stable")  # each pair's rows together, in file order
    starts = np.flatnonzero(np.r_[True, np.diff(pair[order]) != 0])
    rank = np.arange(len(order)) - np.repeat(starts, np.diff(np.r_[starts, len(order)]))
    kept = rows.copy()
    kept[index[order[rank >= count]]] = False
    return kept


def _repeats(paths: Sequence[Path], parts: Sequence[TransitionData]) -> tuple[list[np.ndarray], list[str]]:
    """Per file, (n,) true for the samples an earlier file already holds, and a note naming each file that repeats
    another and how many of its samples are left out for it."""
    if len(parts) == 1:
        return [np.zeros(len(parts[0].samples), dtype=bool)], []
    first_with: dict[str, Path] = {}
    seen: dict[bytes, int] = {}
    repeats, notes = [], []
    for k, (path, part) in enumerate(zip(paths, parts, strict=True)):
        count = len(part.samples)
        content = part.info.files[0][1]
        if content in first_with:
            repeats.append(np.ones(count, dtype=bool))
            if count:
                notes.append(
                    f"{path} holds the same {count:,} samples as {first_with[content]} (content SHA-256 "
                    f"{content[:12]}: one file under two names, a link, a copy, or a collection with the same seed "
                    "and settings); counted once"
                )
            continue
        first_with[content] = Path(path)
        digests = _row_digests(part.samples)
        earlier = np.array([seen.get(d, k) for d in digests], dtype=np.int64)
        repeats.append(earlier < k)
        for j, times in zip(*np.unique(earlier[earlier < k], return_counts=True), strict=True):
            notes.append(
                f"{path}: {int(times):,} of its {count:,} samples are byte for byte samples of {paths[j]} (collected "
                "with the same seed and settings); counted once"
            )
        for d in digests:
            seen.setdefault(d, k)
    return repeats, notes


def _row_digests(batch: TransitionBatch) -> list[bytes]:
    """A 16-byte BLAKE2b digest of every sample's bytes, all its columns together."""
    count = len(batch)
    rows = np.concatenate(
        [np.ascontiguousarray(values).reshape(count, -1).view(np.uint8) for values in batch.columns().values()],
        axis=1,
    )
    return [hashlib.blake2b(row, digest_size=16).digest() for row in rows]
