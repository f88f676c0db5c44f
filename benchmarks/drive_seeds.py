"""One drive over many seeds: whether the robot stays up, and for waypoints whether each is reached (within the
reach radius, :data:`gaitlib.meta.steering.REACH_M`) and the end error, seed by seed, into one evidence file.

    python -m benchmarks.drive_seeds --waypoints examples/drive/slalom.csv --seeds 100 --out runs/slalom-seeds.json
    python -m benchmarks.drive_seeds --commands examples/drive/figure.csv --seeds 100 --strategy random --no-guard \\
        --out runs/figure-seeds.json --jobs 2

Seeds 0 to N - 1, each exactly ``gaitlib drive ... --seed k`` (one robot, its own randomization and strategy seed),
run one after the other in each of ``--jobs`` processes (one torch thread each). The goal: the robot stays up on at
least 99 of 100 seeds, and every waypoint is reached (closest approach within 0.25 m). The file is evidence as the
results pages read it (``python -m benchmarks.results``, the table ``drive-seeds`` of ``docs/driving.md``):
``command``, this one with the arguments given; ``made``, the day; and ``result``: the library and its switching
models' checksum, the strategy and the guard; per seed its outcome (a fall, each waypoint's arrival and closest
approach, the end error, the switches, those forced by the deadline and the longest wait, catches, touches) and its
wall time; and the totals.
"""

from __future__ import annotations

import argparse
import datetime
import os
import shlex
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from gaitlib.atomic import write_json

GOAL_M = 0.25
"""A waypoint counts for the goal when the robot came within this of it, m."""
STAY_UP = 0.99
"""The goal's share of seeds on which the robot stays up."""

_SETUP: dict = {}
"""This process's loaded library and options (one load per process)."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--library", type=Path, default=None)
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--waypoints", type=Path)
    source.add_argument("--commands", type=Path)
    parser.add_argument("--seeds", type=int, default=100)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--strategy", default="net-lookahead")
    parser.add_argument("--guard", action=argparse.BooleanOptionalAction, default=True)
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    options = {"library": args.library, "waypoints": args.waypoints, "commands": args.commands,
               "strategy": args.strategy, "guard": args.guard}
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    start = time.perf_counter()
    if args.jobs > 1:
        with ProcessPoolExecutor(args.jobs, initializer=_load, initargs=(options,)) as pool:
            rows = list(pool.map(_drive, seeds))
    else:
        _load(options)
        rows = [_drive(seed) for seed in seeds]
    wall = time.perf_counter() - start
    why_off = {row.pop("guard_why_off") for row in rows}.pop()
    up = [r for r in rows if r["stayed_up"]]
    summary = {
        "seeds": len(rows),
        "stayed_up": len(up),
        "wall_s": wall,
        "drive_wall_s_mean": sum(r["wall_s"] for r in rows) / len(rows),
        "drive_s_mean": sum(r["duration_s"] for r in rows) / len(rows),
        "jobs": args.jobs,
    }
    if args.waypoints is not None:
        summary |= {
            "reached_all": sum(r["reached_all"] for r in rows),
            "within_goal_all": sum(r["within_goal_all"] for r in rows),
            "end_error_m_max": max(r["end_error_m"] for r in rows),
            "goal_met": len(up) >= STAY_UP * len(rows) and all(r["within_goal_all"] for r in up),
        }
    else:
        summary["goal_met"] = len(up) >= STAY_UP * len(rows)
    result = {"library": str(args.library or "library"), "switching_checksum": _switching_checksum(args.library),
              "input": str(args.waypoints or args.commands), "strategy": args.strategy, "guard": args.guard,
              "guard_why_off": why_off, "goal_m": GOAL_M, "summary": summary, "runs": rows}
    write_json(args.out, {"command": _command(), "made": datetime.date.today().isoformat(), "result": result})
    print(f"{args.out}: {summary}")


def _command() -> str:
    """This run's command line as the evidence names it: ``python -m benchmarks.drive_seeds`` and its arguments."""
    return shlex.join(["python", "-m", "benchmarks.drive_seeds", *sys.argv[1:]])


def _switching_checksum(library: Path | None) -> str | None:
    """The checksum of the library's switching models and survival estimate (``switching/checksums.json``), which
    names the models the drives ran with; ``None`` without one."""
    import json

    from gaitlib.library.layout import default_library_dir

    path = (library or default_library_dir()) / "switching" / "checksums.json"
    return json.loads(path.read_text()).get("checksum") if path.is_file() else None


def _load(options: dict) -> None:
    """Load the library and the input once in this process (a worker's initializer)."""
    import torch

    from gaitlib.cli.guarding import choose_guard
    from gaitlib.meta import load_switching
    from gaitlib.meta.commands import read_commands, read_waypoints

    torch.set_num_threads(1)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    setup = load_switching(options["library"])
    guard, why_off = choose_guard(setup, on=options["guard"], margin=None, quiet=True)
    points = None if options["waypoints"] is None else read_waypoints(options["waypoints"])
    commands = None if options["commands"] is None else read_commands(options["commands"])
    _SETUP.update(setup=setup, guard=guard, why_off=why_off, points=points, commands=commands,
                  strategy=options["strategy"])


def _drive(seed: int) -> dict:
    """One seed's drive, as a JSON-ready row."""
    from gaitlib.meta.drive import drive, drive_waypoints

    s = _SETUP
    start = time.perf_counter()
    options = {"strategy": s["strategy"], "backend": "mujoco", "seed": seed, "guard": s["guard"]}
    result = (drive(s["setup"], s["commands"], **options) if s["points"] is None
              else drive_waypoints(s["setup"], s["points"], **options))
    trace = result.trace
    row = {"seed": seed, "stayed_up": trace.stayed_up, "fell_s": trace.fell_s, "duration_s": float(result.pose[-1, 0]),
           "switches": len(trace.switches), "forced": sum(e.forced for e in trace.switches),
           "wait_s_max": max((e.wait_s for e in trace.switches), default=0.0), "catches": len(trace.catches),
           "touches": trace.touches,
           "end_error_m": result.end_error_m, "wall_s": time.perf_counter() - start,
           "guard_why_off": s["why_off"]}
    if result.waypoints is not None:
        outcome = result.waypoints
        row |= {"reached_all": outcome.reached_all, "reached_s": outcome.reached_s, "closest_m": outcome.closest_m,
                "within_goal_all": all(c is not None and c <= GOAL_M for c in outcome.closest_m)}
    return row


if __name__ == "__main__":
    main()
