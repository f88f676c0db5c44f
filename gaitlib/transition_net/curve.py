"""The transition-net's learning curve: held-out accuracy against the samples collected per ordered pair.

A library that grows collects only its new pairs; how many samples each needs is read from this curve, measured on
pairs already collected. Per ordered pair, a share of the collected samples (``test_fraction``, by default
:data:`TEST_FRACTION`, drawn once from ``seed``) is held out. For each size n, the net is fitted as ``gaitlib fit``
fits it (its own balanced split) on the first n of each pair's other samples, in one seeded order, so that each set
holds the smaller ones, as a shorter collection's would; it is scored on the held-out samples, balanced per pair by
sub-sampling the larger label class (:func:`~gaitlib.transition_net.evaluate.evaluate_net`). A pair whose held-out
samples lack a label has no accuracy.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from gaitlib.errors import TransitionDataError
from gaitlib.transition_net.evaluate import evaluate_net
from gaitlib.transition_net.fit import FitConfig, fit
from gaitlib.transitions.records import TransitionData

__all__ = ["TEST_FRACTION", "CurvePoint", "learning_curve"]


TEST_FRACTION = 0.2
"""Share of each pair's samples held out by default."""


@dataclass(frozen=True)
class CurvePoint:
    """One fit of the curve."""

    samples_per_pair: int
    """Collected samples per ordered pair the fit drew from (fewer where a pair has fewer)."""
    trained_on: int
    """Samples the fit trained on: balanced per pair, its validation share left out (0: nothing to fit)."""
    accuracy: dict[str, float]
    """``"m-n"`` -> balanced accuracy on the held-out samples, 0-1."""

    @property
    def mean_accuracy(self) -> float:
        """Mean over the pairs with an accuracy (NaN without any)."""
        return float(np.mean(list(self.accuracy.values()))) if self.accuracy else math.nan

    def as_dict(self) -> dict:
        return {"samples_per_pair": self.samples_per_pair, "trained_on": self.trained_on,
                "mean_accuracy": None if math.isnan(self.mean_accuracy) else self.mean_accuracy,
                "accuracy": self.accuracy}


def learning_curve(data: TransitionData, sizes: Sequence[int], *, config: FitConfig | None = None,
                   test_fraction: float = TEST_FRACTION, progress: Callable[[CurvePoint], None] | None = None
                   ) -> list[CurvePoint]:
    """The curve of ``data`` at each of ``sizes`` collected samples per pair (module doc); ``config`` is each fit's
    (default: ``gaitlib fit``'s; its seed draws the held-out share and the order too)."""
    config = FitConfig() if config is None else config
    if not 0.0 < test_fraction < 1.0:
        raise ValueError(f"test_fraction must be in (0, 1), got {test_fraction}")
    samples = data.labelled(config.falls).samples
    rng = np.random.default_rng(config.seed)
    held_out, rest = [], []
    for m, n in samples.pairs():
        rows = rng.permutation(np.flatnonzero((samples.source == m) & (samples.dest == n)))
        k = round(len(rows) * test_fraction)
        held_out.append(rows[:k])
        rest.append(rows[k:])
    test = TransitionData(data.info, samples.select(np.sort(np.concatenate(held_out))))
    points = []
    for size in sizes:
        train = TransitionData(data.info, samples.select(np.sort(np.concatenate([r[:size] for r in rest]))))
        try:
            result = fit(train, dataclasses.replace(config, samples_per_pair=None))
        except TransitionDataError:  # no pair has both labels yet: nothing to fit
            point = CurvePoint(size, 0, {})
        else:
            scored = evaluate_net(result.net, test, seed=config.seed)
            point = CurvePoint(size, len(result.split.train),
                               {f"{m}-{n}": a for (m, n), a in scored.items()})
        points.append(point)
        if progress is not None:
            progress(point)
    return points
