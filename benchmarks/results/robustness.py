"""The robustness tables: the gaits themselves against the robust recipe's goals
(:mod:`benchmarks.results.switches` tables the switches). :mod:`benchmarks.results.doc` writes them into
``docs/ablation.md`` (``robustness-gaits``, ``robust-library``) and ``docs/results.md`` (``shove-curves``).

- ``robustness-gaits``: the robust recipe's ablation, ``docs/results/ablation/GAIT-VARIANT.json`` for each gait of
  :data:`ABLATION_GAITS` (``GAIT-today.json``: the switch-start library's gait, today's recipe: the recipe before
  the ablation), each ``{"command", "result"}`` as ``benchmarks/robust_ablation.py`` writes it (the date is the
  result's own ``made``): falls and leg touches with their 95% intervals, each row's recipe, and each row against
  :data:`BARS` and :data:`GAIT_BARS`, read from its numbers.
- ``robust-library``: each of the six gaits with today's recipe (``GAIT-today.json``, ``library-switch-start/``)
  beside the same gait in the shipped library (``GAIT-`` :data:`CHOSEN` ``.json``), each against every bar.
- ``shove-curves``: every gait's falls under one shove of each impulse in both libraries, from the same rows.

A table whose evidence is not stored yet says "not yet measured", one file missing of several says which.
"""

from __future__ import annotations

import json
from pathlib import Path

from benchmarks.results.evidence import (
    BAR_HEADING_DEG,
    BAR_SPEED,
    GAITS,
    HEADING_BAR,
    ROOT,
    SPEED_BAR,
    cite,
    interval,
    not_yet,
    pct,
    speed_heading_misses,
)
from gaitlib.training.recipe import PAPER_RECIPE, Recipe

__all__ = [
    "ABLATION", "ABLATION_GAITS", "BARS", "CHOSEN", "GAIT_BARS", "SHOVES", "ablation_rows", "library_table", "misses",
    "read_row", "recipe_options", "robustness_table", "shove_table",
]

ABLATION = ROOT / "docs" / "results" / "ablation"
"""The robust recipe's ablation rows: ``GAIT-VARIANT.json``, ``today`` the switch-start library's gaits as
trained."""
ABLATION_GAITS = ("pace", "trot")
"""The gaits of the ablation's baseline, in the table's order."""
CHOSEN = "gamma-kick-trunk-touch5"
"""The variant the ablation chose (docs/ablation.md, "Decision"), the recipe of the
shipped library: each gait's row of it is ``GAIT-gamma-kick-trunk-touch5.json``."""
LIBRARIES = (("today", "switch-start"), (CHOSEN, "robust"))
"""Each library's variant of the ablation rows and its name in the tables: the library shipped before
(``library-switch-start/``), then the shipped one (``library/``)."""
SHOVES = (6.0, 12.0, 18.0)
"""The single shoves tabled, N s."""
SHOVE_UP_TO_NS = 12.0
BARS = {"single shove": 0.01, "pushes up to 50 N": 0.02, "0 N": 0.005, "one step late": 0.01}
"""The robust recipe's goals, falls at most: a single shove of up to :data:`SHOVE_UP_TO_NS` in any direction, pushes
up to 50 N while walking (``gaitlib eval --push-max 50``), 0 N with the trained delay, every action one step late."""
GAIT_BARS = ("touches at 0 N", SPEED_BAR, HEADING_BAR)
"""The robust recipe's goals beside the falls, at 0 N with the trained delay: the legs touching the ground in no more
episodes than with today's recipe (the row's 95% interval reaching down into today's; judged where the gait's
``today`` row is stored), and the quality bar's speed and median heading change."""


def read_row(path: Path) -> dict | None:
    """The ablation row stored at ``path`` as evidence (``command``, ``made``, ``result``); ``None`` when there is
    none yet."""
    if not path.is_file():
        return None
    stored = json.loads(path.read_text(encoding="utf-8"))
    missing = sorted({"command", "result"} - set(stored))
    if missing:
        raise ValueError(f"{path} is not an ablation row: no {', '.join(missing)}")
    return {"made": stored["result"]["made"][:10]} | stored


def _rate(count: int, total: int, bounds: list[float]) -> str:
    return f"{pct(count / total)} {interval(*bounds)}"


def _shove_at(figures: dict, impulse: float) -> dict | None:
    return next((p for p in figures["single_shove"] if float(p["impulse_ns"]) == impulse), None)


def _worst(point: dict) -> tuple[str, int, int]:
    """The direction a shove felled the largest share of, its falls and episodes."""
    name, (falls, episodes) = max(((s, c) for s, c in point["by_sector"].items() if c[1]),
                                  key=lambda item: (item[1][0] / item[1][1], item[1][0]))
    return name, falls, episodes


def _shove_rate(point: dict | None, what: str = "falls") -> str:
    """A shove's ``falls`` (or ``touches``) with their 95% interval; "-" unmeasured."""
    if point is None:
        return "-"
    return _rate(point[what], point["episodes"], point["ci95" if what == "falls" else "touch_ci95"])


def _shove_cells(point: dict | None) -> list[str]:
    """A shove's falls with their interval, and its worst direction (its falls of its episodes); "-" unmeasured."""
    if point is None:
        return ["-", "-"]
    name, falls, episodes = _worst(point)
    return [_shove_rate(point), f"{name} {falls}/{episodes}" if falls else "none"]


def _run_cell(run: dict, what: str) -> str:
    """An evaluation's rate of ``what`` (``fall`` or ``touch``) with its 95% interval."""
    return f"{pct(run[f'{what}_rate'])} {interval(*run[f'{what}_ci95'])}"


def _sources(figures: dict) -> list[str]:
    return [f["source"] for k, f in figures.items() if k.startswith("switch_in_from_")]


def _shove_miss(figures: dict) -> str | None:
    """Why the single-shove curve misses its bar, or ``None`` when it meets it."""
    points = [p for p in figures["single_shove"] if float(p["impulse_ns"]) <= SHOVE_UP_TO_NS]
    if not any(float(p["impulse_ns"]) == SHOVE_UP_TO_NS for p in points):
        return f"not measured at {SHOVE_UP_TO_NS:g} N s"
    worst = max(((p, *_worst(p)) for p in points), key=lambda w: w[2] / w[3])
    point, name, falls, episodes = worst
    if falls / episodes <= BARS["single shove"]:
        return None
    return f"{pct(falls / episodes)}% in the {name} direction ({falls} of {episodes}) at {point['impulse_ns']:g} N s"


def _bars(today: dict | None) -> list[str]:
    """The bars a row is judged against: touches only where today's row of its gait is stored."""
    return [*BARS, *(GAIT_BARS if today is not None else GAIT_BARS[1:])]


def misses(row: dict, today: dict | None = None) -> dict[str, str]:
    """Each bar of :data:`BARS` and :data:`GAIT_BARS` an ablation row misses, with why, from its numbers; the
    touches against ``today``, the same gait's row trained with today's recipe (not judged without it)."""
    figures = row["figures"]
    found = {"single shove": _shove_miss(figures)}
    for bar, key in (("pushes up to 50 N", "push_50n"), ("0 N", "zero_n"), ("one step late", "one_step_late")):
        rate = figures[key]["fall_rate"]
        found[bar] = f"{pct(rate)}%" if rate > BARS[bar] else None
    zero = figures["zero_n"]
    if today is not None:
        base = today["figures"]["zero_n"]
        worse = zero["touch_ci95"][0] > base["touch_ci95"][1]
        found[GAIT_BARS[0]] = (f"{pct(zero['touch_rate'])}% {interval(*zero['touch_ci95'])} against today's "
                               f"{pct(base['touch_rate'])}% {interval(*base['touch_ci95'])}") if worse else None
    found.update(speed_heading_misses(zero))
    return {bar: why for bar, why in found.items() if why}


def _falls_row(label: str, row: dict, sources: list[str]) -> str:
    figures = row["figures"]
    cells = [cell for impulse in SHOVES for cell in _shove_cells(_shove_at(figures, impulse))]
    cells += [_run_cell(figures[key], "fall") for key in ("push_50n", "zero_n", "one_step_late")]
    for source in sources:
        switch = figures.get(f"switch_in_from_{source}")
        cells.append(_rate(switch["falls"], switch["episodes"], switch["fall_ci95"]) if switch else "-")
    return f"| {label} | " + " | ".join(cells) + " |"


def _touches_row(label: str, row: dict, sources: list[str]) -> str:
    figures = row["figures"]
    cells = [_shove_rate(_shove_at(figures, impulse), "touches") for impulse in SHOVES]
    cells += [_run_cell(figures[key], "touch") for key in ("push_50n", "zero_n", "one_step_late")]
    for source in sources:
        switch = figures.get(f"switch_in_from_{source}")
        cells.append(_rate(switch["touches"], switch["episodes"], switch["touch_ci95"]) if switch else "-")
    zero, minutes = figures["zero_n"], row.get("training_minutes")
    cells += [f"{pct(zero['speed_error'])}%", f"{zero['median_heading_change_deg']:.1f} deg",
              "-" if minutes is None else f"{minutes:g}"]
    return f"| {label} | " + " | ".join(cells) + " |"


def _judged(row: dict, today: dict | None) -> tuple[dict[str, str], list[str]]:
    """The bars a row misses (:func:`misses`) and the bars it is judged against (:func:`_bars`)."""
    return misses(row, today), _bars(today)


def _verdict(label: str, missed: dict[str, str], bars: list[str]) -> str:
    met = [bar for bar in bars if bar not in missed]
    text = f"{label}: meets {len(met)} of the {len(bars)} bars"
    text += f" ({', '.join(met)})" if met else ""
    return text + (f"; misses {'; '.join(f'{bar}: {why}' for bar, why in missed.items())}." if missed else ".")


def recipe_options(recipe: dict | str) -> str:
    """A row's recipe as the ``gaitlib train`` options that set it apart from today's recipe (the ablation's
    baseline, :data:`~gaitlib.training.recipe.PAPER_RECIPE`)."""
    if not isinstance(recipe, dict):
        return "today's recipe"
    recipe = json.loads(json.dumps(Recipe.from_record(recipe).as_dict()))
    default = json.loads(json.dumps(PAPER_RECIPE.as_dict()))
    kicks = recipe["push_kind"] == "kick"  # a kick's size, draw and interval are named; without kicks, none
    options = []
    for key in (k for k, v in recipe.items() if (kicks if k.startswith("kick_") else default[k] != v)):
        value, option = recipe[key], f"--{key.replace('_', '-')}"
        if value is True:
            options.append(option)
        elif isinstance(value, list):
            options.append(f"{option} " + ":".join(f"{v:g}" for v in value))
        else:
            options.append(f"{option} {value:g}" if isinstance(value, float) else f"{option} {value}")
    return f"`{' '.join(options)}`" if options else "today's recipe"


def ablation_rows(ablation_dir: Path = ABLATION) -> dict[str, tuple[Path, dict]]:
    """Every stored ablation row by its label ("GAIT, VARIANT"): for each gait of :data:`ABLATION_GAITS`, today's
    recipe first, then its variants by file name."""
    found = {}
    for gait in ABLATION_GAITS:
        paths = sorted(Path(ablation_dir).glob(f"{gait}-*.json"), key=lambda p: (p.stem != f"{gait}-today", p.stem))
        for path in paths:
            found[f"{gait}, {path.stem.removeprefix(f'{gait}-')}"] = (path, read_row(path))
    return found


def robustness_table(ablation_dir: Path = ABLATION) -> str:
    """``robustness-gaits``: every ablation row (``GAIT-VARIANT.json``, today's recipe ``GAIT-today.json``), falls
    then touches, each row's recipe, and each row against :data:`BARS`."""
    found = ablation_rows(ablation_dir)
    if not found:
        return not_yet(Path(ablation_dir) / "GAIT-today.json")
    rows = {label: e["result"] for label, (_, e) in found.items()}
    sources = list(dict.fromkeys(s for r in rows.values() for s in _sources(r["figures"])))
    shoves = [f"shove {i:g} N s" for i in SHOVES]
    others = ["pushes up to 50 N", "0 N", "one step late", *(f"switch in from {s}" for s in sources)]
    falls = ["| gait, recipe | " + " | ".join(f"{s} [95%] | worst direction" for s in shoves) + " | "
             + " | ".join(f"{o} [95%]" for o in others) + " |",
             "|---|" + "---|---|" * len(shoves) + "---|" * len(others)]
    touches = ["| gait, recipe | " + " | ".join(f"{c} [95%]" for c in [*shoves, *others])
               + " | speed error (0 N) | median heading change (0 N) | training, minutes |",
               "|---|" + "---|" * (len(shoves) + len(others) + 3)]
    runs = sorted({f"{r['settings']['episodes']:,} episodes of {r['settings']['seconds']:g} s a figure, "
                   f"{r['settings']['switches']:,} switches from each source; seed {r['settings']['seed']}, falls by "
                   f"the `{r['settings']['falls']}` definition" for r in rows.values()})
    recipes = [f"- {label}: {recipe_options(r['recipe'])}, {r['iterations']:,} iterations"
               for label, r in rows.items()]
    lines = ["Falls, % of episodes (of switches for a switch in) [95% interval]; a shove's worst direction: its falls "
             "of its episodes:", "", *falls, *(_falls_row(k, r, sources) for k, r in rows.items()), "",
             "Leg touches ridden through, % [95% interval]; speed and heading at 0 N:", "", *touches,
             *(_touches_row(k, r, sources) for k, r in rows.items()), "",
             "The recipes (`gaitlib train` options beyond today's recipe):", "", *recipes, "",
             f"{' / '.join(runs)}. The bars (the robust recipe's goals): falls at most "
             f"{pct(BARS['single shove'])}% after a single shove of up to {SHOVE_UP_TO_NS:g} N s in any direction, "
             f"{pct(BARS['pushes up to 50 N'])}% under pushes up to 50 N, {pct(BARS['0 N'])}% at 0 N and "
             f"{pct(BARS['one step late'])}% one step late; at 0 N, the legs touching the ground in no more episodes "
             f"than with today's recipe (the row's interval reaching into today's), speed within {BAR_SPEED:.0%} and "
             f"a median heading change of at most {BAR_HEADING_DEG:g} degrees.", "",
             *(f"- {_verdict(k, *_judged(r, rows.get(r['gait'] + ', today')))}" for k, r in rows.items())]
    missing = [Path(ablation_dir) / f"{g}-today.json" for g in ABLATION_GAITS if f"{g}, today" not in found]
    if missing:
        lines.append(not_yet(*missing))
    return "\n".join([*lines, "", "Evidence:", "", *(f"- {cite(p, e)}" for p, e in found.values())])


def _library_row(gait: str, library: str, row: dict, met: str) -> str:
    figures = row["figures"]
    cells = [gait, library, *_shove_cells(_shove_at(figures, SHOVE_UP_TO_NS)),
             *(_run_cell(figures[key], "fall") for key in ("push_50n", "zero_n", "one_step_late")),
             _run_cell(figures["zero_n"], "touch"), met]
    return "| " + " | ".join(cells) + " |"


def _library_rows(ablation_dir: Path) -> tuple[dict[tuple[str, str], Path], dict[tuple[str, str], tuple[Path, dict]]]:
    """Each (gait, library) of :data:`GAITS` and :data:`LIBRARIES`: the path of its row, and the rows stored (path,
    row), in the tables' order."""
    paths = {(gait, library): Path(ablation_dir) / f"{gait}-{variant}.json"
             for gait in GAITS for variant, library in LIBRARIES}
    return paths, {key: (path, row) for key, path in paths.items() if (row := read_row(path)) is not None}


def library_table(ablation_dir: Path = ABLATION) -> str:
    """``robust-library``: each gait of :data:`GAITS` trained with today's recipe (the switch-start library,
    ``GAIT-today.json``) and with the :data:`CHOSEN` one (the shipped library), side by side against the bars; the
    touches of both judged against the switch-start gait's."""
    paths, found = _library_rows(ablation_dir)
    robust = [gait for gait in GAITS if (gait, "robust") in found]
    if not robust:
        return not_yet(*(Path(ablation_dir) / f"{gait}-{CHOSEN}.json" for gait in GAITS))
    lines = [f"| gait | library | shove {SHOVE_UP_TO_NS:g} N s [95%] | worst direction | pushes up to 50 N [95%] "
             "| 0 N [95%] | one step late [95%] | touches at 0 N [95%] | bars met |", "|---|---|" + "---|" * 7]
    verdicts, whole = [], []
    for (gait, library), (_, row) in found.items():
        earlier = found.get((gait, "switch-start"))
        today = None if earlier is None else earlier[1]["result"]
        missed, bars = _judged(row["result"], today)
        lines.append(_library_row(gait, library, row["result"], f"{len(bars) - len(missed)} of {len(bars)}"))
        verdicts.append(f"- {_verdict(f'{gait}, {library}', missed, bars)}")
        if library == "robust" and not missed:
            whole.append(gait)
    absent = [path for key, path in paths.items() if key not in found]
    notes = [f"Falls, % of episodes [95% interval], each figure as in the ablation's table above. With the robust "
             f"recipe {len(whole)} of the {len(robust)} gaits measured meet every bar"
             + (f" ({', '.join(whole)})." if whole else ".")]
    if absent:
        notes.append(not_yet(*absent))
    return "\n".join([*lines, "", " ".join(notes), "", *verdicts, "", "Evidence:", "",
                      *(f"- {cite(p, e)}" for p, e in found.values())])


def shove_table(ablation_dir: Path = ABLATION) -> str:
    """Every gait's falls under one shove of each impulse in each library of :data:`LIBRARIES`, with its interval,
    the worst direction at the bar's impulse and the touches there."""
    paths, found = _library_rows(ablation_dir)
    curves = {key: (row["result"]["figures"]["single_shove"], path, row) for key, (path, row) in found.items()}
    absent = [path for key, path in paths.items() if key not in curves]
    if not curves:
        return not_yet(*absent)
    impulses = sorted({float(p["impulse_ns"]) for points, _, _ in curves.values() for p in points})
    bar = f"{SHOVE_UP_TO_NS:g} N s"
    lines = ["| gait | library | " + " | ".join(f"{i:g} N s [95%]" for i in impulses)
             + f" | worst direction at {bar} | touches at {bar} [95%] | at most {pct(BARS['single shove'])}% up to "
             f"{bar}, every direction |", "|---|---|" + "---|" * (len(impulses) + 3)]
    verdicts = {key: _shove_miss({"single_shove": points}) for key, (points, _, _) in curves.items()}
    for (gait, library), (points, _, _) in curves.items():
        at = {float(p["impulse_ns"]): p for p in points}
        cells = [_shove_rate(at.get(i)) for i in impulses]
        point = at.get(SHOVE_UP_TO_NS)
        worst, touches = _shove_cells(point)[1], _shove_rate(point, "touches")
        miss = verdicts[gait, library]
        lines.append(f"| {gait} | {library} | " + " | ".join(cells) + f" | {worst} | {touches} | "
                     + (f"no: {miss}" if miss else "yes") + " |")
    episodes = sorted({p["episodes"] for points, _, _ in curves.values() for p in points})
    counts = []
    for _, library in LIBRARIES:
        measured = [g for g in GAITS if (g, library) in curves]
        met = [g for g in measured if verdicts[g, library] is None]
        counts.append(f"{library} {len(met)} of {len(measured)}" + (f" ({', '.join(met)})" if met else ""))
    notes = [f"One 0.1 s push per episode at a random phase and direction, {', '.join(f'{e:,}' for e in episodes)} "
             f"episodes a point, falls by the `trunk` definition. Gaits meeting the bar: {'; '.join(counts)}."]
    if absent:
        notes.append(not_yet(*absent))
    sources = "\n".join(f"- {cite(path, record)}" for _, path, record in curves.values())
    return "\n".join([*lines, "", *notes, "", "Evidence:", "", sources])
