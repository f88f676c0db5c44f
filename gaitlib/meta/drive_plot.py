"""The figure ``gaitlib drive`` writes: the robot's path in the plane against the commanded path (or the waypoints
and their reach circles), and its velocity against the commands (or the skills asked for) over time."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gaitlib.atomic import save_figure
from gaitlib.meta.drive import DriveResult, WaypointOutcome, step_velocity
from gaitlib.meta.steering import REACH_M

__all__ = ["plot_drive"]

_SMOOTH_S = 0.5
"""The achieved velocity is shown as its moving mean over this long, s (a gait cycle or more)."""


def plot_drive(result: DriveResult, path: Path) -> Path:
    """Write ``result`` as a PNG (atomically): on the left the plane, the commanded path dashed (for waypoints: the
    legs between them, each waypoint numbered in its reach circle, green reached, red not), the robot's path solid,
    its switches (red dots), the guard's catches (orange), its start (green) and a fall (purple cross); on the right
    the forward speed, lateral speed and yaw rate commanded (steps; for waypoints those of the skills asked for) and
    achieved (a moving mean), requests and switches marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    trace, pose, commanded = result.trace, result.pose, result.commanded
    fig = plt.figure(figsize=(12, 6.5))
    grid = fig.add_gridspec(3, 2, width_ratios=[1.1, 1.0])
    plane = fig.add_subplot(grid[:, 0])
    waypoints = result.waypoints
    plane.plot(commanded[:, 0], commanded[:, 1], "--", color="gray",
               label="commanded" if waypoints is None else "waypoint legs")
    plane.plot(pose[:, 1], pose[:, 2], color="black", linewidth=1.2, label="robot")
    plane.plot(*pose[0, 1:3], "o", color="tab:green", label="start")
    if waypoints is None:
        plane.plot(*commanded[-1], "s", color="gray", fillstyle="none", label="commanded end")
    else:
        _waypoints(plane, waypoints)
    steps = [event.step for event in trace.switches]
    if steps:
        plane.plot(pose[steps, 1], pose[steps, 2], "o", color="tab:red", markersize=5, label="switch")
    caught = [catch.step for catch in trace.catches]
    if caught:
        plane.plot(pose[caught, 1], pose[caught, 2], "^", color="tab:orange", markersize=6, label="guard's catch")
    if trace.fell_s is not None:
        plane.plot(*pose[-1, 1:3], "x", color="tab:purple", markersize=10, mew=2, label="fall")
    plane.set_aspect("equal", adjustable="datalim")
    plane.set_xlabel("x (m)")
    plane.set_ylabel("y (m)")
    plane.legend(loc="best", fontsize=8)
    t = pose[1:, 0]
    velocity = _smoothed(pose)
    times = result.commands.time_s
    labels = ("forward (m/s)", "lateral (m/s)", "yaw rate (rad/s)")
    axes = [fig.add_subplot(grid[k, 1]) for k in range(3)]
    for k, ax in enumerate(axes):
        ax.step(times, [*result.commands.velocity[:, k], result.commands.velocity[-1, k]], where="post",
                color="gray", linestyle="--", label="commanded")
        ax.plot(t, velocity[:, k], color="black", linewidth=1, label=f"achieved ({_SMOOTH_S:g} s mean)")
        for request_s in trace.requests_s:
            ax.axvline(request_s, color="tab:green", linestyle=":", linewidth=1.2)
        for switch_s in trace.switches_s:
            ax.axvline(switch_s, color="tab:red", linewidth=1.2)
        for catch in trace.catches:
            ax.axvline(catch.step * trace.dt, color="tab:orange", linewidth=1.2)
        ax.set_ylabel(labels[k])
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time (s)")
    outcome = "stayed up" if trace.stayed_up else f"fell at {trace.fell_s:.2f} s"
    rms = result.rms_error()["distance"]
    if waypoints is None:
        end = f"ended {result.end_error_m:.2f} m from the commanded end of a {result.path_length_m:.2f} m path"
    else:
        reached = sum(t is not None for t in waypoints.reached_s)
        end = (f"{reached} of {len(waypoints.reached_s)} waypoints reached (within {REACH_M:g} m), ended "
               f"{result.end_error_m:.2f} m from the last")
    fig.suptitle(
        f"drive with {trace.strategy}: {len(trace.requests_s)} request(s) (green), {len(trace.switches)} switch(es) "
        f"(red), {outcome} (falls: {trace.falls});\n{end}" + ("" if rms is None else
                                                              f"; velocity error {rms:.3f} m/s (rms)"),
        fontsize=10,
    )
    fig.tight_layout()
    return save_figure(fig, path)


def _waypoints(plane, waypoints: WaypointOutcome) -> None:
    """The later waypoints on ``plane``, each numbered as in its file inside its reach circle: green if reached, red
    if not."""
    from matplotlib.patches import Circle

    for k, ((x, y), reached) in enumerate(zip(waypoints.world[1:].tolist(), waypoints.reached_s, strict=True)):
        color = "tab:green" if reached is not None else "tab:red"
        plane.add_patch(Circle((x, y), REACH_M, fill=False, color=color, linewidth=1.2))
        plane.plot(x, y, "+", color=color, markersize=7)
        plane.annotate(str(k + 2), (x, y), textcoords="offset points", xytext=(6, 6), fontsize=8, color=color)
    plane.plot([], [], "o", color="tab:green", fillstyle="none", label=f"reach circle ({REACH_M:g} m)")


def _smoothed(pose: np.ndarray) -> np.ndarray:
    """(T, 3) :func:`~gaitlib.meta.drive.step_velocity` as a moving mean over :data:`_SMOOTH_S`."""
    raw = step_velocity(pose)
    if len(raw) == 0:  # a fall in the first step
        return raw
    width = max(1, round(_SMOOTH_S / (pose[1, 0] - pose[0, 0])))
    sums = np.vstack([np.zeros((1, 3)), np.cumsum(raw, axis=0)])
    start = np.clip(np.arange(len(raw)) - width // 2, 0, len(raw))
    stop = np.clip(start + width, 0, len(raw))
    return (sums[stop] - sums[start]) / (stop - start)[:, None]
