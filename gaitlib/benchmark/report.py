"""Reading a disturbance sweep: success rates with 95% intervals, the CSV, the Fig. 4 plot, the pair matrix and the
summary.

The interval is Wilson's score interval for a binomial proportion (sound at 0% and 100%, unlike the normal one).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gaitlib.atomic import atomic_path, save_figure
from gaitlib.stats import Z95, wilson_interval

__all__ = [
    "NET_STRATEGIES",
    "CellResult",
    "cell_results",
    "success_matrix",
    "success_table",
    "summary",
    "write_csv",
    "write_matrix",
    "write_plot",
]


@dataclass(frozen=True)
class CellResult:
    """One (strategy, pair, magnitude) cell of a sweep."""

    strategy: str
    pair: str
    """``source-destination``, e.g. ``trot-stand``."""
    magnitude_n: float
    samples: int
    successes: int
    success_rate: float
    ci95_low: float
    ci95_high: float
    forced_rate: float
    """Share of the switches the deadline forced."""
    mean_wait_s: float
    """Mean time from request to switch over the transitions that switched, s."""
    source_falls: int
    touch_rate: float
    """Share of transitions in which a non-foot body touched the ground from the request to the verdict."""
    touch_ci95_low: float
    touch_ci95_high: float
    longest_touch_s: float
    """The longest unbroken touch of the cell, s."""


def cell_results(results: dict) -> list[CellResult]:
    """Every finished cell of ``results`` (as :func:`~gaitlib.benchmark.sweep.run_sweep` returns), strategy, pair and
    magnitude in sweep order."""
    rows = []
    for group in results["groups"].values():
        for pair, c in group["cells"].items():
            low, high = wilson_interval(c["successes"], c["samples"])
            touch_low, touch_high = wilson_interval(c["touched"], c["samples"])
            rows.append(
                CellResult(
                    strategy=group["strategy"],
                    pair=pair,
                    magnitude_n=float(group["magnitude_n"]),
                    samples=c["samples"],
                    successes=c["successes"],
                    success_rate=c["successes"] / c["samples"] if c["samples"] else float("nan"),
                    ci95_low=low,
                    ci95_high=high,
                    forced_rate=c["forced"] / c["switched"] if c["switched"] else 0.0,
                    mean_wait_s=c["wait_s"] / c["switched"] if c["switched"] else float("nan"),
                    source_falls=c["source_falls"],
                    touch_rate=c["touched"] / c["samples"] if c["samples"] else float("nan"),
                    touch_ci95_low=touch_low,
                    touch_ci95_high=touch_high,
                    longest_touch_s=c["longest_touch_s"],
                )
            )
    return rows


def success_table(rows: list[CellResult], *, field: str = "success_rate") -> dict[str, dict[str, dict[str, float]]]:
    """strategy -> pair -> magnitude (as ``"%g"``) -> success rate (or another ``field`` of the cells, such as
    ``touch_rate``)."""
    table: dict[str, dict[str, dict[str, float]]] = {}
    for r in rows:
        table.setdefault(r.strategy, {}).setdefault(r.pair, {})[f"{r.magnitude_n:g}"] = getattr(r, field)
    return table


NET_STRATEGIES = ("net", "net-lookahead")
"""The strategies built on the transition-net, whose margins :func:`summary` reports by default."""


def summary(rows: list[CellResult], *, focus: tuple[str, ...] = NET_STRATEGIES) -> dict:
    """Mean success (and mean touch rate) over magnitudes per strategy and pair, the ranking by overall mean success,
    and for each strategy of
    ``focus`` that ran, per pair, its margins over the best other strategy and over ``random`` (percentage points),
    each with the half-width of its 95% interval (normal approximation, the two strategies' cells taken as
    independent binomials: conservative under the sweep's common random numbers), where those exist."""
    means: dict[str, dict[str, float]] = {}
    touches: dict[str, dict[str, float]] = {}
    variances: dict[str, dict[str, float]] = {}  # of each mean
    for strategy in dict.fromkeys(r.strategy for r in rows):
        per_pair: dict[str, list[CellResult]] = {}
        for r in rows:
            if r.strategy == strategy:
                per_pair.setdefault(r.pair, []).append(r)
        means[strategy] = {pair: sum(r.success_rate for r in v) / len(v) for pair, v in per_pair.items()}
        touches[strategy] = {pair: sum(r.touch_rate for r in v) / len(v) for pair, v in per_pair.items()}
        variances[strategy] = {pair: _variance_of_mean(v) for pair, v in per_pair.items()}
    overall = {s: sum(p.values()) / len(p) for s, p in means.items()}
    margins: dict[str, dict[str, dict]] = {}
    for strategy in (s for s in focus if s in means):
        for pair in means[strategy]:
            others = [(means[s][pair], s) for s in means if s != strategy and pair in means[s]]
            if not others:
                continue
            second = max(others)[1]
            margin = {"second_best": second, **_margin(means, variances, pair, strategy, second)}
            if pair in means.get("random", {}) and strategy != "random":
                margin["over_random"] = _margin(means, variances, pair, strategy, "random")
            margins.setdefault(strategy, {})[pair] = margin
    return {
        "mean_success": means,
        "overall": overall,
        "mean_touch": touches,
        "overall_touch": {s: sum(p.values()) / len(p) for s, p in touches.items()},
        "ranking": sorted(overall, key=overall.get, reverse=True),
        "margins": margins,
    }


def _margin(means: dict, variances: dict, pair: str, strategy: str, other: str) -> dict:
    """``strategy``'s mean success on ``pair`` less ``other``'s, in percentage points, with its 95% half-width."""
    half = Z95 * math.sqrt(variances[strategy][pair] + variances[other][pair])
    return {"margin_pp": 100 * (means[strategy][pair] - means[other][pair]), "ci95_pp": 100 * half}


def _variance_of_mean(cells: list[CellResult]) -> float:
    """Variance of the mean success rate over ``cells`` (independent binomial cells)."""
    per_cell = [r.success_rate * (1 - r.success_rate) / r.samples for r in cells if r.samples]
    return sum(per_cell) / len(cells) ** 2


def write_csv(path: Path, rows: list[CellResult]) -> Path:
    """All cells as CSV (atomically)."""
    path = Path(path)
    fields = list(CellResult.__dataclass_fields__)
    with atomic_path(path) as tmp, open(tmp, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(fields)
        for r in rows:
            writer.writerow([f"{v:.4f}" if isinstance(v, float) else v for v in (getattr(r, f) for f in fields)])
    return path


def write_plot(path: Path, rows: list[CellResult], *, title: str = "") -> Path:
    """Success rate against push magnitude, one panel per pair, one line (with its 95% band) per strategy, in the
    layout of paper Fig. 4 (top). PNG, written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    pairs = list(dict.fromkeys(r.pair for r in rows))
    strategies = list(dict.fromkeys(r.strategy for r in rows))
    columns = min(3, len(pairs))
    lines = math.ceil(len(pairs) / columns)
    fig, axes = plt.subplots(lines, columns, figsize=(4.2 * columns, 3.3 * lines), squeeze=False, sharey=True)
    for ax, pair in zip(axes.flat, pairs, strict=False):
        for strategy in strategies:
            cells = sorted((r for r in rows if r.pair == pair and r.strategy == strategy), key=lambda r: r.magnitude_n)
            x = [r.magnitude_n for r in cells]
            ax.plot(x, [r.success_rate for r in cells], marker="o", markersize=3, label=strategy)
            ax.fill_between(x, [r.ci95_low for r in cells], [r.ci95_high for r in cells], alpha=0.15)
        ax.set_title(pair.replace("-", " → "))
        ax.set_xlabel("push magnitude (N)")
        ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
    for ax in axes[:, 0]:
        ax.set_ylabel("success rate")
    for ax in list(axes.flat)[len(pairs) :]:
        ax.set_visible(False)
    axes.flat[0].legend(fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return save_figure(fig, path)


def success_matrix(rows: list[CellResult], *, strategy: str, magnitude_n: float) -> tuple[list[str], np.ndarray]:
    """The gaits of ``rows`` (in the order they first appear, as source or destination) and the (G, G) success
    rates of ``strategy`` at ``magnitude_n`` N: row the source, column the destination; NaN where no such cell ran
    (the diagonal, and pairs the sweep left out)."""
    gaits = list(dict.fromkeys(g for r in rows for g in r.pair.split("-")))
    index = {g: i for i, g in enumerate(gaits)}
    matrix = np.full((len(gaits), len(gaits)), np.nan)
    for r in rows:
        if r.strategy == strategy and r.magnitude_n == magnitude_n:
            source, destination = r.pair.split("-")
            matrix[index[source], index[destination]] = r.success_rate
    return gaits, matrix


def write_matrix(path: Path, rows: list[CellResult], *, magnitude_n: float | None = None, title: str = "") -> Path:
    """Every ordered pair's success rate as a source-by-destination heat map, one panel per strategy, at
    ``magnitude_n`` N (default: the smallest swept), each cell labelled in percent; the colour scale runs from 80%
    (and below) to 100% in every figure, so that figures compare and the last points to a 99% goal show. PNG,
    written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    magnitude = min(r.magnitude_n for r in rows) if magnitude_n is None else magnitude_n
    strategies = list(dict.fromkeys(r.strategy for r in rows))
    gaits = success_matrix(rows, strategy=strategies[0], magnitude_n=magnitude)[0]
    size = 1.6 + 0.6 * len(gaits)  # inches a panel
    fig, axes = plt.subplots(
        1, len(strategies), figsize=(size * len(strategies) + 1.0, size + 0.6), squeeze=False, layout="constrained"
    )
    for ax, strategy in zip(axes.flat, strategies, strict=True):
        matrix = success_matrix(rows, strategy=strategy, magnitude_n=magnitude)[1]
        image = ax.imshow(matrix, cmap="RdYlGn", vmin=0.8, vmax=1.0)
        for (i, j), value in np.ndenumerate(matrix):
            if not np.isnan(value):
                ax.text(j, i, f"{100 * value:.1f}", ha="center", va="center", fontsize=7)
        ax.set_xticks(range(len(gaits)), gaits, rotation=45, ha="right", rotation_mode="anchor")
        ax.set_yticks(range(len(gaits)), gaits if ax is axes[0, 0] else [])
        ax.set_xlabel("to")
        ax.set_title(strategy)
    axes[0, 0].set_ylabel("from")
    fig.colorbar(image, ax=list(axes.flat), fraction=0.05, label="success rate")
    fig.suptitle(f"{title}{'; ' if title else ''}{magnitude:g} N")
    return save_figure(fig, path)
