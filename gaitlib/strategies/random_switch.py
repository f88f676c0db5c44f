"""The ``random`` strategy: switch at once, at a uniformly random destination phase."""

from __future__ import annotations

import torch

from gaitlib.strategies.base import Decision, Strategy, SwitchQuery

__all__ = ["RandomStrategy"]


class RandomStrategy(Strategy):
    """Switches every waiting world immediately at a random phase (the baseline)."""

    name = "random"

    def __init__(self, *, seed: int = 0) -> None:
        super().__init__(threshold=float("-inf"))
        self._gen = torch.Generator().manual_seed(seed)

    def scores(self, query: SwitchQuery) -> torch.Tensor:
        """Uniform random scores: the best candidate is a random one."""
        return torch.rand((len(query.source), len(query.candidates)), generator=self._gen).to(query.source.device)

    def decide(self, query: SwitchQuery) -> Decision:
        k = len(query.source)
        phase = torch.rand(k, generator=self._gen).to(query.source.device)
        return Decision(
            switch=torch.ones(k, dtype=torch.bool, device=phase.device),
            phase=phase,
            score=torch.full((k,), float("nan"), device=phase.device),
        )
