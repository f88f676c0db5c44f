"""One small registry shape, reused for robots, backends, gaits, presets and strategies (as brax's
``envs/__init__.py`` keeps one ``_envs`` mapping with ``register_environment`` / ``get_environment``).

A :class:`Registry` maps names to values; an unknown name raises :class:`~gaitlib.errors.UnknownNameError` with the
known names. A value given as a ``"module:attribute"`` string is imported on first use (``lazy=True``), so that a
heavy optional dependency (Newton, say) is imported only by the code that asks for it.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterator
from typing import Generic, TypeVar

from gaitlib.errors import UnknownNameError

__all__ = ["Registry"]

T = TypeVar("T")


class Registry(Generic[T]):
    """Named values of one kind (``kind`` names it in error messages: "robot", "gait", ...)."""

    def __init__(
        self, kind: str, *, lazy: bool = False, on_import_error: Callable[[str, ImportError], Exception] | None = None
    ) -> None:
        self.kind = kind
        """What the registry holds, as said in an error message."""
        self._lazy = lazy
        self._on_import_error = on_import_error
        self._items: dict[str, T | str] = {}

    def register(self, name: str, value: T | str) -> None:
        """Add (or replace) ``name``; with ``lazy``, ``value`` may be a ``"module:attribute"`` path."""
        self._items[name] = value

    def get(self, name: str) -> T:
        """The value of ``name``; :class:`UnknownNameError` for a name the registry does not hold."""
        if name not in self._items:
            raise UnknownNameError(self.kind, name, list(self._items))
        value = self._items[name]
        if self._lazy and isinstance(value, str):
            module_name, attr = value.split(":")
            try:
                module = importlib.import_module(module_name)
            except ImportError as error:
                if self._on_import_error is None:
                    raise
                raise self._on_import_error(name, error) from error
            value = getattr(module, attr)
            self._items[name] = value
        return value  # type: ignore[return-value]

    def names(self) -> list[str]:
        """Registered names, in registration order."""
        return list(self._items)

    def __contains__(self, name: object) -> bool:
        return name in self._items

    def __iter__(self) -> Iterator[str]:
        return iter(self._items)
