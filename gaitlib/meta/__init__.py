"""The meta-controller (paper Algorithm 1) and what it needs from a library to be built."""

from gaitlib.meta.controller import DEADLINE_S, MetaController, MetaStep, SwitchEvent
from gaitlib.meta.setup import SwitchingSetup, load_switching

__all__ = ["DEADLINE_S", "MetaController", "MetaStep", "SwitchEvent", "SwitchingSetup", "load_switching"]
