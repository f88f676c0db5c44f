"""What a catch made on time could save, and how much of it the guard's choice of gait keeps: one gait's single
shove (``gaitlib eval GAIT --impulses IMPULSE --guard``'s draws), with every world switched at once a fixed number of
control steps after its shove starts, into

* the gait the guard's reading offers most (the calibrated net at each gait's best destination phase, or the catch
  table's gait where the estimate has one), and
* each other gait of the library, at its best destination phase;

beside the unguarded rollout (no switch) and the guard itself, all on the same draws. A switched world keeps its new
gait to the episode's end (no return). The oracle is, world by world, the best of staying and every fixed
destination. Prints one JSON object: falls of each rollout with 95% intervals.

    python benchmarks/guard_oracle.py --library runs/library --gait pace --impulse 12 --episodes 512 --delays 2,4

The library needs a survival estimate (``gaitlib survival fit``): the timed catches read the guard's offers.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from gaitlib.benchmark.catches import timed_catch_falls
from gaitlib.benchmark.guarded_push import guarded_push_rollout, shove_episode
from gaitlib.defaults import DEFAULT_FALLS
from gaitlib.meta import load_switching
from gaitlib.stats import wilson_interval


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
    sizes = {"impulse_ns": args.impulse, "episodes": args.episodes, "seed": args.seed, "backend": args.backend}

    def fell(dest: int | None, delay: int):
        return timed_catch_falls(setup, guard, g, dest, delay_steps=delay, **sizes)

    cfg, cycle_s = shove_episode(setup, g, duration_s=0.1, falls=DEFAULT_FALLS)
    guarded = guarded_push_rollout(setup, g, guard, cfg, impulse=args.impulse, episodes=args.episodes,
                                   duration_s=0.1, cycle_s=cycle_s, backend=args.backend, seed=args.seed)
    delays = [int(d) for d in args.delays.split(",")]
    rows = {"stay (unguarded)": fell(-1, 0), "the guard": guarded.tally.fell.cpu().bool()}
    for delay in delays:
        rows[f"the guard's choice at {delay} steps"] = fell(None, delay)
    best = rows["stay (unguarded)"].clone()
    for n, name in enumerate(setup.gaits):
        if n != g:
            rows[f"{name} at {delays[0]} steps"] = fixed = fell(n, delays[0])
            best &= fixed
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
