"""The transition-matrix table (TMT, Soeseno et al. 2021) and the calibration of the data-driven thresholds.

The TMT counts collected switch outcomes by (m, n, source phase bin, destination phase bin); a cell's score is its
alive rate with a uniform prior, (successes + 1) / (samples + 2), so an empty cell scores 0.5. (The published TMT
also scores duration, effort and control accuracy; gaitlib's keeps the alive rate only, the quantity switching is
judged on.) Beside it the table keeps what the ``value`` strategies need: each gait's typical on-gait critic value
(the mean source critic value of the samples starting from that gait), by which destination values are divided.

Thresholds of ``value``, ``tmt`` and ``tmt-value`` are calibrated per ordered pair on the same data: each sample is
scored as the strategy would score its (state, phi_n), and the threshold is the one that best separates successes
from failures (largest balanced accuracy). The table is written to ``library/switching/tmt.json`` and, like the
transition-net, refused at load time when the library's policies are not the ones it was built for.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import torch

from gaitlib.atomic import read_json, write_json
from gaitlib.defaults import Falls
from gaitlib.errors import TransitionDataError
from gaitlib.library.layout import check_identities, merged_fit
from gaitlib.strategies.base import PHASE_GRID, Strategy, SwitchQuery
from gaitlib.transitions.schema import TransitionData

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "TMTStrategy",
    "TMTValueStrategy",
    "TransitionTable",
    "best_threshold",
    "build_table",
    "load_table",
    "merge_tables",
    "save_table",
]

FORMAT_NAME = "gaitlib.tmt"
FORMAT_VERSION = 1
CALIBRATED = ("value", "tmt", "tmt-value")
"""Strategies whose thresholds the table holds."""


@dataclass
class TransitionTable:
    """Switch outcomes by pair and phase bins, typical values, and calibrated thresholds."""

    gaits: tuple[str, ...]
    """Gait names; indices in ``successes``/``counts`` follow this order."""
    identities: dict[str, str]
    """Library identity (SHA-256) of each gait's policy."""
    successes: np.ndarray
    """(G, G, B, B) successful switches by m, n, source phase bin, destination phase bin."""
    counts: np.ndarray
    """(G, G, B, B) switches in each cell."""
    typical_value: np.ndarray
    """(G,) mean critic value of each gait while it runs on-gait (before a switch)."""
    thresholds: dict[str, dict[tuple[int, int], float]]
    """Strategy name -> (m, n) -> threshold, for the strategies of :data:`CALIBRATED`."""
    info: dict
    """Where the table came from: data file, samples, calibration rule."""

    @property
    def bins(self) -> int:
        """B: phase bins per cycle."""
        return self.counts.shape[-1]

    def alive_rate(self, source: np.ndarray, dest: np.ndarray, bin_source: np.ndarray, bin_dest: np.ndarray):
        """Smoothed alive rate of the given cells (numpy index arrays of one broadcast shape)."""
        ok = self.successes[source, dest, bin_source, bin_dest]
        n = self.counts[source, dest, bin_source, bin_dest]
        return (ok + 1.0) / (n + 2.0)

    def phase_bin(self, phase: np.ndarray) -> np.ndarray:
        """Bin index of phases in cycles."""
        return np.clip((np.asarray(phase) % 1.0 * self.bins).astype(np.int64), 0, self.bins - 1)


def best_threshold(scores: np.ndarray, labels: np.ndarray) -> float:
    """The threshold t maximizing balanced accuracy of "success iff score >= t" (-inf when every label is a
    success, +inf when none is)."""
    labels = np.asarray(labels).astype(bool)
    if labels.all():
        return float("-inf")
    if not labels.any():
        return float("inf")
    order = np.argsort(-scores, kind="stable")
    s, y = scores[order], labels[order]
    tpr = np.cumsum(y) / y.sum()  # predicting success for the top i+1 scores
    fpr = np.cumsum(~y) / (~y).sum()
    last = np.r_[s[1:] != s[:-1], True]  # only cut between distinct scores
    balanced = np.where(last, (tpr + 1.0 - fpr) / 2.0, -1.0)
    return float(s[int(np.argmax(balanced))])


def sample_scores(table: TransitionTable, data: TransitionData) -> dict[str, np.ndarray]:
    """The score each calibrated strategy gives each stored sample's (state, phi_n)."""
    x = data.samples
    value = x.value_dest / table.typical_value[x.dest]
    tmt = table.alive_rate(x.source, x.dest, table.phase_bin(x.phase_source), table.phase_bin(x.phase_dest))
    return {"value": value, "tmt": tmt, "tmt-value": tmt * value}


def build_table(
    data: TransitionData, *, identities: dict[str, str], source: str, falls: Falls, bins: int = PHASE_GRID,
    typical_value: Mapping[str, float] | None = None,
) -> TransitionTable:
    """Count ``data``'s outcomes into a TMT, measure typical values and calibrate the thresholds; ``source`` says
    where the data came from and ``falls`` the definition of a fall its ``success`` labels follow (both kept in
    the table's info). ``typical_value``: gait name -> the critic value to use as that gait's typical value instead
    of the data's mean (an extension keeps the library's, so that the new pairs' thresholds are calibrated against
    the values the merged table divides by)."""
    x, gaits = data.samples, tuple(data.header.gaits)
    g = len(gaits)
    if len(x) == 0:
        raise TransitionDataError("no transition samples to build a TMT from")
    table = TransitionTable(
        gaits=gaits,
        identities=dict(identities),
        successes=np.zeros((g, g, bins, bins), dtype=np.int64),
        counts=np.zeros((g, g, bins, bins), dtype=np.int64),
        typical_value=np.ones(g),
        thresholds={},
        info={},
    )
    cell = (x.source, x.dest, table.phase_bin(x.phase_source), table.phase_bin(x.phase_dest))
    np.add.at(table.successes, cell, x.success.astype(np.int64))
    np.add.at(table.counts, cell, 1)
    for i in range(g):
        values = x.value_source[x.source == i]
        table.typical_value[i] = float(values.mean()) if len(values) else 1.0
        if typical_value is not None and gaits[i] in typical_value:
            table.typical_value[i] = float(typical_value[gaits[i]])
    scores = sample_scores(table, data)
    pairs = x.pairs()
    for name in CALIBRATED:
        table.thresholds[name] = {}
        for m, n in pairs:
            rows = (x.source == m) & (x.dest == n)
            table.thresholds[name][(m, n)] = best_threshold(scores[name][rows], x.success[rows])
    table.info = {
        "data": source,
        "falls": falls,
        "samples": len(x),
        "bins": bins,
        "score": "alive rate (successes + 1) / (samples + 2) per cell",
        "calibration": "per ordered pair, the threshold of largest balanced accuracy on the same data",
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
    }
    return table


def merge_tables(kept: TransitionTable, new: TransitionTable, *, new_pairs: Collection[tuple[str, str]],
                 gaits: Sequence[str], parts: Sequence[dict]) -> TransitionTable:
    """The TMT of a composite transition-net (``gaitlib fit --extend``) over ``gaits`` (the union of the parts',
    canonical order): the successes, counts and thresholds of the pairs of ``new_pairs`` (names) from ``new``, those
    of every other pair from ``kept``, copied; each gait's typical value from ``kept`` where it has the gait, else
    from ``new``. ``parts`` is what the info records of each part; the definition of a fall and the bins stay at its
    top level. Tables of other phase bins, definitions of a fall or policies of one gait are refused in one line."""
    if kept.bins != new.bins:
        raise TransitionDataError(f"the kept TMT has {kept.bins} phase bins a cycle and the new one {new.bins}; they "
                                  "cannot be merged")
    falls, identities = merged_fit(kept.info.get("falls", Falls.CONTACT), new.info.get("falls", Falls.CONTACT),
                                   kept.identities, new.identities, what="TMT")
    index, g = {name: i for i, name in enumerate(gaits)}, len(gaits)
    valued = [kept if name in kept.gaits else new for name in gaits]  # the table each typical value comes from
    merged = TransitionTable(
        gaits=tuple(gaits),
        identities={name: identities[name] for name in gaits},
        successes=np.zeros((g, g, kept.bins, kept.bins), dtype=np.int64),
        counts=np.zeros((g, g, kept.bins, kept.bins), dtype=np.int64),
        typical_value=np.array([t.typical_value[t.gaits.index(name)] for t, name in zip(valued, gaits, strict=True)]),
        thresholds={name: {} for name in CALIBRATED},
        info={"falls": falls, "bins": kept.bins, "score": new.info["score"],
              "calibration": new.info["calibration"], "parts": list(parts),
              "created": datetime.now(UTC).isoformat(timespec="seconds")},
    )
    for table in (kept, new):
        for i, m in enumerate(table.gaits):
            for j, n in enumerate(table.gaits):
                if ((m, n) in new_pairs) == (table is new) and m != n and m in index and n in index:
                    merged.successes[index[m], index[n]] = table.successes[i, j]
                    merged.counts[index[m], index[n]] = table.counts[i, j]
                    for name in CALIBRATED:
                        if (i, j) in table.thresholds[name]:
                            merged.thresholds[name][(index[m], index[n])] = table.thresholds[name][(i, j)]
    return merged


def save_table(path: Path, table: TransitionTable) -> Path:
    """Write ``table`` as JSON (a temporary file beside ``path``, then renamed over it)."""
    path = Path(path)
    g = table.gaits
    payload = {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "gaits": list(g),
        "library_identities": table.identities,
        "successes": table.successes.tolist(),
        "counts": table.counts.tolist(),
        "typical_value": table.typical_value.tolist(),
        "thresholds": {
            name: {f"{g[m]}-{g[n]}": _encode_threshold(t) for (m, n), t in per_pair.items()}
            for name, per_pair in table.thresholds.items()
        },
        "info": table.info,
    }
    return write_json(path, payload, indent=None, checksum=True)


def load_table(path: Path, *, identities: dict[str, str]) -> TransitionTable:
    """Read the TMT at ``path`` for the current library (gait name -> identity); one-line errors when it is
    missing, foreign, of another version, damaged (missing keys, tables of the wrong shape), or built for other
    policies."""
    path = Path(path)
    if not path.is_file():
        raise TransitionDataError(f"no TMT at {path} (run gaitlib fit)")
    header = {"format": FORMAT_NAME, "format_version": FORMAT_VERSION}
    payload = read_json(path, header=header, what="a gaitlib TMT", error=TransitionDataError)
    try:
        table = _from_payload(payload)
    except (KeyError, TypeError, ValueError, AttributeError) as error:
        what = f"missing {error}" if isinstance(error, KeyError) else str(error).splitlines()[0]
        raise TransitionDataError(f"TMT {path} is damaged ({what}); run gaitlib fit") from error
    check_identities(table.identities, identities, what=f"TMT {path}")
    return table


def _from_payload(payload: dict) -> TransitionTable:
    """The table a ``tmt.json`` payload describes; ``KeyError``/``ValueError``/``TypeError`` where keys are missing,
    tables have the wrong shapes, or a calibrated strategy lacks its thresholds."""
    gaits = tuple(str(name) for name in payload["gaits"])
    identities = {str(k): str(v) for k, v in payload["library_identities"].items()}
    if set(identities) != set(gaits):
        raise ValueError(f"identities of {sorted(identities)} for gaits {list(gaits)}")
    successes, counts = (_array(payload, key, np.int64) for key in ("successes", "counts"))
    typical_value = _array(payload, "typical_value", np.float64)
    g = len(gaits)
    if successes.ndim != 4 or successes.shape[:2] != (g, g) or successes.shape[2] != successes.shape[3]:
        raise ValueError(f"a table of shape {successes.shape} for {g} gaits")
    if counts.shape != successes.shape or typical_value.shape != (g,):
        raise ValueError(f"counts {counts.shape} and typical values {typical_value.shape} for tables {successes.shape}")
    index = {name: i for i, name in enumerate(gaits)}

    def pair(text: str) -> tuple[int, int]:
        m, _, n = text.partition("-")
        if m not in index or n not in index:
            raise ValueError(f"thresholds of pair '{text}', not of its gaits")
        return index[m], index[n]

    thresholds = {
        name: {pair(p): _decode_threshold(t) for p, t in payload["thresholds"][name].items()} for name in CALIBRATED
    }
    if not np.isfinite(typical_value).all():
        raise ValueError("a threshold or typical value is not a finite number")
    return TransitionTable(
        gaits=gaits,
        identities=identities,
        successes=successes,
        counts=counts,
        typical_value=typical_value,
        thresholds=thresholds,
        info=dict(payload["info"]),
    )


_UNBOUNDED = {"-inf": float("-inf"), "inf": float("inf")}
"""How ``tmt.json`` writes the thresholds of a pair whose samples all succeeded (switch at any score) or all
failed (never): JSON has no infinities, so as these strings."""


def _encode_threshold(threshold: float) -> float | str:
    """A threshold as strict JSON: a finite number, or ``"-inf"`` / ``"inf"``."""
    return float(threshold) if np.isfinite(threshold) else ("inf" if threshold > 0 else "-inf")


def _decode_threshold(value: object) -> float:
    """The threshold ``tmt.json`` holds as ``value``; ``ValueError`` unless a finite number, ``"-inf"`` or
    ``"inf"``."""
    if isinstance(value, str) and value in _UNBOUNDED:
        return _UNBOUNDED[value]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise ValueError('a threshold or typical value is not a finite number (nor, for a threshold, "-inf" or "inf")')
    return float(value)


def _array(payload: dict, key: str, dtype) -> np.ndarray:
    try:
        return np.asarray(payload[key], dtype=dtype)
    except ValueError:  # ragged nested lists, or entries that are not numbers
        raise ValueError(f"'{key}' is not a table of numbers") from None


class TMTStrategy(Strategy):
    """At the current source phase, the destination phase bin with the best alive rate in the TMT."""

    name = "tmt"

    def __init__(self, table: TransitionTable) -> None:
        super().__init__(threshold=table.thresholds[self.name])
        self.table = table

    def scores(self, query: SwitchQuery) -> torch.Tensor:
        t = self.table
        source, dest = query.source.cpu().numpy()[:, None], query.dest.cpu().numpy()[:, None]
        bin_source = t.phase_bin(query.phase_source.cpu().numpy())[:, None]
        bin_dest = t.phase_bin(query.candidates.cpu().numpy())[None, :]
        rate = t.alive_rate(source, dest, bin_source, bin_dest)
        return torch.as_tensor(rate, dtype=torch.float32, device=query.source.device)


class TMTValueStrategy(TMTStrategy):
    """The TMT alive rate times the destination critic's normalized value of each candidate."""

    name = "tmt-value"
    needs_value = True

    def scores(self, query: SwitchQuery) -> torch.Tensor:
        assert query.dest_value is not None
        return super().scores(query) * query.dest_value
