"""The guard's tables: each gait with and without the guard on the same draws, under one shove and under the paper's
random pushes, from the evaluations stored in ``docs/results/guard`` (``gaitlib eval GAIT --impulses I --guard``:
``shove-I-GAIT-TAG.json``; ``gaitlib eval GAIT --push-max 50 --guard``: ``push50-GAIT-TAG.json``; ``--push-max 0
--seconds 60``: ``GAIT-0n-TAG.json``), one table pair a guard, named by the files' ``TAG``."""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

from benchmarks.results.evidence import (
    GAITS,
    ROOT,
    arrow,
    groups_at,
    interval,
    not_yet,
    pct,
    pooled,
    reached,
    read_evidence,
    shown,
    success,
)
from benchmarks.results.switches import SWITCH_GOALS
from gaitlib.stats import wilson_interval
from gaitlib.strategies.survival import FALSE_ALARMS_PER_MIN

__all__ = [
    "GOALS", "GUARD", "PAIR_TABLES", "PairTable", "guard_curve", "guard_pairs", "guard_pushes", "guard_shoves",
    "guard_summary",
]

GUARD = ROOT / "docs" / "results" / "guard"
"""The guard's stored evaluations."""
GOALS = {12.0: 0.01, 18.0: 0.10, 50.0: 0.01}
"""The guard's goals: the share of episodes a gait may fall in, guarded, after a shove of 12 and of 18 N s and under
random pushes of up to 50 N; a guarded figure within its goal is bold."""
class PairTable(NamedTuple):
    """The guard's pairs on one robot: its evidence files' prefix and the goals its table counts against."""

    prefix: str
    """The files are ``PREFIX-MAGNITUDEn-ARM-TAG.json``."""
    robot: str
    """The robot as the table names it."""
    pair_goals: dict[float, float]
    """Magnitude (N) -> the success every pair should reach, bold where it does."""
    pooled_goals: dict[float, float]
    """Magnitude (N) -> the pooled success the guard's goals ask for."""
    falls_per: int | None = None
    """Where given, the pooled goal at 0 N is read as falls in this many switches (the goal's own words)."""


def _goal(name: str, magnitude: float) -> float:
    return next(g.goal for g in SWITCH_GOALS if (g.name, g.strategy, g.magnitude) == (name, "net-lookahead", magnitude))


PAIR_TABLES = {
    "sim": PairTable("bench", "gaitlib's A1", {0.0: _goal("bench-0n", 0.0), 50.0: _goal("bench-50n", 50.0)},
                     {0.0: 1 - 15 / 30_000, 50.0: 0.97}, falls_per=30_000),
    "menagerie": PairTable("bench-menagerie", "MuJoCo Menagerie's A1", {0.0: _goal("bench-menagerie-0n", 0.0)},
                           {0.0: 0.99, 50.0: 0.95}),
}
"""The guard's pair tables: on gaitlib's A1, every pair at the recipe's goals (99.5% at 0 N, 95% at 50 N) and
pooled at most 15 falls in 30,000 switches at 0 N, 97% at 50 N; on Menagerie's A1, every pair at the recipe's goal
there (97% at 0 N) and pooled 99% at 0 N, 95% at 50 N."""


def _gaits(folder: Path, pattern: str) -> list[str]:
    """The gaits with a file ``pattern`` (``{gait}`` in it) in ``folder``: the shipped ones in :data:`GAITS`' order,
    then any other by name (a name with a hyphen is another tag's file: no gait's name has one)."""
    prefix, suffix = pattern.split("{gait}")
    found = {p.name[len(prefix):len(p.name) - len(suffix)] for p in Path(folder).glob(pattern.replace("{gait}", "*"))}
    found = {name for name in found if "-" not in name}
    return [g for g in GAITS if g in found] + sorted(found - set(GAITS))


def _falls(point: dict, goal: float | None = None) -> str:
    low, high = wilson_interval(point["falls"], point["episodes"])
    rate = point["falls"] / point["episodes"]
    figure = f"{point['falls']} ({pct(rate)}% {interval(low, high)})"
    return f"**{figure}**" if goal is not None and rate <= goal else figure


def _share(share: float) -> str:
    """The share of time the measured gait ran, %: to 0.1, or to 0.01 where that would read 100 short of it."""
    return "100%" if share >= 1.0 else f"{share:.2%}" if share >= 0.9995 else f"{share:.1%}"


def _worst(point: dict) -> str:
    sectors = {name: (falls, episodes) for name, (falls, episodes) in point["by_sector"].items() if falls}
    if not sectors:
        return "none"
    name, (falls, episodes) = max(sectors.items(), key=lambda item: item[1][0] / item[1][1])
    return f"{name}, {falls} of {episodes}"


def guard_shoves(tag: str, folder: Path = GUARD) -> str:
    """Each gait after one shove of each stored impulse, unguarded and guarded (``shove-IMPULSE-GAIT-TAG.json``)."""
    rows, cited = [], []
    for impulse in (12, 18):
        for gait in _gaits(folder, f"shove-{impulse}-{{gait}}-{tag}.json"):
            path = Path(folder) / f"shove-{impulse}-{gait}-{tag}.json"
            result = read_evidence(path)["result"]
            guarded, unguarded = result["points"][0], result["unguarded_points"][0]
            guard = guarded["guard"]
            catches = len(guard["catches"])
            delay = guard["delay_steps_median"]
            steps = "-" if not catches else f"{delay:g} step{'s' if delay != 1 else ''}"
            rows.append(f"| {gait} | {guarded['impulse_ns']:g} N s | {_falls(unguarded)} | "
                        f"{_falls(guarded, GOALS.get(guarded['impulse_ns']))} | {_worst(guarded)} | {catches} "
                        f"({guard['false_catches']}) | {steps} | {_share(guard['measured_gait_share'])} |")
            cited.append(path)
    if not rows:
        return not_yet(Path(folder) / f"shove-12-GAIT-{tag}.json")
    episodes = read_evidence(cited[0])["result"]["points"][0]["episodes"]
    return "\n".join([
        "| gait | shove | falls unguarded | falls guarded | worst direction, guarded | catches (false) | median delay "
        "| time in the gait |", "|---|---|---|---|---|---|---|---|", *rows, "",
        f"One shove of 0.1 s in a random direction, {episodes:,} episodes a row, the same draws both ways (seed 0); "
        "falls by the `trunk` definition with 95% Wilson intervals, bold where within the goal (at most 1% at 12 N s, "
        "10% at 18 N s). A catch before the shove is a false one; the delay counts control steps from the shove's "
        "start to the catch. Evidence: " + f"`{shown(Path(folder))}/shove-IMPULSE-GAIT-{tag}.json`, each with its "
        "command."])


def guard_curve(tag: str, folder: Path = GUARD) -> str:
    """Each gait's single-shove curve, unguarded and guarded: the share of episodes that fall after one shove of each
    stored impulse (``shove-IMPULSE-GAIT-TAG.json``)."""
    impulses = sorted({int(p.name.split("-")[1]) for p in Path(folder).glob(f"shove-*-*-{tag}.json")})
    if not impulses:
        return not_yet(Path(folder) / f"shove-12-GAIT-{tag}.json")
    gaits = list(dict.fromkeys(g for i in impulses for g in _gaits(folder, f"shove-{i}-{{gait}}-{tag}.json")))
    rows, episodes = [], set()
    for gait in gaits:
        cells = []
        for impulse in impulses:
            evidence = read_evidence(Path(folder) / f"shove-{impulse}-{gait}-{tag}.json")
            if evidence is None:
                cells.append("-")
                continue
            result = evidence["result"]
            guarded, unguarded = result["points"][0], result["unguarded_points"][0]
            episodes.add(guarded["episodes"])
            rate = guarded["falls"] / guarded["episodes"]
            goal = GOALS.get(float(impulse))
            figure = pct(rate)
            cells.append(f"{pct(unguarded['falls'] / unguarded['episodes'])} → "
                         f"{f'**{figure}**' if goal is not None and rate <= goal else figure}")
        rows.append(f"| {gait} | " + " | ".join(cells) + " |")
    return "\n".join([
        "| gait | " + " | ".join(f"{i} N s" for i in impulses) + " |", "|---|" + "---|" * len(impulses), *rows, "",
        "The share of episodes that fall (%), unguarded → guarded, after one shove of 0.1 s in a random direction, "
        f"{', '.join(f'{n:,}' for n in sorted(episodes))} episodes a point, the same draws both ways (seed 0); falls "
        "by the `trunk` definition; bold where within the goal (at most 1% at 12 N s, 10% at 18 N s). Unshoved, no "
        "entry falls either way (the unpushed rows below). Evidence: "
        f"`{shown(Path(folder))}/shove-IMPULSE-GAIT-{tag}.json`, each with its command."])


def guard_pushes(tag: str, folder: Path = GUARD) -> str:
    """Each gait under random pushes of up to 50 N (``push50-GAIT-TAG.json``) and unpushed (``GAIT-0n-TAG.json``),
    unguarded and guarded."""
    rows = []
    for pattern in (f"push50-{{gait}}-{tag}.json", f"{{gait}}-0n-{tag}.json"):
        for gait in _gaits(folder, pattern):
            result = read_evidence(Path(folder) / pattern.format(gait=gait))["result"]
            guarded, unguarded = result["guarded"], result["unguarded"]
            pushed = guarded["push_max_n"] > 0
            pushes = f"up to {guarded['push_max_n']:g} N" if pushed else "none"
            catches = guarded["guard"]["catches"]
            count = catches if isinstance(catches, int) else len(catches)
            rate = f"{count} ({guarded['catches_per_min']:.2f} /min{'' if pushed else ', every one false'})"
            if not pushed and guarded["catches_per_min"] <= FALSE_ALARMS_PER_MIN:
                rate = f"**{rate}**"
            rows.append(f"| {gait} | {pushes}, "
                        f"{guarded['minutes']:,.0f} minutes | {_falls(unguarded)} | "
                        f"{_falls(guarded, GOALS[50.0] if pushed else None)} | {rate} | "
                        f"{_share(guarded['guard']['measured_gait_share'])} |")
    if not rows:
        return not_yet(Path(folder) / f"push50-GAIT-{tag}.json")
    return "\n".join([
        "| gait | pushes, running time guarded | falls unguarded | falls guarded | catches | time in the gait |",
        "|---|---|---|---|---|---|", *rows, "",
        "Episodes of 20 s under the paper's random pushes of up to 50 N, and of 60 s unpushed (where every catch is a "
        "false one, the guard's cost), the same draws both ways (seed 0); bold where within the goals: falls in at "
        "most 1% of episodes under pushes, unpushed at most one false catch per 10 minutes of running. "
        f"Evidence: `{shown(Path(folder))}/push50-GAIT-{tag}.json` and `GAIT-0n-{tag}.json`, each with its command."])


def _bench(folder: Path, prefix: str, magnitude: float, arm: str, tag: str) -> tuple[Path, dict | None]:
    path = Path(folder) / f"{prefix}-{magnitude:g}n-{arm}-{tag}.json"
    return path, read_evidence(path)


def _worse(guarded: dict, unguarded: dict) -> bool:
    """Whether a pair's guarded success lies below the unguarded one's Wilson 95% interval."""
    low, _ = wilson_interval(unguarded["successes"], unguarded["samples"])
    return guarded["successes"] / guarded["samples"] < low


def guard_pairs(tag: str, folder: Path = GUARD, *, robot: str = "sim") -> str:
    """Every ordered pair switched by ``net-lookahead`` on ``robot`` (a key of :data:`PAIR_TABLES`) at each stored
    magnitude, unguarded and guarded with one seed (``PREFIX-MAGNITUDEn-ARM-TAG.json``), the pooled rates over the six
    shipped gaits' pairs and over all, the pairs at the goal, and the guard's catches."""
    table = PAIR_TABLES[robot]
    stored = {}
    for magnitude in table.pooled_goals:
        found = {arm: _bench(folder, table.prefix, magnitude, arm, tag) for arm in ("unguarded", "guarded")}
        if all(evidence is not None for _, evidence in found.values()):
            stored[magnitude] = found
    if not stored:
        return not_yet(Path(folder) / f"{table.prefix}-0n-guarded-{tag}.json")
    cells = {(m, arm): groups_at(evidence["result"], m)["net-lookahead"]
             for m, arms in stored.items() for arm, (_, evidence) in arms.items()}
    pairs = sorted({p for c in cells.values() for p in c}, key=lambda p: p.split("-"))
    shipped = [p for p in pairs if all(g in GAITS for g in p.split("-"))]
    columns = [(m, arm) for m in stored for arm in ("unguarded", "guarded")]
    head = " | ".join(f"{m:g} N, {arm}" for m, arm in columns)
    lines = [f"| pair | {head} |", "|---|" + "---|" * len(columns)]
    for pair in pairs:
        lines.append(f"| {arrow(pair)} | " + " | ".join(
            success(cells[key][pair]["successes"], cells[key][pair]["samples"], goal=table.pair_goals.get(key[0]))
            for key in columns) + " |")
    groups = [(f"the {len(shipped)} pairs of the six shipped gaits", shipped), (f"all {len(pairs)} pairs", pairs)]
    for name, chosen in (groups if len(shipped) < len(pairs) else groups[1:]):
        counts = [pooled(cells[key][p] for p in chosen) for key in columns]
        lines.append(f"| {name} | " + " | ".join(success(s, n) for s, n, _ in counts) + " |")
    lines.append("| pairs at the goal | " + " | ".join(
        f"{reached(cells[key].values(), table.pair_goals[key[0]])} of {len(pairs)}"
        if key[0] in table.pair_goals else "-" for key in columns) + " |")
    notes = [_pair_note(m, cells[(m, "guarded")], cells[(m, "unguarded")], arms["guarded"][1]["result"], pairs,
                        table=table) for m, arms in stored.items()]
    sizes = ", ".join(f"{arms['guarded'][1]['result']['settings']['samples']:,} transitions at {m:g} N"
                      for m, arms in stored.items())
    settings = next(iter(stored.values()))["guarded"][1]["result"]["settings"]
    paths = [path for arms in stored.values() for path, _ in arms.values()]
    goals = ", ".join(f"{pct(goal)}% at {m:g} N" for m, goal in table.pair_goals.items())
    return "\n".join([*lines, "", *notes, "",
                      f"On {table.robot}, each cell {sizes}, seed {settings['seed']} both ways (the draws part where a "
                      "trial ends differently: a world draws its next trial when the last one ends); falls by the "
                      f"`{settings['falls']}` definition; bold where the pair reaches its goal ({goals}). Evidence: "
                      + ", ".join(f"`{shown(p)}`" for p in paths) + ", each with its command."])


def _pair_note(magnitude: float, guarded: dict, unguarded: dict, result: dict, pairs: list[str], *,
               table: PairTable) -> str:
    """One magnitude's verdict: the pooled goal, the pairs the guard made worse, its catches by caught pair."""
    s, n, _ = pooled(guarded.values())
    s0, n0, _ = pooled(unguarded.values())
    goal = table.pooled_goals[magnitude]
    within = "within" if s >= goal * n else "short of"
    if magnitude == 0 and table.falls_per:
        per = table.falls_per
        verdict = (f"{n - s} falls in {n:,} switches guarded ({(n - s) * per / n:.1f} per {per:,}, {within} the goal "
                   f"of {round((1 - goal) * per)}; unguarded {n0 - s0}, {(n0 - s0) * per / n0:.1f} per {per:,})")
    else:
        verdict = (f"{pct(s / n)}% pooled guarded, {within} the goal of {pct(goal)}% (unguarded {pct(s0 / n0)}%)")
    worse = [arrow(p) for p in pairs if _worse(guarded[p], unguarded[p])]
    catch = next(g for g in result["groups"].values() if float(g["magnitude_n"]) == magnitude)["guard"]
    caught = ", ".join(f"{arrow(k)} {v}" for k, v in sorted(catch["by_pair"].items(), key=lambda kv: (-kv[1], kv[0])))
    return (f"- {magnitude:g} N: {verdict}; pairs guarded below their unguarded interval: "
            f"{', '.join(worse) if worse else 'none'}; {catch['catches']:,} catches{f' ({caught})' if caught else ''}.")


def _entries(points: dict[str, dict], goal: float, *, guarded: bool) -> str:
    """How many entries (gait -> a point with ``falls`` and ``episodes``) fall within ``goal``, and the others."""
    over = [(g, p) for g, p in points.items() if p["falls"] / p["episodes"] > goal]
    figures = ", ".join(f"{g} {pct(p['falls'] / p['episodes'])}%"
                        + (f" {interval(*wilson_interval(p['falls'], p['episodes']))}" if guarded else "")
                        for g, p in sorted(over, key=lambda gp: gp[1]["falls"] / gp[1]["episodes"]))
    within = f"{len(points) - len(over)} of {len(points)}{' entries' if not guarded else ''} at most {pct(goal)}%"
    return within + (f"; over it: {figures}" if over else "")


def _verdict(points: dict[str, dict], goal: float) -> str:
    met = [g for g, p in points.items() if p["falls"] / p["episodes"] <= goal]
    return "met" if len(met) == len(points) else f"met by {len(met)} of {len(points)}"


def guard_summary(tag: str, folder: Path = GUARD, *, section: str = "Where the guard stands") -> str:
    """The guard against its goals, one row a measure, unguarded and guarded: one shove of 12 and of 18 N s, the
    paper's pushes of up to 50 N, every pair at 0 N and under 50 N pushes on both A1 models, false catches unpushed
    and the README's six-gait sequence over 100 seeds; from the same stored evaluations as the detailed tables (in
    ``section`` of ``docs/switching.md``)."""
    folder = Path(folder)
    rows = []
    for impulse in (12, 18):
        gaits = _gaits(folder, f"shove-{impulse}-{{gait}}-{tag}.json")
        if not gaits:
            return not_yet(folder / f"shove-{impulse}-GAIT-{tag}.json")
        results = {g: read_evidence(folder / f"shove-{impulse}-{g}-{tag}.json")["result"] for g in gaits}
        guarded = {g: r["points"][0] for g, r in results.items()}
        unguarded = {g: r["unguarded_points"][0] for g, r in results.items()}
        goal = GOALS[float(impulse)]
        episodes = next(iter(guarded.values()))["episodes"]
        rows.append(f"| one {impulse} N s shove, {episodes:,} episodes a gait | "
                    f"{_entries(unguarded, goal, guarded=False)} | {_entries(guarded, goal, guarded=True)} | "
                    f"every entry at most {pct(goal)}%: "
                    f"{_verdict(guarded, goal)} |")
    pushes = {g: read_evidence(folder / f"push50-{g}-{tag}.json")["result"]
              for g in _gaits(folder, f"push50-{{gait}}-{tag}.json")}
    if pushes:
        goal = GOALS[50.0]
        guarded = {g: r["guarded"] for g, r in pushes.items()}
        episodes = next(iter(guarded.values()))["episodes"]
        rows.append(f"| random pushes of up to 50 N, {episodes:,} episodes of 20 s a gait | "
                    f"{_entries({g: r['unguarded'] for g, r in pushes.items()}, goal, guarded=False)} | "
                    f"{_entries(guarded, goal, guarded=True)} | every entry at most {pct(goal)}%: "
                    f"{_verdict(guarded, goal)} |")
    for robot, table in PAIR_TABLES.items():
        for magnitude, pooled_goal in table.pooled_goals.items():
            found = {arm: _bench(folder, table.prefix, magnitude, arm, tag)[1] for arm in ("unguarded", "guarded")}
            if any(evidence is None for evidence in found.values()):
                continue
            cells = {arm: groups_at(e["result"], magnitude)["net-lookahead"] for arm, e in found.items()}
            samples = found["guarded"]["result"]["settings"]["samples"]
            pair_goal = table.pair_goals.get(magnitude)
            figures = {}
            for arm, cell in cells.items():
                s, n, _ = pooled(cell.values())
                if magnitude == 0 and table.falls_per:
                    text = f"{n - s} falls in {n:,} ({(n - s) * table.falls_per / n:.1f} per {table.falls_per:,})"
                else:
                    text = success(s, n).replace(" [", "% [", 1)
                if pair_goal is not None:
                    text += f"; {reached(cell.values(), pair_goal)} of {len(cell)} pairs at {pct(pair_goal)}%"
                if arm == "guarded":
                    worse = sum(_worse(cell[p], cells["unguarded"][p]) for p in cell)
                    text += (f"; {worse} pair{'s' if worse > 1 else ''} below {'their' if worse > 1 else 'its'} "
                             "unguarded interval" if worse else "; no pair below its unguarded interval")
                figures[arm] = (text, s, n)
            s, n = figures["guarded"][1:]
            if magnitude == 0 and table.falls_per:
                goal_text = f"{round((1 - pooled_goal) * table.falls_per)} falls per {table.falls_per:,}"
            else:
                goal_text = f"{pct(pooled_goal)}% pooled"
            goal_text += f": {'met' if s >= pooled_goal * n else 'missed'}"
            if pair_goal is not None:
                every = reached(cells["guarded"].values(), pair_goal) == len(cells["guarded"])
                goal_text += f"; {pct(pair_goal)}% a pair: {'met' if every else 'missed'}"
            where = "" if robot == "sim" else f" on {table.robot}"
            push = "at 0 N" if magnitude == 0 else f"under {magnitude:g} N pushes"
            rows.append(f"| every pair{where} {push}, `net-lookahead`, {samples:,} a pair | "
                        f"{figures['unguarded'][0]} | {figures['guarded'][0]} | {goal_text} |")
    calm = {g: read_evidence(folder / f"{g}-0n-{tag}.json")["result"]["guarded"]
            for g in _gaits(folder, f"{{gait}}-0n-{tag}.json")}
    if calm:
        count = {g: p["guard"]["catches"] if isinstance(p["guard"]["catches"], int) else len(p["guard"]["catches"])
                 for g, p in calm.items()}
        minutes = sum(p["minutes"] for p in calm.values())
        falls = sum(p["falls"] for p in calm.values())
        over = [(g, p["catches_per_min"]) for g, p in calm.items() if p["catches_per_min"] > FALSE_ALARMS_PER_MIN]
        none = sum(1 for c in count.values() if not c)
        pooled_rate = sum(count.values()) / minutes
        per_gait = f"{round(next(iter(calm.values()))['minutes']):,} minutes an entry"
        rows.append(f"| false catches unpushed, {per_gait} | - | {sum(count.values())} in {minutes:,.0f} minutes "
                    f"({pooled_rate:.2f} /min); {none} entries none"
                    + "".join(f", {g} {rate:.3g} /min" for g, rate in over)
                    + f"; {falls or 'no'} fall{'s' if falls > 1 else ''} | at most {FALSE_ALARMS_PER_MIN:g} /min: "
                    + ("met" if not over else "met pooled, missed by " + " and ".join(g for g, _ in over)
                       if pooled_rate <= FALSE_ALARMS_PER_MIN else "missed") + " |")
    runs = {arm: read_evidence(folder / f"sequence-seeds-0-99-{tag}{suffix}.json")
            for arm, suffix in (("guarded", ""), ("unguarded", "-unguarded"))}
    if all(e is not None for e in runs.values()):
        texts = {}
        for arm, evidence in runs.items():
            result = evidence["result"]
            fell = [r["seed"] for r in result["runs"] if not r["stayed_up"]]
            text = f"{result['stayed_up']} of {result['seeds']} stay up"
            text += f" (seed{'s' if len(fell) > 1 else ''} {', '.join(map(str, fell))} falls)" if fell else ""
            if arm == "guarded":
                caught = [r for r in result["runs"] if r["catches"]]
                text += f"; {result['catches']} catches in {len(caught)} runs"
            texts[arm] = text
        up = runs["guarded"]["result"]
        rows.append(f"| the README's six-gait sequence, {up['seeds']} seeds | {texts['unguarded']} | {texts['guarded']}"
                    f" | 99 of 100: {'met' if up['stayed_up'] >= 0.99 * up['seeds'] else 'missed'} |")
    return "\n".join([
        "| measure | unguarded | guarded | goal (guarded) |", "|---|---|---|---|", *rows, "",
        "Falls by the `trunk` definition with 95% Wilson intervals, the same draws both ways (seed 0). Evidence: "
        f"`{shown(folder)}/*-{tag}.json` (the detailed tables of `docs/switching.md`, \"{section}\"), "
        "each with its command."])
