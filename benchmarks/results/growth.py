"""The growth of the shipped library by the steering skills: what each stage cost (``growth-stages``) and how the new
pairs switch on the grown library (``growth-pairs``), from the stored record ``docs/results/growth/growth.json`` and
the benchmarks beside it."""

from __future__ import annotations

from pathlib import Path

from benchmarks.results.evidence import ROOT, arrow, interval, not_yet, pct, read_evidence, shown
from gaitlib.stats import wilson_interval

__all__ = ["BENCHES", "GROWTH", "GROWTH_GOAL_MIN", "POOLED", "growth_pairs", "growth_pooled", "growth_stages"]

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
    at the budget and the pairs that never fell in the screen (each group from its own benchmark: :data:`BENCHES`),
    and the pairs ``net-lookahead`` fails most."""
    paths = [Path(folder) / name for name in BENCHES]
    stored = [read_evidence(path) for path in paths]
    record = read_evidence(Path(folder) / "growth.json")
    if record is None or any(evidence is None for evidence in stored):
        return not_yet(*(path for path, evidence in zip(paths, stored, strict=True) if evidence is None))
    fitted = set(record["result"]["screen"]["fitted_pairs"])
    groups: dict[str, dict] = {}  # the fitted pairs from the first benchmark, the others from the second
    for evidence, keep in zip(stored, (lambda p: p in fitted, lambda p: p not in fitted), strict=True):
        for group in evidence["result"]["groups"].values():
            groups.setdefault(group["strategy"], {}).update({p: c for p, c in group["cells"].items() if keep(p)})
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


POOLED = (("bench-all-50n.json", "the paper's random pushes of up to 50 N", 0.95),
          ("bench-menagerie-0n.json", "MuJoCo Menagerie's A1 at 0 N", 0.99))
"""The grown library's every pair, pooled: the stored benchmark, what it measures, and the goal (a pooled share)."""


def growth_pooled(folder: Path = GROWTH) -> str:
    """``net-lookahead`` over every pair of the grown library under the paper's pushes and on another A1: pooled
    success of the seven first entries' 42 pairs, the 114 new ones and all, against each goal."""
    paths = [Path(folder) / name for name, _, _ in POOLED]
    stored = [read_evidence(path) for path in paths]
    record = read_evidence(Path(folder) / "growth.json")
    if record is None or all(evidence is None for evidence in stored):
        return not_yet(*paths)
    counts = record["result"]["screen"]["counts"]
    gaits = {gait for pair in counts for gait in pair.split("-")}
    steering = {g for g in gaits if all(f"{g}-{other}" in counts for other in gaits - {g})}  # every pair of it new
    lines = ["| where | the seven entries' 42 pairs | the 114 new pairs | all pairs | goal |", "|---|---|---|---|---|"]
    cited = []
    for (_, what, goal), path, evidence in zip(POOLED, paths, stored, strict=True):
        if evidence is None:
            lines.append(f"| {what} | not measured | | | {goal:.0%} pooled |")
            continue
        (group,) = (g for g in evidence["result"]["groups"].values() if g["strategy"] == "net-lookahead")
        cells = group["cells"]
        row = []
        for chosen in ([p for p in cells if not set(p.split("-")) & steering],
                       [p for p in cells if set(p.split("-")) & steering], list(cells)):
            won, n = sum(cells[p]["successes"] for p in chosen), sum(cells[p]["samples"] for p in chosen)
            row.append(f"{pct(won / n)} {interval(*wilson_interval(won, n))} ({n - won:,} falls of {n:,})")
        won, n = sum(c["successes"] for c in cells.values()), sum(c["samples"] for c in cells.values())
        verdict = "met" if won >= goal * n else f"missed by {pct(goal - won / n)} points"
        lines.append(f"| {what} | " + " | ".join(row) + f" | {goal:.0%} pooled: {verdict} |")
        cited.append(f"`{shown(path)}` (made {evidence['made']}): `{evidence['command']}`")
    per_pair = sorted({e["result"]["settings"]["samples"] for e in stored if e is not None})
    return "\n".join([*lines, "", (
        f"Success, % [95% interval], of `net-lookahead`, {'-'.join(map(str, per_pair))} trials a pair on benchmark "
        "seed 1, pooled. Evidence: " + "; ".join(cited) + "."
    )])
