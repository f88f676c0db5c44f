"""Label-balanced training and validation sets of transition samples (the paper balances by sub-sampling).

For every ordered pair (m, n) the larger label class is sub-sampled to the size of the smaller one, so each pair
contributes equally many failures and successes; the kept samples of each class are then split into training and
validation in the same proportion, so the validation set is balanced per pair too. Pairs without both labels are
left out (and listed). All draws come from one seeded generator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["BalancedSplit", "balanced_split"]


@dataclass(frozen=True)
class BalancedSplit:
    """Sample indices of a balanced split."""

    train: np.ndarray
    """(n_train,) indices of training samples, shuffled."""
    validation: np.ndarray
    """(n_validation,) indices of validation samples, shuffled."""
    per_class: dict[tuple[int, int], tuple[int, int]]
    """(m, n) -> (training, validation) samples of each label kept for that pair."""
    skipped: tuple[tuple[int, int], ...]
    """Pairs present in the data that lack one of the labels."""


def balanced_split(
    source: np.ndarray,
    dest: np.ndarray,
    success: np.ndarray,
    *,
    validation_fraction: float = 0.2,
    samples_per_pair: int | None = None,
    seed: int = 0,
) -> BalancedSplit:
    """Balance (n,) ``source``/``dest`` gait indices and (n,) 0/1 ``success`` labels per ordered pair and split.

    ``samples_per_pair`` caps the kept samples of a pair (both labels together); ``validation_fraction`` of each
    pair's kept samples of each label (at least one when the fraction is positive and two or more are kept) go to
    validation.
    """
    if not 0.0 <= validation_fraction < 1.0:
        raise ValueError(f"validation_fraction must be in [0, 1), got {validation_fraction}")
    rng = np.random.default_rng(seed)
    source, dest, success = np.asarray(source), np.asarray(dest), np.asarray(success).astype(bool)
    train, validation, per_class, skipped = [], [], {}, []
    for m, n in sorted(set(zip(source.tolist(), dest.tolist(), strict=True))):
        in_pair = (source == m) & (dest == n)
        positives = rng.permutation(np.flatnonzero(in_pair & success))
        negatives = rng.permutation(np.flatnonzero(in_pair & ~success))
        k = min(len(positives), len(negatives))
        if samples_per_pair is not None:
            k = min(k, samples_per_pair // 2)
        if k == 0:
            skipped.append((m, n))
            continue
        v = round(k * validation_fraction)
        if validation_fraction > 0 and k >= 2:
            v = min(max(v, 1), k - 1)
        for kept in (positives[:k], negatives[:k]):
            validation.append(kept[:v])
            train.append(kept[v:])
        per_class[(m, n)] = (k - v, v)
    return BalancedSplit(
        train=rng.permutation(np.concatenate(train)) if train else np.zeros(0, dtype=np.int64),
        validation=rng.permutation(np.concatenate(validation)) if validation else np.zeros(0, dtype=np.int64),
        per_class=per_class,
        skipped=tuple(skipped),
    )
