"""Measure a library's gaits against the quality bar: `gaitlib eval` without pushes, with pushes of up to 50, 100 and
150 N, and with every action on time or one control step (33 ms) late (the other runs draw 0 or 1 step per
episode, as training did); one JSON line per run, then a markdown table.

    python benchmarks/gait_quality.py --library library [--gaits trot,pace] [--episodes 256] [--out quality.json]

Each run is `gaitlib eval GAIT --episodes 256 --seconds 20 [--push N] [--action-delay 1] --seed 0` (Table 1
randomization, the deterministic policy, one world per episode). Pushes: random horizontal direction, magnitude
uniform up to N, 0.1-0.3 s each, 1-3 s apart.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from gaitlib.atomic import write_json
from gaitlib.envs import EnvConfig
from gaitlib.evaluation import evaluate_policy
from gaitlib.library import Library

RUNS = (("no pushes", 0.0, None), ("push <= 50 N", 50.0, None), ("push <= 100 N", 100.0, None),
        ("push <= 150 N", 150.0, None), ("action on time", 0.0, 0), ("action 1 step late", 0.0, 1))
"""(label, largest push N, fixed action delay in control steps or None for training's random 0-1)."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--library", type=Path, default=None, help="library folder (default: the shipped one)")
    parser.add_argument("--gaits", default=None, help="comma-separated gaits (default: all)")
    parser.add_argument("--episodes", type=int, default=256)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--out", type=Path, default=None, help="also write the results here as JSON")
    args = parser.parse_args()
    library = Library(args.library)
    names = library.order(args.gaits.split(",")) if args.gaits else library.gaits()
    results = []
    for name in names:
        entry = library.entry(name)
        env_cfg = library.shared_policy_settings([name]).env_config(EnvConfig())
        for label, push, delay in RUNS:
            result = evaluate_policy(
                entry.policy, entry.clip, env_cfg=env_cfg, episodes=args.episodes, seconds=args.seconds,
                push_max=push, action_delay_steps=delay, seed=0,
            )
            row = {"gait": name, "run": label} | result.as_dict()
            results.append(row)
            print(json.dumps(row), flush=True)
    if args.out is not None:
        write_json(args.out, {"library": str(library.root), "runs": results})
    print("\n| gait | run | fall rate | heading lost | median heading change (deg) | joint RMSE (rad) | speed (m/s) |")
    print("|---|---|---|---|---|---|---|")
    for r in results:
        print(
            f"| {r['gait']} | {r['run']} | {r['fall_rate']:.3f} | {r['heading_loss_rate']:.3f} | "
            f"{r['median_heading_change_deg']:.1f} | {r['joint_rmse']:.3f} | {r['forward_speed']:.2f} "
            f"(ref {r['reference_speed']:.2f}) |"
        )


if __name__ == "__main__":
    main()
