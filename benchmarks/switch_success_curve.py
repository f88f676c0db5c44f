"""Switch success against the samples collected per ordered pair: the budget a new pair needs.

For each budget N, a copy of the library gets switching models fitted on the first N samples of each pair of each
collection (``gaitlib fit --per-pair N``: nested subsets, as shorter collections with the same seeds would hold
them), and ``gaitlib benchmark`` measures ``net-lookahead`` on the collected pairs alone; ``random`` is measured
beside it on the same draws (one seed for every row, one no collection used). Every step is the command a user
types, run in turn and resumed where it stopped (each fit is published whole; each benchmark resumes itself).
Writes one evidence file (``command``, ``made``, ``result``: the commands, every cell's counts and each row's
falls with a 95% interval), which ``python -m benchmarks.results`` tables in ``docs/transitions.md``.

    python benchmarks/switch_success_curve.py --data data/curve-0n.h5 --data data/curve-150n.h5 \\
        --pairs trot-walk,trot-pace --budgets 250,750,2000,3334 --samples 500 --seed 1 \\
        --work runs/curve --out docs/results/budget/success-curve.json

A budget is per file: with two collections (one unpushed, one pushed, as the shipped models are fitted), 250 a file
is 500 samples a pair.
"""

from __future__ import annotations

import argparse
import datetime
import json
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

from gaitlib.atomic import write_json
from gaitlib.stats import wilson_interval


def _run(command: list[str]) -> None:
    """``command``, its output passed through; stops the script when it fails."""
    subprocess.run(command, check=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, action="append", required=True, help="collection (repeatable)")
    parser.add_argument("--library", type=Path, default=Path("library"), help="the library the data were collected on")
    parser.add_argument("--pairs", required=True, help="the collected pairs, comma-separated")
    parser.add_argument("--budgets", default="250,750,2000,3334", help="samples a pair a file, comma-separated")
    parser.add_argument("--samples", type=int, default=500, help="benchmark trials a pair")
    parser.add_argument("--magnitudes", default="0", help="push magnitudes, N (gaitlib benchmark --magnitudes)")
    parser.add_argument("--seed", type=int, default=1, help="benchmark seed (no collection's)")
    parser.add_argument("--work", type=Path, default=Path("runs/curve"), help="libraries and benchmarks go here")
    parser.add_argument("--out", type=Path, required=True, help="the curve, JSON")
    args = parser.parse_args()
    budgets = [int(b) for b in args.budgets.split(",")]
    bench = ["gaitlib", "benchmark", "--pairs", args.pairs, "--magnitudes", args.magnitudes, "--samples",
             str(args.samples), "--seed", str(args.seed), "--backend", "mujoco", "--json"]
    rows, commands = [], []

    def measure(name: str, library: Path, strategy: str, made: list[str] | None) -> None:
        out = args.work / f"bench-{name}-{args.magnitudes.replace(',', '_')}n"
        command = [*bench, "--library", str(library), "--strategies", strategy, "--out", str(out)]
        _run(command)
        commands.extend(shlex.join(c) for c in ([made] if made else []) + [command])
        for group in json.loads((out / "results.json").read_text())["groups"].values():
            cells = {pair: {"samples": c["samples"], "successes": c["successes"]} for pair, c in group["cells"].items()}
            trials = sum(c["samples"] for c in cells.values())
            falls = trials - sum(c["successes"] for c in cells.values())
            rows.append({"row": name, "strategy": strategy, "magnitude_n": group["magnitude_n"], "falls": falls,
                         "trials": trials, "falls_ci95": list(wilson_interval(falls, trials)), "cells": cells,
                         "benchmark_s": group["elapsed_s"]})

    measure("random", args.library, "random", None)
    for budget in budgets:
        library = args.work / f"lib-{budget}"
        fit = ["gaitlib", "fit", "--library", str(library), "--per-pair", str(budget)]
        for path in args.data:
            fit += ["--data", str(path)]
        marker = library / "switching" / "fitted-per-pair"
        if not (marker.is_file() and marker.read_text() == str(budget)):
            shutil.rmtree(library, ignore_errors=True)
            shutil.copytree(args.library, library)
            _run(fit)
            marker.write_text(str(budget))
        measure(f"{budget * len(args.data)}", library, "net-lookahead", fit)
    invocation = shlex.join(["python", "benchmarks/switch_success_curve.py", *sys.argv[1:]])
    result = {"pairs": args.pairs.split(","), "budgets_per_file": budgets, "files": [str(p) for p in args.data],
              "samples": args.samples, "seed": args.seed, "commands": commands, "rows": rows}
    write_json(args.out, {"command": invocation, "made": datetime.date.today().isoformat(), "result": result})
    for row in rows:
        low, high = row["falls_ci95"]
        print(f"{row['row']:>8} {row['strategy']:>14} {row['magnitude_n']:>5} N: {row['falls']} falls of "
              f"{row['trials']} [{100 * low:.2f}, {100 * high:.2f}]%")


if __name__ == "__main__":
    main()
