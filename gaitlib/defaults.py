"""Defaults shared by the command line and the Python API, kept here (no heavy imports) so that the command line
can show them in ``--help`` without importing torch."""

from __future__ import annotations

__all__ = ["COMPARED", "DEFAULT_STRATEGY"]

COMPARED = ("random", "value", "tmt", "tmt-value", "net", "net-lookahead")
"""The switching strategies ``gaitlib benchmark`` compares by default: the paper's Fig. 4 baselines, its rule
(``net``) and the calibrated net (``net-lookahead``)."""
DEFAULT_STRATEGY = "net-lookahead"
"""The strategy ``gaitlib run`` and :func:`gaitlib.meta.run_episode` switch with by default: the best measured on
the shipped library (``docs/results.md``); ``net`` is the paper's rule."""
