"""Registry of gait descriptions: the shipped ones (``descriptions/*.toml``, one file per gait) and the user's own.

Adding a gait to gaitlib means adding one TOML file to ``gaitlib/gaits/descriptions/``; a user's gait file is
read with :func:`gaitlib.gaits.load_gait_file` and added with :func:`register_gait`.
"""

from __future__ import annotations

from importlib import resources

from gaitlib.gaits.description import GaitDescription, load_gait_file
from gaitlib.registry import Registry

__all__ = ["gait_names", "get_gait", "register_gait"]

_GAITS: Registry[GaitDescription] = Registry("gait")


def register_gait(desc: GaitDescription) -> None:
    """Add ``desc`` to the registry under ``desc.name`` (replacing any gait of that name)."""
    _GAITS.register(desc.name, desc)


def get_gait(name: str) -> GaitDescription:
    """Return the registered gait called ``name``; raises :class:`~gaitlib.errors.UnknownNameError` for an unknown
    name."""
    return _GAITS.get(name)


def gait_names() -> list[str]:
    """Names of the registered gaits, sorted."""
    return sorted(_GAITS.names())


def _register_shipped() -> None:
    for entry in resources.files("gaitlib.gaits").joinpath("descriptions").iterdir():
        if entry.name.endswith(".toml"):
            with resources.as_file(entry) as path:
                register_gait(load_gait_file(path))


_register_shipped()
