"""The catch skill alone, started at the guard's moment from every gait: each gait of a library shoved once (the
single shove of ``gaitlib eval GAIT --impulses``: one impulse, a uniform direction, a random moment of the cycle) and,
on the same draws, left alone (staying) or switched into the catch skill a fixed number of control steps after the
shove starts (:func:`gaitlib.benchmark.catches.timed_catch_falls`, as the catch table measures a catch), kept to the
episode's end. One evidence file (``command``, ``made``, ``result``): per gait and impulse, the falls each way with
95% Wilson intervals and by the direction of the shove.

    python -m benchmarks.catch_alone --library runs/LIB14 --impulses 12,18 --episodes 1024 --seed 7 \
        --out docs/results/catch/alone.json

The library needs its switching models over the catch skill's pairs and a survival estimate (the timed catch reads
the guard's offer of the catch skill at its best destination phase). Use a seed that took part in no training or
choice: the catch table draws from seeds 1000 and up, the survival recording from 0.
"""

from __future__ import annotations

import argparse
import datetime
import shlex
import sys
from pathlib import Path

from gaitlib.atomic import write_json
from gaitlib.benchmark.catches import timed_catch_falls
from gaitlib.evaluation import SECTORS, SinglePush
from gaitlib.meta import load_switching
from gaitlib.stats import wilson_interval


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--library", type=Path, default=None)
    parser.add_argument("--catch", default="catch", help="the catch skill's entry")
    parser.add_argument("--gaits", default=None, help="comma-separated (default: every other entry)")
    parser.add_argument("--impulses", default="12,18", help="N s")
    parser.add_argument("--episodes", type=int, default=1024)
    parser.add_argument("--delay", type=int, default=2, help="control steps from the shove's start to the catch")
    parser.add_argument("--seed", type=int, default=7, help="gait g's draws at impulse k: seed + 100 k + g")
    parser.add_argument("--backend", default="mujoco")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    setup = load_switching(args.library)
    guard = setup.guard()
    catch = setup.gait_index(args.catch)
    names = args.gaits.split(",") if args.gaits else [g for g in setup.gaits if g != args.catch]
    impulses = [float(v) for v in args.impulses.split(",")]
    rows = []
    for k, impulse in enumerate(impulses):
        for name in names:
            g = setup.gait_index(name)
            sizes = {"impulse_ns": impulse, "episodes": args.episodes, "delay_steps": args.delay,
                     "seed": args.seed + 100 * k + g, "backend": args.backend}
            stay, _ = timed_catch_falls(setup, guard, g, -1, **sizes)
            caught, catching = timed_catch_falls(setup, guard, g, catch, **sizes)
            row = {"gait": name, "impulse_ns": impulse, "seed": sizes["seed"]}
            for label, fell in (("stay", stay), ("catch", caught)):
                falls = int(fell.sum())
                row[label] = {"falls": falls, "episodes": len(fell), "fall_rate": falls / len(fell),
                              "ci95": list(wilson_interval(falls, len(fell))),
                              "by_sector": {s: [int(fell[catching.shoved == i].sum()),
                                                int((catching.shoved == i).sum())] for i, s in enumerate(SECTORS)}}
            rows.append(row)
            print(f"{name} {impulse:g} N s: stay {row['stay']['falls']}, catch {row['catch']['falls']} of "
                  f"{args.episodes}", flush=True)
    result = {"library": str(args.library or "library"), "catch": args.catch, "delay_steps": args.delay,
              "episodes": args.episodes, "shove": {"duration_s": 0.1, "kind": SinglePush.__name__},
              "rows": rows}
    write_json(args.out, {"command": shlex.join(["python", "-m", "benchmarks.catch_alone", *sys.argv[1:]]),
                          "made": datetime.date.today().isoformat(), "result": result})
    print(args.out)


if __name__ == "__main__":
    main()
