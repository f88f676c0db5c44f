"""``gaitlib eval GAIT``: a library policy evaluated under paper Table 1 randomization, or its fall rate against
one push's impulse."""

from __future__ import annotations

from pathlib import Path

import typer

from gaitlib.atomic import json_text
from gaitlib.cli.guarding import guard_margin_option, opt_in_guard_option
from gaitlib.cli.options import DELAY_STEPS, EPISODE_SECONDS, PUSH_N, SEED, WORLDS, Bounds, bounded, falls_option
from gaitlib.cli.tables import print_measures, rate_text
from gaitlib.defaults import Falls

__all__ = ["eval_command"]


def eval_command(
    ctx: typer.Context,
    gait: str = typer.Argument(..., help="Library entry to evaluate."),
    episodes: int = bounded(256, "--episodes", help="Episodes (one world each);", bounds=WORLDS),
    seconds: float = bounded(20.0, "--seconds", help="Episode length;", bounds=EPISODE_SECONDS),
    backend: str = typer.Option("auto", "--backend", help="auto, mujoco or newton."),
    seed: int = bounded(0, "--seed", help="Random seed;", bounds=SEED),
    push_max: float = bounded(
        0.0, "--push-max", help="Largest random push during the episodes (0: none);", bounds=PUSH_N
    ),
    action_delay: int | None = bounded(
        None, "--action-delay", help="Control steps (33 ms) every action waits (default: training's random delay);",
        bounds=DELAY_STEPS,
    ),
    late: int = bounded(0, "--late", help="Every action this many control steps later than trained (the delay's "
                        "range shifted);", bounds=Bounds(low=0, high=3, whole=True)),
    impulses: str | None = typer.Option(
        None, "--impulses",
        help="Instead: one push per episode of each impulse, N s, START:STOP:STEP or a list (e.g. 0:30:3), in [0, "
        "200]; fall rate per impulse (--episodes each) and direction, 0.1 s pushes at random phases.",
    ),
    plot: Path | None = typer.Option(None, "--plot", help="With --impulses: the curve as a PNG."),
    library: Path | None = typer.Option(None, "--library", help="Library folder (default: the shipped library/)."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object instead of a table."),
    falls: str = falls_option(),
    record: bool = typer.Option(
        False, "--record", help="Store this evaluation as the entry's own (its metadata.json; the weights untouched), "
        "in the library --library names, else $GAITLIB_LIBRARY, else your own runs/library."
    ),
    replace: bool = typer.Option(False, "--replace", help="With --record: into the shipped library (refused without)."),
    guard: bool = opt_in_guard_option("Run on the meta-controller with the guard on, beside the same draws unguarded, "
                                      "under --impulses or --push-max (docs/switching.md, \"The guard\")."),
    guard_margin: float | None = guard_margin_option(opt_in=True),
) -> None:
    """Evaluate a library policy under paper Table 1 randomization: falls, leg touches, heading held, tracking
    errors; or, with --impulses, its fall rate against a single push's impulse (with --guard, guarded and not)."""
    from gaitlib.cli.options import IMPULSE_NS, check_worlds, parse_values
    from gaitlib.cli.preflight import no_effect, writable_file, writing_library
    from gaitlib.library import Library

    no_effect(ctx, ("replace",), when=not record, because="without --record (nothing is written)")
    no_effect(ctx, ("plot",), when=impulses is None, because="without --impulses (the push curve is what it plots)")
    no_effect(ctx, ("seconds", "push_max", "action_delay", "late"), when=impulses is not None,
              because="with --impulses (each episode is the push curve's: one 0.1 s push, the trained delay)")
    no_effect(ctx, ("record",), when=impulses is not None,
              because="with --impulses (it stores the quality-bar evaluation, not a push curve)")
    check_worlds("--episodes", episodes, backend=backend)
    values = None if impulses is None else parse_values(impulses, option="--impulses", bounds=IMPULSE_NS,
                                                        example="0:30:3")
    if plot is not None:
        writable_file("--plot", plot)
    if guard or guard_margin is not None:
        from gaitlib.cli.survival import guarded_curve

        guarded_curve(gait, library, values, guard_margin, record=record, episodes=episodes, seconds=seconds,
                      push_max=push_max, other=action_delay is not None or late > 0, backend=backend, seed=seed,
                      plot=plot, as_json=as_json, falls=falls)
        return
    if values is not None:
        lib = Library(library)
        _push_curve(lib.entry(gait), lib, values, episodes=episodes, backend=backend, seed=seed, plot=plot,
                    as_json=as_json, falls=falls)
        return
    if not record:
        _evaluate(Library(library), gait, episodes=episodes, seconds=seconds, backend=backend, seed=seed,
                  push_max=push_max, action_delay=action_delay, late=late, falls=falls, as_json=as_json)
        return
    # --record: into the library a writing command writes (gaitlib.library.target), a protected one on purpose only,
    # its writer lock held from before the evaluation (a second writer is refused before, not after, the work)
    from gaitlib.library.target import copy_library, library_writer

    library, copy_from = writing_library(library, replace=replace, command="gaitlib eval --record",
                                         what=f"the entry {gait}")
    Library(copy_from or library).entry(gait)  # an unknown gait: one line, before the copy
    if copy_from is not None:
        copy_library(copy_from, library)
    with library_writer(library, command="gaitlib eval --record"):
        _evaluate(Library(library), gait, episodes=episodes, seconds=seconds, backend=backend, seed=seed,
                  push_max=push_max, action_delay=action_delay, late=late, falls=falls, as_json=as_json, record=True)


def _evaluate(lib, gait: str, *, episodes: int, seconds: float, backend: str, seed: int, push_max: float,
              action_delay: int | None, late: int, falls: str, as_json: bool, record: bool = False) -> None:
    """``gaitlib eval GAIT`` without ``--impulses``: evaluate, store it as the entry's own with ``record`` (the
    caller holds the library's writer lock), and print it."""
    from gaitlib.envs import EnvConfig
    from gaitlib.evaluation import evaluate_policy

    entry = lib.entry(gait)
    result = evaluate_policy(
        entry.policy,
        entry.clip,
        env_cfg=lib.shared_policy_settings([gait]).env_config(EnvConfig()),
        episodes=episodes,
        seconds=seconds,
        backend=backend,
        push_max=push_max,
        action_delay_steps=action_delay,
        late_steps=late,
        falls=falls,
        seed=seed,
    )
    if record:
        from gaitlib.values import number_text

        command = (f"gaitlib eval {gait} --episodes {episodes} --seconds {number_text(seconds)} --push-max "
                   f"{number_text(push_max)} --seed "
                   f"{seed} --backend {backend} --falls {falls}"
                   + ("" if action_delay is None else f" --action-delay {action_delay}")
                   + (f" --late {late}" if late else ""))
        lib.record_evaluation(gait, result.as_dict() | {"seed": seed, "command": command})
    if as_json:
        print(json_text({"gait": gait} | result.as_dict()))
        return
    print_measures(
        f"eval {gait}: {episodes} episodes x {seconds:g} s, Table 1 randomization, pushes <= {push_max:g} N, action "
        + ("delay 0-1 steps" if action_delay is None else f"delay {action_delay} step(s)")
        + (f", {late} step(s) late" if late else ""),
        [
            (f"falls ({result.falls} definition)", rate_text(result.fall_rate, result.fall_ci95)),
            ("leg touches (episodes with a non-foot body on the ground)",
             rate_text(result.touch_rate, result.touch_ci95)),
            ("longest touch (s)", f"{result.longest_touch_s:.3f}"),
            ("falls by cause (one may meet several)",
             ", ".join(f"{name.replace('_', ' ')} {n}" for name, n in result.falls_by_cause.items()) or "-"),
            ("heading lost (> 90 deg)", f"{result.heading_loss_rate:.3f}"),
            ("median |heading change| (deg)", f"{result.median_heading_change_deg:.1f}"),
            ("joint tracking RMSE (rad)", f"{result.joint_rmse:.4f}"),
            ("feet in the reference's contact state", f"{result.contact_agreement:.3f}"),
            ("forward speed (m/s)", f"{result.forward_speed:.3f}"),
            ("reference speed (m/s)", f"{result.reference_speed:.3f}"),
            ("speed error", f"{result.speed_error:.3f}"),
            *_steering_rows(result.steering),
            ("mean episode length (s)", f"{result.mean_episode_seconds:.2f}"),
        ],
        header=("metric", "value"),
    )


def _steering_rows(steering) -> list[tuple[str, str]]:
    """The rows of ``gaitlib eval``'s table for a gait that sidesteps or turns (none for one that goes straight)."""
    if steering is None:
        return []
    return [
        ("lateral speed (m/s)", f"{steering.lateral_speed:.3f}"),
        ("reference lateral speed (m/s)", f"{steering.reference_lateral_speed:.3f}"),
        ("lateral speed error", f"{steering.lateral_speed_error:.3f}"),
        ("yaw rate (rad/s)", f"{steering.yaw_rate:.3f}"),
        ("reference yaw rate (rad/s)", f"{steering.reference_yaw_rate:.3f}"),
        ("yaw rate error", f"{steering.yaw_rate_error:.3f}"),
        ("median |heading - reference heading| (deg)", f"{steering.median_heading_error_deg:.1f}"),
    ]


def _push_curve(entry, lib, impulses, *, episodes: int, backend: str, seed: int, plot: Path | None,
                as_json: bool, falls: Falls) -> None:
    """``gaitlib eval GAIT --impulses ...``: the single-push curve as a table (or JSON) and a plot."""
    from gaitlib.envs import EnvConfig
    from gaitlib.evaluation import SECTORS, single_push_curve, write_push_plot

    points = single_push_curve(
        entry.policy, entry.clip, env_cfg=lib.shared_policy_settings([entry.name]).env_config(EnvConfig()),
        impulses=impulses, episodes=episodes, backend=backend, seed=seed, falls=falls,
    )
    if plot is not None:
        write_push_plot({entry.name: points}, plot)
    if as_json:
        print(json_text({"gait": entry.name, "points": [p.as_dict() for p in points]}))
        return
    from rich.table import Table

    from gaitlib.cli.tables import table_console

    table = Table(title=f"{entry.name}: falls ({falls} definition) under one push of 0.1 s per episode ({episodes} "
                        "episodes each, 95% interval), per direction, and the episodes with a leg's touch")
    for column in ("impulse N s", "force N", "falls", *SECTORS, "touches", "longest touch s"):
        table.add_column(column, justify="right")
    for p in points:
        sectors = (f"{f}/{k}" for f, k in p.by_sector.values())
        table.add_row(f"{p.impulse_ns:g}", f"{p.force_n:.0f}", rate_text(p.fall_rate, p.fall_ci95, digits=1),
                      *sectors, rate_text(p.touch_rate, p.touch_ci95, digits=1), f"{p.longest_touch_s:.2f}")
    table_console().print(table)
