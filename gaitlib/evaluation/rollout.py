"""The rollout loop every evaluation of a gait policy runs, and the record of what it counts.

Every world of an environment runs one episode with the deterministic policy from its state now; per world the loop
counts whether the episode ended in a fall (by the definition the environment's terminations count,
:meth:`~gaitlib.envs.terminations.TerminationConfig.counting`), whether a non-foot body touched the ground while the
robot was up, and its longest unbroken touch (:class:`~gaitlib.envs.terminations.FallTally`). Over the worlds these
are one :class:`FallRecord`: the counts, their rates with Wilson 95% intervals, and the definition counted.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields

import torch

from gaitlib.defaults import Falls
from gaitlib.envs import ImitationEnv
from gaitlib.envs.terminations import FallTally
from gaitlib.library.policy import GaitPolicy
from gaitlib.stats import wilson_interval

__all__ = ["AfterStep", "BeforeStep", "FallRecord", "rollout"]

BeforeStep = Callable[[int, torch.Tensor], None]
"""``before(step, alive)``: called before control step ``step`` (0, 1, ...) with the (N,) worlds still up."""
AfterStep = Callable[[dict, torch.Tensor, torch.Tensor, torch.Tensor], None]
"""``after(extras, fell, ended, alive)``: called after each control step with the environment's ``extras`` and, per
world (N,) bool, those that fell at it, those whose episode ended at it (a fall or the episode's end) and those
still up after it."""


@dataclass(frozen=True, kw_only=True)
class FallRecord:
    """Falls and touches over ``episodes`` episodes, one per world."""

    episodes: int
    """Episodes run (one per world)."""
    fell: int
    """Episodes that ended in a fall, by the definition ``falls``."""
    touched: int
    """Episodes in which a non-foot body (a leg's thigh or calf, or the trunk) touched the ground while the robot
    was up, a fall or not: the touches ridden through are counted here whether or not they were falls."""
    longest_touch_s: float
    """The longest unbroken touch of a non-foot body over the episodes, s (0: none)."""
    falls: Falls
    """The definition of a fall counted: ``trunk`` (the field's) or ``contact`` (a non-foot body on the ground is a
    fall too)."""

    @property
    def fall_rate(self) -> float:
        """``fell / episodes``, 0-1."""
        return self.fell / self.episodes

    @property
    def fall_ci95(self) -> tuple[float, float]:
        """Wilson 95% interval of :attr:`fall_rate`."""
        return wilson_interval(self.fell, self.episodes)

    @property
    def touch_rate(self) -> float:
        """``touched / episodes``, 0-1."""
        return self.touched / self.episodes

    @property
    def touch_ci95(self) -> tuple[float, float]:
        """Wilson 95% interval of :attr:`touch_rate`."""
        return wilson_interval(self.touched, self.episodes)

    @classmethod
    def of(cls, tally: FallTally, *, dt: float, falls: Falls) -> FallRecord:
        """The record over every world of ``tally``, one episode each (``dt``: the control step, s; ``falls``: the
        definition the environment counted)."""
        return cls(episodes=len(tally.fell), fell=int(tally.fell.sum()), touched=int(tally.touched.sum()),
                   longest_touch_s=float(tally.longest.max()) * dt, falls=falls)

    def counted(self) -> dict:
        """This record's own fields, by name (to make a record of a measure that holds one)."""
        return {f.name: getattr(self, f.name) for f in fields(FallRecord)}


def rollout(env: ImitationEnv, policy: GaitPolicy, *, steps: int, before: BeforeStep | None = None,
            after: AfterStep | None = None) -> tuple[FallRecord, FallTally]:
    """Run ``policy`` on every world of ``env`` for ``steps`` control steps from its state now, one episode each (a
    world that ends its episode is no longer counted); ``before`` and ``after`` see each step. Returns the record over
    the worlds and the per-world tally it was made from."""
    n, dev = env.num_envs, env.device
    alive = torch.ones(n, dtype=torch.bool, device=dev)
    tally = FallTally(n, dev)
    obs = env.get_observations()
    with torch.inference_mode():
        for step in range(steps):
            if before is not None:
                before(step, alive)
            obs, _, dones, extras = env.step(policy.act(obs))
            # The rows of worlds that just finished hold their reset state: count only those still alive before it.
            ended = dones & alive
            fell = tally.step(dones, extras, alive)
            alive &= ~dones
            if after is not None:
                after(extras, fell, ended, alive)
    return FallRecord.of(tally, dt=env.dt, falls=env.cfg.termination.falls), tally
