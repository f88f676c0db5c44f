"""Evaluation of the library's gait policies, each on its own: ``gaitlib eval`` (falls, touches, heading and
tracking under paper Table 1 randomization, :func:`evaluate_policy`), the single-push curve (``gaitlib eval
--impulses``, :func:`single_push_curve`) and switches into a gait at random moments (:func:`switch_in`). All three
run one rollout loop and count falls, touches and their intervals in one record (:mod:`~gaitlib.evaluation.rollout`,
:class:`FallRecord`)."""

from gaitlib.evaluation.evaluate import EvalResult, SteeringFigures, evaluate_policy, steers
from gaitlib.evaluation.push_curve import (
    AFTER_S,
    SECTORS,
    SETTLE_S,
    PushPoint,
    SinglePush,
    sector_of,
    single_push_curve,
    write_push_plot,
)
from gaitlib.evaluation.rollout import FallRecord, rollout
from gaitlib.evaluation.switch_in import SwitchIn, switch_in

__all__ = [
    "AFTER_S",
    "SECTORS",
    "SETTLE_S",
    "EvalResult",
    "FallRecord",
    "PushPoint",
    "SinglePush",
    "SteeringFigures",
    "SwitchIn",
    "evaluate_policy",
    "rollout",
    "sector_of",
    "single_push_curve",
    "steers",
    "switch_in",
    "write_push_plot",
]
