"""Domain randomization and random pushes: every range in one place, beside its line (paper Table 1)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import torch

from gaitlib.robots.a1.constants import FOOT_FRICTION, KD_DEFAULT, KD_RANGE, KP_DEFAULT, KP_RANGE

__all__ = [
    "PUSH_DRAWS", "PushConfig", "PushSchedule", "RandomizationConfig", "WorldParameters", "sample_world_parameters",
]


@dataclass(frozen=True, kw_only=True)
class RandomizationConfig:
    """Uniform ranges, re-sampled per world at every reset (paper Table 1). ``enabled=False`` uses nominal values."""

    enabled: bool = True
    """Randomize at all; when off every world gets the robot's default gains, unit scales, nominal friction, no
    noise."""
    gravity_scale: tuple[float, float] = (0.8, 1.2)  # Table 1: gravity, x nominal
    action_noise: float = 0.03  # Table 1: additive uniform noise on actions, +/- rad
    observation_noise: float = 0.03  # Table 1: additive uniform noise on observations, +/-
    mass_scale: tuple[float, float] = (0.85, 1.15)  # Table 1: rigid body mass, x nominal
    friction: tuple[float, float] = (0.25, 1.5)  # Table 1: ground friction coefficient
    latency: tuple[float, float] = (0.0, 0.020)  # Table 1: observation latency, s
    # Beyond Table 1: whole control steps (33 ms each) an action waits before the servos get it. The paper
    # randomizes latency; a policy on the robot acts on readings a step old, and must survive it.
    action_delay_steps: tuple[int, int] = (0, 1)
    kp: tuple[float, float] = KP_RANGE  # Table 1: PD stiffness, N m/rad
    kd: tuple[float, float] = KD_RANGE  # Table 1: PD damping, N m s/rad
    nominal_friction: float = FOOT_FRICTION  # the model's own friction, used when randomization is off


@dataclass
class WorldParameters:
    """One sample of the randomized parameters for k worlds; each tensor (k,)."""

    gravity_scale: torch.Tensor
    mass_scale: torch.Tensor
    friction: torch.Tensor
    latency: torch.Tensor
    """Observation latency, s."""
    action_delay: torch.Tensor
    """Control steps each action waits before it reaches the PD servos (a whole number stored as a float)."""
    kp: torch.Tensor
    """PD stiffness applied to every joint, N m/rad."""
    kd: torch.Tensor
    """PD damping applied to every joint, N m s/rad."""


def _uniform(bounds: tuple[float, float], k: int, generator: torch.Generator) -> torch.Tensor:
    low, high = bounds
    return low + (high - low) * torch.rand(k, generator=generator)


def sample_world_parameters(cfg: RandomizationConfig, k: int, generator: torch.Generator) -> WorldParameters:
    """Draw parameters for ``k`` worlds (on the CPU) from ``cfg``'s ranges, or nominal values if disabled."""
    if not cfg.enabled:
        return WorldParameters(
            gravity_scale=torch.ones(k),
            mass_scale=torch.ones(k),
            friction=torch.full((k,), cfg.nominal_friction),
            latency=torch.zeros(k),
            action_delay=torch.zeros(k),
            kp=torch.full((k,), KP_DEFAULT),
            kd=torch.full((k,), KD_DEFAULT),
        )
    return WorldParameters(
        gravity_scale=_uniform(cfg.gravity_scale, k, generator),
        mass_scale=_uniform(cfg.mass_scale, k, generator),
        friction=_uniform(cfg.friction, k, generator),
        latency=_uniform(cfg.latency, k, generator),
        action_delay=torch.randint(
            cfg.action_delay_steps[0], cfg.action_delay_steps[1] + 1, (k,), generator=generator
        ).float(),
        kp=_uniform(cfg.kp, k, generator),
        kd=_uniform(cfg.kd, k, generator),
    )


DISTURBANCE_INTERVAL_S = (0.2, 1.0)
"""Quiet time before each push where pushes test a switch (collection source runs, benchmark, ``gaitlib run``), s:
short enough that a push or two lands in every transition window."""

DISTURBANCE_LEAD_S = 0.6
"""Where pushes test a requested switch (benchmark, ``gaitlib run``), they begin this long before the request, s:
the mean of :data:`DISTURBANCE_INTERVAL_S`, so the first push starts between 0.4 s before and 0.4 s after the
request and a strategy meets the robot in every state of a push (under way, just over, about to come)."""


PUSH_DRAWS = ("disk", "axes")
"""How a push's horizontal force is drawn (:attr:`PushConfig.draw`)."""


@dataclass(frozen=True, kw_only=True)
class PushConfig:
    """Random horizontal pushes on the trunk: random direction, magnitude, duration and interval."""

    max_force: float = 0.0
    """Largest push, N (0 disables pushes): the magnitude's bound with the ``disk`` draw, each horizontal axis's with
    ``axes``."""
    fixed_force: bool = False
    """Push with exactly ``max_force`` every time (the benchmark's fixed magnitudes) instead of a uniform draw (the
    ``disk`` draw only)."""
    draw: str = "disk"
    """``disk``: a random direction, the magnitude uniform in [0, max_force] (the paper's pushes); ``axes``: each
    horizontal axis uniform in [-max_force, max_force], as legged_gym (``push_robots``) and Isaac Lab
    (``push_by_setting_velocity``) draw their velocity kicks."""
    duration: tuple[float, float] = (0.1, 0.3)  # paper: pushes last 0.1-0.3 s
    interval: tuple[float, float] = (1.0, 3.0)  # choice: quiet time between pushes, s

    def __post_init__(self) -> None:
        if self.draw not in PUSH_DRAWS or (self.fixed_force and self.draw != "disk"):
            raise ValueError(f"pushes: draw is one of {PUSH_DRAWS} (fixed_force with 'disk' only), got '{self.draw}'")


class PushSchedule:
    """Per-world push timers, counted in control steps: which worlds start or stop being pushed at each step."""

    def __init__(self, cfg: PushConfig, num_worlds: int, control_dt: float, generator: torch.Generator) -> None:
        self.cfg = cfg
        self._dt = control_dt
        self._gen = generator
        self.force = torch.zeros(num_worlds, 3)
        """(N, 3) the push force currently applied, world frame, N."""
        self._pushing = torch.zeros(num_worlds, dtype=torch.bool)
        self._steps_left = torch.zeros(num_worlds, dtype=torch.long)  # of the current push or quiet time
        self.enabled = torch.ones(num_worlds, dtype=torch.bool)
        """(N,) which worlds may be pushed."""
        self.reset(torch.arange(num_worlds))

    def enable(self, world_ids: torch.Tensor, enabled: bool) -> None:
        """Let ``world_ids`` be pushed (after a fresh quiet time), or start no new push on them (a push under way
        runs out)."""
        self.enabled[world_ids] = enabled
        if enabled:
            self.reset(world_ids)

    def set_max_force(self, force: float) -> None:
        """Draw the magnitudes of pushes that start from now on up to ``force``, N (a training curriculum)."""
        self.cfg = replace(self.cfg, max_force=force)

    def hold(self, world_ids: torch.Tensor, force: torch.Tensor, steps: torch.Tensor) -> None:
        """Push ``world_ids`` (k,) with ``force`` (k, 3) N, world frame, through the next ``steps`` (k,) control
        steps (a shove under way when a recorded state was taken, :meth:`under_way`); 0 steps: no push. It ends as
        a random push ends, whatever the largest random push, and random pushes then follow as after any push."""
        steps = torch.as_tensor(steps).long()
        held = steps > 0
        self.force[world_ids] = torch.where(held.unsqueeze(1), torch.as_tensor(force, dtype=torch.float32), 0.0)
        self._pushing[world_ids] = held
        self._steps_left[world_ids] = torch.where(held, steps + 1, self._steps_left[world_ids])  # advance counts 1

    def under_way(self, world_ids: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The push on ``world_ids`` (k,) now, between two control steps: its force (k, 3) N, world frame, and the
        control steps it still lasts (k,), 0 (and no force) where none is under way: what :meth:`hold` continues."""
        steps = torch.where(self._pushing[world_ids], self._steps_left[world_ids] - 1, 0).clamp(min=0)
        pushing = steps > 0
        return torch.where(pushing.unsqueeze(1), self.force[world_ids], 0.0), steps

    def _steps(self, bounds: tuple[float, float], k: int) -> torch.Tensor:
        return torch.round(_uniform(bounds, k, self._gen) / self._dt).long().clamp(min=1)

    def reset(self, world_ids: torch.Tensor) -> None:
        """Stop pushing ``world_ids`` and draw their next quiet time."""
        self.force[world_ids] = 0.0
        self._pushing[world_ids] = False
        self._steps_left[world_ids] = self._steps(self.cfg.interval, len(world_ids))

    def _draw(self, k: int) -> torch.Tensor:
        """(k, 3) horizontal forces of ``k`` new pushes, N (:attr:`PushConfig.draw`)."""
        if self.cfg.draw == "axes":
            xy = self.cfg.max_force * (2 * torch.rand(k, 2, generator=self._gen) - 1)
            return torch.cat([xy, torch.zeros(k, 1)], 1)
        angle = 2 * torch.pi * torch.rand(k, generator=self._gen)
        if self.cfg.fixed_force:
            magnitude = torch.full((k,), self.cfg.max_force)
        else:
            magnitude = self.cfg.max_force * torch.rand(k, generator=self._gen)
        return torch.stack([magnitude * torch.cos(angle), magnitude * torch.sin(angle), 0 * angle], 1)

    def advance(self) -> torch.Tensor:
        """Move the timers on by one control step; return the ids of worlds whose force changed."""
        random = self.cfg.max_force > 0.0
        if not random and not bool(self._pushing.any()):  # no random pushes, no held one (:meth:`hold`)
            return torch.zeros(0, dtype=torch.long)
        self._steps_left -= 1
        due = ((self._steps_left <= 0) & (self.enabled | self._pushing)).nonzero().squeeze(1)
        if len(due) == 0:
            return due
        stop = due[self._pushing[due]]
        start = due[~self._pushing[due] & self.enabled[due]] if random else due[:0]
        self.force[stop] = 0.0
        self._pushing[stop] = False
        self._steps_left[stop] = self._steps(self.cfg.interval, len(stop))
        self.force[start] = self._draw(len(start))
        self._pushing[start] = True
        self._steps_left[start] = self._steps(self.cfg.duration, len(start))
        return due
