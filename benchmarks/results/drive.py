"""The drive's table over seeds (``docs/driving.md``): each example input driven over 100 seeds by
``benchmarks/drive_seeds.py``, whether the robot stayed up, whether every waypoint was reached within the goal, the
end error, the drive's length, its switches and its wall time, and the goal met or missed."""

from __future__ import annotations

import math
import statistics
from pathlib import Path

from benchmarks.drive_seeds import STAY_UP
from benchmarks.results.evidence import ROOT, cite, not_yet, read_evidence

__all__ = ["DRIVE", "INPUTS", "RUNS", "drive_paths", "drive_table"]

DRIVE = ROOT / "docs" / "results" / "drive"
"""The stored drives over seeds, one file an input and a strategy (``readme-slalom.json`` beside them is one drive)."""
INPUTS = ("square", "slalom", "figure")
"""The example inputs (``examples/drive/``), in the table's order within each strategy."""
RUNS = ("net-lookahead", "net-lookahead-unguarded", "random")
"""The strategies and guards measured, by the files' name after the input, in the table's order."""


def drive_paths(folder: Path = DRIVE) -> list[Path]:
    """The stored drives' files in the table's order: every strategy's inputs, one strategy after another."""
    return [Path(folder) / f"{name}-{run}.json" for run in RUNS for name in INPUTS]


def _need(seeds: int) -> int:
    """The fewest of ``seeds`` the robot must stay up on for the goal."""
    return math.ceil(STAY_UP * seeds - 1e-9)


def _row(result: dict) -> tuple[list[str], str | None]:
    """One drive's cells, and why it misses the goal (``None`` when it meets it)."""
    runs, goal_m = result["runs"], result["goal_m"]
    seeds = len(runs)
    up = [r for r in runs if r["stayed_up"]]
    waypoints = all("within_goal_all" in r for r in runs)
    name = Path(result["input"]).name
    cells = [f"`{name}`" if waypoints else f"`{name}` (commands)",
             f"{result['strategy']}, {'guarded' if result['guard_why_off'] is None else 'unguarded'}",
             f"{len(up)} of {seeds}"]
    misses = []
    need = _need(seeds)
    if len(up) < need:
        misses.append(f"up {len(up)} of {seeds}, {need - len(up)} short of {need}")
    if waypoints:
        closest = [c for r in runs for c in r["closest_m"] if c is not None]
        unaimed = sum(any(c is None for c in r["closest_m"]) for r in runs)
        worst = f"{max(closest):.3f} m" if closest else "-"
        if unaimed:
            worst += f"; a waypoint never approached on {unaimed} seeds"
        ends = [r["end_error_m"] for r in runs]
        cells += [f"{sum(r['within_goal_all'] for r in runs)} of {seeds}", worst,
                  f"{statistics.median(ends):.3f} m ({max(ends):.3f} m)"]
        beyond = [r for r in up if not r["within_goal_all"]]
        if beyond:
            far = [c for r in beyond for c in r["closest_m"] if c is not None and c > goal_m]
            over = f", the farthest {max(far):.3f} m ({max(far) - goal_m:.3f} m over)" if far else ""
            misses.append(f"{len(beyond)} of the seeds up with a waypoint beyond {goal_m:g} m{over}")
    else:
        cells += ["-", "-", "-"]
    durations, switches = [r["duration_s"] for r in runs], [r["switches"] for r in runs]
    cells += [f"{statistics.median(durations):.1f} s ({max(durations):.1f} s)",
              f"{statistics.median(switches):g} ({max(switches)})",
              f"{statistics.mean(r['wall_s'] for r in runs):.2f} s", f"{result['summary']['wall_s'] / 60:.1f} min"]
    return cells, ", and ".join(misses) or None


def drive_table(folder: Path = DRIVE) -> str:
    """Each stored drive over seeds a row (stayed up; for waypoints every one within the goal, the worst closest
    approach, the end error's median and max; the drive's length and switches, median and max; the wall time a drive
    and of all seeds), the goal met or missed by how much, and the evidence."""
    paths = drive_paths(folder)
    stored = [read_evidence(path) for path in paths]
    if all(evidence is None for evidence in stored):
        return not_yet(*paths)
    found = [(path, evidence) for path, evidence in zip(paths, stored, strict=True) if evidence is not None]
    counts = {len(e["result"]["runs"]) for _, e in found}
    goals = {e["result"]["goal_m"] for _, e in found}
    n = counts.pop() if len(counts) == 1 else None
    seeds, up = (f"{n} seeds", f"{_need(n)} of {n} seeds") if n else ("all seeds", f"{STAY_UP:.0%} of the seeds")
    within = f"{goals.pop():g} m" if len(goals) == 1 else "the goal"
    lines = [f"| input | strategy, guard | stayed up | every waypoint within {within} | closest approach, worst | "
             f"end error, median (max) | drive, median (max) | switches, median (max) | wall per drive | {seeds} |",
             "|---" * 10 + "|"]
    missed, absent = [], []
    for path, evidence in zip(paths, stored, strict=True):
        if evidence is None:
            name, run = path.stem.split("-", 1)
            lines.append(f"| `{name}.csv` | {run} | not measured | | | | | | | |")
            absent.append(path)
            continue
        cells, miss = _row(evidence["result"])
        lines.append("| " + " | ".join(cells) + " |")
        if miss:
            missed.append(f"{cells[0]} {cells[1]}: {miss}")
    measured = len(found)
    first = min(r["seed"] for _, e in found for r in e["result"]["runs"])
    last = max(r["seed"] for _, e in found for r in e["result"]["runs"])
    verdict = (f"met by all {measured} drives" if not missed else
               f"met by {measured - len(missed)} of {measured} drives, missed by " + "; by ".join(missed))
    libraries = sorted({e["result"]["library"] for _, e in found})
    text = [
        f"Seeds {first} to {last}, each exactly `gaitlib drive ... --seed k`, with the library "
        f"{', '.join(f'`{lib}`' for lib in libraries)}. The closest approach is each waypoint's, the end error the "
        "distance from the last position to the last waypoint (waypoints alone: a command timeline has no goal "
        "position), the drive the simulated time to the last waypoint, the timeline's end or the fall; the wall "
        "per drive is the mean over the seeds, the last column the whole run's.",
        f"The goal, up on at least {up} and every waypoint within "
        f"{within} on the seeds up: {verdict}."
        + (" Not measured: " + ", ".join(f"`{p.name}`" for p in absent) + "." if absent else ""),
        "Evidence: " + "; ".join(cite(path, evidence) for path, evidence in found) + ".",
    ]
    return "\n".join(lines) + "\n\n" + "\n\n".join(text)
