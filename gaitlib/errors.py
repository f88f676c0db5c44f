"""gaitlib's exception types: each carries a message meant to be shown to a user as one line."""

from __future__ import annotations

__all__ = ["GaitError", "GaitlibError", "SimulationError", "TransitionDataError", "UnknownNameError"]


class GaitlibError(Exception):
    """Base class of every error gaitlib reports to a user; the CLI prints ``str(error)`` on one line."""


class UnknownNameError(GaitlibError, KeyError):
    """A registry (robots, backends, gaits, strategies) was asked for a name it does not hold."""

    def __init__(self, kind: str, name: str, known: list[str]) -> None:
        super().__init__(f"unknown {kind} '{name}' (known: {', '.join(sorted(known)) or 'none'})")

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0])


class SimulationError(GaitlibError):
    """The simulator cannot be built or stepped: bad model file, bad sizes, non-finite commands, no device."""


class GaitError(GaitlibError):
    """A gait description or reference motion file is malformed, or describes a gait the robot cannot perform."""


class TransitionDataError(GaitlibError):
    """A transition-sample file or transition-net is unreadable, foreign, of another version, or does not match
    the current library or collection settings."""
