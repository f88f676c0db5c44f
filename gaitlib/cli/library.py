"""``gaitlib library``: what a library holds, what is stale, and the commands that fix it."""

from __future__ import annotations

from pathlib import Path

import typer

from gaitlib.atomic import json_text
from gaitlib.defaults import DEFAULT_FALLS
from gaitlib.values import number_text

__all__ = ["library_command"]


def library_command(
    library: Path | None = typer.Option(None, "--library", help="Library folder (default: the shipped library/)."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object instead of tables."),
) -> None:
    """List a library's gaits (description, training, evaluation, identity), the pairs its switching models cover,
    and what is stale or inconsistent, each with the exact commands that fix it."""
    from rich.markup import escape
    from rich.table import Table

    from gaitlib.cli.tables import table_console
    from gaitlib.errors import GaitlibError
    from gaitlib.library import Library, library_status

    lib = Library(library)
    if not lib.root.is_dir():
        raise GaitlibError(f"no library at {lib.root}")
    status = library_status(lib)
    routes = _routes(lib, status)
    survival = _survival(lib, status)
    if as_json:
        print(json_text(status.as_dict() | {"routes": routes, "survival": survival}))
        return
    console = table_console()
    gaits = Table(title=f"{lib.root}{' (shipped with gaitlib)' if status.shipped else ''}: gaits")
    for column in ("gait", "speed m/s", "cycle s", "preset", "iterations", "train min", "eval falls", "eval touches",
                   "eval m/s", "identity"):
        gaits.add_column(column, justify="left" if column in ("gait", "preset", "identity") else "right")
    for g in status.gaits:
        s = g.summary
        gaits.add_row(
            g.name, _num(s["speed_m_s"], 2), _num(s["cycle_s"], 3),
            str(s["preset"] or (f"mirror of {s['mirror_of']}" if s["mirror_of"] else "-")),
            str(s["iterations"] or "-"), _num(s["train_minutes"], 1),
            "-" if s["eval_fall_rate"] is None
            else f"{100 * s['eval_fall_rate']:.1f}% of {s['eval_episodes']} ({s['eval_falls']})",
            "-" if s["eval_touch_rate"] is None else f"{100 * s['eval_touch_rate']:.1f}%",
            _num(s["eval_speed_m_s"], 2), "unusable" if g.identity is None else g.identity[:12],
        )
    console.print(gaits)
    if status.bundle is not None:
        b = status.bundle
        data = ", ".join(d["path"] for d in b.data)
        fits = len(set(b.parts.values()))
        composite = (f"; {fits} fits kept together by gaitlib fit --extend, 'fit' the one serving a pair, the last "
                     "the newest") if b.parts else ""
        pairs = Table(title=f"switching models (inputs {', '.join(b.inputs)}; fitted on {escape(data)}{composite})")
        for column in ("pair", "state", "samples", "net accuracy", *(("fit",) if b.parts else ())):
            pairs.add_column(column, justify="left" if column in ("pair", "state") else "right")
        for pair, state in status.pairs.items():
            samples = b.pair_samples.get(pair)
            accuracy = b.accuracy.get(pair)
            part = (f"{b.parts[pair]} of {fits}" if pair in b.parts else "-",) if b.parts else ()
            pairs.add_row(pair, state, "-" if samples is None else f"{samples:,}",
                          "-" if accuracy is None or state != "covered" else f"{100 * accuracy:.1f}%", *part)
        console.print(pairs)
    if routes is not None and routes["state"] == "current":
        detours = "; ".join(f"{pair} through {' -> '.join(path)}" for pair, path in routes["detours"].items())
        console.print(f"route table ({routes['strategy']}, {routes['push_n']:g} N): "
                      f"{detours or 'every pair best directly'}", soft_wrap=True)
    elif routes is not None:  # stale: measured with other switching models or policies (a refit keeps it so)
        console.print(f"problem: {escape(routes['why'])}", soft_wrap=True)
        if routes["fix"]:
            console.print(f"  fix: {escape(routes['fix'])}", soft_wrap=True)
    if survival is not None and survival["state"] == "current":
        console.print(f"survival estimate (the guard): horizon {number_text(survival['horizon_s'])} s, margin "
                      f"{number_text(survival['margin'])}, inputs {', '.join(survival['inputs'])}", soft_wrap=True)
    elif survival is not None:
        console.print(f"problem: {escape(survival['why'])}", soft_wrap=True)
    other = status.other_falls()
    if routes is not None and routes.get("falls", DEFAULT_FALLS) != DEFAULT_FALLS:
        other["switching/routes.json"] = routes["falls"]
    if other:
        console.print(f"counted with another definition of a fall than the default ({DEFAULT_FALLS}): "
                      + ", ".join(f"{name} ({falls})" for name, falls in other.items()), soft_wrap=True)
    if not status.problems and all(x is None or x["state"] == "current" for x in (routes, survival)):
        console.print("nothing stale: every gait is usable and every pair is covered")
    for problem in status.problems:
        console.print(f"problem: {escape(problem.text)}", soft_wrap=True)
        for command in problem.commands:
            console.print(f"  fix: {escape(command)}", soft_wrap=True)


def _routes(lib, status) -> dict | None:
    """The library's route table (``gaitlib routes``): ``None`` without one, else its state, and its detours when
    it is current."""
    from gaitlib.errors import GaitlibError
    from gaitlib.strategies.routes import ROUTES_FILE, load_routes

    if status.bundle is None or not (lib.switching_dir / ROUTES_FILE).is_file():
        return None
    try:
        table = load_routes(lib, status.bundle.gaits)
    except GaitlibError as stale:  # measured with other switching models or policies (a refit keeps it so)
        why, _, command = str(stale).partition("; measure it again: ")
        return {"state": "stale", "why": why, "fix": command or None}
    detours = {pair: list(path) for pair, path in table.detours().items()}
    return {"state": "current", "strategy": table.strategy, "push_n": table.push_n, "detours": detours,
            "falls": table.falls}


def _survival(lib, status) -> dict | None:
    """The library's survival estimate (``gaitlib survival fit``): ``None`` without one, else its state, and its
    horizon, margin and inputs when it is current."""
    from gaitlib.errors import GaitlibError
    from gaitlib.strategies.survival import SURVIVAL_FILE, SurvivalFileError, load_survival

    if status.bundle is None or not (lib.switching_dir / SURVIVAL_FILE).is_file():
        return None
    try:
        estimate = load_survival(lib, status.bundle.gaits)
    except GaitlibError as stale:  # recorded with other policies, or damaged (refused by every command using it)
        return {"state": "damaged" if isinstance(stale, SurvivalFileError) else "stale", "why": str(stale)}
    return {"state": "current", "horizon_s": estimate.horizon_s, "margin": estimate.margin,
            "floor": estimate.floor, "inputs": list(estimate.inputs)}


def _num(value: float | None, digits: int) -> str:
    return "-" if value is None else f"{value:.{digits}f}"
