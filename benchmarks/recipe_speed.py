"""How much training time does each robustness lever cost? The same gait, preset, states and seed, trained for the
same number of iterations with today's recipe and with each variant, one after the other (never side by side: they
would share the cores); prints each run's samples per second and its ratio against today's recipe, measured in the
same run. Results go into docs/benchmarks.md.

    python benchmarks/recipe_speed.py --gait pace --states data/states-0n.npz --iterations 60

The first iterations are not the whole run's mix (episodes are short then, so worlds reset more often): the ratio,
not the absolute rate, is what carries over to a full run.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from dataclasses import replace
from pathlib import Path

from gaitlib.defaults import SWITCH_START, Falls
from gaitlib.gaits import get_gait
from gaitlib.training import get_preset
from gaitlib.training.recipe import PAPER_RECIPE, Recipe
from gaitlib.training.trainer import TrainRequest, train_gait

VARIANTS = {
    "today": PAPER_RECIPE,
    "kick": replace(PAPER_RECIPE, push_kind="kick", kick_max=1.0, kick_draw="disk", kick_interval=(1.0, 3.0)),
    "trunk": replace(PAPER_RECIPE, falls=Falls.TRUNK, contact_penalty=1.0),
    "gamma": replace(PAPER_RECIPE, gamma=0.99, lam=0.95),
    "critic-delay": replace(PAPER_RECIPE, critic_delay=True),
    "robust": Recipe(),
}
"""The ablation's recipes as measured (docs/training.md, "The recipe's levers"), each today's recipe (the paper's)
with one lever changed, and the one it chose (``robust``, the shipped library's); ``today`` the reference."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gait", default="pace")
    parser.add_argument("--states", type=Path, default=None, help="handover states (gaitlib states --out)")
    parser.add_argument("--iterations", type=int, default=60)
    parser.add_argument("--variants", default="today,kick,trunk", help="comma-separated; today's recipe first")
    args = parser.parse_args()
    names = args.variants.split(",")
    if names[0] != "today" or any(n not in VARIANTS for n in names):
        parser.error(f"--variants: names from {', '.join(VARIANTS)}, today first")
    preset = get_preset("cpu")
    rates = {}
    for name in names:
        recipe = VARIANTS[name]
        with tempfile.TemporaryDirectory() as tmp:
            result = train_gait(TrainRequest(
                description=get_gait(args.gait), preset=recipe.preset(preset), iterations=args.iterations,
                library=Path(tmp) / "library", run_dir=Path(tmp) / "run", states=args.states,
                switch_start=SWITCH_START if args.states else 0.0, recipe=recipe, backend="mujoco", seed=0,
                eval_episodes=1, eval_seconds=1.0,
            ))
        rates[name] = result.samples / result.wall_clock_s
        print(json.dumps({"recipe": name, "iterations": result.iterations, "samples": result.samples,
                          "seconds": round(result.wall_clock_s, 1), "samples_per_s": round(rates[name]),
                          "time_vs_today": round(rates["today"] / rates[name], 3)}), flush=True)


if __name__ == "__main__":
    main()
