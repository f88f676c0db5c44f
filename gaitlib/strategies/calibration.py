"""The transition-net's score mapped to the real success probability of a switch.

The net is fitted on label-balanced samples, as in the paper, so its score is a success probability under a 50%
prior, not under a pair's real success rate: a score of 0.9 on a pair where 95% of switches succeed means less
than it says, and no fixed threshold means the same on every pair. Platt scaling (J. Platt, "Probabilistic
Outputs for Support Vector Machines", 1999) maps it, per ordered pair: ``p = sigmoid(a * logit(score) + b)``, with
``a`` and ``b`` fitted by maximum likelihood on the samples the net never trained on, each label class weighted
back to its share of the whole collection (the training rows took as many successes as failures, so the held-out
rows alone would overstate the larger class), and Platt's smoothed targets so that a pair without failures keeps
finite parameters. It is fitted on collection data, never on benchmark runs, and written beside the net
(``library/switching/calibration.json``).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from gaitlib.atomic import read_json, write_json
from gaitlib.defaults import Falls
from gaitlib.errors import TransitionDataError
from gaitlib.library.layout import check_identities, merged_fit
from gaitlib.transition_net import TransitionNet, batch_features
from gaitlib.transitions import TransitionData

__all__ = ["Calibration", "calibrate", "load_calibration", "merge_calibrations", "platt", "save_calibration"]

FORMAT = {"format": "gaitlib.calibration", "format_version": 1}
_EPS = 1e-6
"""Scores are clipped to [eps, 1 - eps] before their logit."""


def _logit(score: np.ndarray) -> np.ndarray:
    s = np.clip(np.asarray(score, dtype=np.float64), _EPS, 1 - _EPS)
    return np.log(s / (1 - s))


def platt(score: np.ndarray, success: np.ndarray, weight: np.ndarray | None = None) -> tuple[float, float]:
    """Platt's (a, b) for ``p = sigmoid(a * logit(score) + b)``: weighted maximum likelihood with targets
    (N+ + 1) / (N+ + 2) for successes and 1 / (N- + 2) for failures (N: weighted counts), by Newton's method with a
    backtracking line search (Lin, Lin and Weng, "A note on Platt's probabilistic outputs for support vector
    machines", Machine Learning 68, 2007): a plain Newton step overshoots where the logistic's curvature vanishes."""
    z = _logit(score)
    y = np.asarray(success, dtype=bool)
    w = np.ones_like(z) if weight is None else np.asarray(weight, dtype=np.float64)
    positives, negatives = w[y].sum(), w[~y].sum()
    target = np.where(y, (positives + 1) / (positives + 2), 1 / (negatives + 2))

    def loss(ab: np.ndarray) -> float:  # the weighted negative log-likelihood
        s = ab[0] * z + ab[1]
        return float(np.sum(w * (np.logaddexp(0.0, s) - target * s)))

    ab, current = np.array([1.0, 0.0]), loss(np.array([1.0, 0.0]))
    for _ in range(100):
        p = 0.5 * (1 + np.tanh(0.5 * (ab[0] * z + ab[1])))  # the logistic function, without exp's overflow
        gradient = np.array([np.sum(w * (p - target) * z), np.sum(w * (p - target))])
        curvature = w * p * (1 - p)
        cross = np.sum(curvature * z)
        hessian = np.array([[np.sum(curvature * z * z), cross], [cross, curvature.sum()]]) + 1e-12 * np.eye(2)
        step = -np.linalg.solve(hessian, gradient)
        size = 1.0
        while size >= 1e-10:  # halve the step until the loss falls enough (Armijo's rule)
            trial = loss(ab + size * step)
            if trial < current + 1e-4 * size * float(gradient @ step):
                break
            size /= 2
        else:
            break  # no step lowers the loss: at its minimum to machine precision
        ab, current = ab + size * step, trial
        if np.abs(size * step).max() < 1e-10:
            break
    return float(ab[0]), float(ab[1])


@dataclass(frozen=True)
class Calibration:
    """Per ordered pair, Platt's (a, b) for one library's transition-net."""

    gaits: tuple[str, ...]
    """Gait names, in the net's order."""
    identities: dict[str, str]
    """Library identity of each gait's policy."""
    pairs: dict[tuple[int, int], tuple[float, float]]
    """(m, n) -> (a, b); a pair missing here is left as the net scores it."""
    info: dict
    """How it was fitted: samples and successes per pair, the rule."""

    def probability(self, source: torch.Tensor, dest: torch.Tensor, score: torch.Tensor) -> torch.Tensor:
        """(k,) calibrated success probability of net scores ``score`` (k,) for pairs ``source``/``dest`` (k,)."""
        a = torch.ones_like(score)
        b = torch.zeros_like(score)
        for (m, n), (pa, pb) in self.pairs.items():
            rows = (source == m) & (dest == n)
            a[rows], b[rows] = pa, pb
        z = torch.logit(score.clamp(_EPS, 1 - _EPS))
        return torch.sigmoid(a * z + b)


def calibrate(net: TransitionNet, data: TransitionData, *, train_rows: np.ndarray, identities: dict[str, str],
              falls: Falls):
    """Fit the :class:`Calibration` of ``net`` on the rows of ``data`` outside ``train_rows`` (the rows it was
    trained on), each (pair, label) class weighted by its count in ``data`` over its count among those rows; the
    labels are ``data``'s ``success``, which ``falls`` names the definition of (recorded in the info)."""
    x = data.samples
    held = np.ones(len(x), dtype=bool)
    held[train_rows] = False
    score = net.probability(batch_features(net.spec, x.select(held))).cpu().numpy()
    source, dest, success = x.source[held], x.dest[held], x.success[held].astype(bool)
    pairs, info = {}, {}
    for m, n in sorted(set(zip(source.tolist(), dest.tolist(), strict=True))):
        rows = (source == m) & (dest == n)
        weight = np.empty(rows.sum())
        for label in (True, False):
            share = success[rows] == label
            everywhere = ((x.source == m) & (x.dest == n) & (x.success.astype(bool) == label)).sum()
            weight[share] = everywhere / max(1, share.sum())
        pairs[(m, n)] = platt(score[rows], success[rows], weight)
        gaits = data.header.gaits
        info[f"{gaits[m]}-{gaits[n]}"] = {"held_out": int(rows.sum()), "successes": int(success[rows].sum())}
    rule = "Platt scaling per ordered pair on held-out rows, classes weighted back to their share of the data"
    return Calibration(tuple(data.header.gaits), dict(identities), pairs, {"pairs": info, "rule": rule,
                                                                           "falls": falls})


def merge_calibrations(kept: Calibration, new: Calibration, *, new_pairs: Collection[tuple[str, str]],
                       gaits: Sequence[str], parts: Sequence[dict]) -> Calibration:
    """The calibration of a composite transition-net (``gaitlib fit --extend``) over ``gaits`` (the union of the
    parts', canonical order): the pairs of ``new_pairs`` (names) as ``new`` maps them, every other pair as ``kept``
    does, its (a, b) copied. ``parts`` is what the info records of each part (the pairs it serves, how it was fitted);
    the definition of a fall stays at the info's top level. Calibrations of different definitions of a fall, or of
    another policy of one gait, are refused in one line."""
    falls, identities = merged_fit(kept.info.get("falls", Falls.CONTACT), new.info.get("falls", Falls.CONTACT),
                                   kept.identities, new.identities, what="net calibration")
    index = {name: i for i, name in enumerate(gaits)}
    pairs = {}
    for calibration in (kept, new):
        for (m, n), ab in calibration.pairs.items():
            names = (calibration.gaits[m], calibration.gaits[n])
            if (names in new_pairs) == (calibration is new) and set(names) <= set(index):
                pairs[(index[names[0]], index[names[1]])] = ab
    info = {"falls": falls, "rule": new.info["rule"], "parts": list(parts)}
    return Calibration(tuple(gaits), {g: identities[g] for g in gaits}, dict(sorted(pairs.items())), info)


def save_calibration(path: Path, calibration: Calibration) -> Path:
    """Write ``calibration`` as JSON, atomically."""
    g = calibration.gaits
    payload = FORMAT | {
        "gaits": list(g),
        "library_identities": calibration.identities,
        "pairs": {f"{g[m]}-{g[n]}": {"a": a, "b": b} for (m, n), (a, b) in calibration.pairs.items()},
        "info": calibration.info,
    }
    return write_json(path, payload, checksum=True)


def load_calibration(path: Path, *, identities: dict[str, str]) -> Calibration:
    """Read the calibration at ``path`` for the current library; one-line errors when it is missing (a library
    fitted before calibration existed), foreign, damaged, or made for other policies."""
    path = Path(path)
    if not path.is_file():
        raise TransitionDataError(f"no net calibration at {path} (run gaitlib fit again)")
    payload = read_json(path, header=FORMAT, what="a gaitlib net calibration", error=TransitionDataError)
    try:
        gaits = tuple(payload["gaits"])
        index = {name: i for i, name in enumerate(gaits)}
        pairs = {}
        for text, ab in payload["pairs"].items():
            m, _, n = text.partition("-")
            pairs[(index[m], index[n])] = (float(ab["a"]), float(ab["b"]))
        calibration = Calibration(gaits, dict(payload["library_identities"]), pairs, dict(payload["info"]))
        if not all(math.isfinite(v) for ab in pairs.values() for v in ab):
            raise ValueError("a pair's a or b is not a finite number")
    except (ValueError, KeyError, TypeError, AttributeError) as error:
        raise TransitionDataError(f"{path} is a damaged net calibration ({error!r}); run gaitlib fit") from error
    check_identities(calibration.identities, identities, what=f"net calibration {path}")
    return calibration
