"""One row of the robust recipe's ablation: every figure a variant of a gait is judged by, with 95% intervals, one
JSON file. Falls are counted the field's way (the default definition), leg touches beside every fall figure.

    python benchmarks/robust_ablation.py --library library --gait pace --states data/states-0n.npz \
        --sources trot,stand --out docs/results/ablation/pace-today.json

The states are those the variants were trained from (``gaitlib states``: each source gait's robots recorded as a
switch would hand them over). Each figure is the command's own evaluation, nothing tuned to a variant:

- single shove: ``gaitlib eval GAIT --impulses 0:30:6 --episodes 1024`` (one 0.1 s push at a random phase and
  direction per episode, falls per impulse and per direction);
- pushes while walking: ``gaitlib eval GAIT --push-max 50 --episodes 1024 --seconds 20``;
- falls and touches at 0 N with the trained delay (Table 1's random 0-1 control steps, or the fixed delay of a
  variant trained with ``--action-delay K``), and one step late (``--late 1``), 1,024 x 20 s each;
- switches into the gait at random moments from each source gait's states, 1,000 each (2.5 s horizon);
- speed and median heading change against the quality bar (from the 0 N run), training minutes (the entry's
  metadata).
"""

from __future__ import annotations

import argparse
import time
from datetime import UTC, datetime
from pathlib import Path

from gaitlib.atomic import write_json
from gaitlib.defaults import BAR_HEADING_DEG, BAR_SPEED
from gaitlib.envs import EnvConfig
from gaitlib.envs.handover import load_states
from gaitlib.evaluation import evaluate_policy, single_push_curve, switch_in
from gaitlib.library import Library
from gaitlib.values import IMPULSE_NS, parse_values

__all__ = ["ablation_row"]


def ablation_row(library: Library, gait: str, *, states: Path, sources: list[str], impulses: list[float],
                 episodes: int, switches: int, seconds: float, backend: str, seed: int) -> dict:
    """Every figure of one variant (see the module doc), as one JSON-able dict with the time each part took."""
    entry = library.entry(gait)
    env_cfg = library.shared_policy_settings([gait]).env_config(EnvConfig())
    timings, row = {}, {}

    def timed(name, make):
        start = time.perf_counter()
        row[name] = make()
        timings[name] = round(time.perf_counter() - start, 1)

    common = {"env_cfg": env_cfg, "backend": backend, "seed": seed}
    training = entry.metadata.get("training", {})
    recipe = training.get("recipe")
    trained_delay = recipe.get("action_delay") if isinstance(recipe, dict) else None  # None: Table 1's random 0-1
    timed("single_shove", lambda: [p.as_dict() for p in single_push_curve(
        entry.policy, entry.clip, impulses=impulses, episodes=episodes, **common)])
    # pushes while walking under Table 1's delay, as every other figure; 0 N and one step late from the trained delay
    for name, push, late, delay in (("push_50n", 50.0, 0, None), ("zero_n", 0.0, 0, trained_delay),
                                    ("one_step_late", 0.0, 1, trained_delay)):
        timed(name, lambda push=push, late=late, delay=delay: evaluate_policy(
            entry.policy, entry.clip, episodes=episodes, seconds=seconds, push_max=push, late_steps=late,
            action_delay_steps=delay, **common).as_dict())
    recorded, sha256 = load_states(states)
    for source in sources:
        timed(f"switch_in_from_{source}", lambda source=source: switch_in(
            entry.policy, entry.clip, states=recorded, source=source, episodes=switches, **common).as_dict())
    zero = row["zero_n"]
    row["quality_bar"] = {
        "speed_error": zero["speed_error"],
        "speed_within_10_percent": zero["speed_error"] <= BAR_SPEED,
        "median_heading_change_deg": zero["median_heading_change_deg"],
        "heading_within_15_deg": zero["median_heading_change_deg"] <= BAR_HEADING_DEG,
    }
    return {
        "gait": gait,
        "library": str(library.root),
        "identity": entry.identity,
        "recipe": training.get("recipe", "today's (recorded before the recipe's levers existed)"),
        "training_minutes": None if training.get("wall_clock_s") is None else round(training["wall_clock_s"] / 60, 1),
        "iterations": training.get("iterations"),
        "states": {"path": str(states), "sha256": sha256},
        "settings": {"episodes": episodes, "switches": switches, "seconds": seconds, "impulses_ns": impulses,
                     "backend": backend, "seed": seed, "falls": "trunk"},
        "made": datetime.now(UTC).isoformat(timespec="seconds"),
        "seconds_per_part": timings,
        "figures": row,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--library", type=Path, default=None, help="library folder (default: the shipped one)")
    parser.add_argument("--gait", required=True)
    parser.add_argument("--states", type=Path, required=True, help="handover states (gaitlib states --out)")
    parser.add_argument("--sources", default="trot,stand", help="the two gaits to switch in from")
    parser.add_argument("--impulses", default="0:30:6", help="single-shove impulses, N s")
    parser.add_argument("--episodes", type=int, default=1024)
    parser.add_argument("--switches", type=int, default=1000)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--backend", default="mujoco")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    impulses = parse_values(args.impulses, option="--impulses", bounds=IMPULSE_NS, example="0:30:6")
    row = ablation_row(Library(args.library), args.gait, states=args.states, sources=args.sources.split(","),
                       impulses=impulses, episodes=args.episodes, switches=args.switches, seconds=args.seconds,
                       backend=args.backend, seed=args.seed)
    write_json(args.out, {"command": "python benchmarks/robust_ablation.py " + " ".join(
        f"--{k.replace('_', '-')} {v}" for k, v in vars(args).items() if v is not None), "result": row}, indent=1)
    print(args.out)


if __name__ == "__main__":
    main()
