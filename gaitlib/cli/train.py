"""``gaitlib train GAIT``."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import typer

from gaitlib.cli.options import COUNT, EPISODE_SECONDS, SEED, WORLDS, Bounds, bounded, falls_option
from gaitlib.defaults import SWITCH_START

__all__ = ["train_command"]


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
        ..., help="Gait to train: a shipped description (pace, trot, stand, ..., catch: the catch skill) or "
        "--gait-file."
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
        None, "--states", help="Handover states of other gaits (gaitlib states) to start a share of episodes from "
        "(a catch task: the states it catches from, every episode, gaitlib states --shove-max)."
    ),
    switch_start: float | None = bounded(
        None, "--switch-start",
        help="Share of episodes that start from a handover state (default: 0.4 with --states, else 0: the paper's "
        "recipe; a catch task's: 1);", bounds=Bounds(low=0, high=1),
    ),
    run_dir: Path | None = typer.Option(None, "--run-dir", help="Checkpoints and TensorBoard logs (runs/GAIT)."),
    resume: bool = typer.Option(False, "--resume", help="Continue from the run's latest checkpoint."),
    checkpoint_every: int = bounded(50, "--checkpoint-every", help="Iterations between checkpoints;", bounds=COUNT),
    worlds: int | None = bounded(
        None, "--worlds", help="Parallel training worlds (default: the preset's, cpu 512, paper 4096);", bounds=WORLDS
    ),
    eval_episodes: int = bounded(
        64, "--eval-episodes", help="Episodes of the final evaluation (one world each);", bounds=WORLDS
    ),
    eval_seconds: float = bounded(
        20.0, "--eval-seconds", help="Length of each final evaluation episode (gaitlib eval's default);",
        bounds=EPISODE_SECONDS,
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
    if worlds is not None:
        check_worlds("--worlds", worlds, backend=backend)
    description = _description(gait, gait_file)
    recipe = Recipe(push_kind=push_kind, kick_max=kick_max, kick_draw=kick_draw,
                    kick_interval=_interval(kick_interval), falls=terminate, contact_penalty=contact_penalty,
                    gamma=gamma, lam=lam, action_delay=action_delay, critic_delay=critic_delay,
                    cycle_sync=cycle_sync)
    chosen = recipe.preset(get_preset(preset))
    if worlds is not None:  # recorded with the preset in the entry, as every other size of the run
        chosen = dataclasses.replace(chosen, num_envs=worlds)
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
        switch_start=switch_start if switch_start is not None else _switch_start(description, states),
        run_dir=run_dir or Path("runs") / gait,
        backend=backend,
        seed=seed,
        resume=resume,
        checkpoint_every=checkpoint_every,
        eval_episodes=eval_episodes,
        eval_seconds=eval_seconds,
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



def _switch_start(description, states: Path | None) -> float:
    """The default share of episodes started from ``states``: every one for a catch task (it has no reference to
    start from), :data:`~gaitlib.defaults.SWITCH_START` for a gait with states, none without."""
    if states is None:
        return 0.0
    return 1.0 if description.task == "catch" else SWITCH_START


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
