"""Parsing of option values shared by several commands."""

from __future__ import annotations

__all__ = ["parse_pairs"]


def parse_pairs(text: str | None, gaits: list[str]) -> tuple[tuple[str, str], ...] | None:
    """``trot-stand,pace-stand`` -> ordered pairs; a bare gait name stands for every pair involving it."""
    if text is None:
        return None
    pairs: list[tuple[str, str]] = []
    for item in (part.strip() for part in text.split(",") if part.strip()):
        if "-" in item:
            m, n = item.split("-", 1)
            pairs.append((m, n))
        else:
            pairs += [(item, g) for g in gaits if g != item] + [(g, item) for g in gaits if g != item]
    return tuple(dict.fromkeys(pairs))
