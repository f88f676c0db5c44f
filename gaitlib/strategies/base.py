"""The switching-strategy contract: given worlds that wait to switch gaits, decide whether to switch now and at
which destination phase, searching a grid of candidate destination phases.

Every strategy scores each candidate phase of each waiting world (higher is better) and switches a world when its
best candidate reaches the strategy's threshold; ``random`` switches at once at a random phase.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import torch

__all__ = ["PHASE_GRID", "Decision", "Strategy", "SwitchQuery", "phase_grid"]

PHASE_GRID = 16
"""Candidate destination phases searched: the centres of 16 equal bins of a cycle (1/32, 3/32, ..., 31/32)."""


def phase_grid(size: int = PHASE_GRID, device: torch.device | str = "cpu") -> torch.Tensor:
    """(size,) candidate destination phases: the centres of ``size`` equal bins of [0, 1), cycles."""
    return (torch.arange(size, device=device, dtype=torch.float32) + 0.5) / size


@dataclass
class SwitchQuery:
    """What is known of k worlds waiting to switch, at this control step."""

    source: torch.Tensor
    """(k,) active gait m (index into the library's gaits)."""
    dest: torch.Tensor
    """(k,) requested gait n."""
    phase_source: torch.Tensor
    """(k,) active reference phase phi_m, cycles in [0, 1)."""
    latent: torch.Tensor
    """(k, L) the active actor's last hidden layer psi_m on the current observation."""
    candidates: torch.Tensor
    """(C,) candidate destination phases phi_n, cycles."""
    dest_value: torch.Tensor | None = None
    """(k, C) destination critic V_n(s, g_n(phi_n)) on each candidate, divided by gait n's typical on-gait value;
    filled only for strategies whose ``needs_value`` is set."""
    steps_left: torch.Tensor | None = None
    """(k,) control steps left before the request is forced (0: this step); the meta-controller fills it."""
    phase_step: torch.Tensor | None = None
    """(k,) how far the source phase advances in one control step, cycles; the meta-controller fills it."""


@dataclass
class Decision:
    """A strategy's answer for k worlds."""

    switch: torch.Tensor
    """(k,) bool: switch now."""
    phase: torch.Tensor
    """(k,) destination phase to switch to (the best candidate), cycles."""
    score: torch.Tensor
    """(k,) the score of that candidate (NaN where the strategy has none)."""


class Strategy(ABC):
    """Scores candidate destination phases; switches where the best one reaches :attr:`threshold`."""

    name: str = ""
    """Registry name."""
    needs_value: bool = False
    """Whether :meth:`scores` reads ``query.dest_value`` (costs one critic pass per candidate)."""

    def __init__(self, *, threshold: float | dict[tuple[int, int], float]) -> None:
        self.threshold = threshold
        """Score a world's best candidate must reach to switch: one number, or one per (m, n) gait-index pair."""

    @abstractmethod
    def scores(self, query: SwitchQuery) -> torch.Tensor:
        """(k, C) score of every candidate destination phase of every waiting world."""

    def thresholds(self, query: SwitchQuery) -> torch.Tensor:
        """(k,) the threshold that applies to each waiting world."""
        if isinstance(self.threshold, dict):
            pairs = zip(query.source.tolist(), query.dest.tolist(), strict=True)
            values = [self.threshold.get(pair, float("inf")) for pair in pairs]
            return torch.tensor(values, device=query.source.device)
        return torch.full(query.source.shape, float(self.threshold), device=query.source.device)

    def decide(self, query: SwitchQuery) -> Decision:
        """Switch the worlds whose best candidate reaches the threshold, at that candidate."""
        scores = self.scores(query)
        best, index = scores.max(dim=1)
        return Decision(switch=best >= self.thresholds(query), phase=query.candidates[index], score=best)
