"""``gaitlib collect`` (transition samples to HDF5), ``gaitlib fit`` (the transition-net) and ``gaitlib map``
(where the switches of a file fail)."""

from __future__ import annotations

import math
from pathlib import Path

import typer

from gaitlib.atomic import json_text
from gaitlib.cli.options import (
    CHUNK,
    COUNT,
    PUSH_N,
    SEED,
    WORLDS,
    Bounds,
    bounded,
    falls_option,
    ray_address_argument,
    ray_option,
    workers_option,
)
from gaitlib.defaults import MIN_PER_LABEL

__all__ = ["collect_command", "fit_command", "map_command", "states_command"]


def collect_command(
    samples: float = bounded(
        2e6,
        "--samples",
        help="Samples the file holds when done (2e6 is accepted);",
        bounds=Bounds(low=1, high=1e8, whole=True),
    ),
    out: Path = typer.Option(
        Path("data/transitions.h5"),
        "--out",
        help="Transition file: a small HDF5 index, its samples in OUT.parts/ (resumed if it exists).",
    ),
    gaits: str | None = typer.Option(None, "--gaits", help="Comma-separated gaits (default: every library entry)."),
    pairs: str | None = typer.Option(
        None, "--pairs", help="Ordered pairs like trot-stand,pace-stand; a bare gait name: every pair with it; "
        "fell:FILE: every pair in which a switch of the transition file FILE (a screen of this library) fell."
    ),
    push_max: float = bounded(0.0, "--push-max", help="Largest random push (0: none);", bounds=PUSH_N),
    horizon: float | None = bounded(
        None,
        "--horizon",
        help="Time after the switch that decides success (default: the success horizon chosen from data, "
        "docs/transitions.md);",
        bounds=Bounds(low=0, high=60, unit="s", low_open=True),
    ),
    worlds: int = bounded(256, "--worlds", help="Parallel worlds;", bounds=WORLDS),
    backend: str = typer.Option("auto", "--backend", help="auto, mujoco or newton."),
    seed: int | None = bounded(
        None, "--seed", help="Random seed (default: the file's when it is resumed, else one drawn anew and printed, "
        "so that two collections never draw the same samples);", bounds=SEED,
    ),
    library: Path | None = typer.Option(None, "--library", help="Library folder (default: the shipped library/)."),
    chunk: int | None = bounded(
        None, "--chunk", help="Samples per chunk, the unit of work and of a commit (default: 16 per world);",
        bounds=CHUNK,
    ),
    ray: bool = ray_option(),
    address: str | None = ray_address_argument(),
    workers: int | None = workers_option(),
) -> None:
    """Collect policy-switch samples into HDF5: run m, switch to n at a random phase, label whether it stays up."""
    from rich.console import Console
    from rich.markup import escape

    from gaitlib.cli.options import check_worlds, cluster_config, parse_pairs
    from gaitlib.cli.preflight import writable_file
    from gaitlib.cli.progress import job_progress
    from gaitlib.collection import CollectConfig, collect
    from gaitlib.library import Library
    from gaitlib.meta import TrialProtocol

    cluster = cluster_config(ray, address, workers)
    check_worlds("--worlds", worlds, backend=backend)
    writable_file("--out", out)
    lib = Library(library)
    names = lib.order(gaits.split(",") if gaits else None)
    drawn = False
    if seed is None:  # a resumed file's own seed, else a new one (said at the end)
        seed = _recorded_seed(out)
        drawn = seed is None
        seed = _draw_seed() if drawn else seed
    config = CollectConfig(
        samples=int(samples),
        num_worlds=worlds,
        protocol=TrialProtocol.collection(**({} if horizon is None else {"horizon_s": horizon})),
        push_max=push_max,
        pairs=parse_pairs(pairs, names, identities=lib.identities()),
        backend=backend,
        seed=seed,
        chunk=chunk,
    )
    console = Console(stderr=True)
    with job_progress(console, "collect") as progress:
        task = progress.add_task("collect", total=config.samples, status="building the worlds")
        last_line = [-math.inf]

        def show(p) -> None:
            rates = " ".join(f"{m}-{n} {r:.2f}" for (m, n), r in sorted(p.success_rates.items()))
            done = p.samples + p.under_way
            left = (p.target - done) / p.samples_per_s if p.samples_per_s > 0 else math.inf
            status = escape(
                f"{p.samples_per_s:6.1f} samples/s  {p.samples} in the file  ~{_duration(left)} left  success [{rates}]"
            )
            progress.update(task, completed=done, status=status)
            if not console.is_terminal and (p.under_way == 0 or p.elapsed_s - last_line[0] >= 30.0):
                last_line[0] = p.elapsed_s
                console.print(f"{done}/{p.target} {p.elapsed_s:7.0f}s  {status}", soft_wrap=True)

        result = collect(out, library=lib, gaits=names, config=config, progress=show, cluster=cluster)
    if result.note:
        console.print(result.note)
    if drawn:
        console.print(f"seed {seed}, drawn for this collection (--seed {seed} draws the same samples again)",
                      soft_wrap=True)
    console.print(
        f"{result.path}: {result.samples:,} samples ({result.written:,} new, {result.samples_per_s:.1f}/s); "
        + ", ".join(f"{m}-{n} {ok}/{k}" for (m, n), (ok, k) in sorted(result.pair_counts.items())),
        soft_wrap=True,
    )


def _recorded_seed(out: Path) -> int | None:
    """The seed the transition file ``out`` records (a collection without ``--seed`` resumes with it), else
    ``None``."""
    from gaitlib.transitions.schema import recorded_settings

    recorded = recorded_settings(out) if out.is_file() else None
    seed = None if recorded is None else recorded.get("seed")
    return seed if isinstance(seed, int) else None


def _draw_seed() -> int:
    """A seed from the system's entropy, for a new collection without ``--seed``: two collections with one seed
    draw the same samples (``docs/transitions.md``, "Seeds")."""
    import secrets

    return secrets.randbelow(int(SEED.high) + 1)


def states_command(
    out: Path = typer.Option(Path("data/states.npz"), "--out", help="Handover-states file to write (.npz)."),
    per_gait: float = bounded(
        2e4, "--per-gait", help="States of each gait (2e4 is accepted);", bounds=Bounds(low=1, high=1e7, whole=True)
    ),
    push_max: float = bounded(0.0, "--push-max", help="Largest random push while the gaits run (0: none);",
                              bounds=PUSH_N),
    shove_max: float = bounded(0.0, "--shove-max", help="Instead, states 1-3 control steps into single 0.1 s shoves "
                               "of up to this impulse, uniform from 0 (a quarter unshoved), the push under way kept: "
                               "what a catch skill is trained from (gaitlib train catch; 0: none);",
                               bounds=Bounds(low=0, high=200, unit="N s")),
    gaits: str | None = typer.Option(None, "--gaits", help="Comma-separated gaits (default: every library entry)."),
    worlds: int = bounded(256, "--worlds", help="Parallel worlds;", bounds=WORLDS),
    backend: str = typer.Option("auto", "--backend", help="auto, mujoco or newton."),
    seed: int = bounded(0, "--seed", help="Random seed;", bounds=SEED),
    library: Path | None = typer.Option(None, "--library", help="Library folder (default: the shipped library/)."),
) -> None:
    """Record handover states of a library's gaits as they run (body, velocities, observation history, previous
    actions), for switch-start training: gaitlib train GAIT --states OUT; with --shove-max, the states the catch skill
    is trained from (gaitlib train catch --states OUT)."""
    from rich.console import Console

    from gaitlib.cli.options import check_worlds
    from gaitlib.cli.preflight import writable_file
    from gaitlib.cli.progress import job_progress
    from gaitlib.library import Library
    from gaitlib.transitions.states import StatesConfig, record_states

    writable_file("--out", out)
    check_worlds("--worlds", worlds, backend=backend)
    lib = Library(library)
    names = lib.order(gaits.split(",") if gaits else None)
    config = StatesConfig(per_gait=int(per_gait), push_max=push_max, shove_max_ns=shove_max, num_worlds=worlds,
                          backend=backend, seed=seed)
    console = Console(stderr=True)
    with job_progress(console, "states") as progress:
        task = progress.add_task("states", total=len(names) * config.per_gait, status="")
        states = record_states(
            lib, gaits=names, config=config, progress=lambda done, total: progress.update(task, completed=done)
        )
    states.save(out)
    console.print(f"{out}: {len(states):,} handover states of {', '.join(states.gaits)}", soft_wrap=True)


def _duration(seconds: float) -> str:
    """``seconds`` as ``1h02m``, ``3m05s`` or ``42s`` (``?`` before there is a rate)."""
    if not math.isfinite(seconds):
        return "?"
    seconds = max(0, round(seconds))
    if seconds >= 3600:
        return f"{seconds // 3600}h{seconds % 3600 // 60:02d}m"
    return f"{seconds // 60}m{seconds % 60:02d}s" if seconds >= 60 else f"{seconds}s"


def fit_command(
    ctx: typer.Context,
    data: list[Path] = typer.Option(
        [Path("data/transitions.h5")], "--data", help="HDF5 transition samples; repeat to fit on several files."
    ),
    input_kind: str = typer.Option("latent", "--input", help="latent, phase or explicit."),
    epochs: int = bounded(100, "--epochs", help="Training epochs;", bounds=COUNT),
    seed: int = bounded(0, "--seed", help="Random seed;", bounds=SEED),
    ablation: bool = typer.Option(False, "--ablation", help="Fit all three inputs and compare with the paper."),
    evaluate: bool = typer.Option(False, "--evaluate", help="Score the library's net on --data instead of fitting."),
    curve: str | None = typer.Option(
        None, "--curve", help="Measure the learning curve instead of fitting (writes nothing): held-out accuracy "
        "per pair of a net fitted on the first N collected samples of each pair, for each N of this list or "
        "START:STOP:STEP (docs/transitions.md, \"Growing the library\")."
    ),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
    library: Path | None = typer.Option(
        None, "--library", help="Library to fit into (default: $GAITLIB_LIBRARY, else your own runs/library, made "
        "from the shipped one on its first write); with --evaluate, the library read (default: the shipped one)."
    ),
    falls: str = falls_option(),
    replace: bool = typer.Option(False, "--replace", help="Fit into the shipped library (refused without it)."),
    min_per_label: int = bounded(
        MIN_PER_LABEL, "--min-per-label", help="Fewest successful and fewest failed switches each ordered pair "
        "needs, so that its held-out fifth validates the fit (0: accept a fit that cannot be validated);",
        bounds=Bounds(low=0, high=1e6, whole=True),
    ),
    per_pair: int | None = bounded(
        None, "--per-pair", help="Fit on the first N collected samples of each ordered pair of each --data file, as "
        "a shorter collection with the same seed holds them (default: every sample; docs/transitions.md, \"The "
        "switch-success budget\");", bounds=Bounds(low=1, high=1e8, whole=True),
    ),
    extend: bool = typer.Option(
        False, "--extend", help="Fit only the pairs the data hold and keep the library's switching models for the "
        "rest (growth that costs the new pairs only; docs/transitions.md, \"Growing by extension\")."
    ),
) -> None:
    """Fit the transition-net (balanced per pair, held-out balanced validation) and the TMT with its calibrated
    thresholds, and write both to the library; the labels follow --falls (every sample holds both outcomes). With
    --extend, only the pairs of the data are fitted, and the library's models kept for the others."""
    from gaitlib.cli.preflight import no_effect, writing_library
    from gaitlib.library import Library
    from gaitlib.library.target import check_library, copy_library, library_writer
    from gaitlib.strategies.extend import extend_library, kept_models
    from gaitlib.strategies.fitting import check_validatable, evaluate_library, fit_library
    from gaitlib.transition_net import INPUT_KINDS, check_input_kinds
    from gaitlib.transitions import read_all

    no_effect(ctx, ("replace", "ablation", "epochs", "seed", "input_kind", "min_per_label", "curve", "per_pair",
                    "extend"), when=evaluate,
              because="with --evaluate (it scores the library's net and fits nothing)")
    if curve is not None:
        no_effect(ctx, ("replace", "ablation", "min_per_label", "per_pair", "extend"), when=True,
                  because="with --curve (it fits into no library)")
        _curve(data, curve, library=library, input_kind=input_kind, epochs=epochs, seed=seed, falls=falls,
               as_json=as_json)
        return
    if evaluate:
        lib = Library(library)
        samples = read_all(data, current=lib.identities())
        _report(evaluate_library(lib, samples, sources=data, falls=falls), as_json)
        return
    check_input_kinds((input_kind,))  # before the library is copied
    target, copy_from = writing_library(library, replace=replace, command="gaitlib fit", what="the switching models")
    check_library(copy_from or target, command="gaitlib fit")
    if extend:  # no, damaged or stale models to keep, or of another input or falls: refused before any copy
        kept_models(Library(copy_from or target), input_kind=input_kind, falls=falls)
    samples = read_all(data, current=Library(copy_from or target).identities(), per_pair=per_pair)  # foreign: refused
    check_validatable(samples, falls=falls, min_per_label=min_per_label)  # too few to validate: refused here too
    inputs = (input_kind, *(k for k in INPUT_KINDS if k != input_kind)) if ablation else (input_kind,)
    if copy_from is not None:
        copy_library(copy_from, target)
    with library_writer(target, command="gaitlib fit"):
        lib = Library(target)
        report = (extend_library if extend else fit_library)(lib, samples, sources=data, inputs=inputs, epochs=epochs,
                                                             seed=seed, falls=falls, min_per_label=min_per_label)
    _report(report.as_dict(), as_json)
    if not as_json:
        if report.note:
            print(f"data: {report.note}")
        if extend:
            for by, what in (("kept", "the library's kept models"), ("new", "the new fit")):
                print(f"served by {what}: {', '.join(p for p, s in report.served.items() if s == by) or 'none'}")
        uncovered = ", ".join(report.uncovered) or "none"
        print(f"wrote {lib.switching_dir}; pairs of the library it does not cover: {uncovered}")
        if (lib.switching_dir / Library.ROUTES).is_file():
            print(f"stale now: the route table {lib.switching_dir / Library.ROUTES} was measured with the switching "
                  f"models this fit replaced; gaitlib library --library {lib.root} gives the command that measures it "
                  "again")


def _curve(data: list[Path], sizes: str, *, library: Path | None, input_kind: str, epochs: int, seed: int,
           falls: str, as_json: bool) -> None:
    """``gaitlib fit --curve``: the learning curve of the net on ``data`` (nothing written)."""
    import sys

    from gaitlib.library import Library
    from gaitlib.transition_net import TEST_FRACTION, FitConfig, check_input_kinds, learning_curve
    from gaitlib.transitions import read_all
    from gaitlib.values import parse_values

    counts = parse_values(sizes, option="--curve", bounds=Bounds(low=1, high=1e7, whole=True), example="250,500,1000")
    check_input_kinds((input_kind,))
    samples = read_all(data, current=Library(library).identities())  # foreign data: refused before any fit
    config = FitConfig(kind=input_kind, epochs=epochs, seed=seed, falls=falls)
    points = learning_curve(samples, [int(n) for n in counts], config=config, progress=lambda p: print(
        f"{p.samples_per_pair} samples per pair: mean held-out accuracy {100 * p.mean_accuracy:.2f}%", file=sys.stderr,
        flush=True))
    result = {"data": [str(d) for d in data], "input": input_kind, "epochs": epochs, "seed": seed, "falls": falls,
              "test_fraction": TEST_FRACTION, "points": [p.as_dict() for p in points]}
    if as_json:
        print(json_text(result))
        return
    from rich.table import Table

    from gaitlib.cli.tables import table_console

    table = Table(title=f"learning curve: held-out balanced accuracy (%) per ordered pair against the samples "
                        f"collected per pair ({input_kind} net, labels by the {falls} definition of a fall)")
    table.add_column("pair")
    for p in points:
        table.add_column(str(p.samples_per_pair), justify="right")
    for pair in sorted({pair for p in points for pair in p.accuracy}):
        table.add_row(pair, *(f"{100 * p.accuracy[pair]:.2f}" if pair in p.accuracy else "-" for p in points))
    table.add_row("mean", *("-" if math.isnan(p.mean_accuracy) else f"{100 * p.mean_accuracy:.2f}" for p in points))
    table.add_row("trained on", *(str(p.trained_on) for p in points))
    table_console().print(table)


def _report(report: dict, as_json: bool) -> None:
    if as_json:
        print(json_text(report))
        return
    from rich.table import Table

    from gaitlib.cli.tables import table_console
    from gaitlib.strategies.fitting import PAPER_PAIRS, PAPER_TABLE_3

    rows = report.get("balanced_validation_accuracy") or {"library net": report["accuracy"]}
    pairs = [p for p in PAPER_PAIRS if any(p in r for r in rows.values())]
    pairs += sorted({p for r in rows.values() for p in r} - set(pairs))
    table = Table(title=f"balanced accuracy (%) per ordered pair (paper Table 3, one row a pair), labels by the "
                        f"{report.get('falls', 'trunk')} definition of a fall")
    table.add_column("pair")
    columns = []
    for kind, accuracy in rows.items():
        columns.append(accuracy)
        table.add_column(kind, justify="right")
        if kind in PAPER_TABLE_3:
            columns.append(dict(zip(PAPER_PAIRS, PAPER_TABLE_3[kind], strict=True)))
            table.add_column(f"paper {kind}", justify="right")
    for pair in pairs:
        table.add_row(pair, *(f"{100 * column[pair]:.2f}" if pair in column else "-" for column in columns))
    table_console().print(table)


def map_command(
    data: Path = typer.Argument(..., help="A transition file (gaitlib collect --out)."),
    out: Path | None = typer.Option(None, "--out", help="Folder for map.png and map.json (default: DATA-map/)."),
    bins: int = bounded(10, "--bins", help="Phase bins per cycle;", bounds=Bounds(low=2, high=100, whole=True)),
    falls: str = falls_option(),
) -> None:
    """Map where switches fail: per ordered pair, success over source x destination phase, per tenth of either
    cycle and by the feet on the ground, with counts and 95% intervals, and when switch-caused falls happen."""
    from gaitlib.benchmark.maps import fall_time_quantile, transition_maps, write_map_json, write_map_plot
    from gaitlib.cli.preflight import writable_folder
    from gaitlib.cli.tables import print_measures, table_console
    from gaitlib.transitions import read

    out = writable_folder("--out", out if out is not None else data.with_name(data.stem + "-map"))
    samples = read(data)
    maps = transition_maps(samples, bins=bins, falls=falls)
    out.mkdir(parents=True, exist_ok=True)
    write_map_json(maps, out / "map.json", source=str(data), falls=falls)
    write_map_plot(maps, out / "map.png", title=f"{data.name}: switch success")

    from rich.table import Table

    def rate(r) -> str:
        return f"{100 * r.rate:.0f}% [{100 * r.ci95[0]:.0f}, {100 * r.ci95[1]:.0f}] of {r.samples}"

    table = Table(title=f"{data}: success of a switch (falls: {falls} definition; 95% interval, samples); bins of "
                        f"1/{bins} cycle; leg touches beside")
    for column in ("pair", "random switch", "best source bin", "worst source bin", "best dest bin", "worst dest bin",
                   "touches"):
        table.add_column(column, justify="left" if column == "pair" else "right")
    for m in maps:
        best, worst = m.best_worst_source_bins()
        dest = sorted(m.by_dest_phase, key=lambda r: r.rate)
        table.add_row(m.pair, rate(m.overall), rate(best), rate(worst), rate(dest[-1]), rate(dest[0]), rate(m.touches))
    table_console().print(table)
    q99 = fall_time_quantile(maps)
    print_measures(
        "switch-caused falls",
        [
            ("falls with a recorded time", str(sum(len(m.fall_after_s) for m in maps))),
            ("99% of them within (s)", "-" if q99 is None else f"{q99:.2f}"),
            ("horizon of the file (s)", f"{samples.header.settings.get('horizon_s', math.nan):g}"),
            ("written", f"{out / 'map.png'}, {out / 'map.json'}"),
        ],
    )
