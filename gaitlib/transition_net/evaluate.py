"""Score a fitted transition-net on any collection: accuracy per ordered pair on label-balanced samples."""

from __future__ import annotations

import numpy as np
import torch

from gaitlib.errors import TransitionDataError
from gaitlib.transition_net.dataset import balanced_split
from gaitlib.transition_net.features import batch_features
from gaitlib.transition_net.model import TransitionNet
from gaitlib.transitions.schema import TransitionData

__all__ = ["evaluate_net"]


def evaluate_net(net: TransitionNet, data: TransitionData, *, seed: int = 0) -> dict[tuple[str, str], float]:
    """Accuracy (0-1, threshold 0.5) of ``net`` per ordered pair (names) over ``data`` balanced per pair by
    sub-sampling the larger label class. The data's gaits must be the net's, in the same order."""
    if tuple(data.header.gaits) != tuple(net.spec.gaits):
        raise TransitionDataError(
            f"the data's gaits {list(data.header.gaits)} are not the net's {list(net.spec.gaits)}"
        )
    samples = data.samples
    split = balanced_split(samples.source, samples.dest, samples.success, validation_fraction=0.0, seed=seed)
    features = batch_features(net.spec, samples)
    labels = torch.from_numpy(samples.success.astype(np.float32))
    predicted = net.probability(features) >= 0.5
    gaits = net.spec.gaits
    accuracy = {}
    for m, n in split.per_class:
        rows = split.train[(samples.source[split.train] == m) & (samples.dest[split.train] == n)]
        hits = (predicted[rows].float() == labels[rows]).float()
        accuracy[(gaits[m], gaits[n])] = float(hits.mean())
    return accuracy
