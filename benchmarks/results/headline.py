"""The tables of each gait against the quality bar (``quality-bar``) and the transition-net's accuracy beside the
paper's Table 3 (``net-accuracy``) in docs/results.md, and of every pair at 0 N (``pairs-0n``), the routes of both
libraries (``routes``, ``routes-switch-start``) and the switch-start library's net (``net-accuracy-switch-start``) in
docs/switching_results.md.

Each is made from the evidence in ``docs/results/library/`` (``eval-GAIT.json``, ``bench-0n.json``,
``bench-direct.json``, ``bench-routed.json``, ``routes.json``; the switch-start library's of the same names in
``docs/results/switch-start/``) and each library's own ``switching/accuracy.json``. A table whose evidence is not
stored yet says "not yet measured".
"""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import Sequence
from pathlib import Path

from benchmarks.results.evidence import (
    BAR_FALLS,
    EVIDENCE,
    GAITS,
    ROOT,
    arrow,
    cite,
    groups_at,
    interval,
    not_yet,
    pct,
    pooled,
    reached,
    read_evidence,
    settings_line,
    shown,
    speed_heading_misses,
    success,
)
from benchmarks.results.switches import SWITCH_GOALS
from gaitlib.strategies.fitting import PAPER_PAIRS

__all__ = [
    "ACCURACY", "CURVE", "GOAL", "INPUTS", "ROBUST_GOAL", "SWITCH_START_ACCURACY", "accuracy_table", "curve_table",
    "pairs_table", "quality_bar", "routes_table",
]

ACCURACY = ROOT / "library" / "switching" / "accuracy.json"
"""The shipped transition-net's accuracy report (paper Table 3's measure), written by ``gaitlib fit``."""
SWITCH_START_ACCURACY = ROOT / "library-switch-start" / "switching" / "accuracy.json"
"""The accuracy report of the transition-net of the library shipped before (switch-start)."""
CURVE = EVIDENCE / "curve-150n-200k.json"
"""The transition-net's learning curve on the shipped library's pushed collection (``gaitlib fit --curve``)."""
GOAL = 0.99
"""The success a switch is counted against (the switch-start library's routes)."""
ROBUST_GOAL = next(g.goal for g in SWITCH_GOALS if (g.name, g.strategy) == ("bench-0n", "net-lookahead"))
"""The robust recipe's goal for a switch at 0 N with ``net-lookahead``, which the shipped library's routes are counted
against."""
INPUTS = ("latent", "explicit", "phase")
"""The transition-net's input kinds, in the order of the paper's claim (latent >= explicit > phase)."""


def _speed(value: float) -> str:
    return f"{abs(value) if round(value, 2) == 0 else value:.2f}"


def _gait_order(name: str) -> tuple[int, str]:
    return (GAITS.index(name) if name in GAITS else len(GAITS), name)


def _misses(r: dict) -> list[str]:
    """What of the quality bar an evaluation misses, from its numbers."""
    misses = [f"falls {pct(r['fall_rate'])}% over {pct(BAR_FALLS)}%"] if r["fall_rate"] > BAR_FALLS else []
    return misses + [f"{bar}: {why}" for bar, why in speed_heading_misses(r).items()]


def _quality_row(r: dict) -> str:
    episodes = r["episodes"]
    falls, touches = round(r["fall_rate"] * episodes), round(r["touch_rate"] * episodes)
    still = abs(r["reference_speed"]) < 1e-6  # the evaluation's speed error is then the drift in m/s
    error = f"{r['speed_error']:.3f} m/s drift" if still else f"{pct(r['speed_error'])}%"
    misses = _misses(r)
    return (f"| {r['gait']} | {pct(r['fall_rate'])}% ({falls} of {episodes}) {interval(*r['fall_ci95'])} "
            f"| {pct(r['touch_rate'])}% ({touches}) {interval(*r['touch_ci95'])} | {r['longest_touch_s']:.2f} s "
            f"| {_speed(r['forward_speed'])} ({_speed(r['reference_speed'])}) | {error} "
            f"| {r['median_heading_change_deg']:.1f} deg | {'no: ' + '; '.join(misses) if misses else 'yes'} |")


def _eval_sources(found: dict[str, tuple[Path, dict]]) -> str:
    """The evaluations' evidence: one line when the commands differ only in the gait, else one per file."""
    templates = {e["command"].replace(f"eval {g} ", "eval GAIT ") for g, (_, e) in found.items()}
    dates = {e["made"] for _, e in found.values()}
    if len(templates) == 1 and len(dates) == 1:
        folder = shown(next(iter(found.values()))[0].parent)
        return (f"Evidence: `{folder}/eval-GAIT.json` for GAIT in {', '.join(found)} (made {dates.pop()}), each the "
                f"output of `{templates.pop()}`.")
    return "Evidence:\n\n" + "\n".join(f"- {cite(p, e)}" for p, e in found.values())


def quality_bar(evidence_dir: Path = EVIDENCE) -> str:
    """Table (a): each gait's evaluation against the quality bar, from ``eval-GAIT.json``."""
    paths = sorted(Path(evidence_dir).glob("eval-*.json"), key=lambda p: _gait_order(p.stem.removeprefix("eval-")))
    found = {p.stem.removeprefix("eval-"): (p, read_evidence(p)) for p in paths}
    if not found:
        return not_yet(Path(evidence_dir) / "eval-GAIT.json")
    results = [e["result"] for _, e in found.values()]
    lines = ["| gait | falls [95%] | leg touches [95%] | longest touch | speed (reference), m/s | speed error "
             "| median heading change | meets the bar |", "|---|---|---|---|---|---|---|---|"]
    lines += [_quality_row(r) for r in results]
    runs = sorted({f"{r['episodes']} episodes of {r['seconds']:g} s" for r in results})
    definitions = sorted({r["falls"] for r in results})
    meeting = [r["gait"] for r in results if not _misses(r)]
    missing = [g for g in GAITS if g not in found]
    lines += ["", f"{' / '.join(runs)} a gait, no pushes; falls by the `{'` / `'.join(definitions)}` definition. "
              f"{len(meeting)} of {len(results)} gaits meet the bar."]
    lines += [f"The {r['gait']} misses it: {'; '.join(_misses(r))}." for r in results if _misses(r)]
    if missing:
        lines.append(f"Not yet measured: {', '.join(missing)}.")
    return "\n".join([*lines, "", _eval_sources(found)])


def pairs_table(evidence_dir: Path = EVIDENCE) -> str:
    """Table (b): every ordered pair at 0 N, each strategy's success with its interval and its touches."""
    path = Path(evidence_dir) / "bench-0n.json"
    evidence = read_evidence(path)
    if evidence is None:
        return not_yet(path)
    groups = groups_at(evidence["result"], 0.0)
    pairs = sorted({p for cells in groups.values() for p in cells}, key=lambda p: p.split("-"))
    lines = ["| pair | " + " | ".join(f"{s} [95%] | {s} touches" for s in groups) + " |",
             "|---|" + "---|---|" * len(groups)]
    for pair in pairs:
        cells = [groups[s].get(pair) for s in groups]
        lines.append(f"| {arrow(pair)} | " + " | ".join(
            f"{success(c['successes'], c['samples'], goal=GOAL)} | {pct(c['touched'] / c['samples'])}%"
            if c else "- | -" for c in cells) + " |")
    totals = [pooled(cells.values()) for cells in groups.values()]
    lines.append(f"| all {len(pairs)} pairs | " + " | ".join(f"{pct(s / n)} | {pct(t / n)}%" for s, n, t in totals)
                 + " |")
    at_goal = [reached(cells.values(), GOAL) for cells in groups.values()]
    counts = [f"{k} of {len(cells)} | " for k, cells in zip(at_goal, groups.values(), strict=True)]
    lines.append(f"| pairs at {pct(GOAL)}% or more | " + " | ".join(counts) + " |")
    summary = ", ".join(f"`{s}` {k} of {len(c)}" for (s, c), k in zip(groups.items(), at_goal, strict=True))
    return "\n".join([*lines, "", f"Pairs at {pct(GOAL)}% or more: {summary}. "
                      f"{settings_line(evidence['result']['settings'])}; a touch: a non-foot body on the ground from "
                      "the request to the verdict, ridden through.", "", f"Evidence: {cite(path, evidence)}"])


def _route(pair: str, routed: dict, table: dict | None) -> list[str]:
    """The gaits a routed transition of ``pair`` went through: the routed benchmark's own, else the table's."""
    route = routed["result"]["settings"].get("routes", {}).get(pair)
    if route is None and table is not None:
        route = table["result"].get("detours", {}).get(pair)
    return list(route) if route else []


def _predicted(route: list[str], table: dict | None) -> str:
    """The product of the route's legs' rates in the route table, %."""
    rates = table["result"].get("rates", {}) if table is not None else {}
    legs = [f"{a}-{b}" for a, b in itertools.pairwise(route)]
    if not legs or any(leg not in rates for leg in legs):
        return "-"
    product = 1.0
    for leg in legs:
        successes, samples = rates[leg]
        product *= successes / samples
    return pct(product)


def routes_table(evidence_dir: Path = EVIDENCE, *, goal: float = GOAL) -> str:
    """Table (c): the detour pairs switched directly and routed (the same strategy, seed and pairs), each counted
    against ``goal``."""
    paths = {name: Path(evidence_dir) / f"{name}.json" for name in ("bench-direct", "bench-routed", "routes")}
    found = {name: read_evidence(p) for name, p in paths.items()}
    direct, routed, table = found["bench-direct"], found["bench-routed"], found["routes"]
    if direct is None or routed is None:
        return not_yet(*(paths[n] for n in ("bench-direct", "bench-routed") if found[n] is None))
    common = sorted(direct["result"]["groups"].keys() & routed["result"]["groups"].keys())
    if not common:
        raise ValueError(f"{shown(paths['bench-direct'])} and {shown(paths['bench-routed'])} share no group")
    key = common[0]
    cells, routed_cells = direct["result"]["groups"][key]["cells"], routed["result"]["groups"][key]["cells"]
    pairs = sorted(cells.keys() & routed_cells.keys(), key=lambda p: p.split("-"))
    table_rates = table["result"].get("rates", {}) if table is not None else {}
    lines = ["| pair | through | route table: direct | route table: predicted | direct [95%] | routed [95%] |",
             "|---|---|---|---|---|---|"]
    for pair in pairs:
        route = _route(pair, routed, table)
        through = ", ".join(route[1:-1]) or "-"
        rate = pct(table_rates[pair][0] / table_rates[pair][1]) if pair in table_rates else "-"
        d, r = cells[pair], routed_cells[pair]
        lines.append(f"| {arrow(pair)} | {through} | {rate} | {_predicted(route, table)} "
                     f"| {success(d['successes'], d['samples'], goal=goal)} "
                     f"| {success(r['successes'], r['samples'], goal=goal)} |")
    at_goal = [reached((c[p] for p in pairs), goal) for c in (cells, routed_cells)]
    lines.append(f"| at {pct(goal)}% or more | | | | {at_goal[0]} of {len(pairs)} | {at_goal[1]} of {len(pairs)} |")
    strategy, magnitude = key.split("@")
    notes = [f"Routed, {at_goal[1]} of {len(pairs)} pairs reach {pct(goal)}%; directly, {at_goal[0]}. Both "
             f"benchmarks: `{strategy}` at {magnitude} N, {settings_line(routed['result']['settings'])}."]
    if table is not None:
        measured = table["result"].get("measured_with", {})
        notes.append(f"The route table's rates, and its predictions (the product of the legs' rates): "
                     f"`{table['result'].get('strategy', '?')}`, {measured.get('samples', 0):,} transitions a pair, "
                     f"seed {measured.get('seed', '?')}, falls by the `{measured.get('falls', '?')}` definition.")
    sources = [f"- {cite(paths[n], found[n])}" for n in ("bench-direct", "bench-routed", "routes") if found[n]]
    return "\n".join([*lines, "", " ".join(notes), "", "Evidence:", "", *sources])


def _mean(values: Sequence[float | None]) -> float | None:
    known = [v for v in values if v is not None]
    return sum(known) / len(known) if known else None


def _cell(value: float | None) -> str:
    return "-" if value is None else pct(value)


def accuracy_table(path: Path = ACCURACY) -> str:
    """Table (d): the transition-net's balanced validation accuracy per input, beside the paper's Table 3."""
    path = Path(path)
    if not path.is_file():
        return not_yet(path)
    report = json.loads(path.read_text(encoding="utf-8"))
    ours, paper = report["balanced_validation_accuracy"], report.get("paper_table_3", {})
    kinds = [k for k in INPUTS if k in ours] + [k for k in ours if k not in INPUTS]
    header = " | ".join(arrow(p) for p in PAPER_PAIRS)
    lines = [f"| input | {header} | mean of these six | mean of all pairs |", "|---|" + "---|" * 8]
    means = {}
    for kind in kinds:
        row = [ours[kind].get(p) for p in PAPER_PAIRS]
        means[kind], known = _mean(list(ours[kind].values())), sum(v is not None for v in ours[kind].values())
        lines.append(f"| **{kind}** | " + " | ".join(_cell(v) for v in row)
                     + f" | {_cell(_mean(row))} | {_cell(means[kind])} ({known} pairs) |")
        if kind in paper:
            row = [paper[kind].get(p) for p in PAPER_PAIRS]
            lines.append(f"| {kind}, paper | " + " | ".join(_cell(v) for v in row) + f" | {_cell(_mean(row))} | - |")
    claims = []
    for better, worse, sign in (("latent", "explicit", ">="), ("explicit", "phase", ">")):
        if means.get(better) is not None and means.get(worse) is not None:
            holds = means[better] >= means[worse] if sign == ">=" else means[better] > means[worse]
            claims.append(f"{better} {sign} {worse} {'holds' if holds else 'does not hold'} "
                          f"({pct(means[better])} against {pct(means[worse])})")
    falls = report.get("falls")
    labels = (f"labels by the `{falls}` definition" if falls else
              "labels by the `contact` definition (the fit predates the choice of definition)")
    command = "gaitlib fit " + ("" if path.resolve() == ACCURACY else f"--library {shown(path.parent.parent)} ")
    command += " ".join(f"--data {d}" for d in report.get("data", []))
    command += " --ablation" if set(INPUTS) <= set(ours) else f" --input {report.get('input_written', 'latent')}"
    command += f" --falls {falls}" if falls else ""
    notes = [f"Means over all pairs, the paper's order: {'; '.join(claims)}." if claims else "",
             f"`{report.get('input_written', '?')}` is the input the library's net uses; {report.get('samples', 0):,} "
             f"samples, {labels}."]
    return "\n".join([*lines, "", " ".join(n for n in notes if n), "",
                      f"Evidence: `{shown(path)}`, written by `{command}` (the data and inputs the file records)."])


def curve_table(path: Path = CURVE) -> str:
    """The transition-net's held-out accuracy against the samples collected a pair (``gaitlib fit --curve``), with
    what each step up the curve gained per doubling of the collection."""
    evidence = read_evidence(Path(path))
    if evidence is None:
        return not_yet(Path(path))
    result = evidence["result"]
    lines = ["| collected a pair | balanced samples trained on, all pairs | mean held-out accuracy | gain a doubling "
             "| lowest pair | highest pair |", "|---|---|---|---|---|---|"]
    before = None
    for point in result["points"]:
        n, acc, pairs = point["samples_per_pair"], point["mean_accuracy"], point["accuracy"]
        low, high = min(pairs, key=pairs.get), max(pairs, key=pairs.get)
        gain = "-" if before is None else f"{100 * (acc - before[1]) / math.log2(n / before[0]):+.1f} points"
        lines.append(f"| {n:,} | {point['trained_on']:,} | {pct(acc)}% | {gain} | {pct(pairs[low])}% ({low}) "
                     f"| {pct(pairs[high])}% ({high}) |")
        before = (n, acc)
    return "\n".join([*lines, "", f"The `{result['input']}` net, {result['epochs']} epochs, seed {result['seed']}, "
                      f"a fifth of each pair held out; evidence: {cite(Path(path), evidence)}."])
