"""Transition samples: the HDF5 schema they are stored in (crash-safe, one writer at a time), the explicit state,
and the collector that draws them by switching library policies at random moments and phases."""

from gaitlib.transitions.collector import SUCCESS_HORIZON_S, CollectConfig, CollectProgress, CollectResult, collect
from gaitlib.transitions.combine import read_all
from gaitlib.transitions.explicit import EXPLICIT_DIM, EXPLICIT_LAYOUT, explicit_state
from gaitlib.transitions.schema import (
    SCHEMA_NAME,
    SCHEMA_VERSION,
    TransitionBatch,
    TransitionData,
    TransitionFileInfo,
    TransitionHeader,
    read,
    validate,
)

__all__ = [
    "EXPLICIT_DIM",
    "EXPLICIT_LAYOUT",
    "SCHEMA_NAME",
    "SCHEMA_VERSION",
    "SUCCESS_HORIZON_S",
    "CollectConfig",
    "CollectProgress",
    "CollectResult",
    "TransitionBatch",
    "TransitionData",
    "TransitionFileInfo",
    "TransitionHeader",
    "collect",
    "explicit_state",
    "read",
    "read_all",
    "validate",
]
