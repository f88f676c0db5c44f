"""Intervals of rates measured by counting: every fall, touch and success rate gaitlib reports carries one."""

from __future__ import annotations

import math

__all__ = ["Z95", "wilson_interval"]

Z95 = 1.959963984540054
"""The standard normal quantile of a two-sided 95% interval."""


def wilson_interval(successes: int, samples: int, z: float = Z95) -> tuple[float, float]:
    """95% (by default) Wilson score interval of a success rate; (0, 1) without samples."""
    if samples == 0:
        return 0.0, 1.0
    p = successes / samples
    denominator = 1 + z * z / samples
    centre = (p + z * z / (2 * samples)) / denominator
    half = z * math.sqrt(p * (1 - p) / samples + z * z / (4 * samples * samples)) / denominator
    # The interval holds p exactly; rounding alone could put a bound past it (5.6e-17 above p = 0, say).
    return min(p, max(0.0, centre - half)), max(p, min(1.0, centre + half))
