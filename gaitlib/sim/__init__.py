"""Simulation backends: one contract (:mod:`gaitlib.sim.contract`), several engines, a small registry.

``make_backend("auto", ...)`` picks ``newton`` when CUDA is present and ``mujoco`` otherwise.
Backend modules are imported lazily, so importing :mod:`gaitlib.sim` never loads Warp or MuJoCo.
"""

from __future__ import annotations

from collections.abc import Callable

from gaitlib.errors import SimulationError, UnknownNameError
from gaitlib.registry import Registry
from gaitlib.robots import RobotSpec, get_robot
from gaitlib.sim.contract import KinematicState, SimBackend, SimState, standing_state

__all__ = [
    "KinematicState",
    "SimBackend",
    "SimState",
    "backend_names",
    "make_backend",
    "register_backend",
    "resolve_backend_name",
    "standing_state",
]

BackendFactory = Callable[..., SimBackend]
"""``factory(robot, num_worlds, *, device=None) -> SimBackend``."""

_BACKENDS: Registry[BackendFactory] = Registry(
    "backend",
    lazy=True,
    on_import_error=lambda name, error: SimulationError(f"backend '{name}' is not available here: {error}"),
)
_BACKENDS.register("mujoco", "gaitlib.sim.mujoco_backend:MujocoBackend")
_BACKENDS.register("newton", "gaitlib.sim.newton_backend:NewtonBackend")


def register_backend(name: str, factory: str | BackendFactory) -> None:
    """Register a backend factory, or a ``"module:attribute"`` path to one that is imported on first use."""
    _BACKENDS.register(name, factory)


def backend_names() -> list[str]:
    """Names accepted by :func:`make_backend` (``auto`` included)."""
    return ["auto", *sorted(_BACKENDS.names())]


def resolve_backend_name(name: str) -> str:
    """Map ``auto`` to ``newton`` when CUDA is available, else ``mujoco``; check that ``name`` is known."""
    if name == "auto":
        import torch

        return "newton" if torch.cuda.is_available() else "mujoco"
    if name not in _BACKENDS:
        raise UnknownNameError("backend", name, backend_names())
    return name


def make_backend(
    name: str = "auto",
    *,
    num_worlds: int,
    robot: RobotSpec | str = "a1",
    device: str | None = None,
) -> SimBackend:
    """Build backend ``name`` holding ``num_worlds`` copies of ``robot`` standing at rest.

    ``device`` is a torch device string (``"cpu"``, ``"cuda:0"``); ``None`` lets the backend choose.
    Raises :class:`~gaitlib.errors.GaitlibError` subclasses with a one-line message on bad input.
    """
    if num_worlds < 1:
        raise SimulationError(f"need at least one world, got {num_worlds}")
    spec = get_robot(robot) if isinstance(robot, str) else robot
    if not spec.mjcf_path.is_file():
        raise SimulationError(f"robot model file not found: {spec.mjcf_path}")
    backend = resolve_backend_name(name)
    adapted = spec.build_model is not None or spec.stance_contact_geoms or spec.motor_strength != 1.0
    if backend != "mujoco" and adapted:
        raise SimulationError(
            f"robot '{spec.name}' (an adapted model, stance geoms or a motor strength) runs on the mujoco backend only"
        )
    return _BACKENDS.get(backend)(spec, num_worlds, device=device)
