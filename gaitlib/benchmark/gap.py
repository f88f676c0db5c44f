"""A deployment gap for the sweep (paper Fig. 4, bottom: the real robot): another A1 model, a fixed action latency,
weaker or stronger motors.

The paper's real-robot half runs the strategies on the real A1, without pushes; what separates it from the
simulated half is a robot that is not the training simulator. :class:`DeploymentGap` is gaitlib's stand-in: the
policies run on another MJCF of the A1 (:mod:`gaitlib.robots.variant`, e.g. MuJoCo Menagerie's ``unitree_a1``),
every action reaches the servos a fixed number of control steps late, and the motors deliver a multiple of the
PD torque. It runs on the ``mujoco`` backend.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.errors import GaitlibError
from gaitlib.meta import SwitchingSetup
from gaitlib.robots import RobotSpec, get_robot
from gaitlib.sim import SimBackend, resolve_backend_name

__all__ = ["MAX_ACTION_DELAY", "DeploymentGap"]

MAX_ACTION_DELAY = 10
"""Longest fixed action delay, control steps (a third of a second at 30 Hz)."""


@dataclass(frozen=True, kw_only=True)
class DeploymentGap:
    """What differs from the training simulator (checked when built: one-line errors). The defaults are none."""

    robot: str | None = None
    """MJCF of another A1 model (made absolute when built); ``None``: gaitlib's own A1."""
    robot_sha256: str | None = None
    """SHA-256 of that file and the files it includes (:func:`gaitlib.robots.variant.model_sha256`), computed when
    built if not given; a worker refuses a file that no longer matches."""
    action_delay: int | None = None
    """Control steps every action waits before it reaches the servos, the same for every world; ``None``: the
    policies' trained random delay."""
    motor_strength: float = 1.0
    """Multiple of the PD torque the motors deliver, kp, kd and torque limit alike
    (:attr:`gaitlib.robots.RobotSpec.motor_strength`)."""

    def __post_init__(self) -> None:
        if self.action_delay is not None and not 0 <= self.action_delay <= MAX_ACTION_DELAY:
            raise GaitlibError(
                f"the action delay must be 0 to {MAX_ACTION_DELAY} control steps, got {self.action_delay}"
            )
        if not (math.isfinite(self.motor_strength) and self.motor_strength > 0):
            raise GaitlibError(f"the motor strength must be a positive finite number, got {self.motor_strength:g}")
        if self.robot is not None:
            from gaitlib.robots.variant import model_sha256

            path = str(Path(self.robot).expanduser().resolve())
            object.__setattr__(self, "robot", path)
            if self.robot_sha256 is None:
                object.__setattr__(self, "robot_sha256", model_sha256(path))

    @property
    def needs_mujoco(self) -> bool:
        """Another robot model or motor strength: only the ``mujoco`` backend simulates them."""
        return self.robot is not None or self.motor_strength != 1.0

    def backend_name(self, backend: str) -> str:
        """The backend ``backend`` (``auto`` included) stands for under this gap; one line for ``newton`` where the
        gap needs ``mujoco``."""
        if not self.needs_mujoco:
            return resolve_backend_name(backend)
        if backend not in ("auto", "mujoco"):
            raise GaitlibError(
                f"--robot and --motor-strength run on the mujoco backend only, not on '{backend}'; use --backend mujoco"
            )
        return "mujoco"

    def settings(self) -> dict:
        """The entries that differ from no gap (a sweep without a gap records none, as before gaps existed)."""
        return {k: v for k, v in dataclasses.asdict(self).items() if v != getattr(DeploymentGap(), k)}

    def robot_spec(self) -> RobotSpec:
        """The robot to simulate: the adapted model of :attr:`robot` (its file checked against
        :attr:`robot_sha256`), or gaitlib's A1, with :attr:`motor_strength`."""
        if self.robot is None:
            return dataclasses.replace(get_robot("a1"), motor_strength=self.motor_strength)
        from gaitlib.robots.variant import load_variant, model_sha256

        if model_sha256(self.robot) != self.robot_sha256:
            raise GaitlibError(f"robot model {self.robot} changed since the sweep began (its SHA-256 differs)")
        return load_variant(self.robot, motor_strength=self.motor_strength)

    def make_env(self, setup: SwitchingSetup, sim: SimBackend, cfg: EnvConfig, *, seed: int) -> ImitationEnv:
        """``setup.make_env(sim, cfg)``, with every world's action delay fixed at :attr:`action_delay` if set."""
        return setup.make_env(sim, cfg, seed=seed, action_delay=self.action_delay)
