"""``gaitlib train GAIT`` and ``gaitlib eval GAIT``."""

from __future__ import annotations

import math
from pathlib import Path

import typer

from gaitlib.atomic import json_text
from gaitlib.cli.options import (
    COUNT,
    DELAY_STEPS,
    EPISODE_SECONDS,
    PUSH_N,
    SEED,
    WORLDS,
    Bounds,
    bounded,
    falls_option,
)
from gaitlib.cli.tables import print_measures, rate_text
from gaitlib.defaults import SWITCH_START, Falls

__all__ = ["eval_command", "train_command"]


def _description(gait: str, gait_file: Path | None):
    from gaitlib.gaits import clip_from_description, get_gait, load_gait_file

    if gait_file is not None:
        description = load_gait_file(gait_file)
        clip_from_description(description)  # a gait its feet cannot carry: one line, before any work
        if description.name != gait:
            from gaitlib.errors import GaitError

            raise GaitError(f"{gait_file} describes gait '{description.name}', not '{gait}'")
        return description
    return get_gait(gait)


def train_command(
    ctx: typer.Context,
    gait: str = typer.Argument(
        ..., help="Gait to train: a shipped description (pace, trot, stand, ...) or --gait-file."
    ),
    preset: str = typer.Option(
        "cpu", "--preset",
        help="cpu (tuned for a 2-core CPU) or paper (Table 2). (tiny is for tests only: it learns nothing, and is "
        "refused in a library of trained gaits.)",
    ),
    iterations: int | None = bounded(
        None, "--iterations", help="PPO iterations (default: the preset's);", bounds=COUNT
    ),
    minutes: float | None = bounded(
        None,
        "--minutes",
        help="Stop after this much training time (default: no limit);",
        bounds=Bounds(low=0, high=1e5, unit="min", low_open=True),
    ),
    backend: str = typer.Option("auto", "--backend", help="auto, mujoco or newton."),
    seed: int = bounded(0, "--seed", help="Random seed;", bounds=SEED),
    gait_file: Path | None = typer.Option(None, "--gait-file", help="TOML gait description of a new gait."),
    library: Path | None = typer.Option(
        None, "--library",
        help="Library to write the gait into (default: $GAITLIB_LIBRARY, else your own runs/library, made from the "
        "shipped library on its first write).",
    ),
    replace: bool = typer.Option(
        False, "--replace", help="Replace the gait's entry in the shipped library (refused without it)."
    ),
    states: Path | None = typer.Option(
        None, "--states", help="Handover states of other gaits (gaitlib states) to start a share of episodes from."
    ),
    switch_start: float | None = bounded(
        None, "--switch-start",
        help="Share of episodes that start from a handover state (default: 0.4 with --states, else 0: the paper's "
        "recipe);", bounds=Bounds(low=0, high=1),
    ),
    run_dir: Path | None = typer.Option(None, "--run-dir", help="Checkpoints and TensorBoard logs (runs/GAIT)."),
    resume: bool = typer.Option(False, "--resume", help="Continue from the run's latest checkpoint."),
    checkpoint_every: int = bounded(50, "--checkpoint-every", help="Iterations between checkpoints;", bounds=COUNT),
    eval_episodes: int = bounded(
        64, "--eval-episodes", help="Episodes of the final evaluation (one world each);", bounds=WORLDS
    ),
    push_kind: str = typer.Option(
        "kick", "--push-kind", help="Training pushes: kick (velocity kicks, legged_gym's and mjlab's way: --kick-max, "
        "--kick-draw, --kick-interval; the shipped library's) or force (the paper's, up to the preset's largest force, "
        "0.1-0.3 s every 1-3 s)."
    ),
    kick_max: float = bounded(1.0, "--kick-max", help="With --push-kind kick: the largest change of speed a kick "
                              "gives along each axis (axes) or in all (disk);",
                              bounds=Bounds(low=0, high=5, unit="m/s")),
    kick_draw: str = typer.Option("axes", "--kick-draw", help="With --push-kind kick: axes (each horizontal axis "
                                  "uniform in +-kick-max: legged_gym's and Isaac Lab's) or disk (a random direction, "
                                  "the magnitude uniform in 0-kick-max)."),
    kick_interval: str = typer.Option("1:3", "--kick-interval", help="With --push-kind kick: the quiet time before "
                                      "each kick, LOW:HIGH s, in (0, 60]."),
    terminate: str = falls_option(
        "--terminate", help="What ends a training episode: trunk (the trunk too low, tilted or on the ground: "
        "legged_gym's, the shipped library's) or contact (any non-foot body on the ground, the paper's)."
    ),
    contact_penalty: float = bounded(5.0, "--contact-penalty", help="Reward taken off per control step while a "
                                     "non-foot body touches the ground (the paper's recipe: 0);",
                                     bounds=Bounds(low=0, high=10)),
    gamma: float = bounded(0.99, "--gamma", help="PPO discount (rsl-rl's locomotion tasks'; the paper's: 0.95);",
                           bounds=Bounds(low=0, high=1, low_open=True)),
    lam: float = bounded(0.95, "--lam", help="GAE lambda;", bounds=Bounds(low=0, high=1, low_open=True)),
    action_delay: int | None = bounded(None, "--action-delay", help="Train with every action this many control "
                                       "steps late, fixed (default: Table 1's random 0-1);",
                                       bounds=Bounds(low=0, high=3, whole=True)),
    critic_delay: bool = typer.Option(False, "--critic-delay", help="The critic sees each world's action delay "
                                      "(privileged; the actor does not)."),
    cycle_sync: bool = typer.Option(False, "--cycle-sync", help="At the start of every gait cycle, re-anchor the "
                                    "reference horizontally where the robot is (Peng et al.'s cycle sync; the "
                                    "reward only)."),
) -> None:
    """Train one gait policy with PPO and write it into a library (other gaits are never touched; the shipped
    library only with --replace). The recipe's robustness levers (--push-kind, --terminate, --contact-penalty,
    --gamma, --lam, --action-delay, --critic-delay, --cycle-sync) are recorded in the entry's metadata; their defaults
    are the shipped library's recipe, and --push-kind force --terminate contact --contact-penalty 0 --gamma 0.95 is
    the paper's."""
    from rich.console import Console

    from gaitlib.cli.options import check_worlds
    from gaitlib.cli.preflight import no_effect, writable_folder
    from gaitlib.cli.progress import job_progress
    from gaitlib.gaits import clip_from_description
    from gaitlib.gaits.feasibility import check_reference
    from gaitlib.library.target import writing_target
    from gaitlib.training import get_preset
    from gaitlib.training.distributed import Ranks
    from gaitlib.training.recipe import Recipe
    from gaitlib.training.target import check_target
    from gaitlib.training.trainer import TrainRequest, resume_point, train_gait

    no_effect(ctx, ("kick_max", "kick_draw", "kick_interval"), when=push_kind == "force",
              because="with --push-kind force (its pushes are forces, not kicks)")
    check_worlds("--eval-episodes", eval_episodes, backend=backend)
    description = _description(gait, gait_file)
    recipe = Recipe(push_kind=push_kind, kick_max=kick_max, kick_draw=kick_draw,
                    kick_interval=_interval(kick_interval), falls=terminate, contact_penalty=contact_penalty,
                    gamma=gamma, lam=lam, action_delay=action_delay, critic_delay=critic_delay,
                    cycle_sync=cycle_sync)
    chosen = recipe.preset(get_preset(preset))
    target, copy_from = writing_target(library)
    writable_folder("--library", target, what="a library folder")
    writable_folder("--run-dir", run_dir or Path("runs") / gait)
    plan = check_target(target, gait, preset=chosen.name, replace=replace, copy_from=copy_from, states=states)
    request = TrainRequest(
        description=description,
        preset=chosen,
        iterations=iterations if iterations is not None else chosen.iterations,
        time_limit_s=None if minutes is None else 60.0 * minutes,
        library=target,
        copy_from=copy_from,
        replace=replace,
        states=states,
        switch_start=switch_start if switch_start is not None else (SWITCH_START if states is not None else 0.0),
        run_dir=run_dir or Path("runs") / gait,
        backend=backend,
        seed=seed,
        resume=resume,
        checkpoint_every=checkpoint_every,
        eval_episodes=eval_episodes,
        recipe=recipe,
    )
    resume_point(request)  # a checkpoint of another run, or none: one line, before the notes below
    if not Ranks.from_env().main:  # under torchrun, rank 0 alone reports
        train_gait(request)
        return
    console = Console(stderr=True)
    for note in plan.notes:
        console.print(f"gaitlib: {note}", soft_wrap=True)
    with job_progress(console, f"train {gait}") as progress:
        task = progress.add_task("train", total=request.iterations, status="starting")

        last_line = [0.0]
        check = [check_reference(clip_from_description(description))]

        def show(stats) -> None:
            if check:  # after the first iteration, so that every refusal stays one line
                console.print(f"gaitlib: {check.pop().summary()}", soft_wrap=True)
            terms = " ".join(f"{k[:4]} {v:.2f}" for k, v in stats.reward_terms.items())
            length = "" if math.isnan(stats.mean_episode_length) else f" ep {stats.mean_episode_length:4.1f}s"
            status = f"{stats.samples_per_s:5.0f} samples/s  reward {stats.mean_reward:.3f}{length}  [{terms}]"
            progress.update(task, completed=stats.iteration, status=status)
            if not console.is_terminal and stats.elapsed - last_line[0] >= 30.0:  # logs get a line every 30 s
                last_line[0] = stats.elapsed
                console.print(
                    f"iteration {stats.iteration}/{stats.total} {stats.elapsed:7.0f}s  {status}", soft_wrap=True
                )

        result = train_gait(request, on_iteration=show)
    e = result.evaluation
    console.print(
        f"wrote {result.entry} after {result.iterations} iterations, {result.samples:,} samples, "
        f"{result.wall_clock_s / 60:.1f} min; eval over {e.episodes} episodes: falls {e.fall_rate:.3f} ({e.falls}), "
        f"touches {e.touch_rate:.3f}, "
        f"joint RMSE {e.joint_rmse:.3f} rad, speed {e.forward_speed:.2f} m/s (reference {e.reference_speed:.2f})",
        soft_wrap=True,
    )
    if copy_from is not None:
        console.print(f"{target} is your own library, made now as a copy of the shipped {copy_from}", soft_wrap=True)
    _say_status(console, target, gait)


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


def _interval(text: str) -> tuple[float, float]:
    """``LOW:HIGH`` seconds as a pair (the recipe checks the range); anything else is one line."""
    from gaitlib.cli.options import OptionError

    try:
        low, high = (float(part) for part in text.split(":"))
    except ValueError:
        raise OptionError(f"--kick-interval takes LOW:HIGH in seconds (e.g. 1:3), got '{text}'") from None
    return low, high


def _say_status(console, library: Path, gait: str) -> None:
    """What the library a gait was just written into needs before it switches, and how to use it."""
    from gaitlib.library import Library, library_status

    status = library_status(Library(library))
    for problem in status.problems:
        console.print(f"next: {problem.line()}", soft_wrap=True)
    console.print(f"use it: gaitlib eval {gait} --library {library} (or export GAITLIB_LIBRARY={library})")


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
    guard: bool = typer.Option(False, "--guard", help="Run on the meta-controller with the guard on, beside the same "
                               "draws unguarded, under --impulses or --push-max (docs/switching.md, \"The guard\")."),
    guard_margin: float | None = typer.Option(None, "--guard-margin", help="With --guard: the guard's margin, in "
                                              "[0, 1) (default: the one chosen with the survival estimate)."),
) -> None:
    """Evaluate a library policy under paper Table 1 randomization: falls, leg touches, heading held, tracking
    errors; or, with --impulses, its fall rate against a single push's impulse (with --guard, guarded and not)."""
    from gaitlib.cli.options import IMPULSE_NS, check_worlds, parse_values
    from gaitlib.cli.preflight import no_effect, writable_file, writable_folder
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
    from gaitlib.library.target import check_writable, copy_library, library_writer, writing_target

    library, copy_from = writing_target(library)
    writable_folder("--library", library, what="a library folder")
    check_writable(library, replace=replace, command="gaitlib eval --record", what=f"the entry {gait}")
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
