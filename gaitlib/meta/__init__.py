"""The meta-controller (paper Algorithm 1), what it needs from a library to be built, the switch trial that
collection, benchmark and ``gaitlib run`` share, and the drive by velocity commands (``gaitlib drive``)."""

from gaitlib.meta.controller import DEADLINE_S, MetaController, MetaStep, SwitchDetail, SwitchEvent
from gaitlib.meta.setup import SwitchingSetup, load_switching
from gaitlib.meta.trials import SUCCESS_HORIZON_S, SwitchTrials, TrialOutcome, TrialProtocol, TrialSchedule

__all__ = [
    "DEADLINE_S",
    "SUCCESS_HORIZON_S",
    "MetaController",
    "MetaStep",
    "SwitchDetail",
    "SwitchEvent",
    "SwitchTrials",
    "SwitchingSetup",
    "TrialOutcome",
    "TrialProtocol",
    "TrialSchedule",
    "load_switching",
]
