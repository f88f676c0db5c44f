"""``gaitlib drive``: one robot steered by a command timeline (open loop, each command requesting the library's
nearest skill) or through waypoints (closed loop, aimed again every step from the measured pose), through the
meta-controller, with the path against the commanded one and each waypoint's arrival."""

from __future__ import annotations

from pathlib import Path

import typer

from gaitlib.atomic import json_text
from gaitlib.cli.guarding import choose_guard, guard_margin_option, guard_option, print_guard
from gaitlib.cli.options import SEED, action_delay_option, bounded, falls_option
from gaitlib.defaults import DEFAULT_STRATEGY

__all__ = ["drive_command"]


def drive_command(
    commands: Path | None = typer.Option(
        None, "--commands", help="Command timeline, CSV with the header time_s,forward,lateral,yaw_rate (s, m/s, m/s, "
        "rad/s): each row in force until the next, the first at 0 s, the last row's time ending the drive."
    ),
    waypoints: Path | None = typer.Option(
        None, "--waypoints", help="Waypoints, CSV with the header x,y (m): the first where the robot starts, facing "
        "+x. Closed loop: every step the robot aims again from its measured pose, turning while the waypoint's "
        "bearing is off and going straight when aligned, until within 0.2 m of each (docs/driving.md)."
    ),
    strategy: str = typer.Option(
        DEFAULT_STRATEGY, "--strategy", help="random, value, tmt, tmt-value, net (the paper's rule) or net-lookahead."
    ),
    action_delay: int | None = action_delay_option(),
    seed: int = bounded(0, "--seed", help="Random seed (randomization, strategy);", bounds=SEED),
    plot: Path = typer.Option(Path("drive.png"), "--plot", help="Where to write the plot (PNG)."),
    video: Path | None = typer.Option(None, "--video", help="Also render a video of the drive (MP4)."),
    backend: str = typer.Option("auto", "--backend", help="auto, mujoco or newton."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
    library: Path | None = typer.Option(None, "--library", help="Library folder (default: the shipped library/)."),
    falls: str = falls_option(),
    guard: bool = guard_option(),
    guard_margin: float | None = guard_margin_option(),
) -> None:
    """Drive one robot by --commands (open loop: at each command the skill nearest the commanded velocity is
    requested) or through --waypoints (closed loop: a turning or the straight skill, chosen every step from the
    measured pose); the meta-controller switches with --strategy (guarded unless --no-guard)."""
    from gaitlib.cli.options import OptionError
    from gaitlib.cli.preflight import plot_and_video
    from gaitlib.meta import load_switching
    from gaitlib.meta.commands import read_commands, read_waypoints, skills_of
    from gaitlib.meta.drive import drive, drive_waypoints
    from gaitlib.meta.drive_plot import plot_drive
    from gaitlib.strategies.survival import check_guard

    if (commands is None) == (waypoints is None):
        raise OptionError("gaitlib drive takes one of --commands FILE.csv or --waypoints FILE.csv")
    plot_and_video(plot, video, inputs={"--commands": commands, "--waypoints": waypoints}, library=library)
    points = read_waypoints(waypoints) if waypoints is not None else None
    timeline = read_commands(commands) if commands is not None else None
    check_guard(margin=guard_margin)
    setup = load_switching(library)
    if points is not None:
        from gaitlib.meta.steering import check_waypoints

        check_waypoints(points, skills_of([e.description for e in setup.entries]))  # before the guard's line
    guarding, unguarded = choose_guard(setup, on=guard, margin=guard_margin, quiet=as_json)
    options = {"strategy": strategy, "action_delay": action_delay, "backend": backend, "seed": seed, "falls": falls,
               "guard": guarding}
    result = (drive(setup, timeline, **options) if points is None else drive_waypoints(setup, points, **options))
    plot_drive(result, plot)
    if video is not None:
        from gaitlib.meta.video import render_trace

        render_trace(result.trace, video)
    report = _report(result, setup.gaits, source=str(commands or waypoints), plot=plot, video=video)
    report["guard"] = result.trace.guard_report(why_off=unguarded)
    if as_json:
        print(json_text(report))
        return
    for row in report["commands"]:
        achieved = row["achieved"]
        got = "not run" if achieved is None else (
            f"achieved {achieved['forward']:+.2f} m/s, {achieved['lateral']:+.2f} m/s, {achieved['yaw_rate']:+.2f} "
            "rad/s")
        velocity = (f"forward {row['forward']:+.2f} m/s, lateral {row['lateral']:+.2f} m/s, yaw rate "
                    f"{row['yaw_rate']:+.2f} rad/s")
        asked = (f"{row['skill']} asked for ({velocity})" if result.waypoints is not None else
                 f"{velocity} -> {row['skill']} ({row['skill_distance']:.3f} m/s away)")
        print(f"{row['from_s']:7.2f} s  {asked}; {got}")
    for switch in report["switches"]:
        how = "forced by the deadline" if switch["forced"] else (
            "random: no score" if switch["score"] is None else f"score {switch['score']:.3f}")
        print(f"{switch['from']} -> {switch['to']}: requested at {switch['request_s']:.2f} s, switched at "
              f"{switch['switch_s']:.2f} s ({how})")
    trace = result.trace
    outcome = "stayed up" if trace.stayed_up else f"FELL at {trace.fell_s:.2f} s"
    touches = (f"{trace.touches} leg touch(es) ridden through, the longest {trace.longest_touch_s:.2f} s"
               if trace.touches else "no leg touched the ground")
    error = report["velocity_error_rms"]
    print(f"{len(report['switches'])} switch(es) for {len(trace.requests_s)} request(s); the robot {outcome} (falls "
          f"counted the {trace.falls} way); {touches}")
    if error["distance"] is not None:
        print(f"velocity error (rms): forward {error['forward']:.3f} m/s, lateral {error['lateral']:.3f} m/s, yaw rate "
              f"{error['yaw_rate']:.3f} rad/s; {error['distance']:.3f} m/s by the drive's distance")
    print_guard(report["guard"], guarding, trace)
    if result.waypoints is None:
        print(f"ended {report['end_error_m']:.2f} m from the commanded end of a {report['path_length_m']:.2f} m path")
    else:
        _print_waypoints(report, trace)
    print(f"plot: {plot}" + (f"  video: {video}" if video else ""))


def _print_waypoints(report: dict, trace) -> None:
    """Each waypoint's arrival, or why the drive ended before it, and the end error."""
    ended = (f"the robot fell at {trace.fell_s:.2f} s" if not trace.stayed_up else
             f"the drive reached its time limit, {report['time_limit_s']:.1f} s")
    for row in report["waypoints"]:
        where = f"waypoint {row['index']} ({row['x']:g}, {row['y']:g})"
        if row["reached_s"] is not None:
            print(f"{where}: reached at {row['reached_s']:.2f} s, closest {row['closest_m']:.2f} m")
        elif row["closest_m"] is not None:
            print(f"{where}: NOT reached, closest {row['closest_m']:.2f} m: {ended}")
        else:
            print(f"{where}: NOT reached, never aimed at: {ended}")
    done = "every waypoint reached" if report["reached_all"] else "NOT every waypoint reached"
    print(f"{done}; ended {report['end_error_m']:.2f} m from the last waypoint, after {report['path'][-1][0]:.2f} s "
          f"({report['path_length_m']:.2f} m of legs)")


def _report(result, gaits: tuple[str, ...], *, source: str, plot: Path, video: Path | None) -> dict:
    """The drive as one JSON-ready dict."""
    trace, commands = result.trace, result.commands
    rows = []
    for i, (forward, lateral, yaw_rate) in enumerate(commands.velocity.tolist()):
        achieved = result.achieved[i]
        rows.append({
            "from_s": float(commands.time_s[i]), "until_s": float(commands.time_s[i + 1]),
            "forward": forward, "lateral": lateral, "yaw_rate": yaw_rate,
            "skill": result.skills[i], "skill_distance": float(result.skill_distance[i]),
            "achieved": None if achieved[0] != achieved[0] else dict(
                zip(("forward", "lateral", "yaw_rate"), achieved.tolist(), strict=True)),
        })
    switches = [
        {
            "from": gaits[event.source], "to": gaits[event.dest], "request_s": switch_s - event.wait_s,
            "switch_s": switch_s, "wait_s": event.wait_s,
            "score": None if event.score != event.score else event.score,  # NaN (random): null
            "phase": event.phase, "forced": event.forced,
        }
        for event, switch_s in zip(trace.switches, trace.switches_s, strict=True)
    ]
    return {
        "input": source,
        "strategy": trace.strategy,
        "commands": rows,
        "requests_s": trace.requests_s,
        "requested": list(trace.dests),
        "switches": switches,
        "falls": trace.falls,
        "stayed_up": trace.stayed_up,
        "fell_s": trace.fell_s,
        "touches": trace.touches,
        "longest_touch_s": trace.longest_touch_s,
        "velocity_error_rms": result.rms_error(),
        "path_length_m": result.path_length_m,
        "end_commanded": result.commanded[-1].tolist(),
        "end_reached": result.pose[-1, 1:3].tolist(),
        "end_error_m": result.end_error_m,
        "path": [[round(v, 4) for v in row] for row in result.pose.tolist()],
        "plot": str(plot),
        "video": None if video is None else str(video),
    } | ({} if result.waypoints is None else result.waypoints.report())

