"""``gaitlib run`` (one robot, requested switches, with a plot and a video) and ``gaitlib benchmark`` (the
disturbance sweep of every strategy over every pair)."""

from __future__ import annotations

from pathlib import Path

import typer

from gaitlib.atomic import json_text
from gaitlib.cli.guarding import choose_guard, guard_margin_option, guard_option, opt_in_guard_option, print_guard
from gaitlib.cli.options import (
    COUNT,
    EPISODE_SECONDS,
    MAX_MAGNITUDES,
    MOTOR_STRENGTH,
    PUSH_N,
    SEED,
    TIME_IN_RUN,
    WORLDS,
    action_delay_option,
    bounded,
    falls_option,
    ray_address_argument,
    ray_option,
    workers_option,
)
from gaitlib.defaults import COMPARED, DEFAULT_STRATEGY, Falls
from gaitlib.values import number_text

__all__ = ["benchmark_command", "run_command"]


def run_command(
    source: str = typer.Option("trot", "--from", help="Gait the robot starts in."),
    dests: str = typer.Option(
        "stand", "--to", help="Gait requested, or gaits one after the other (stand,pace,trot)."
    ),
    strategy: str = typer.Option(
        DEFAULT_STRATEGY, "--strategy", help="random, value, tmt, tmt-value, net (the paper's rule) or net-lookahead."
    ),
    request_at: float = bounded(
        2.0, "--request-at", help="When the first switch is requested, from the start;", bounds=TIME_IN_RUN
    ),
    hold: float = bounded(
        4.0, "--hold", help="Time each requested gait runs after its switch, before the next request or the end;",
        bounds=EPISODE_SECONDS,
    ),
    push: float = bounded(
        0.0,
        "--push",
        help="Push magnitude (0: none); pushes from 0.6 s before each request until 2 s after it;",
        bounds=PUSH_N,
    ),
    action_delay: int | None = action_delay_option(),
    seed: int = bounded(0, "--seed", help="Random seed (randomization, pushes, strategy);", bounds=SEED),
    plot: Path = typer.Option(Path("run.png"), "--plot", help="Where to write the plot (PNG)."),
    video: Path | None = typer.Option(None, "--video", help="Also render a video of the run (MP4)."),
    backend: str = typer.Option("auto", "--backend", help="auto, mujoco or newton."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
    library: Path | None = typer.Option(None, "--library", help="Library folder (default: the shipped library/)."),
    routed: bool = typer.Option(False, "--routed", help="Make each switch through another gait where the library's "
                                "route table (gaitlib routes) measured that better."),
    falls: str = falls_option(),
    guard: bool = guard_option(),
    guard_margin: float | None = guard_margin_option(),
) -> None:
    """Run one robot in --from, request --to (one gait or several in turn), and let the meta-controller switch
    with --strategy (guarded unless --no-guard)."""
    from gaitlib.cli.options import OptionError
    from gaitlib.cli.preflight import plot_and_video
    from gaitlib.cli.routes import route_table
    from gaitlib.meta import load_switching
    from gaitlib.meta.episode import check_run_length, run_episode
    from gaitlib.meta.trace_plot import plot_trace
    from gaitlib.strategies.survival import check_guard

    sequence = [g.strip() for g in dests.split(",")]
    if "" in sequence:
        raise OptionError(f"--to takes gait names separated by commas, got '{dests}'")
    check_run_length(request_s=request_at, requests=len(sequence), hold_s=hold)
    plot_and_video(plot, video, library=library)
    check_guard(margin=guard_margin)
    setup = load_switching(library)
    guarding, unguarded = choose_guard(setup, on=guard, margin=guard_margin, quiet=as_json)
    asked = sequence
    if routed:
        table = route_table(setup, strategies=(strategy,), pushes=(push,), falls=falls)
        sequence = list(table.expand(source, tuple(sequence)))
    trace = run_episode(
        setup,
        source=source,
        dests=sequence,
        strategy=strategy,
        request_s=request_at,
        hold_s=hold,
        push_n=push,
        action_delay=action_delay,
        backend=backend,
        seed=seed,
        falls=falls,
        guard=guarding,
    )
    plot_trace(trace, plot)
    if video is not None:
        from gaitlib.meta.video import render_trace

        render_trace(trace, video)
    switches = [
        {
            "from": setup.gaits[event.source],
            "to": setup.gaits[event.dest],
            "request_s": request_s,
            "switch_s": switch_s,
            "wait_s": event.wait_s,
            "score": None if event.score != event.score else event.score,  # NaN (random): null
            "phase": event.phase,
            "forced": event.forced,
        }
        for event, request_s, switch_s in zip(trace.switches, trace.requests_s, trace.switches_s, strict=False)
    ]
    report = {
        "from": source,
        "to": sequence,
        "asked": asked,
        "strategy": strategy,
        "requests_s": trace.requests_s,
        "switches": switches,
        "falls": trace.falls,
        "stayed_up": trace.stayed_up,
        "fell_s": trace.fell_s,
        "touches": trace.touches,
        "longest_touch_s": trace.longest_touch_s,
        "plot": str(plot),
        "video": None if video is None else str(video),
        "guard": trace.guard_report(why_off=unguarded),
    }
    if as_json:
        print(json_text(report))
        return
    for switch in switches:
        if switch["forced"]:
            how = "forced by the deadline"
        else:
            how = "random: no score" if switch["score"] is None else f"score {switch['score']:.3f}"
        print(
            f"{switch['from']} -> {switch['to']}: requested at {switch['request_s']:.2f} s, switched at "
            f"{switch['switch_s']:.2f} s after waiting {switch['wait_s']:.2f} s ({how}, φn = {switch['phase']:.3f})"
        )
    if sequence != asked:
        print(f"routed: {' -> '.join((source, *asked))} through {' -> '.join((source, *sequence))}")
    outcome = "stayed up" if trace.stayed_up else f"FELL at {trace.fell_s:.2f} s"
    touches = (f"{trace.touches} leg touch(es) ridden through, the longest {trace.longest_touch_s:.2f} s"
               if trace.touches else "no leg touched the ground")
    print(f"{' -> '.join((source, *sequence))} with {strategy}: {len(switches)} of {len(sequence)} switch(es) made; "
          f"the robot {outcome} (falls counted the {trace.falls} way); {touches}")
    print_guard(report["guard"], guarding, trace)
    print(f"plot: {plot}" + (f"  video: {video}" if video else ""))


def benchmark_command(
    strategies: str = typer.Option(
        ",".join(COMPARED), "--strategies", help="Comma-separated strategies to compare."
    ),
    magnitudes: str = typer.Option(
        "0:500:50",
        "--magnitudes",
        help=f"Push magnitudes, N: START:STOP:STEP (STOP included) or a list; each in {PUSH_N.describe()}, "
        f"at most {MAX_MAGNITUDES} distinct values.",
    ),
    samples: int = bounded(100, "--samples", help="Transitions per (strategy, pair, magnitude) cell;", bounds=COUNT),
    pairs: str | None = typer.Option(
        None, "--pairs", help="Ordered pairs like trot-stand,pace-stand (default: all; fell:FILE: the pairs in which a "
        "switch of the transition file FILE fell); the switching models need to drive these alone, unless --guard or "
        "--routed (they switch among every gait)."
    ),
    out: Path = typer.Option(Path("benchmark"), "--out", help="Output folder (resumed if it holds results)."),
    worlds: int = bounded(256, "--worlds", help="Parallel worlds;", bounds=WORLDS),
    backend: str = typer.Option("auto", "--backend", help="auto, mujoco or newton."),
    seed: int = bounded(0, "--seed", help="Random seed;", bounds=SEED),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object (success per strategy, pair, N)."),
    library: Path | None = typer.Option(None, "--library", help="Library folder (default: the shipped library/)."),
    robot: Path | None = typer.Option(
        None, "--robot", help="Run on another A1 model, an MJCF file (e.g. MuJoCo Menagerie's unitree_a1), adapted in "
        "memory (docs/robot.md); mujoco backend."
    ),
    action_delay: int | None = action_delay_option(),
    motor_strength: float = bounded(
        1.0, "--motor-strength", help="Multiple of the PD torque the motors deliver, kp, kd and torque limit alike "
        "(mujoco backend);", bounds=MOTOR_STRENGTH,
    ),
    routed: bool = typer.Option(False, "--routed", help="Each transition follows the library's route table "
                                "(gaitlib routes): through another gait where that measured better, counted once."),
    falls: str = falls_option(),
    guard: bool = opt_in_guard_option("Every transition with the guard on (docs/switching.md, \"The guard\"); off by "
                                      "default, so that the strategies' figures stay the paper's."),
    guard_margin: float | None = guard_margin_option(opt_in=True),
    ray: bool = ray_option(),
    address: str | None = ray_address_argument(),
    workers: int | None = workers_option(),
) -> None:
    """Success rate of each switching strategy on each ordered pair under pushes (paper Fig. 4): CSV, JSON, plot.
    With --robot, --action-delay, --motor-strength: on a stand-in for the real robot (Fig. 4, bottom). With
    --routed: each pair along its route, every switch of it with the strategy."""
    from gaitlib.benchmark.gap import DeploymentGap
    from gaitlib.benchmark.report import (
        cell_results,
        success_table,
        summary,
        write_csv,
        write_matrix,
        write_plot,
    )
    from gaitlib.benchmark.sweep import SweepConfig
    from gaitlib.cli.options import check_worlds, cluster_config, parse_magnitudes, parse_pairs
    from gaitlib.cli.preflight import writable_folder
    from gaitlib.cli.routes import route_table, sweep_with_progress
    from gaitlib.errors import GaitlibError
    from gaitlib.meta import load_switching
    from gaitlib.strategies import get_strategy

    cluster = cluster_config(ray, address, workers)
    writable_folder("--out", out)
    gap = DeploymentGap(robot=robot and str(robot), action_delay=action_delay, motor_strength=motor_strength)
    if gap.needs_mujoco:
        backend = gap.backend_name(backend)  # auto: mujoco; newton: refused in one line
        gap.robot_spec()  # a model without the A1's joints, feet or ground: refused in one line, before any work
    check_worlds("--worlds", worlds, backend=backend)
    swept = parse_magnitudes(magnitudes)
    setup = load_switching(library)
    served = parse_pairs(pairs, list(setup.gaits), identities=setup.resources.library.identities())
    if served is not None and not (guard or guard_margin is not None or routed):
        setup = setup.serving(served)  # models fitted on these pairs alone will do (not for a guard or routes)
    names = tuple(s.strip() for s in strategies.split(",") if s.strip())
    for name in names:
        get_strategy(name, setup.resources)  # unknown names and missing TMT/net fail here, before any work
    guard = guard or guard_margin is not None  # --guard-margin turns the guard on too
    if guard:
        guarding = setup.guard(margin=guard_margin)  # no survival estimate, a stale one, a bad margin: one line
    detours = {}
    if routed:
        detours = route_table(setup, strategies=names, pushes=swept, falls=falls).detours()
    config = SweepConfig(
        strategies=names,
        magnitudes=swept,
        samples=samples,
        pairs=served,
        num_worlds=worlds,
        gap=gap,
        backend=backend,
        seed=seed,
        falls=falls,
        guard=guard,
        guard_margin=guard_margin,
        routes=detours,
    )
    results = sweep_with_progress(out, setup, config, cluster=cluster)
    catches = {key: group["guard"] for key, group in results["groups"].items() if "guard" in group}
    rows = cell_results(results)
    if not rows:
        raise GaitlibError("the benchmark produced no results")
    write_csv(out / "results.csv", rows)
    title = f"{samples} transitions per point, 95% Wilson intervals" + _gap_title(gap)
    plot = write_plot(out / "success.png", rows, title=title)
    write_matrix(out / "matrix.png", rows, title=title)
    facts = summary(rows)
    if as_json:
        touches = success_table(rows, field="touch_rate")
        guarded = {"on": config.guard, "margin": guarding.margin if config.guard else None, "catches": catches}
        print(json_text({"falls": falls, "success": success_table(rows), "touches": touches, "summary": facts,
                         "out": str(out), "guard": guarded}))
        return
    _print_summary(facts, out, plot, falls)
    if config.guard:
        print(f"guard on (margin {number_text(guarding.margin)}, horizon {number_text(guarding.horizon_s)} s): "
              + "; ".join(f"{key}: {g['catches']} catch(es) {g['by_pair']}" for key, g in catches.items()))
    else:
        print("guard off (--guard turns it on)")


def _gap_title(gap) -> str:
    """What the plot's title adds for a deployment gap: the robot file, the delay, the motor strength."""
    parts = [f"on {Path(gap.robot).name}"] if gap.robot else []
    if gap.action_delay is not None:
        parts.append(f"action delay {gap.action_delay} steps")
    if gap.motor_strength != 1.0:
        parts.append(f"motor strength {gap.motor_strength:g}")
    return "".join(f"; {part}" for part in parts)


def _print_summary(facts: dict, out: Path, plot: Path, falls: Falls) -> None:
    from rich.table import Table

    from gaitlib.cli.tables import table_console

    means, touches = facts["mean_success"], facts["mean_touch"]
    strategies = facts["ranking"]
    pairs = list(dict.fromkeys(p for per in means.values() for p in per))
    table = Table(title=f"mean success over push magnitudes (falls: {falls} definition), and in brackets the share "
                        "of transitions in which a leg touched the ground")
    table.add_column("pair")
    for strategy in strategies:
        table.add_column(strategy, justify="right")
    for pair in pairs:
        table.add_row(pair, *(f"{means[s][pair]:.3f} ({touches[s][pair]:.3f})" if pair in means[s] else "-"
                              for s in strategies))
    table.add_section()
    table.add_row("all", *(f"{facts['overall'][s]:.3f} ({facts['overall_touch'][s]:.3f})" for s in strategies))
    console = table_console()
    console.print(table)
    for strategy, per_pair in facts["margins"].items():
        for pair, margin in per_pair.items():
            against = [(margin["second_best"], margin)]
            if "over_random" in margin and margin["second_best"] != "random":
                against.append(("random", margin["over_random"]))
            console.print(
                f"{strategy} on {pair}: "
                + "; ".join(f"vs {name} {m['margin_pp']:+.1f} ± {m['ci95_pp']:.1f}" for name, m in against)
                + " percentage points (95%)"
            )
    console.print(f"results: {out / 'results.csv'}, {out / 'results.json'}; plot: {plot}")
