"""The switch-success budget's table: ``net-lookahead``'s success on the hardest pairs against the samples its models
were fitted on a pair, ``random`` beside it (``benchmarks/switch_success_curve.py``), and the budget it sets."""

from __future__ import annotations

from pathlib import Path

from benchmarks.results.evidence import ROOT, arrow, cite, interval, not_yet, pct, read_evidence
from gaitlib.stats import wilson_interval

__all__ = ["BUDGET", "SCREEN", "budget_per_pair", "budget_table", "screen_table"]

BUDGET = ROOT / "docs" / "results" / "budget" / "success-curve.json"
"""The stored curve."""
SCREEN = ROOT / "docs" / "results" / "budget" / "screen-steer-0n.json"
"""The stored random screen of the steering skills' new pairs."""


def _success(row: dict) -> tuple[int, int]:
    """(successes, trials) of a row, pooled over its pairs."""
    return row["trials"] - row["falls"], row["trials"]


def budget_per_pair(result: dict) -> int:
    """The budget the curve sets, collected samples a pair over every file: the smallest whose pooled success lies
    within the 95% interval of the largest budget's (``net-lookahead`` rows)."""
    fitted = [row for row in result["rows"] if row["strategy"] != "random"]
    low, _ = wilson_interval(*_success(fitted[-1]))
    return next(int(row["row"]) for row in fitted if _success(row)[0] / _success(row)[1] >= low)


def budget_table(path: Path = BUDGET) -> str:
    """Success per pair and pooled, each row's falls with its 95% interval, and (at 0 N) the budget the curve sets."""
    evidence = read_evidence(Path(path))
    if evidence is None:
        return not_yet(Path(path))
    result = evidence["result"]
    pairs = result["pairs"]
    lines = ["| models | " + " | ".join(arrow(p) for p in pairs) + " | falls | falls, % [95% interval] |",
             "|---" * (len(pairs) + 3) + "|"]
    for row in result["rows"]:
        name = "random moment" if row["strategy"] == "random" else f"{int(row['row']):,} a pair"
        cells = [row["cells"][p] for p in pairs]
        rates = " | ".join(pct(c["successes"] / c["samples"]) for c in cells)
        low, high = row["falls_ci95"]
        lines.append(f"| {name} | {rates} | {row['falls']:,} of {row['trials']:,} | "
                     f"{pct(row['falls'] / row['trials'])} {interval(low, high)} |")
    files = len(result["files"])
    magnitude = result["rows"][0]["magnitude_n"]
    how = (f"Success, %, of `net-lookahead` at {magnitude:g} N, {result['samples']:,} trials a pair on benchmark seed "
           f"{result['seed']} (no collection's), every row on the same draws. Each row's models were fitted on the "
           f"first samples of each pair of {files} collection{'s' if files > 1 else ''} (`gaitlib fit --per-pair`, "
           "nested subsets).")
    if magnitude == 0:
        budget = budget_per_pair(result)
        how += (" The budget a new pair gets, the smallest whose pooled success lies within the largest's 95% "
                f"interval: **{budget:,} samples a pair** ({budget // files:,} a collection).")
    return "\n".join([*lines, "", f"{how} Evidence: {cite(Path(path), evidence)}."])


def screen_table(path: Path = SCREEN, *, most: int = 10) -> str:
    """A short random screen of a growth's new pairs: how many pairs fell at all, the pooled falls, and the ``most``
    pairs that fell most."""
    evidence = read_evidence(Path(path))
    if evidence is None:
        return not_yet(Path(path))
    (group,) = evidence["result"]["groups"].values()
    cells = group["cells"]
    trials = sum(c["samples"] for c in cells.values())
    falls = trials - sum(c["successes"] for c in cells.values())
    fell = sorted((p for p, c in cells.items() if c["successes"] < c["samples"]),
                  key=lambda p: (cells[p]["successes"] / cells[p]["samples"], p))
    per_pair = {c["samples"] for c in cells.values()}
    lines = ["| pair | falls | success, % [95% interval] |", "|---|---|---|"]
    for pair in fell[:most]:
        won, n = cells[pair]["successes"], cells[pair]["samples"]
        lines.append(f"| {arrow(pair)} | {n - won} of {n} | {pct(won / n)} {interval(*wilson_interval(won, n))} |")
    low, high = wilson_interval(falls, trials)
    return "\n".join([
        *lines, "",
        f"A random moment at 0 N, {'/'.join(map(str, sorted(per_pair)))} trials a pair on seed "
        f"{evidence['result']['settings']['seed']}: {len(cells) - len(fell)} of {len(cells)} pairs never fell; "
        f"{falls} falls in {trials:,} switches pooled, {pct(falls / trials)}% {interval(low, high)}. The "
        f"{min(most, len(fell))} of the {len(fell)} pairs that fell most are listed. Evidence: "
        f"{cite(Path(path), evidence)}.",
    ])

