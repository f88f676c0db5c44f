"""The ``net`` strategy (the paper's): the transition-net's success probability, maximized over phi_n."""

from __future__ import annotations

import torch

from gaitlib.strategies.base import Strategy, SwitchQuery
from gaitlib.transition_net.model import TransitionNet

__all__ = ["NET_THRESHOLD", "NetStrategy"]

NET_THRESHOLD = 0.95
"""Switch when the best candidate's predicted success probability exceeds this (paper: th = 0.95)."""


class NetStrategy(Strategy):
    """Scores every candidate phi_n with the transition-net on (m, n, psi_m, phi_n)."""

    name = "net"

    def __init__(self, net: TransitionNet, *, threshold: float = NET_THRESHOLD) -> None:
        super().__init__(threshold=threshold)
        self.net = net

    def scores(self, query: SwitchQuery) -> torch.Tensor:
        k, c = len(query.source), len(query.candidates)
        score = self.net.score(
            source=query.source.repeat_interleave(c),
            dest=query.dest.repeat_interleave(c),
            phase_dest=query.candidates.repeat(k),
            latent=query.latent.repeat_interleave(c, dim=0),
            phase_source=query.phase_source.repeat_interleave(c),
        )
        return score.reshape(k, c).to(query.source.device)
