"""The catch skill's tables: the catch alone at the guard's moment from every gait (``docs/results/catch/alone.json``,
``python -m benchmarks.catch_alone``), and each entry's single-shove falls unguarded, guarded with the gaits of the
library before it (``shove-IMPULSE-GAIT-grown.json``) and guarded with the catch skill (``-catch.json``), on the
same draws."""

from __future__ import annotations

from pathlib import Path

from benchmarks.results.evidence import ROOT, interval, not_yet, pct, read_evidence, shown
from benchmarks.results.guard import GOALS, GUARD, _gaits, _worst
from gaitlib.stats import wilson_interval

__all__ = ["ALONE_GOALS", "CATCH", "catch_alone", "guard_with_catch"]

CATCH = ROOT / "docs" / "results" / "catch"
"""The catch skill's stored evaluations."""
ALONE_GOALS = {12.0: 0.01, 18.0: 0.10}
"""Impulse (N s) -> the share of episodes the catch alone may let fall, started at the guard's moment."""


def _rate(falls: int, episodes: int, goal: float | None = None) -> str:
    low, high = wilson_interval(falls, episodes)
    figure = f"{pct(falls / episodes)}% {interval(low, high)}"
    return f"**{figure}**" if goal is not None and falls <= goal * episodes else figure


def catch_alone(folder: Path = CATCH) -> str:
    """Per gait and impulse: falls staying and caught into the catch skill at the guard's moment, the same draws."""
    path = Path(folder) / "alone.json"
    evidence = read_evidence(path)
    if evidence is None:
        return not_yet(path)
    result = evidence["result"]
    impulses = sorted({r["impulse_ns"] for r in result["rows"]})
    by = {(r["gait"], r["impulse_ns"]): r for r in result["rows"]}
    gaits = list(dict.fromkeys(r["gait"] for r in result["rows"]))
    lines = ["| gait | " + " | ".join(f"{i:g} N s: stay | {i:g} N s: catch" for i in impulses) + " |",
             "|---|" + "---|---|" * len(impulses)]
    missed = {i: [] for i in impulses}
    for gait in gaits:
        cells = []
        for i in impulses:
            row = by.get((gait, i))
            if row is None:
                cells += ["-", "-"]
                continue
            goal = ALONE_GOALS.get(i)
            cells += [_rate(row["stay"]["falls"], row["stay"]["episodes"]),
                      _rate(row["catch"]["falls"], row["catch"]["episodes"], goal)]
            if goal is not None and row["catch"]["falls"] > goal * row["catch"]["episodes"]:
                missed[i].append(f"{gait} by {pct(row['catch']['fall_rate'] - goal)} points")
        lines.append(f"| {gait} | " + " | ".join(cells) + " |")
    episodes = result["episodes"]
    verdicts = [f"at {i:g} N s {pct(1 - ALONE_GOALS[i])}% stay up: "
                + ("met by every gait" if not missed[i] else "missed by " + ", ".join(missed[i]))
                for i in impulses if i in ALONE_GOALS]
    return "\n".join([*lines, "",
                      f"Falls (% of {episodes:,} episodes a cell, 95% Wilson intervals) after one shove of 0.1 s in "
                      "a uniform direction at a random moment of the gait's cycle: left alone (stay), or switched "
                      f"into `{result['catch']}` {result['delay_steps']} control steps after the shove starts and "
                      "kept there (catch), on the same draws; seeds that took part in no training or choice. Bold "
                      "where within the goal; " + "; ".join(verdicts) + f". Evidence: `{shown(path)}` (made "
                      f"{evidence['made']}): `{evidence['command']}`."])


def _verdict(point: dict, goal: float) -> str:
    """The goal pooled and in every direction of shove: met, or by how many points the pooled rate and the worst
    direction's miss it."""
    name, (falls, episodes) = max(point["by_sector"].items(), key=lambda item: item[1][0] / item[1][1])
    over, worst = point["falls"] / point["episodes"] - goal, falls / episodes - goal
    if over > 0:
        return f"missed by {pct(over)} points; {name} by {pct(worst)}"
    return "met in every direction" if worst <= 0 else f"met pooled; {name} missed by {pct(worst)} points"


def guard_with_catch(folder: Path = GUARD) -> str:
    """Per entry and impulse: falls unguarded, guarded with the library's gaits before the catch skill, guarded
    with it, the same draws (the unguarded rollouts of both files agree, or the row says they do not)."""
    rows, episodes = [], set()
    for impulse in (12, 18):
        goal = GOALS[float(impulse)]
        for gait in _gaits(folder, f"shove-{impulse}-{{gait}}-catch.json"):
            now = read_evidence(Path(folder) / f"shove-{impulse}-{gait}-catch.json")["result"]
            before = read_evidence(Path(folder) / f"shove-{impulse}-{gait}-grown.json")
            off, on = now["unguarded_points"][0], now["points"][0]
            episodes.add(on["episodes"])
            if before is None:
                today = "- (not in the library before)"
            else:
                point = before["result"]["points"][0]
                same = before["result"]["unguarded_points"][0]["by_sector"] == off["by_sector"]
                today = _rate(point["falls"], point["episodes"], goal) + ("" if same else " (other draws)")
            into = sum(c["to"] == "catch" for c in on["guard"]["catches"])
            verdict = _verdict(on, goal)
            rows.append(f"| {gait} | {impulse} N s | {_rate(off['falls'], off['episodes'])} | {today} | "
                        f"{_rate(on['falls'], on['episodes'], goal)} | {_worst(on)} | {len(on['guard']['catches'])} "
                        f"({into}; {on['guard']['false_catches']}) | {verdict} |")
    if not rows:
        return not_yet(Path(folder) / "shove-12-GAIT-catch.json")
    return "\n".join([
        "| entry | shove | unguarded | guarded, the gaits before | guarded, with the catch skill | worst direction, "
        "with the catch skill | catches (into the catch skill; false) | goal: pooled, each direction |",
        "|---|---|---|---|---|---|---|---|", *rows, "",
        f"Falls (% of {', '.join(f'{n:,}' for n in sorted(episodes))} episodes a row, 95% Wilson intervals) after one "
        "shove of 0.1 s in a random direction (a direction: the quarter the shove points to, about 128 episodes), "
        "the same draws in every column (seed 0): unguarded; guarded by the "
        "thirteen entries' guard (`shove-IMPULSE-GAIT-grown.json`); guarded by the guard of the library with the "
        "catch skill (`shove-IMPULSE-GAIT-catch.json`). Bold where within the goal (at most 1% at 12 N s, 10% at "
        f"18 N s). Evidence: `{shown(Path(folder))}/`, each file with its command."])
