"""The growth of the shipped library by the steering skills: what each stage cost (``growth-stages``) and how the new
pairs switch on the grown library (``growth-pairs``), from the stored record ``docs/results/growth/growth.json`` and
the benchmarks beside it."""

from __future__ import annotations

from pathlib import Path

from benchmarks.results.evidence import ROOT, arrow, interval, not_yet, pct, read_evidence, shown
from gaitlib.stats import wilson_interval

__all__ = ["GROWTH", "GROWTH_GOAL_MIN", "growth_pairs", "growth_stages"]

GROWTH = ROOT / "docs" / "results" / "growth"
"""The stored record of the growth and its benchmarks."""
GROWTH_GOAL_MIN = 90
"""The growth's goal: all of it within this much compute on the 2-core machine, min."""


def _duration(seconds: float) -> str:
    minutes, rest = divmod(round(seconds), 60)
    return f"{minutes} min {rest:02d} s" if minutes else f"{rest} s"


def growth_stages(folder: Path = GROWTH) -> str:
    """Each stage of the growth: its command, the samples or episodes it made, its wall-clock time, and the total
    against the goal."""
    path = Path(folder) / "growth.json"
    evidence = read_evidence(path)
    if evidence is None:
        return not_yet(path)
    result = evidence["result"]
    lines = ["| stage | command | made | time |", "|---|---|---|---|"]
    for stage in result["stages"]:
        lines.append(f"| {stage['stage']} | `{stage['command']}` | {stage['made']} | {_duration(stage['seconds'])} |")
    total = result["compute_s"]  # the stages' times as a union: stages that ran side by side count once
    met = "met" if total <= 60 * GROWTH_GOAL_MIN else f"missed by {_duration(total - 60 * GROWTH_GOAL_MIN)}"
    lines.append(f"| **all** | | | **{_duration(total)}** (goal {GROWTH_GOAL_MIN} min: {met}) |")
    screen = result["screen"]
    return "\n".join([*lines, "", (
        f"Wall-clock time of each command on this 2-core machine; all: the time any of them ran ({result['cores']}). "
        "The screen "
        f"switched each of the {screen['pairs']} new pairs at a random moment about {screen['per_pair']} times: "
        f"{screen['fell']} pairs fell at least once ({screen['falls']:,} falls in {screen['switches']:,} switches), "
        f"and only these were collected at the budget. Evidence: `{shown(path)}` (made {evidence['made']})."
    )])


BENCHES = ("bench-fitted-0n.json", "bench-screened-0n.json")
"""The new pairs' benchmarks at 0 N: the pairs fitted at the budget, and the pairs that never fell in the screen."""


def growth_pairs(folder: Path = GROWTH, *, worst: int = 8) -> str:
    """The new pairs on the grown library at 0 N: pooled success of each strategy benchmarked, by the pairs fitted
    at the budget and the pairs that never fell in the screen (a benchmark each), and the pairs ``net-lookahead``
    fails most."""
    paths = [Path(folder) / name for name in BENCHES]
    stored = [read_evidence(path) for path in paths]
    record = read_evidence(Path(folder) / "growth.json")
    if record is None or any(evidence is None for evidence in stored):
        return not_yet(*(path for path, evidence in zip(paths, stored, strict=True) if evidence is None))
    fitted = set(record["result"]["screen"]["fitted_pairs"])
    groups: dict[str, dict] = {}
    for evidence in stored:
        for group in evidence["result"]["groups"].values():
            groups.setdefault(group["strategy"], {}).update(group["cells"])
    lines = ["| strategy | pairs fitted at the budget | pairs that never fell in the screen |", "|---|---|---|"]
    for name, cells in groups.items():
        row = []
        for chosen in (fitted, set(cells) - fitted):
            won = sum(cells[p]["successes"] for p in chosen if p in cells)
            n = sum(cells[p]["samples"] for p in chosen if p in cells)
            row.append(f"{pct(won / n)} {interval(*wilson_interval(won, n))} ({n - won:,} falls of {n:,})" if n
                       else "not measured")
        lines.append(f"| `{name}` | " + " | ".join(row) + " |")
    cells = groups["net-lookahead"]
    low = sorted(cells, key=lambda p: (cells[p]["successes"] / cells[p]["samples"], p))[:worst]
    lines += ["", "| pair | falls | success, % [95% interval] |", "|---|---|---|"]
    for pair in low:
        won, n = cells[pair]["successes"], cells[pair]["samples"]
        lines.append(f"| {arrow(pair)} | {n - won} of {n} | {pct(won / n)} {interval(*wilson_interval(won, n))} |")
    trials = ", ".join(f"{e['result']['settings']['samples']:,} trials a pair in `{shown(p)}` (made {e['made']}): "
                       f"`{e['command']}`" for p, e in zip(paths, stored, strict=True))
    return "\n".join([*lines, "", (
        f"Success, % [95% interval], at 0 N on benchmark seed {stored[0]['result']['settings']['seed']}, the "
        f"strategies of one benchmark on the same draws; below, the {worst} new pairs `net-lookahead` fails most. "
        f"Evidence: {trials}."
    )])
