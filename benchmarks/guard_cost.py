"""What the whole meta-controller costs per control step on one CPU thread: ``net-lookahead``'s decision for a
waiting request plus the guard's reading (the survival estimate and the calibrated net's offer of every other gait),
against the 33 ms a 30 Hz step allows, and as a ratio of the gait policy's own step (its actor on one observation),
measured in the same run. The simulator's step is not counted: a robot runs its own physics.

    python benchmarks/guard_cost.py --library runs/library --gait pace --steps 2000

The library needs a survival estimate (``gaitlib survival fit``). One world, one thread (``torch.set_num_threads(1)``);
the robot runs the gait with a request for another gait always waiting (queued again after each switch), so that
every step pays for both decisions. Prints the median and the 99th percentile of each part, ms and ratios.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

from gaitlib.envs import EnvConfig
from gaitlib.library.policy import per_gait
from gaitlib.meta import load_switching
from gaitlib.sim import make_backend

STEP_BUDGET_MS = 1000 / 30
"""What one control step at 30 Hz allows, ms."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--library", type=Path, default=None)
    parser.add_argument("--gait", default="pace")
    parser.add_argument("--steps", type=int, default=2000)
    args = parser.parse_args()
    torch.set_num_threads(1)
    setup = load_switching(args.library)
    guard = setup.guard()
    gait = setup.gait_index(args.gait)
    other = (gait + 1) % len(setup.gaits)
    sim = make_backend("mujoco", num_worlds=1)
    try:
        env = setup.make_env(sim, EnvConfig(episode_seconds=args.steps * sim.control_dt + 10), seed=0)
        env.reset_worlds(torch.zeros(1, dtype=torch.long), gait=torch.full((1,), gait))
        ctl = setup.controller(env, "net-lookahead", guard=guard)
        world = torch.zeros(1, dtype=torch.long)
        times: dict[str, list[float]] = {"policy": [], "guard": [], "lookahead": []}
        with torch.inference_mode():
            for _ in range(args.steps):
                if int(ctl.queued[0]) < 0:
                    ctl.request(world, other if int(env.gait[0]) != other else gait)
                obs = env.get_observations()
                start = time.perf_counter()
                per_gait(ctl.policies, env.gait, obs)
                times["policy"].append(time.perf_counter() - start)
                start = time.perf_counter()
                guard.fires(guard.read(env, ctl.policies, world, ctl.candidates))
                times["guard"].append(time.perf_counter() - start)
                start = time.perf_counter()
                ctl._decide(world)  # the waiting request's decision, as the controller makes it
                times["lookahead"].append(time.perf_counter() - start)
                ctl.step()
    finally:
        sim.close()
    ms = {name: 1000 * np.asarray(t) for name, t in times.items()}
    ms["meta-controller"] = ms["guard"] + ms["lookahead"]
    reference = float(np.median(ms["policy"]))
    for name, values in ms.items():
        median, p99 = float(np.median(values)), float(np.percentile(values, 99))
        print(json.dumps({"part": name, "median_ms": round(median, 3), "p99_ms": round(p99, 3),
                          "median_vs_policy": round(median / reference, 2),
                          "p99_of_30hz_step": round(p99 / STEP_BUDGET_MS, 3), "steps": args.steps}))


if __name__ == "__main__":
    main()
