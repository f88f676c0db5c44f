"""The ``net-lookahead`` strategy: switch when the calibrated chance of success now is at least what waiting for a
better moment of the source cycle is worth.

The paper's ``net`` rule waits until the transition-net's best score passes 0.95, a threshold on a score fitted to
a 50% prior: on a pair where no moment reaches it, every request waits for the deadline and is forced wherever the
robot then is. ``net-lookahead`` instead compares two success probabilities at every control step:

* now: the net's score of the best candidate destination phase, calibrated to the real success rate of the pair
  (:mod:`gaitlib.strategies.calibration`);
* waiting: the best success the source phases still to come before the deadline offer, each at its best
  destination phase bin, read from the TMT of the same collection (the alive rate of the switches made at that
  source phase).

It switches as soon as now is at least waiting. At the deadline nothing is left to wait for, so it switches at
the latest there, by its own choice. It assumes the source keeps running safely while it waits: under pushes, the
risk of falling during the wait is not counted.
"""

from __future__ import annotations

import torch

from gaitlib.strategies.base import Decision, Strategy, SwitchQuery
from gaitlib.strategies.calibration import Calibration
from gaitlib.strategies.net import NetStrategy
from gaitlib.strategies.tmt import TransitionTable
from gaitlib.transition_net.model import TransitionNet

__all__ = ["LookaheadStrategy"]


class LookaheadStrategy(Strategy):
    """Calibrated net score now against the best the coming source phases offer before the deadline."""

    name = "net-lookahead"

    def __init__(self, net: TransitionNet, calibration: Calibration, table: TransitionTable) -> None:
        super().__init__(threshold=float("nan"))  # the bar moves: see :meth:`waiting_value`
        self._net = NetStrategy(net)
        self.calibration = calibration
        best_dest = (table.successes + 1.0) / (table.counts + 2.0)  # the TMT's smoothed alive rate
        self._best_by_source_bin = best_dest.max(axis=-1)  # (G, G, B): at each source phase bin, the best n-phase
        self._table = table

    def scores(self, query: SwitchQuery) -> torch.Tensor:
        """(k, C) calibrated success probability of each candidate destination phase."""
        raw = self._net.scores(query)
        c = raw.shape[1]
        calibrated = self.calibration.probability(
            query.source.repeat_interleave(c), query.dest.repeat_interleave(c), raw.reshape(-1)
        )
        return calibrated.reshape(raw.shape)

    def waiting_value(self, query: SwitchQuery) -> torch.Tensor:
        """(k,) the best TMT success rate among the source phases of the control steps still left before the
        deadline (-inf where none is left)."""
        assert query.steps_left is not None and query.phase_step is not None
        k = len(query.source)
        horizon = int(query.steps_left.max().item()) if k else 0
        if horizon <= 0:
            return torch.full((k,), float("-inf"), device=query.source.device)
        ahead = torch.arange(1, horizon + 1, device=query.source.device)
        phases = query.phase_source.unsqueeze(1) + ahead.unsqueeze(0) * query.phase_step.unsqueeze(1)  # (k, H)
        bins = self._table.phase_bin(phases.cpu().numpy())
        m, n = query.source.cpu().numpy()[:, None], query.dest.cpu().numpy()[:, None]
        rates = torch.as_tensor(self._best_by_source_bin[m, n, bins], dtype=torch.float32, device=query.source.device)
        rates[ahead.unsqueeze(0) > query.steps_left.unsqueeze(1)] = float("-inf")  # past that world's deadline
        return rates.max(dim=1).values

    def offers(self, source: torch.Tensor, latent: torch.Tensor, phase_source: torch.Tensor,
               candidates: torch.Tensor, gaits: int) -> tuple[torch.Tensor, torch.Tensor]:
        """What switching now offers worlds running ``source`` (k,) (actor latents ``latent`` (k, L), phases
        ``phase_source`` (k,)): (k, G) the calibrated success of switching to each gait at its best candidate
        destination phase (NaN on the world's own gait) and (k, G) that phase, cycles."""
        k = len(source)
        dest = torch.arange(gaits, device=source.device).repeat(k)
        rows = torch.arange(k, device=source.device).repeat_interleave(gaits)
        other = dest != source[rows]
        rows, dest = rows[other], dest[other]
        query = SwitchQuery(source=source[rows], dest=dest, phase_source=phase_source[rows], latent=latent[rows],
                            candidates=candidates)
        best, index = self.scores(query).max(dim=1)
        offer = torch.full((k, gaits), float("nan"), device=source.device)
        phase = torch.full((k, gaits), float("nan"), device=source.device)
        offer[rows, dest], phase[rows, dest] = best, candidates[index]
        return offer, phase

    def decide(self, query: SwitchQuery) -> Decision:
        scores = self.scores(query)
        best, index = scores.max(dim=1)
        return Decision(switch=best >= self.waiting_value(query), phase=query.candidates[index], score=best)

