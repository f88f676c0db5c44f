"""Push robustness the way the field measures it: one push per episode, fall rate against the push's impulse.

The paper's protocol (and ``gaitlib eval --push``) pushes every 1-3 s with up to a given force for 0.1-0.3 s: a
100 N push for 0.3 s is 30 N s, a 2.4 m/s change of speed for the 12.45 kg A1, far beyond what legged_gym
(https://github.com/leggedrobotics/legged_gym: ``push_robots``, a velocity kick of up to 1 m/s) and Isaac Lab train
for. Here each episode meets a single push: after :data:`SETTLE_S` of walking, at a uniformly random moment of the
next gait cycle (so every phase is hit), a horizontal force of ``impulse / duration`` in a uniformly random direction
for ``duration``; the episode then runs :data:`AFTER_S` more. A fall is any termination before the end, by the
definition asked for (``trunk`` by default; a gait that falls unpushed counts too: the 0 N s point shows it); the
episodes in which a non-foot body touched the ground are counted beside. Directions are reported in four sectors of
the robot's heading at the push: front (pushed forward), back, left, right.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import torch

from gaitlib.defaults import DEFAULT_FALLS, Falls
from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs.randomization import PushConfig
from gaitlib.evaluation.rollout import FallRecord, rollout
from gaitlib.gaits import ReferenceClip
from gaitlib.library.policy import GaitPolicy
from gaitlib.rotations import yaw_of
from gaitlib.sim import make_backend

__all__ = ["AFTER_S", "SECTORS", "SETTLE_S", "PushPoint", "SinglePush", "sector_of", "single_push_curve",
           "write_push_plot"]

SETTLE_S = 1.0
"""Walking time before the push window opens, s."""
AFTER_S = 3.0
"""Time after the push's end that the episode goes on, s: a push-caused fall comes within about a second."""
SECTORS = ("front", "left", "back", "right")
"""Push directions relative to the robot's heading at the push, 90 degrees each, centred on these."""


def sector_of(angle: torch.Tensor) -> torch.Tensor:
    """(k,) index into :data:`SECTORS` of directions ``angle`` (k,), rad from the robot's forward axis, left
    positive."""
    return torch.remainder(torch.round(angle / (math.pi / 2)), 4).long()


@dataclass(frozen=True, kw_only=True)
class PushPoint(FallRecord):
    """Falls and touches under one impulse (:class:`FallRecord`)."""

    impulse_ns: float
    """Impulse of the push, N s (force x duration)."""
    force_n: float
    """Its force, N."""
    by_sector: dict[str, tuple[int, int]]
    """Sector -> (falls, episodes)."""
    guard: dict | None = None
    """On the meta-controller (:mod:`gaitlib.benchmark.guarded_push`): whether the guard was on, its margin and
    horizon, each catch, the false catches and detection delays, the share of time the measured gait ran;
    ``None``: the gait's own policy alone."""

    def as_dict(self) -> dict:
        """The point as ``gaitlib eval --impulses --json`` prints it (the fall count as ``falls``, the definition as
        ``falls_definition``, as stored curves hold them)."""
        return {
            "impulse_ns": self.impulse_ns, "force_n": self.force_n, "episodes": self.episodes, "falls": self.fell,
            "fall_rate": self.fall_rate, "ci95": self.fall_ci95, "by_sector": dict(self.by_sector),
            "touches": self.touched, "touch_ci95": self.touch_ci95, "longest_touch_s": self.longest_touch_s,
            "falls_definition": self.falls.value, "guard": self.guard,
        }

    @classmethod
    def from_dict(cls, point: dict) -> PushPoint:
        """A point as :meth:`as_dict` wrote it (one written before the definition was recorded: ``trunk``)."""
        return cls(impulse_ns=point["impulse_ns"], force_n=point["force_n"], episodes=point["episodes"],
                   fell=point["falls"], touched=point["touches"], longest_touch_s=point["longest_touch_s"],
                   falls=Falls(point.get("falls_definition", DEFAULT_FALLS)),
                   by_sector={name: tuple(n) for name, n in point["by_sector"].items()}, guard=point.get("guard"))


class SinglePush:
    """The one push of each world of ``env``, drawn from ``seed``: it begins at a uniformly random moment of the
    ``cycle_s`` s after :data:`SETTLE_S`, lasts ``duration_s`` s, and pushes with ``impulse / duration`` N in a
    uniformly random direction relative to the robot's heading as it begins. Called with (control step, worlds
    alive) before each step, it starts and ends the pushes due then."""

    def __init__(self, env, *, impulse: float, duration_s: float, cycle_s: float, seed: int) -> None:
        dev, n, dt = env.device, env.num_envs, env.dt
        gen = torch.Generator().manual_seed(seed)
        self.env = env
        self.start = torch.round((SETTLE_S + cycle_s * torch.rand(n, generator=gen)) / dt).long().to(dev)
        """Control step at which each world's push begins."""
        self.length = max(1, round(duration_s / dt))
        """Control steps each push lasts."""
        self.angle = (2 * math.pi * torch.rand(n, generator=gen)).to(dev)  # relative to the heading at the push
        """Direction of each world's push relative to its heading as the push begins, rad."""
        self.force_n = impulse / (self.length * dt)
        """Force of every push, N."""

    def __call__(self, step: int, alive: torch.Tensor) -> None:
        env = self.env
        begins, ends = (self.start == step) & alive, (self.start + self.length == step) & alive
        if begins.any():
            ids = begins.nonzero().squeeze(1)
            heading = yaw_of(env.sim_state.root_quat[ids]) + self.angle[ids]
            direction = torch.stack([torch.cos(heading), torch.sin(heading), torch.zeros_like(heading)], 1)
            env.backend.set_trunk_force(ids, self.force_n * direction)
        if ends.any():
            ids = ends.nonzero().squeeze(1)
            env.backend.set_trunk_force(ids, torch.zeros(len(ids), 3, device=env.device))

    def by_sector(self, fell: torch.Tensor) -> dict[str, tuple[int, int]]:
        """Sector of :data:`SECTORS` -> (worlds of ``fell``, a flag per world, that fell; worlds pushed there)."""
        sector = sector_of(self.angle).cpu()
        fell = fell.cpu()
        return {name: (int(fell[sector == k].sum()), int((sector == k).sum())) for k, name in enumerate(SECTORS)}


def single_push_curve(
    policy: GaitPolicy,
    clip: ReferenceClip,
    *,
    env_cfg: EnvConfig,
    impulses: Sequence[float],
    episodes: int,
    duration_s: float = 0.1,
    backend: str = "auto",
    seed: int = 0,
    falls: Falls = DEFAULT_FALLS,
) -> list[PushPoint]:
    """The fall rate of ``policy`` under one push of each impulse in ``impulses`` (N s), ``episodes`` episodes (one
    world each) per impulse, under paper Table 1 randomization (``env_cfg`` holds the policy's settings); a fall by
    the definition ``falls``."""
    cycle_s = 1.0 / clip.phase_rate
    seconds = SETTLE_S + cycle_s + duration_s + AFTER_S
    cfg = replace(env_cfg, episode_seconds=seconds, pushes=PushConfig(max_force=0.0),
                  termination=env_cfg.termination.counting(falls, heading=False))
    return [
        _point(policy, clip, cfg, impulse, episodes, duration_s, cycle_s, backend, seed + k)
        for k, impulse in enumerate(impulses)
    ]


def _point(policy, clip, cfg: EnvConfig, impulse: float, episodes: int, duration_s: float, cycle_s: float,
           backend: str, seed: int) -> PushPoint:
    sim = make_backend(backend, num_worlds=episodes)
    try:
        env = ImitationEnv(sim, [clip], cfg, seed=seed)
        push = SinglePush(env, impulse=impulse, duration_s=duration_s, cycle_s=cycle_s, seed=seed)
        counted, tally = rollout(env, policy, steps=env.max_episode_length, before=push)
    finally:
        sim.close()
    return PushPoint(**counted.counted(), impulse_ns=impulse, force_n=push.force_n,
                     by_sector=push.by_sector(tally.fell))


def write_push_plot(curves: dict[str, list[PushPoint]], path) -> None:
    """Fall rate against impulse, one line per label of ``curves``, with 95% intervals, as a PNG at ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gaitlib.atomic import save_figure

    fig, ax = plt.subplots(figsize=(6, 4))
    for label, points in curves.items():
        x = [p.impulse_ns for p in points]
        ax.plot(x, [100 * p.fall_rate for p in points], marker="o", label=label)
        ax.fill_between(x, [100 * p.fall_ci95[0] for p in points], [100 * p.fall_ci95[1] for p in points], alpha=0.2)
    ax.set_xlabel("impulse of one 0.1 s push, N s (12 N s: about 1 m/s for the A1)")
    ax.set_ylabel("episodes that fall, %")
    ax.grid(alpha=0.3)
    ax.legend()
    save_figure(fig, path)
