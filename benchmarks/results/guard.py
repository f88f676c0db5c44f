"""The guard's tables: each gait with and without the guard on the same draws, under one shove and under the paper's
random pushes, from the evaluations stored in ``docs/results/guard`` (``gaitlib eval GAIT --impulses I --guard``:
``shove-I-GAIT-TAG.json``; ``gaitlib eval GAIT --push-max 50 --guard``: ``push50-GAIT-TAG.json``; ``--push-max 0
--seconds 60``: ``GAIT-0n-TAG.json``), one table pair a guard, named by the files' ``TAG``."""

from __future__ import annotations

from pathlib import Path

from benchmarks.results.evidence import GAITS, ROOT, interval, not_yet, pct, read_evidence, shown
from gaitlib.stats import wilson_interval

__all__ = ["GOALS", "GUARD", "guard_pushes", "guard_shoves"]

GUARD = ROOT / "docs" / "results" / "guard"
"""The guard's stored evaluations."""
GOALS = {12.0: 0.01, 18.0: 0.10, 50.0: 0.01}
"""The guard's goals: the share of episodes a gait may fall in, guarded, after a shove of 12 and of 18 N s and under
random pushes of up to 50 N; a guarded figure within its goal is bold."""


def _gaits(folder: Path, pattern: str) -> list[str]:
    """The gaits with a file ``pattern`` (``{gait}`` in it) in ``folder``: the shipped ones in :data:`GAITS`' order,
    then any other by name."""
    prefix, suffix = pattern.split("{gait}")
    found = {p.name[len(prefix):len(p.name) - len(suffix)] for p in Path(folder).glob(pattern.replace("{gait}", "*"))}
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
            rows.append(f"| {gait} | {pushes}, "
                        f"{guarded['minutes']:,.0f} minutes | {_falls(unguarded)} | "
                        f"{_falls(guarded, GOALS[50.0] if pushed else None)} | {count} "
                        f"({guarded['catches_per_min']:.2f} /min{'' if pushed else ', every one false'}) | "
                        f"{_share(guarded['guard']['measured_gait_share'])} |")
    if not rows:
        return not_yet(Path(folder) / f"push50-GAIT-{tag}.json")
    return "\n".join([
        "| gait | pushes, running time guarded | falls unguarded | falls guarded | catches | time in the gait |",
        "|---|---|---|---|---|---|", *rows, "",
        "Episodes of 20 s under the paper's random pushes of up to 50 N, and of 60 s unpushed (where every catch is a "
        "false one, the guard's cost), the same draws both ways (seed 0); bold where within the goal of 1%. "
        f"Evidence: `{shown(Path(folder))}/push50-GAIT-{tag}.json` and `GAIT-0n-{tag}.json`, each with its command."])
