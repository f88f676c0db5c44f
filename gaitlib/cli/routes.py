"""``gaitlib routes`` (the library's route table), the table read for ``run`` and ``benchmark --routed``, and the
benchmark sweep with its progress bar, which ``routes`` and ``benchmark`` both run."""

from __future__ import annotations

from pathlib import Path

import typer

from gaitlib.atomic import json_text
from gaitlib.cli.options import COUNT, LEGS, PUSH_N, SEED, WORLDS, bounded, falls_option
from gaitlib.defaults import DEFAULT_STRATEGY, Falls

__all__ = ["route_table", "routes_command", "sweep_with_progress"]



def routes_command(
    samples: int = bounded(1000, "--samples", help="Transitions per ordered pair;", bounds=COUNT),
    strategy: str = typer.Option(DEFAULT_STRATEGY, "--strategy", help="The strategy every switch is made with."),
    push: float = bounded(0.0, "--push", help="Push magnitude the routes are for, in the benchmark's window around "
                          "each request;", bounds=PUSH_N),
    max_legs: int = bounded(2, "--max-legs", help="Most switches a route may take;", bounds=LEGS),
    out: Path | None = typer.Option(
        None, "--out", help="Benchmark folder the pairs are measured into, resumed (default: runs/routes-LIBRARY)."
    ),
    worlds: int = bounded(256, "--worlds", help="Parallel worlds;", bounds=WORLDS),
    backend: str = typer.Option("auto", "--backend", help="auto, mujoco or newton."),
    seed: int = bounded(0, "--seed", help="Random seed;", bounds=SEED),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object (the route table)."),
    library: Path | None = typer.Option(
        None, "--library", help="Library to measure and write the table into (default: $GAITLIB_LIBRARY, else your "
        "own runs/library, made from the shipped one on its first write)."
    ),
    falls: str = falls_option(),
    replace: bool = typer.Option(False, "--replace", help="Write the shipped library's table (refused without it)."),
) -> None:
    """Measure every ordered pair with --strategy (at --push, default 0 N) and write the library's route table
    (switching/routes.json): the pairs that do better through another gait, for run and benchmark --routed."""
    from gaitlib.benchmark.routes import routes_from_results
    from gaitlib.benchmark.sweep import SweepConfig
    from gaitlib.cli.options import check_worlds
    from gaitlib.cli.preflight import writable_folder, writing_library
    from gaitlib.library.target import check_library, copy_library, library_writer, measurement_id
    from gaitlib.meta import load_switching
    from gaitlib.strategies import get_strategy

    check_worlds("--worlds", worlds, backend=backend)
    if out is not None:
        writable_folder("--out", out)
    target, copy_from = writing_library(library, replace=replace, command="gaitlib routes", what="the route table")
    check_library(copy_from or target, command="gaitlib routes")
    setup = load_switching(copy_from or target)
    get_strategy(strategy, setup.resources)  # an unknown name or missing models: one line, before any work
    if copy_from is not None:
        copy_library(copy_from, target)
    with library_writer(target, command="gaitlib routes"):  # no refit while the pairs are measured
        if copy_from is not None:
            setup = load_switching(target)  # the copy, which the table is written into
        lib = setup.resources.library
        out = out or Path("runs") / f"routes-{measurement_id(lib)}"
        config = SweepConfig(strategies=(strategy,), magnitudes=(push,), samples=samples, num_worlds=worlds,
                             backend=backend, seed=seed, falls=falls)
        results = sweep_with_progress(out, setup, config)
        table = routes_from_results(results, lib, strategy=strategy, push_n=push, max_legs=max_legs)
        path = table.save(lib)
    if as_json:
        print(json_text(table.as_dict() | {"table": str(path), "measured_in": str(out)}))
        return
    from rich.table import Table

    from gaitlib.cli.tables import table_console

    shown = Table(title=f"{strategy} at {push:g} N, {samples} transitions a pair: routes through another gait")
    for column in ("pair", "direct", "route", "predicted"):
        shown.add_column(column, justify="left" if column in ("pair", "route") else "right")
    detours = table.detours()
    for pair, route in detours.items():
        shown.add_row(pair, f"{table.success(route[0], route[-1]):.3f}", " -> ".join(route),
                      f"{table.predicted(route):.3f}")
    console = table_console()
    console.print(shown if detours else "every pair switches best directly")
    console.print(f"route table: {path}; measured in {out}")


def route_table(setup, *, strategies, pushes, falls: Falls):
    """The library's route table, after saying on stderr what it was measured with, and warning where that is not
    what this command runs (another strategy, push or definition of a fall)."""
    from rich.console import Console

    from gaitlib.strategies.routes import load_routes

    table = load_routes(setup.resources.library, setup.gaits)
    measured = table.falls
    console = Console(stderr=True)
    console.print(f"gaitlib: routes from {setup.resources.library.switching_dir / 'routes.json'}, measured with "
                  f"{table.strategy} at {table.push_n:g} N, falls counted the {measured} way", soft_wrap=True)
    differ = [f"strategy {', '.join(s for s in strategies if s != table.strategy)}"] if set(strategies) != {
        table.strategy} else []
    if {round(p, 3) for p in pushes} != {round(table.push_n, 3)}:
        differ.append(f"pushes of {', '.join(f'{p:g}' for p in pushes)} N")
    if falls != measured:
        differ.append(f"falls counted the {falls} way")
    if differ:
        console.print(f"gaitlib: warning: this run differs from what the routes were measured with: "
                      f"{'; '.join(differ)} (measure routes for it: gaitlib routes --strategy ... --push ...)",
                      soft_wrap=True)
    return table


def sweep_with_progress(out: Path, setup, config, *, cluster=None) -> dict:
    """:func:`~gaitlib.benchmark.sweep.run_sweep` with a progress bar on stderr (a line per group in logs)."""
    from rich.console import Console

    from gaitlib.benchmark.sweep import run_sweep
    from gaitlib.cli.progress import job_progress

    console = Console(stderr=True)
    with job_progress(console, "benchmark") as progress:
        task = progress.add_task("benchmark", total=None, status="starting")
        last = [""]

        def show(group: str, done: int, total: int) -> None:
            progress.update(task, completed=done, total=total, status=group)
            if not console.is_terminal and group != last[0]:  # logs get a line per group
                console.print(f"{done}/{total} transitions, now {group}")
                last[0] = group

        return run_sweep(out, setup, config, progress=show, cluster=cluster)
