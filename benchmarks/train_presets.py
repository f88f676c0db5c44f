"""Which training sizes learn fastest per wall-clock second on this machine?

Trains one gait with several variants of the ``cpu`` preset for the same wall-clock budget each (one after the
other, never side by side: they would share the cores) and prints, per variant, the mean reward and episode length
reached and a short evaluation. Results go into docs/benchmarks.md.

    python benchmarks/train_presets.py --gait trot --minutes 4
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import tempfile
from pathlib import Path

from gaitlib.gaits import get_gait
from gaitlib.training import get_preset
from gaitlib.training.trainer import TrainRequest, train_gait

VARIANTS = {
    "cpu": {},  # 512 envs x 24 steps, 4 epochs x 4 mini-batches, 256-128-64 networks
    "envs128": {"num_envs": 128},
    "envs256": {"num_envs": 256},
    "epochs5x8": {"num_envs": 256, "epochs": 5, "mini_batches": 8},
    "net512": {"actor_hidden": (512, 256, 128), "critic_hidden": (512, 256, 128)},
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gait", default="trot")
    parser.add_argument("--minutes", type=float, default=4.0)
    parser.add_argument("--variants", default=",".join(VARIANTS), help="comma-separated variant names")
    args = parser.parse_args()
    base = get_preset("cpu")
    rows = []
    for name in args.variants.split(","):
        preset = dataclasses.replace(base, **VARIANTS[name])
        with tempfile.TemporaryDirectory() as tmp:
            result = train_gait(
                TrainRequest(
                    description=get_gait(args.gait),
                    preset=preset,
                    iterations=10**6,
                    time_limit_s=60.0 * args.minutes,
                    library=Path(tmp) / "library",
                    run_dir=Path(tmp) / "run",
                    backend="mujoco",
                    eval_episodes=64,
                )
            )
            meta = json.loads((result.entry / "metadata.json").read_text())
        last = meta["training"]["curve"]["rows"][-5:]
        row = {
            "variant": name,
            "iterations": result.iterations,
            "samples": result.samples,
            "samples_per_s": round(result.samples / result.wall_clock_s),
            "mean_reward_last": round(sum(r[2] for r in last) / len(last), 3),
            "fall_rate": round(result.evaluation.fall_rate, 3),
            "joint_rmse": round(result.evaluation.joint_rmse, 4),
            "speed_error": round(result.evaluation.speed_error, 3),
        }
        rows.append(row)
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
