"""Fit a transition-net on collected samples: balanced split, AdamW on BCE, per-pair validation accuracy.

The paper's settings (arXiv:2306.08224) are the defaults: AdamW, learning rate 5e-4, mini-batch 128, 100 epochs,
BCE on the logit. The fit runs on the CPU with one torch thread: for an MLP this small more threads only
busy-wait between tiny operations (on 2 busy cores: 0.1 s with one thread against 12 s with two for 120 steps).
Accuracy is measured in eval mode (dropout off) at a 0.5 probability threshold, on the
held-out validation set, which is label-balanced per pair (:mod:`gaitlib.transition_net.dataset`).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
import torch

from gaitlib.defaults import DEFAULT_FALLS, Falls
from gaitlib.errors import TransitionDataError
from gaitlib.transition_net.dataset import BalancedSplit, balanced_split
from gaitlib.transition_net.features import FeatureSpec, batch_features
from gaitlib.transition_net.model import TransitionNet
from gaitlib.transitions.schema import TransitionData

__all__ = ["EpochStats", "FitConfig", "FitResult", "fit"]


@dataclass(frozen=True, kw_only=True)
class FitConfig:
    """Inputs, network, optimizer and split of one fit."""

    kind: str = "latent"
    """Input kind: ``latent`` (m, n, psi_m, phi_n), ``phase`` (m, n, phi_m, phi_n) or ``explicit``."""
    epochs: int = 100
    """Passes over the training set."""
    batch_size: int = 128
    """Mini-batch size."""
    learning_rate: float = 5e-4
    """AdamW learning rate."""
    weight_decay: float = 0.01
    """AdamW decoupled weight decay (PyTorch's default)."""
    hidden: tuple[int, ...] = (128, 64, 32)
    """Hidden layer sizes."""
    dropout: float = 0.4
    """Dropout probability after each hidden layer (training only)."""
    validation_fraction: float = 0.2
    """Share of each pair's balanced samples held out for validation."""
    samples_per_pair: int | None = None
    """Cap on the balanced samples used per pair (both labels together); ``None``: all the smaller class allows."""
    seed: int = 0
    """Seed of the split, the initial weights, the mini-batch order and dropout."""
    falls: Falls = DEFAULT_FALLS
    """The definition of a fall the labels follow: the samples'
    ``trunk`` outcome or their ``contact`` one."""


@dataclass(frozen=True)
class EpochStats:
    """Progress after one epoch."""

    epoch: int
    epochs: int
    loss: float
    """Mean training BCE of the epoch (dropout on)."""
    validation_accuracy: float
    """Accuracy over the whole validation set, 0-1 (NaN without validation samples)."""


@dataclass
class FitResult:
    """A fitted net and how well it does."""

    net: TransitionNet
    """In eval mode."""
    identities: tuple[str, ...]
    """Library identities of the data's gaits (same order as ``net.spec.gaits``)."""
    validation_accuracy: dict[tuple[str, str], float]
    """Per ordered pair (names), balanced validation accuracy, 0-1."""
    validation_overall: float
    """Accuracy over all validation samples, 0-1 (NaN without any)."""
    train_accuracy: float
    """Accuracy on the training set in eval mode, 0-1."""
    split: BalancedSplit
    """Which samples were used for what."""
    data_samples: int
    """Samples in the data before balancing."""
    data_settings: dict
    """The data's collection settings."""
    config: FitConfig


def fit(
    data: TransitionData, config: FitConfig = FitConfig(), *, on_epoch: Callable[[EpochStats], None] | None = None
) -> FitResult:
    """Fit a transition-net of ``config.kind`` inputs on ``data``; raises :class:`TransitionDataError` when no
    ordered pair has both labels."""
    cfg = config
    header, samples = data.header, data.labelled(cfg.falls).samples
    split = balanced_split(
        samples.source,
        samples.dest,
        samples.success,
        validation_fraction=cfg.validation_fraction,
        samples_per_pair=cfg.samples_per_pair,
        seed=cfg.seed,
    )
    if len(split.train) == 0:
        raise TransitionDataError("cannot fit a transition-net: no gait pair has both successful and failed switches")
    spec = FeatureSpec(kind=cfg.kind, gaits=header.gaits, latent_dim=header.latent_dim)
    features = batch_features(spec, samples)
    labels = torch.from_numpy(samples.success.astype(np.float32))
    x_train, y_train = features[split.train], labels[split.train]
    x_val, y_val = features[split.validation], labels[split.validation]

    with _one_torch_thread():
        net = _train(spec, x_train, y_train, x_val, y_val, cfg, on_epoch)
        val_pairs = (samples.source[split.validation], samples.dest[split.validation])
        per_pair = {}
        for m, n in split.per_class:
            rows = torch.from_numpy(np.flatnonzero((val_pairs[0] == m) & (val_pairs[1] == n)))
            if len(rows):
                per_pair[(header.gaits[m], header.gaits[n])] = _accuracy(net, x_val[rows], y_val[rows])
        return FitResult(
            net=net,
            identities=header.identities,
            validation_accuracy=per_pair,
            validation_overall=_accuracy(net, x_val, y_val),
            train_accuracy=_accuracy(net, x_train, y_train),
            split=split,
            data_samples=len(samples),
            data_settings=header.settings,
            config=cfg,
        )


@contextlib.contextmanager
def _one_torch_thread() -> Iterator[None]:
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


def _train(
    spec: FeatureSpec,
    x_train: torch.Tensor,
    y_train: torch.Tensor,
    x_val: torch.Tensor,
    y_val: torch.Tensor,
    cfg: FitConfig,
    on_epoch: Callable[[EpochStats], None] | None,
) -> TransitionNet:
    """A new net trained on (n, dim) features and (n,) 0/1 labels, in eval mode; global RNG state untouched."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(cfg.seed)
        net = TransitionNet(spec, hidden=cfg.hidden, dropout=cfg.dropout)
        net.set_normalization(x_train)
        optimizer = torch.optim.AdamW(net.parameters(), lr=cfg.learning_rate, weight_decay=cfg.weight_decay)
        loss_fn = torch.nn.BCEWithLogitsLoss()
        for epoch in range(cfg.epochs):
            net.train()
            total = 0.0
            for rows in torch.randperm(len(x_train)).split(cfg.batch_size):
                loss = loss_fn(net(x_train[rows]), y_train[rows])
                optimizer.zero_grad()
                loss.backward()
                optimizer.step()
                total += loss.item() * len(rows)
            if on_epoch is not None:
                on_epoch(EpochStats(epoch + 1, cfg.epochs, total / len(x_train), _accuracy(net, x_val, y_val)))
    return net.eval()


def _accuracy(net: TransitionNet, x: torch.Tensor, y: torch.Tensor) -> float:
    """Eval-mode accuracy at threshold 0.5 (NaN for no samples); leaves ``net`` in eval mode."""
    if len(x) == 0:
        return float("nan")
    return float(((net.probability(x) >= 0.5).float() == y).float().mean())
