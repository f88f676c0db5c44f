"""Transition samples: the HDF5 schema they are stored in (crash-safe, one writer at a time), reading and
combining files, the explicit state, and the handover states of ``gaitlib states``. :mod:`gaitlib.collection`
draws them."""

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
    "TransitionBatch",
    "TransitionData",
    "TransitionFileInfo",
    "TransitionHeader",
    "explicit_state",
    "read",
    "read_all",
    "validate",
]
