"""Defaults shared by the command line and the Python API, kept here (no heavy imports) so that the command line
can show them in ``--help`` without importing torch."""

from __future__ import annotations

__all__ = ["COMPARED", "DEFAULT_FALLS", "DEFAULT_STRATEGY", "FALL_DEFINITIONS"]

COMPARED = ("random", "value", "tmt", "tmt-value", "net", "net-lookahead")
"""The switching strategies ``gaitlib benchmark`` compares by default: the paper's Fig. 4 baselines, its rule
(``net``) and the calibrated net (``net-lookahead``)."""
DEFAULT_STRATEGY = "net-lookahead"
"""The strategy ``gaitlib run`` and :func:`gaitlib.meta.run_episode` switch with by default: the best measured on
the shipped library (``docs/results.md``); ``net`` is the paper's rule."""
FALL_DEFINITIONS = ("trunk", "contact")
"""The definitions of a fall (:mod:`gaitlib.envs.terminations`): ``trunk``, the field's (the trunk too low, tilted
past the limit or on the ground, as legged_gym's and Isaac Lab's A1 tasks count one; a leg's touch ridden through is
a *touch*, reported beside), and ``contact``, gaitlib's strict one (any non-foot body on the ground is a fall too)."""
DEFAULT_FALLS = "trunk"
"""The definition every report, label and artefact uses unless told otherwise."""
