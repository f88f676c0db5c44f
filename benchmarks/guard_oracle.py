"""What a catch made on time could save, and how much of it the guard's choice of gait keeps: one gait's single
shove (``gaitlib eval GAIT --impulses IMPULSE --guard``'s draws), with every world switched at once a fixed number of
control steps after its shove starts, into

* the gait the guard's reading offers most (the calibrated net at each gait's best destination phase), and
* each other gait of the library, at its best destination phase;

beside the unguarded rollout (no switch) and the guard itself, all on the same draws. A switched world keeps its new
gait to the episode's end (no return), as the oracle of the guard's design does. The oracle is, world by world, the
best of staying and every fixed destination. Prints one JSON object: falls of each rollout with 95% intervals.

    python benchmarks/guard_oracle.py --library runs/library --gait pace --impulse 12 --episodes 512 --delays 2,4

The library needs a survival estimate (``gaitlib survival fit``): the timed catches read the guard's offers.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch

from gaitlib.benchmark.guarded_push import guarded_push_rollout
from gaitlib.defaults import DEFAULT_FALLS
from gaitlib.envs import EnvConfig
from gaitlib.envs.randomization import PushConfig
from gaitlib.envs.terminations import TerminationConfig
from gaitlib.evaluation import AFTER_S, SETTLE_S, SinglePush
from gaitlib.meta import load_switching
from gaitlib.meta.guard import Guard, GuardReading
from gaitlib.stats import wilson_interval

NEVER_S = 1e6
"""A hold no episode outlasts, s: a timed catch keeps its gait."""


class TimedCatch(Guard):
    """A guard that catches every world exactly ``delay`` control steps after its shove starts, into ``dest`` (a
    gait index) or, with ``dest`` ``None``, into the gait the reading offers most; never returns."""

    def __init__(self, guard: Guard, *, delay: int, dest: int | None, shove: dict) -> None:
        super().__init__(guard.estimate, guard.scorer, margin=guard.margin)
        self.delay, self.dest, self.shove = delay, dest, shove
        self._start: torch.Tensor | None = None
        self._env = None

    @property
    def horizon_s(self) -> float:
        return NEVER_S

    def read(self, env, policies, ids, candidates) -> GuardReading:
        if self._env is not env:  # the rollout's own draws (SinglePush is drawn from its seed alone)
            self._env, self._start = env, SinglePush(env, **self.shove).start
        reading = super().read(env, policies, ids, candidates)
        if self.dest is not None:
            keep = torch.zeros_like(reading.offer, dtype=torch.bool)
            keep[:, self.dest] = True
            reading = GuardReading(reading.stay, reading.offer.masked_fill(~keep, float("nan")), reading.phase,
                                   reading.latent, reading.armed)
        return reading

    def fires(self, reading: GuardReading) -> torch.Tensor:
        best, _ = reading.best()
        due = self._env.episode_length_buf == self._start + self.delay
        return due & torch.isfinite(best)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--library", type=Path, default=None)
    parser.add_argument("--gait", default="pace")
    parser.add_argument("--impulse", type=float, default=12.0, help="N s")
    parser.add_argument("--episodes", type=int, default=512)
    parser.add_argument("--delays", default="2,4", help="control steps from the shove's start to the catch")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--backend", default="mujoco")
    args = parser.parse_args()
    setup = load_switching(args.library)
    guard = setup.guard()
    g = setup.gait_index(args.gait)
    cycle_s, duration_s = 1.0 / setup.entries[g].clip.phase_rate, 0.1
    cfg = EnvConfig(episode_seconds=SETTLE_S + cycle_s + duration_s + AFTER_S, pushes=PushConfig(max_force=0.0),
                    termination=TerminationConfig().counting(DEFAULT_FALLS, heading=False))
    shove = {"impulse": args.impulse, "duration_s": duration_s, "cycle_s": cycle_s, "seed": args.seed}

    def fell(guarding: Guard | None) -> torch.Tensor:
        run = guarded_push_rollout(setup, g, guarding, cfg, impulse=args.impulse, episodes=args.episodes,
                                   duration_s=duration_s, cycle_s=cycle_s, backend=args.backend, seed=args.seed)
        return run.tally.fell.cpu().bool()

    rows = {"stay (unguarded)": fell(None), "the guard": fell(guard)}
    delays = [int(d) for d in args.delays.split(",")]
    for delay in delays:
        rows[f"the guard's choice at {delay} steps"] = fell(TimedCatch(guard, delay=delay, dest=None, shove=shove))
    fixed = {}
    for n, name in enumerate(setup.gaits):
        if n != g:
            fixed[name] = fell(TimedCatch(guard, delay=delays[0], dest=n, shove=shove))
            rows[f"{name} at {delays[0]} steps"] = fixed[name]
    best = rows["stay (unguarded)"].clone()
    for f in fixed.values():
        best &= f
    rows[f"oracle: the best of staying and each gait at {delays[0]} steps"] = best
    result = {}
    for name, f in rows.items():
        k, n = int(f.sum()), len(f)
        low, high = wilson_interval(k, n)
        result[name] = {"falls": k, "episodes": n, "fall_rate": k / n, "ci95": [low, high]}
    print(json.dumps({"gait": args.gait, "impulse_ns": args.impulse, "episodes": args.episodes, "seed": args.seed,
                      "delays": delays, "rows": result}, indent=1))


if __name__ == "__main__":
    main()
