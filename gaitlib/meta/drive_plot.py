"""The figure ``gaitlib drive`` writes: the robot's path in the plane against the commanded path, and its velocity
against the commands over time."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gaitlib.atomic import save_figure
from gaitlib.meta.drive import DriveResult, step_velocity

__all__ = ["plot_drive"]

_SMOOTH_S = 0.5
"""The achieved velocity is shown as its moving mean over this long, s (a gait cycle or more)."""


def plot_drive(result: DriveResult, path: Path) -> Path:
    """Write ``result`` as a PNG (atomically): on the left the plane, the commanded path dashed, the robot's path
    solid, its switches (red dots), the guard's catches (orange), its start (green) and a fall (purple cross); on the
    right the forward speed, lateral speed and yaw rate commanded (steps) and achieved (a moving mean), requests and
    switches marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    trace, pose, commanded = result.trace, result.pose, result.commanded
    fig = plt.figure(figsize=(12, 6.5))
    grid = fig.add_gridspec(3, 2, width_ratios=[1.1, 1.0])
    plane = fig.add_subplot(grid[:, 0])
    plane.plot(commanded[:, 1], commanded[:, 2], "--", color="gray", label="commanded")
    plane.plot(pose[:, 1], pose[:, 2], color="black", linewidth=1.2, label="robot")
    plane.plot(*pose[0, 1:3], "o", color="tab:green", label="start")
    plane.plot(*commanded[-1, 1:3], "s", color="gray", fillstyle="none", label="commanded end")
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
    fig.suptitle(
        f"drive with {trace.strategy}: {len(trace.requests_s)} request(s) (green), {len(trace.switches)} switch(es) "
        f"(red), {outcome} (falls: {trace.falls});\nended {result.end_error_m:.2f} m from the commanded end of a "
        f"{result.path_length_m:.2f} m path" + ("" if rms is None else f"; velocity error {rms:.3f} m/s (rms)"),
        fontsize=10,
    )
    fig.tight_layout()
    return save_figure(fig, path)


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
