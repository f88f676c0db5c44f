"""Defaults shared by the command line and the Python API, kept here (no heavy imports) so that the command line
can show them in ``--help`` without importing torch."""

from __future__ import annotations

from enum import StrEnum

__all__ = [
    "BAR_FALLS", "BAR_HEADING_DEG", "BAR_SPEED", "COMPARED", "DEFAULT_FALLS", "DEFAULT_STRATEGY", "MAX_RUN_SECONDS",
    "MIN_CATCH_WORLDS", "MIN_PER_LABEL", "MIN_UNSHOVED_MINUTES", "SWITCH_START", "Falls",
]

COMPARED = ("random", "value", "tmt", "tmt-value", "net", "net-lookahead")
"""The switching strategies ``gaitlib benchmark`` compares by default: the paper's Fig. 4 baselines, its rule
(``net``) and the calibrated net (``net-lookahead``)."""
MAX_RUN_SECONDS = 600.0
"""The longest one robot is simulated by ``gaitlib run`` (its request time and, for each gait requested, the
switch's deadline and the hold after it: the longest the run can take) or ``gaitlib drive`` (its last command's
time), s: ten minutes, as the longest evaluation episode; a longer one is refused before it starts."""
DEFAULT_STRATEGY = "net-lookahead"
"""The strategy ``gaitlib run`` and :func:`gaitlib.meta.run_episode` switch with by default: the best measured on
the shipped library (``docs/results.md``); ``net`` is the paper's rule."""


class Falls(StrEnum):
    """What a fall is (:mod:`gaitlib.envs.terminations`; one helper builds the terminations from it,
    :meth:`~gaitlib.envs.terminations.TerminationConfig.counting`). A value of this type is one of the two
    definitions and nothing else: the command line makes it from ``--falls`` (``train``: ``--terminate``), refusing
    any other text in one line, and a stored file's reader from the text the file recorded (``"trunk"`` or
    ``"contact"``, the values it writes back)."""

    TRUNK = "trunk"
    """The field's: the trunk too low, tilted past the limit or on the ground, as legged_gym's and Isaac Lab's A1
    tasks count one; a leg's touch ridden through is a *touch*, reported beside."""
    CONTACT = "contact"
    """gaitlib's strict one: any non-foot body on the ground is a fall too."""


DEFAULT_FALLS = Falls.TRUNK
"""The definition every report, label and artefact uses unless told otherwise."""
SWITCH_START = 0.4
"""The share of training episodes that start from another gait's handover state when ``--states`` is given: most
episodes still start from the gait's own reference, which teaches the gait itself (``docs/training.md``)."""
BAR_FALLS, BAR_SPEED, BAR_HEADING_DEG = 0.01, 0.10, 15.0
"""The quality bar a gait is judged against (``docs/results.md``): falls in at most 1% of episodes, forward speed
within 10% of the reference (a fraction), median heading change over an episode at most 15 degrees."""
MIN_PER_LABEL = 25
"""The fewest successful and the fewest failed switches each ordered pair of the data needs for a fit of the
switching models to be written (``gaitlib fit --min-per-label``,
:func:`gaitlib.strategies.fitting.check_validatable`): the validation set holds a fifth of each label's balanced
samples (:class:`gaitlib.transition_net.FitConfig`), so at least 5 of each per pair, and a pair's accuracy rests on
10 held-out switches or more. The shipped fit's rarest label of any pair has 445 samples."""
MIN_UNSHOVED_MINUTES = 1.0
"""The least unshoved running, min, of a survival recording's selection split that the guard's margin (or floor) is
chosen on (:func:`gaitlib.strategies.survival_fit.fit_survival`): its false alarms are counted per minute of it, so
with less not even one minute is seen. A recording of the default 1024 episodes holds about 3."""
MIN_CATCH_WORLDS = 4
"""The fewest worlds per direction of shove (front, left, back, right) a catch is chosen on
(:func:`gaitlib.benchmark.catches.fit_catch_table`): ``gaitlib survival catches --episodes`` takes at least four times
as many, and a direction that still reads fewer names no catch."""
