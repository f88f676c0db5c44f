"""Measure the timings of ``docs/benchmarks.md`` whose tables are generated, and store each command's JSON output as
their evidence.

    python -m benchmarks.record_timings                          # every measurement, one after the other
    python -m benchmarks.record_timings --only sim-throughput    # one table's measurements (or one measurement's name)
    python -m benchmarks.record_timings --missing                # those not stored yet (resumes a run cut short)
    python -m benchmarks.results                                 # then rewrite the tables from what is stored

Each measurement (:data:`benchmarks.results.speeds.MEASURES`) runs the command the page documents, from the
repository's root, and is written atomically as ``docs/results/timings/NAME.json`` (``command``, ``made``: today's
date, ``result``: the command's JSON output) once it has finished; one that fails leaves what was stored before and
the others still run (exit status 1). Run it with nothing else on the cores: every table is a ratio against a
reference measured in the same run, but the figures beside the ratios are the machine's. About 15 minutes in all:
the four ``sim`` commands 6-8 min (Newton's first build on a machine compiles Warp's kernels), ``collect`` 4-5 min
(the collection runs whole chunks), the transition writes 4 min, the backend memory and the entry loads a minute each.
"""

from __future__ import annotations

import argparse
import datetime
import json
import shlex
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from benchmarks.results.evidence import ROOT, shown
from benchmarks.results.speeds import BLOCKS, MEASURES, TIMINGS, evidence_path
from gaitlib.atomic import write_json

__all__ = ["argv_of", "main", "parse_output", "record", "selected"]


def argv_of(command: str) -> list[str]:
    """The process ``command`` (as the page writes it) starts: ``gaitlib`` and ``python`` through this interpreter."""
    tokens = shlex.split(command)
    head = {"gaitlib": [sys.executable, "-m", "gaitlib.cli"], "python": [sys.executable]}.get(tokens[0], tokens[:1])
    return [*head, *tokens[1:]]


def parse_output(stdout: str, *, lines: bool = False) -> object:
    """The JSON a command printed on stdout: the last JSON object, or with ``lines`` the list of every one (other
    lines, such as a library's banner, are left out); a ``ValueError`` when there is none."""
    found = []
    for line in stdout.splitlines():
        if line.lstrip().startswith("{"):
            try:
                found.append(json.loads(line))
            except json.JSONDecodeError:
                continue
    if not found:
        raise ValueError("the command printed no JSON object on stdout")
    return found if lines else found[-1]


def _run(argv: list[str]) -> str:
    return subprocess.run(argv, cwd=ROOT, stdout=subprocess.PIPE, text=True, check=True).stdout


def record(name: str, *, folder: Path = TIMINGS, run: Callable[[list[str]], str] = _run,
           made: datetime.date | None = None) -> Path:
    """Run the measurement ``name`` (``run`` takes the process's arguments and returns its stdout) and store its
    evidence under ``folder``, made ``made`` (default: today); the path written."""
    measure = MEASURES[name]
    result = parse_output(run(argv_of(measure.command)), lines=measure.lines)
    return write_json(evidence_path(name, folder), {
        "command": measure.command, "made": (made or datetime.date.today()).isoformat(), "result": result})


def selected(only: Sequence[str] | None, *, missing: bool = False, folder: Path = TIMINGS) -> list[str]:
    """The measurements to run, in :data:`MEASURES` order: those ``only`` names (a measurement's name or a table's
    block), all by default; with ``missing``, only those not stored under ``folder``."""
    unknown = sorted(set(only or ()) - set(MEASURES) - set(BLOCKS))
    if unknown:
        raise ValueError(f"no measurement or table {', '.join(unknown)} (measurements: {', '.join(MEASURES)}; "
                         f"tables: {', '.join(BLOCKS)})")
    names = [n for n, m in MEASURES.items() if not only or n in only or m.block in only]
    return [n for n in names if not (missing and evidence_path(n, folder).is_file())]


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.record_timings", description=__doc__.splitlines()[0])
    parser.add_argument("--only", action="append", metavar="NAME",
                        help=f"a table ({', '.join(BLOCKS)}) or one measurement (repeatable; default: all)")
    parser.add_argument("--missing", action="store_true", help="only the measurements not stored yet")
    parser.add_argument("--out", type=Path, default=TIMINGS, help="where the evidence goes (docs/results/timings)")
    parser.add_argument("--list", action="store_true", help="print the measurements and their commands, run nothing")
    args = parser.parse_args(argv)
    try:
        names = selected(args.only, missing=args.missing, folder=args.out)
    except ValueError as error:
        parser.error(str(error))
    if args.list:
        for name in names:
            print(f"{name}: {MEASURES[name].command}")
        return 0
    failed = []
    for name in names:
        print(f"{name}: {MEASURES[name].command}", file=sys.stderr, flush=True)
        start = time.perf_counter()
        try:
            path = record(name, folder=args.out)
        except (subprocess.CalledProcessError, ValueError, OSError) as error:
            print(f"{name}: failed ({error}); nothing stored", file=sys.stderr, flush=True)
            failed.append(name)
            continue
        print(f"{name}: {shown(path)} in {time.perf_counter() - start:.0f} s", file=sys.stderr, flush=True)
    if failed:
        print(f"failed: {', '.join(failed)} (rerun them with --only)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
