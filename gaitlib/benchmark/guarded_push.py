"""A gait's push figures on the meta-controller, with the guard on or off on the same draws: the single-shove curve
of :mod:`gaitlib.evaluation.push_curve` (``gaitlib eval GAIT --impulses ... --guard``) and episodes under the paper's
random pushes (``gaitlib eval GAIT --push-max N --guard``: falls, and the guard's catches per minute; at 0 N every
catch is a false one, the guard's cost).

Every world of the library's environment starts in the gait measured and is shoved once exactly as in
:func:`~gaitlib.evaluation.push_curve.single_push_curve` (same settle time, window, duration, sectors, fall
definition); no switch is requested. Guarded, the guard may catch a world into another gait and return it to the
measured one (:mod:`gaitlib.meta.guard`). Each point reports, beside the falls, every catch: from which gait to
which, what the estimate and the net read, the detection delay (control steps from the shove's start to the catch;
a catch before the shove is a false catch) and how long until the measured gait ran again.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from gaitlib.defaults import DEFAULT_FALLS, Falls
from gaitlib.envs import EnvConfig
from gaitlib.envs.randomization import PushConfig
from gaitlib.envs.terminations import FallTally, TerminationConfig
from gaitlib.evaluation import AFTER_S, SETTLE_S, FallRecord, PushPoint, SinglePush
from gaitlib.meta.guard import CatchEvent, Guard
from gaitlib.meta.setup import SwitchingSetup
from gaitlib.sim import make_backend

__all__ = ["GuardedRollout", "guarded_episodes", "guarded_push_curve", "guarded_push_rollout", "shove_episode"]


def guarded_push_curve(setup: SwitchingSetup, gait: str, *, guard: Guard | None, impulses: Sequence[float],
                       episodes: int, duration_s: float = 0.1, backend: str = "auto", seed: int = 0,
                       falls: Falls = DEFAULT_FALLS) -> list[PushPoint]:
    """The fall rate of ``gait`` on ``setup``'s meta-controller under one shove of each impulse (N s), ``episodes``
    worlds per impulse, guarded by ``guard`` (``None``: unguarded, the same draws)."""
    g = setup.gait_index(gait)
    cfg, cycle_s = shove_episode(setup, g, duration_s=duration_s, falls=falls)
    return [_point(setup, g, guard, cfg, impulse, episodes, duration_s, cycle_s, backend, seed + k)
            for k, impulse in enumerate(impulses)]


def shove_episode(setup: SwitchingSetup, g: int, *, duration_s: float, falls: Falls) -> tuple[EnvConfig, float]:
    """(the environment of one single-shove episode of gait ``g``, the gait's cycle, s): as long as
    :func:`~gaitlib.evaluation.push_curve.single_push_curve`'s (settle, a cycle for the shove's start, the shove, the
    time after), no random pushes, falls by ``falls`` and heading drift none."""
    cycle_s = 1.0 / setup.entries[g].clip.phase_rate
    cfg = EnvConfig(episode_seconds=SETTLE_S + cycle_s + duration_s + AFTER_S, pushes=PushConfig(max_force=0.0),
                    termination=TerminationConfig().counting(falls, heading=False))
    return cfg, cycle_s


def _point(setup, g: int, guard: Guard | None, cfg: EnvConfig, impulse: float, episodes: int, duration_s: float,
           cycle_s: float, backend: str, seed: int) -> PushPoint:
    run = guarded_push_rollout(setup, g, guard, cfg, impulse=impulse, episodes=episodes, duration_s=duration_s,
                               cycle_s=cycle_s, backend=backend, seed=seed)
    counted = FallRecord.of(run.tally, dt=run.dt, falls=cfg.termination.falls)
    return PushPoint(**counted.counted(), impulse_ns=impulse, force_n=run.push.force_n,
                     by_sector=run.push.by_sector(run.tally.fell),
                     guard=_guard_summary(guard, run.catches, run.push.start.cpu(), setup.gaits, run.dt,
                                          run.measured_share))


@dataclass(frozen=True)
class GuardedRollout:
    """One rollout of a shove point: per-world falls and touches, the shoves, the catches."""

    tally: FallTally
    push: SinglePush
    catches: list[CatchEvent]
    """The catches of worlds still up (a fallen world's are not counted)."""
    measured_share: float
    """Share of the worlds' time up that the measured gait ran."""
    dt: float
    """Control period, s."""


def guarded_push_rollout(setup: SwitchingSetup, g: int, guard: Guard | None, cfg: EnvConfig, *, impulse: float,
                         episodes: int, duration_s: float, cycle_s: float, backend: str, seed: int) -> GuardedRollout:
    """``episodes`` worlds of gait ``g`` each shoved once (:class:`SinglePush` of ``impulse`` N s, drawn from
    ``seed``) on ``setup``'s meta-controller, guarded by ``guard`` (``None``: unguarded), run to ``cfg``'s end."""
    sim = make_backend(backend, num_worlds=episodes)
    try:
        env = setup.make_env(sim, cfg, seed=seed)
        dev, n, dt = env.device, env.num_envs, env.dt
        env.reset_worlds(torch.arange(n, device=dev), gait=torch.full((n,), g, dtype=torch.long, device=dev))
        ctl = setup.controller(env, "net-lookahead", guard=guard, seed=seed)
        push = SinglePush(env, impulse=impulse, duration_s=duration_s, cycle_s=cycle_s, seed=seed)
        alive = torch.ones(n, dtype=torch.bool, device=dev)
        tally = FallTally(n, dev)
        catches, measured_steps, steps = [], 0, 0
        with torch.inference_mode():
            for step in range(env.max_episode_length):
                push(step, alive)
                result = ctl.step()
                catches += [c for c in result.catches if bool(alive[c.world])]
                measured_steps += int(((env.gait == g) & alive).sum())
                steps += int(alive.sum())
                time_outs = torch.zeros_like(result.fell)
                tally.step(result.fell, {"time_outs": time_outs, "touch": result.touch}, alive)
                alive &= ~result.fell & (env.episode_length_buf > 0)  # a time-out resets the world too
    finally:
        sim.close()
    return GuardedRollout(tally, push, catches, measured_steps / max(1, steps), dt)


def _guard_summary(guard: Guard | None, catches: list, start: torch.Tensor, gaits: tuple[str, ...], dt: float,
                   measured_share: float) -> dict:
    """Whether the guard was on, and its catches (each, and the detection delays in control steps)."""
    listed = [{"world": c.world, "time_s": c.step * dt, "from": gaits[c.source], "to": gaits[c.dest],
               "stay": c.stay, "offer": c.offer, "delay_steps": c.step - int(start[c.world]),
               "back_after_s": None if c.back_step is None else (c.back_step - c.step) * dt} for c in catches]
    delays = np.array([c["delay_steps"] for c in listed if c["delay_steps"] >= 0])
    return {
        "on": guard is not None, "margin": None if guard is None else guard.margin,
        "horizon_s": None if guard is None else guard.horizon_s, "catches": listed,
        "false_catches": sum(c["delay_steps"] < 0 for c in listed),
        "delay_steps_median": float(np.median(delays)) if len(delays) else None,
        "measured_gait_share": measured_share,
    }


def guarded_episodes(setup: SwitchingSetup, gait: str, *, guard: Guard | None, episodes: int, seconds: float,
                     push_max: float, backend: str = "auto", seed: int = 0, falls: Falls = DEFAULT_FALLS) -> dict:
    """``episodes`` episodes (one world each) of ``seconds`` of ``gait`` on ``setup``'s meta-controller under the
    paper's random pushes of up to ``push_max`` N (every 1-3 s, 0.1-0.3 s each; heading drift no fall, as
    ``gaitlib eval``), guarded by ``guard`` (``None``: unguarded, the same draws): falls, touches, the catches and
    catches per minute of running, the share of time the gait ran."""
    g = setup.gait_index(gait)
    cfg = EnvConfig(episode_seconds=seconds, pushes=PushConfig(max_force=push_max),
                    termination=TerminationConfig().counting(falls, heading=False))
    sim = make_backend(backend, num_worlds=episodes)
    try:
        env = setup.make_env(sim, cfg, seed=seed)
        dev, n, dt = env.device, env.num_envs, env.dt
        env.reset_worlds(torch.arange(n, device=dev), gait=torch.full((n,), g, dtype=torch.long, device=dev))
        ctl = setup.controller(env, "net-lookahead", guard=guard, seed=seed)
        alive = torch.ones(n, dtype=torch.bool, device=dev)
        tally = FallTally(n, dev)
        catches, measured_steps, steps = [], 0, 0
        with torch.inference_mode():
            for _ in range(env.max_episode_length):
                result = ctl.step()
                catches += [c for c in result.catches if bool(alive[c.world])]
                measured_steps += int(((env.gait == g) & alive).sum())
                steps += int(alive.sum())
                tally.step(result.fell, {"time_outs": torch.zeros_like(result.fell), "touch": result.touch}, alive)
                alive &= ~result.fell & (env.episode_length_buf > 0)
    finally:
        sim.close()
    counted = FallRecord.of(tally, dt=dt, falls=cfg.termination.falls)
    minutes = steps * dt / 60
    summary = _guard_summary(guard, catches, torch.full((n,), -1), setup.gaits, dt, measured_steps / max(1, steps))
    summary.pop("false_catches"), summary.pop("delay_steps_median")  # no shove to measure them from
    for c in summary["catches"]:
        c.pop("delay_steps")
    return {"gait": gait, "episodes": n, "seconds": seconds, "push_max_n": push_max, "falls": counted.fell,
            "fall_rate": counted.fall_rate, "ci95": counted.fall_ci95, "touches": counted.touched,
            "falls_definition": counted.falls.value, "minutes": minutes,
            "catches_per_min": len(catches) / minutes if minutes > 0 else None, "guard": summary}
