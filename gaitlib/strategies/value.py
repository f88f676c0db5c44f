"""The ``value`` strategy: the destination critic's estimate of how well gait n would go from here."""

from __future__ import annotations

import torch

from gaitlib.strategies.base import Strategy, SwitchQuery

__all__ = ["ValueStrategy"]


class ValueStrategy(Strategy):
    """Score: V_n(s, g_n(phi_n)) divided by gait n's typical on-gait value (1 = as good as running gait n)."""

    name = "value"
    needs_value = True

    def scores(self, query: SwitchQuery) -> torch.Tensor:
        assert query.dest_value is not None
        return query.dest_value
