"""``gaitlib survival record`` (the states the guard's survival estimate learns from) and ``gaitlib survival fit``
(the estimate, its calibration, horizon and margin, into the library's switching folder)."""

from __future__ import annotations

import sys
from pathlib import Path

import typer

from gaitlib.atomic import json_text
from gaitlib.cli.options import COUNT, SEED, WORLDS, Bounds, bounded, falls_option
from gaitlib.defaults import MIN_CATCH_WORLDS, MIN_UNSHOVED_MINUTES, Falls
from gaitlib.values import GUARD_HORIZON_S, GUARD_MARGIN, IMPULSE_NS, OptionError, number_text, parse_values

__all__ = ["app", "guarded_curve"]

app = typer.Typer(help="The guard's survival estimate: record states before falls and survivals, fit it.")

_LIBRARY = typer.Option(None, "--library", help="Library to read (default: $GAITLIB_LIBRARY, else the shipped "
                        "library/).")
_CATCH_EPISODES = Bounds(low=4 * MIN_CATCH_WORLDS, high=COUNT.high, whole=True)
"""``survival catches --episodes``: enough worlds for each of the four directions of shove."""
_WRITTEN = typer.Option(None, "--library", help="Library to write into (default: $GAITLIB_LIBRARY, else your own "
                        "runs/library, made from the shipped one on its first write; one rule for every writer).")


@app.command("record")
def record_command(
    out: Path = typer.Option(Path("data/survival.h5"), "--out", help="State file (HDF5; resumed if it exists)."),
    episodes: int = bounded(1024, "--episodes", help="Episodes the file holds when done;", bounds=COUNT),
    worlds: int = bounded(256, "--worlds", help="Episodes run at once;", bounds=WORLDS),
    impulse_max: float = bounded(30.0, "--impulse-max", help="Largest shove, uniform from 0;",
                                 bounds=Bounds(low=0, high=200, unit="N s")),
    switch_phase: str = typer.Option("best", "--switch-phase", help="Destination phase of the recorded switches: "
                                     "best (the calibrated net's, as gaitlib run switches) or uniform."),
    seed: int = bounded(0, "--seed", help="Random seed (batch b runs with seed + b);", bounds=SEED),
    backend: str = typer.Option("mujoco", "--backend", help="auto, mujoco or newton."),
    falls: str = falls_option(),
    library: Path | None = _LIBRARY,
) -> None:
    """Record states of every gait before falls and survivals: one shove of 0 to --impulse-max N s per episode,
    a quarter of them unshoved and a quarter switched to another gait first (docs/switching.md, "The guard")."""
    from gaitlib.cli.options import check_worlds
    from gaitlib.cli.preflight import writable_file
    from gaitlib.collection.survival import SurvivalRecording, record_survival
    from gaitlib.meta import load_switching

    writable_file("--out", out)
    check_worlds("--worlds", worlds, backend=backend)
    config = SurvivalRecording(episodes=episodes, num_worlds=worlds, impulse_max_ns=impulse_max, seed=seed,
                               backend=backend, falls=falls, switch_phase=switch_phase)
    setup = load_switching(library)
    setup.resources.calibration  # noqa: B018 (refuse a library without a calibrated net before any work)
    data = record_survival(out, setup, config, progress=lambda d, t: print(f"{d}/{t} episodes", flush=True))
    print(f"{out}: {len(data['gait']):,} states of {episodes} episodes; fit: gaitlib survival fit {out}"
          + (f" --library {library}" if library else ""))


@app.command("fit")
def fit_command(
    data: Path = typer.Argument(..., help="A state file of gaitlib survival record."),
    horizons: str = typer.Option("0.5,1,1.5", "--horizons", help="Horizons to choose from, s, each in (0, 5] and "
                                 "at least one control step: START:STOP:STEP or a list."),
    margin: float | None = bounded(None, "--margin", help="Use this margin instead of choosing it (chosen on at "
                                   f"least {MIN_UNSHOVED_MINUTES:g} unshoved minute(s) of the selection split "
                                   "otherwise);", bounds=GUARD_MARGIN),
    floor: str = typer.Option("0", "--floor", help="Below this estimate the guard catches whatever the margin, in "
                              "[0, 1) (0: never), or auto: the highest of 0-0.5 with at most 0.1 false alarms per "
                              "unshoved minute on the selection split (docs/switching.md, \"The guard\")."),
    inputs: str = typer.Option("latent,phase,imu", "--inputs", help="Inputs besides the gait: latent, phase, imu "
                               "(the trunk's acceleration, as an IMU reads it), value (the critic's, privileged: not "
                               "exportable to a robot), explicit."),
    epochs: int = bounded(20, "--epochs", help="Training epochs;", bounds=COUNT),
    seed: int = bounded(0, "--seed", help="Split and training seed;", bounds=SEED),
    library: Path | None = _WRITTEN,
    replace: bool = typer.Option(False, "--replace", help="Write into a protected library (refused without it)."),
    as_json: bool = typer.Option(False, "--json", help="Print the report as one JSON object."),
) -> None:
    """Fit the survival estimate on recorded states, calibrate it, choose the guard's horizon and margin on a
    held-out split, write it into the library's switching folder and report it (the library held for the whole run:
    a second writer of it is refused; a catch table the old estimate held is dropped)."""
    from gaitlib.collection.survival import read_survival_states
    from gaitlib.library import Library
    from gaitlib.library.target import copy_library, library_writer
    from gaitlib.strategies.survival import check_guard, save_survival
    from gaitlib.strategies.survival_fit import check_fit, fit_survival

    chosen = parse_values(horizons, option="--horizons", bounds=GUARD_HORIZON_S, example="0.5:1.5:0.5")
    try:
        chosen_floor = None if floor == "auto" else float(floor)
    except ValueError:
        raise OptionError(f"--floor must be a number in [0, 1) or auto, got '{floor}'") from None
    check_guard(margin=margin, floor=chosen_floor)
    target, copy_from = _writing(library, replace=replace, command="gaitlib survival fit", what="the survival estimate")
    header, states = read_survival_states(data)  # a foreign file, a number no recording writes: refused here
    Library(copy_from or target).check_identities(header["identities"], what=f"survival states {data}")
    options = {"inputs": tuple(i.strip() for i in inputs.split(",")), "horizons_s": chosen, "margin": margin,
               "floor": chosen_floor, "seed": seed}
    check_fit(states, dt=header["dt"], **options)  # estimates chosen on too little: refused before the copy
    if copy_from is not None:
        copy_library(copy_from, target)
    with library_writer(target, command="gaitlib survival fit"):
        estimate = fit_survival(states, gaits=tuple(header["gaits"]), identities=header["identities"],
                                dt=header["dt"], epochs=epochs, **options)
        path = save_survival(Library(target), estimate, data=data)
    report = estimate.info["report"]
    if as_json:
        print(json_text({"path": str(path), "horizon_s": estimate.horizon_s, "margin": estimate.margin,
                         "margin_given": margin is not None, "floor": estimate.floor} | estimate.info))
        return
    how = "given" if margin is not None else "chosen on the selection split"
    print(f"{path}: horizon {number_text(estimate.horizon_s)} s, margin {number_text(estimate.margin)} ({how}), "
          f"floor {number_text(estimate.floor)}" + (" (chosen there too)" if chosen_floor is None else ""))
    print("reliability (selection split): predicted -> observed (states)")
    for row in report["reliability"]:
        print(f"  {row['bin'][0]:.1f}-{row['bin'][1]:.1f}: {row['predicted']:.3f} -> {row['observed']:.3f} "
              f"({row['states']})")
    lead, p10 = (report[k] for k in ("lead_median_s", "lead_p10_s"))
    print(f"falls warned before: {report['warned']} of {report['falls']}; lead time median "
          f"{'-' if lead is None else f'{lead:.2f} s'}, 10th percentile {'-' if p10 is None else f'{p10:.2f} s'}")
    alarms = report["false_alarms_per_min"]
    print(f"false alarms at 0 N: {'-' if alarms is None else f'{alarms:.3f}'} per minute "
          f"(over {report['unshoved_minutes']:.1f} unshoved minutes)")


@app.command("catches")
def catches_command(
    episodes: int = bounded(256, "--episodes", help="Worlds per running gait and catch gait (at least "
                            f"{MIN_CATCH_WORLDS} per direction of shove);", bounds=_CATCH_EPISODES),
    impulse: float = bounded(18.0, "--impulse", help="The shove;", bounds=IMPULSE_NS),
    delay: int = bounded(2, "--delay", help="Control steps from the shove's start to the catch;",
                         bounds=Bounds(low=0, high=30, whole=True)),
    seed: int = bounded(1000, "--seed", help="Random seed (gait g's draws: seed + g), apart from evaluation seeds;",
                        bounds=SEED),
    backend: str = typer.Option("mujoco", "--backend", help="auto, mujoco or newton."),
    falls: str = falls_option(),
    into: str | None = typer.Option(None, "--into", help="Comma-separated gaits a catch may go to (default: every "
                                    "gait); a gait with no other among them is never caught."),
    library: Path | None = _WRITTEN,
    replace: bool = typer.Option(False, "--replace", help="Write into a protected library (refused without it)."),
    as_json: bool = typer.Option(False, "--json", help="Print the table as one JSON object."),
) -> None:
    """Measure where the guard catches each gait to and write it into the library's survival estimate: every gait
    shoved once, caught --delay steps later into each other gait (or each of --into) in turn; in each direction of
    shove, the one that fell least is its catch where it fell less than staying (docs/switching.md, "The guard").
    The library is held for the whole run: a refit of the estimate meanwhile is refused."""
    from gaitlib.atomic import file_sha256
    from gaitlib.benchmark.catches import CatchTableConfig, fit_catch_table
    from gaitlib.library import Library
    from gaitlib.library.target import copy_library, library_writer
    from gaitlib.meta import load_switching
    from gaitlib.strategies.survival import save_catch_table

    names = None if into is None else tuple(dict.fromkeys(n.strip() for n in into.split(",") if n.strip()))
    if names == ():
        raise OptionError("--into names no gait")
    config = CatchTableConfig(impulse_ns=impulse, episodes=episodes, delay_steps=delay, seed=seed, backend=backend,
                              falls=falls, into=names)
    target, copy_from = _writing(library, replace=replace, command="gaitlib survival catches", what="the catch table")
    checked = load_switching(copy_from or target)
    checked.guard()  # no survival estimate, a stale or damaged one: one line, no work
    for name in names or ():
        checked.gait_index(name)  # a gait the library lacks: one line, no work
    if copy_from is not None:
        copy_library(copy_from, target)
    with library_writer(target, command="gaitlib survival catches"):
        measured = file_sha256(Library(target).switching_dir / Library.SURVIVAL)
        setup = load_switching(target)
        table = fit_catch_table(setup, setup.guard(), config,
                                progress=lambda d, t: print(f"{d}/{t} rollouts", file=sys.stderr, flush=True))
        path = save_catch_table(setup.resources.library, table, measured=measured)
    if as_json:
        print(json_text(table))
        return
    print(f"{path}: falls at {number_text(impulse)} N s by the sector the trunk is pushed toward, and the catch chosen "
          "(*)")
    for gait, by_sector in table["falls"].items():
        into = table["catch_into"].get(gait, {})
        for sector, row in by_sector.items():
            counts = ", ".join(f"{d}{'*' if into.get(sector) == d else ''} {k}" for d, k in row.items())
            print(f"  {gait} {sector} ({table['worlds'][gait][sector]} worlds): {counts}")


@app.command("export")
def export_command(
    out: Path = typer.Option(Path("guard"), "--out", help="Folder to write the guard's deployable files into."),
    library: Path | None = _LIBRARY,
) -> None:
    """Export the guard for a robot-side loop: the policies' latents, the survival estimate and the transition-net
    as ONNX, with calibrations, horizon, margin and candidates in guard.json (docs/deploying.md)."""
    from gaitlib.cli.preflight import writable_folder
    from gaitlib.meta import load_switching
    from gaitlib.strategies.guard_export import export_guard

    writable_folder("--out", out)  # a file there, or a folder that cannot be written: one line, before any work
    setup = load_switching(library)
    guard = setup.guard()  # no survival estimate, or a stale or damaged one: one line, before anything is written
    path = export_guard(out, policies=[e.policy for e in setup.entries], estimate=guard.estimate,
                        net=setup.resources.net, calibration=setup.resources.calibration,
                        catchers=tuple(e.name for e in setup.entries if e.description.task == "catch"))
    print(f"{path} (and the ONNX files beside it): horizon {number_text(guard.horizon_s)} s, margin "
          f"{number_text(guard.margin)}")


def _writing(library: Path | None, *, replace: bool, command: str, what: str) -> tuple[Path, Path | None]:
    """(the library ``command`` writes ``what`` into, the library to copy there first) by the one rule of every
    writer of a library (:mod:`gaitlib.library.target`), refused in one line before any work where it is protected
    without ``replace``, held by another writer, not a library, or without (sound) switching models."""
    from gaitlib.cli.preflight import writing_library
    from gaitlib.library import Library
    from gaitlib.library.target import check_library

    target, copy_from = writing_library(library, replace=replace, command=command, what=what)
    check_library(copy_from or target, command=command)
    Library(copy_from or target).check_switching()  # the estimate is published with the switching models' list
    return target, copy_from


def guarded_curve(gait: str, library: Path | None, impulses, margin: float | None, *, record: bool, episodes: int,
                  seconds: float, push_max: float, other: bool, backend: str, seed: int, plot: Path | None,
                  as_json: bool, falls: Falls) -> None:
    """``gaitlib eval GAIT --guard``: with ``impulses``, the single-push curve on the meta-controller, else episodes
    of ``seconds`` under pushes of up to ``push_max`` N; unguarded and guarded on the same draws, with the guard's
    catches. ``other``: an option the guarded evaluation does not take was given (refused)."""
    from gaitlib.benchmark.guarded_push import guarded_push_curve
    from gaitlib.cli.options import OptionError
    from gaitlib.cli.tables import rate_text
    from gaitlib.evaluation import write_push_plot
    from gaitlib.meta import load_switching
    from gaitlib.strategies.survival import check_guard

    if record or other:
        raise OptionError("--guard runs the policies as trained on the meta-controller: it takes neither --record "
                          "nor --action-delay nor --late")
    check_guard(margin=margin)
    setup = load_switching(library)
    setup.gait_index(gait)
    guarding = setup.guard(margin=margin)  # no survival estimate, or a stale one: one line, before any work
    if impulses is None:
        _guarded_pushes(setup, gait, guarding, episodes=episodes, seconds=seconds, push_max=push_max,
                        backend=backend, seed=seed, as_json=as_json, falls=falls)
        return
    curves = {
        label: guarded_push_curve(setup, gait, guard=g, impulses=impulses, episodes=episodes, backend=backend,
                                  seed=seed, falls=falls)
        for label, g in (("unguarded", None), ("guarded", guarding))
    }
    if plot is not None:
        write_push_plot({f"{gait}, {label}": points for label, points in curves.items()}, plot)
    if as_json:
        print(json_text({"gait": gait, "guard": True, "margin": guarding.margin, "horizon_s": guarding.horizon_s,
                         "points": [p.as_dict() for p in curves["guarded"]],
                         "unguarded_points": [p.as_dict() for p in curves["unguarded"]]}))
        return
    from rich.table import Table

    from gaitlib.cli.tables import table_console

    table = Table(title=f"{gait} on the meta-controller, guard on (margin {number_text(guarding.margin)}, "
                        f"horizon {number_text(guarding.horizon_s)} s) and off on the same draws: falls ({falls} "
                        f"definition) under one push of 0.1 s per episode ({episodes} episodes each, 95% interval)")
    for column in ("impulse N s", "falls unguarded", "falls guarded", "worst sector guarded", "catches",
                   "false catches", "delay steps (median)", f"{gait} running"):
        table.add_column(column, justify="right")
    for off, on in zip(curves["unguarded"], curves["guarded"], strict=True):
        worst = max(on.by_sector.items(), key=lambda kv: kv[1][0] / max(1, kv[1][1]))
        delay = on.guard["delay_steps_median"]
        table.add_row(f"{on.impulse_ns:g}", rate_text(off.fall_rate, off.fall_ci95, digits=1),
                      rate_text(on.fall_rate, on.fall_ci95, digits=1), f"{worst[0]} {worst[1][0]}/{worst[1][1]}",
                      str(len(on.guard["catches"])), str(on.guard["false_catches"]),
                      "-" if delay is None else f"{delay:g}", f"{100 * on.guard['measured_gait_share']:.1f}%")
    table_console().print(table)
    for p in curves["guarded"]:
        for c in p.guard["catches"]:
            back = "never" if c["back_after_s"] is None else f"after {c['back_after_s']:.2f} s"
            print(f"{p.impulse_ns:g} N s, world {c['world']}: caught {c['from']} -> {c['to']} at {c['time_s']:.2f} s, "
                  f"{c['delay_steps']} steps after the shove began (staying {c['stay']:.3f}, switching "
                  f"{c['offer']:.3f}); {gait} ran again {back}")


def _guarded_pushes(setup, gait: str, guarding, *, episodes: int, seconds: float, push_max: float, backend: str,
                    seed: int, as_json: bool, falls: Falls) -> None:
    """``gaitlib eval GAIT --push-max N --guard``: falls and catches, unguarded and guarded on the same draws."""
    from gaitlib.benchmark.guarded_push import guarded_episodes
    from gaitlib.cli.tables import rate_text

    runs = {label: guarded_episodes(setup, gait, guard=g, episodes=episodes, seconds=seconds, push_max=push_max,
                                    backend=backend, seed=seed, falls=falls)
            for label, g in (("unguarded", None), ("guarded", guarding))}
    if as_json:
        print(json_text({"gait": gait, "guard": True, "margin": guarding.margin, "horizon_s": guarding.horizon_s}
                        | runs))
        return
    on, off = runs["guarded"], runs["unguarded"]
    print(f"eval {gait} on the meta-controller: {episodes} episodes x {seconds:g} s, pushes <= {push_max:g} N, "
          f"falls ({falls} definition): unguarded {rate_text(off['fall_rate'], off['ci95'])}"
          f", guarded {rate_text(on['fall_rate'], on['ci95'])} (margin {number_text(guarding.margin)}, "
          f"horizon {number_text(guarding.horizon_s)} s)")
    print(f"guard: {len(on['guard']['catches'])} catch(es), {on['catches_per_min']:.3f} per minute of running; "
          f"{gait} ran {100 * on['guard']['measured_gait_share']:.1f}% of the time")
    for c in on["guard"]["catches"]:
        back = "never" if c["back_after_s"] is None else f"after {c['back_after_s']:.2f} s"
        print(f"world {c['world']}: caught {c['from']} -> {c['to']} at {c['time_s']:.2f} s (staying {c['stay']:.3f}, "
              f"switching {c['offer']:.3f}); {gait} ran again {back}")
