"""The figure ``gaitlib run`` writes: score and chosen phase, trunk height, and the foot-contact gait diagram."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from gaitlib.atomic import save_figure
from gaitlib.meta.episode import RunTrace

__all__ = ["plot_trace"]

_FEET = ("FR", "FL", "RR", "RL")


def plot_trace(trace: RunTrace, path: Path) -> Path:
    """Write ``trace`` as a three-panel PNG (atomically): the strategy's best score and its destination phase
    while a request waits (its pair's threshold dashed), trunk height with the pushes shaded, and the gait diagram
    (feet in contact, dark) with the requests, the switches and the guard's catches marked; guarded, the survival
    estimate beside the score."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    t = trace.time_s
    fig, (ax_score, ax_height, ax_feet) = plt.subplots(
        3, 1, figsize=(9, 7), sharex=True, gridspec_kw={"height_ratios": [2, 1.3, 1.2]}
    )
    ax_score.plot(t, trace.score, ".-", color="tab:blue", markersize=3, label="best score")  # a 1-step wait shows
    end_s = t[-1] if len(t) else 0.0
    waits = zip(trace.requests_s, [*trace.switches_s, end_s], trace.thresholds, strict=False)
    for k, (request_s, until_s, threshold) in enumerate(waits):
        if threshold is not None and np.isfinite(threshold):
            ax_score.hlines(threshold, request_s, until_s, color="tab:blue", linestyle="--", linewidth=1,
                            label="threshold" if k == 0 else None)
    if trace.guarded:
        ax_score.plot(t, trace.stay, color="tab:olive", linewidth=1, label="guard: staying up")
    ax_score.set_ylabel(f"{trace.strategy} score")
    phase_axis = ax_score.twinx()
    phase_axis.plot(t, trace.best_phase, ".", color="tab:orange", markersize=3, label="chosen φn")
    phase_axis.set_ylabel("chosen φn (cycles)")
    phase_axis.set_ylim(0, 1)
    ax_score.legend(loc="upper left", fontsize=8)
    ax_height.plot(t, trace.root_height, color="black")
    ax_height.set_ylabel("trunk height (m)")
    if trace.push.any():
        pushed = {"where": trace.push > 0, "step": "pre", "color": "tab:red", "alpha": 0.2}
        ax_height.fill_between(t, 0, 1, transform=ax_height.get_xaxis_transform(), label="push", **pushed)
    if trace.touch.any():
        touched = {"where": trace.touch, "step": "pre", "color": "tab:purple", "alpha": 0.3}
        ax_height.fill_between(t, 0, 1, transform=ax_height.get_xaxis_transform(), label="leg touch", **touched)
    if trace.push.any() or trace.touch.any():
        ax_height.legend(loc="upper left", fontsize=8)
    contact = trace.foot_contact.T.astype(float)
    if len(t):
        ax_feet.imshow(
            contact,
            aspect="auto",
            cmap="Greys",
            vmin=0,
            vmax=1,
            interpolation="nearest",
            extent=(t[0] - trace.dt, t[-1], len(_FEET) - 0.5, -0.5),
        )
    ax_feet.set_yticks(range(len(_FEET)), _FEET)
    ax_feet.set_xlabel("time (s)")
    for ax in (ax_score, ax_height, ax_feet):
        for request_s in trace.requests_s:
            ax.axvline(request_s, color="tab:green", linestyle=":", linewidth=1.5)
        for switch_s in trace.switches_s:
            ax.axvline(switch_s, color="tab:red", linewidth=1.5)
        for catch in trace.catches:
            ax.axvline(catch.step * trace.dt, color="tab:orange", linestyle="--", linewidth=1.5)
        if trace.fell_s is not None:
            ax.axvline(trace.fell_s, color="tab:purple", linewidth=1.5)
    outcome = "stayed up" if trace.stayed_up else f"fell at {trace.fell_s:.2f} s (purple)"
    touches = f"{trace.touches} leg touch(es) ridden through" if trace.touches else "no leg touch"
    guard = (f"guard on, {len(trace.catches)} catch(es) (orange, dashed)" if trace.guarded else "guard off")
    summary = (f"{len(trace.requests_s)} request(s) (green), {len(trace.switches)} switch(es) (red), {outcome} "
               f"(falls: {trace.falls}), {touches}, {guard}")
    fig.suptitle(
        f"{' → '.join((trace.source, *trace.dests))}, strategy {trace.strategy}, push {trace.push_n:g} N:\n"
        + textwrap.fill(summary, width=110),  # the figure's width: a longer line would be cut at its edges
        fontsize=10,
    )
    fig.tight_layout()
    return save_figure(fig, path)
