"""The switching tables beyond 0 N: the shipped library's switches beside those of the library shipped before it
(``docs/results.md``), and where the shipped library's switches fail (``docs/switching_results.md``).
:mod:`benchmarks.results.doc` writes them into the pages with the others.

- ``switches``: every pair in both libraries, the switch-start library's evidence (``docs/results/switch-start/``)
  beside the shipped robust library's (``docs/results/library/``, the same files made with ``--library
  library-robust``, the folder's name before it shipped), in each setting of :data:`SWITCH_GOALS` the shipped library
  has stored, against the robust recipe's goal for it.
- ``map``: ``docs/results/library/map-0n.json`` (``gaitlib map``'s ``map.json`` on the shipped library's 0 N
  collection): each pair's success at a random moment, in its best and worst phase bin of the source and of the
  destination cycle, and its touches.

A table whose evidence is not stored yet says "not yet measured", one file missing of several says which.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

from benchmarks.results.evidence import (
    EVIDENCE,
    SWITCH_START,
    arrow,
    cite,
    groups_at,
    interval,
    libraries_line,
    not_yet,
    pct,
    pooled,
    pooled_success,
    reached,
    read_evidence,
    settings_line,
    success,
)

__all__ = ["SWITCH_GOALS", "SwitchGoal", "map_table", "switches_table"]


class SwitchGoal(NamedTuple):
    """A setting of ``switches`` and the robust recipe's goal in it."""

    name: str
    """The evidence file's name, without ``.json``."""
    strategy: str
    magnitude: float
    """Push magnitude, N."""
    goal: float
    """The success every pair should reach, a fraction."""
    title: str
    """The setting as the table names it."""


SWITCH_GOALS = (SwitchGoal("bench-0n", "random", 0.0, 0.97, "random, 0 N"),
                SwitchGoal("bench-0n", "net-lookahead", 0.0, 0.995, "net-lookahead, 0 N"),
                SwitchGoal("bench-50n", "net-lookahead", 50.0, 0.95, "net-lookahead, 50 N"),
                SwitchGoal("bench-menagerie-0n", "net-lookahead", 0.0, 0.97, "net-lookahead, Menagerie A1, 0 N"))
"""The settings of ``switches``, in the table's order."""


def _cells(name: str, evidence: dict, magnitude: float, strategy: str) -> dict[str, dict]:
    groups = groups_at(evidence["result"], magnitude)
    if strategy not in groups:
        raise ValueError(f"{name}.json holds no {strategy} group at {magnitude:g} N")
    return groups[strategy]


def _rate(cell: dict | None, goal: float) -> str:
    """A pair's success with its Wilson 95% interval, bold at ``goal`` or more; "-" unmeasured."""
    return "-" if cell is None else success(cell["successes"], cell["samples"], goal=goal)


def switches_table(switch_start_dir: Path = SWITCH_START, evidence_dir: Path = EVIDENCE) -> str:
    """``switches``: each pair's success in the switch-start library and in the shipped robust one, setting by setting
    of :data:`SWITCH_GOALS`, with the pooled rate, its touches, and the pairs at the goal in each."""
    folders = {"switch-start": Path(switch_start_dir), "robust": Path(evidence_dir)}
    names = dict.fromkeys(goal.name for goal in SWITCH_GOALS)
    paths = {(library, name): folder / f"{name}.json" for library, folder in folders.items() for name in names}
    stored = {key: read_evidence(path) for key, path in paths.items()}
    goals = [goal for goal in SWITCH_GOALS if stored["robust", goal.name] is not None]
    if not goals:
        return not_yet(*(paths["robust", name] for name in names))
    columns = [(goal, library, None if (e := stored[library, goal.name]) is None else
                _cells(goal.name, e, goal.magnitude, goal.strategy)) for goal in goals for library in folders]
    pairs = sorted({p for *_, cells in columns if cells for p in cells}, key=lambda p: p.split("-"))
    lines = ["| pair | " + " | ".join(f"{g.title}: {library} [95%]" for g, library, _ in columns) + " |",
             "|---|" + "---|" * len(columns)]
    lines += [f"| {arrow(p)} | " + " | ".join(_rate(cells.get(p) if cells else None, g.goal) for g, _, cells in columns)
              + " |" for p in pairs]
    lines.append("| all pairs (touches) | " + " | ".join(
        "-" if cells is None else pooled_success(pooled(cells.values())) for *_, cells in columns) + " |")
    lines.append("| pairs at the goal or more | " + " | ".join(
        "-" if cells is None else f"{reached(cells.values(), g.goal)} of {len(cells)}" for g, _, cells in columns)
                 + " |")
    notes = []
    for goal in goals:
        counts = [f"{library} {reached(cells.values(), goal.goal)} of {len(cells)}"
                  for g, library, cells in columns if g is goal and cells]
        runs = {library: settings_line(e["result"]["settings"]) for library in folders
                if (e := stored[library, goal.name])}
        notes.append(f"{goal.title} (goal {pct(goal.goal)}% on every pair): {', '.join(counts)}; "
                     f"{libraries_line(runs)}.")
    absent = [paths["robust", name] for name in names if stored["robust", name] is None]
    if absent:
        notes.append(not_yet(*absent))
    sources = [f"- {cite(paths[key], e)}" for key, e in stored.items()
               if e is not None and any(key[1] == goal.name for goal in goals)]
    return "\n".join([*lines, "", " ".join(notes), "", "Evidence:", "", *sources])


def _share(rate: dict) -> float:
    return rate["successes"] / rate["samples"]


def _bin(rate: dict) -> str:
    """One of a map's rates: success % with its interval and sample count."""
    if not rate["samples"]:
        return "-"
    return f"{pct(_share(rate))} {interval(*rate['ci95'])} of {rate['samples']:,}"


def map_table(evidence_dir: Path = EVIDENCE) -> str:
    """``map``: where the shipped library's switches fail, pair by pair, from its stored transition map."""
    path = Path(evidence_dir) / "map-0n.json"
    evidence = read_evidence(path)
    if evidence is None:
        return not_yet(path)
    result = evidence["result"]
    maps = sorted(result["pairs"], key=lambda m: m["pair"].split("-"))
    lines = ["| pair | random moment [95%] | best source bin | worst source bin | best destination bin "
             "| worst destination bin | touches |", "|---|---|---|---|---|---|---|"]
    for m in maps:
        source, dest = ([r for r in m[k] if r["samples"]] for k in ("by_source_phase", "by_dest_phase"))
        best_worst = [_bin(pick(rates, key=_share)) for rates in (source, dest) for pick in (max, min)]
        lines.append(f"| {arrow(m['pair'])} | {_bin(m['overall'])} | " + " | ".join(best_worst)
                     + f" | {pct(_share(m['touches']))}% |")
    bins = ", ".join(sorted({str(m["bins"]) for m in maps}))
    q99 = result.get("fall_after_s_q99")
    falls = sum(len(m["fall_after_s"]) for m in maps)
    note = (f"Success % of the collected switches, each at a moment and a destination phase drawn uniformly, "
            f"with 95% Wilson intervals and sample counts; a bin is 1/{bins} of the source's or of the destination's "
            f"cycle; falls by the `{result['falls']}` definition; touches: a non-foot body on the ground, ridden "
            f"through. {falls:,} switch-caused falls with a recorded time"
            + (f", 99% of them within {q99:.2f} s of the switch." if q99 is not None else "."))
    return "\n".join([*lines, "", note, "", f"Evidence: {cite(path, evidence)}"])
