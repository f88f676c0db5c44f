"""The transition map: where switches fail, from any transition file.

Per ordered pair, the success of the switches in a file over source phase x destination phase (a heatmap, as the
tensor plots of the TMT paper show them: Soeseno et al. 2021, "Transition Motion Tensor"), the success in each
tenth (by default) of the source cycle and of the destination cycle, by the feet on the ground at the switch, and
when switch-caused falls happen after the switch. Every rate comes with its sample count and Wilson 95% interval.
A random switch's success is the pair's overall rate (phases are drawn uniformly by the collector); the best and
the worst source bins say how much a strategy that only chooses the moment can gain.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from gaitlib.atomic import null_for_nan, save_figure, write_json
from gaitlib.defaults import DEFAULT_FALLS, Falls
from gaitlib.envs import observations as obs_fn
from gaitlib.robots.a1.constants import LEG_NAMES
from gaitlib.stats import wilson_interval
from gaitlib.transitions import TransitionData
from gaitlib.transitions.explicit import EXPLICIT_DIM

__all__ = ["PairMap", "Rate", "fall_time_quantile", "transition_maps", "write_map_json", "write_map_plot"]

_CONTACT = sum(f.width for f in obs_fn.FRAME[: [f.name for f in obs_fn.FRAME].index("foot_contact")])
"""Column of the first foot contact in the newest explicit frame (its values carry observation noise)."""


@dataclass(frozen=True)
class Rate:
    """A success rate with its sample count and Wilson 95% interval."""

    samples: int
    successes: int
    rate: float
    """successes / samples (nan without samples)."""
    ci95: tuple[float, float]

    @staticmethod
    def of(success: np.ndarray) -> Rate:
        n, k = len(success), int(np.sum(success))
        return Rate(n, k, k / n if n else math.nan, wilson_interval(k, n))


@dataclass(frozen=True)
class PairMap:
    """Where the switches of one ordered pair succeed."""

    pair: str
    """``source-destination``, e.g. ``trot-stand``."""
    overall: Rate
    """All samples: the success of a random switch."""
    bins: int
    """Phase bins per cycle."""
    grid_samples: list[list[int]]
    """[source bin][destination bin] sample counts."""
    grid_success: list[list[float]]
    """[source bin][destination bin] success rates (nan where empty)."""
    by_source_phase: list[Rate]
    """Per source-phase bin, all destination phases together."""
    by_dest_phase: list[Rate]
    """Per destination-phase bin, all source phases together."""
    by_contacts: dict[str, Rate]
    """By the feet on the ground just before the switch (legs in contact, e.g. ``FR+RL``; ``none``: flight)."""
    fall_after_s: list[float]
    """Times from the switch to each switch-caused fall, s, sorted (files that did not record them: empty)."""
    touches: Rate
    """Share of switches in which a non-foot body touched the ground from the request to the verdict."""

    def best_worst_source_bins(self, *, min_samples: int = 1) -> tuple[Rate, Rate]:
        """The source-phase bins of highest and lowest success among those with at least ``min_samples``."""
        filled = [r for r in self.by_source_phase if r.samples >= min_samples] or self.by_source_phase
        return max(filled, key=lambda r: r.rate), min(filled, key=lambda r: r.rate)


def transition_maps(data: TransitionData, *, bins: int = 10, falls: Falls = DEFAULT_FALLS) -> list[PairMap]:
    """The map of every ordered pair present in ``data``, in the file's pair order (source, then destination), a
    success being no fall by the definition ``falls``."""
    s = data.labelled(falls).samples
    gaits = data.header.gaits
    if s.explicit.shape[1] != EXPLICIT_DIM:
        raise ValueError(f"explicit state of width {s.explicit.shape[1]}, expected {EXPLICIT_DIM}")
    contacts = s.explicit[:, _CONTACT : _CONTACT + len(LEG_NAMES)] > 0.5
    src_bin = np.minimum((s.phase_source * bins).astype(int), bins - 1)
    dst_bin = np.minimum((s.phase_dest * bins).astype(int), bins - 1)
    maps = []
    for m, n in s.pairs():
        rows = (s.source == m) & (s.dest == n)
        ok = s.success[rows].astype(bool)
        sb, db = src_bin[rows], dst_bin[rows]
        counts = np.zeros((bins, bins), dtype=int)
        wins = np.zeros((bins, bins), dtype=int)
        np.add.at(counts, (sb, db), 1)
        np.add.at(wins, (sb, db), ok)
        with np.errstate(invalid="ignore", divide="ignore"):
            grid = np.where(counts > 0, wins / np.maximum(counts, 1), np.nan)
        feet = contacts[rows]
        labels = np.array(["+".join(g for g, down in zip(LEG_NAMES, f, strict=True) if down) or "none" for f in feet])
        falls = s.fall_after[rows][~ok]
        maps.append(
            PairMap(
                pair=f"{gaits[m]}-{gaits[n]}",
                overall=Rate.of(ok),
                bins=bins,
                grid_samples=counts.tolist(),
                grid_success=grid.tolist(),
                by_source_phase=[Rate.of(ok[sb == b]) for b in range(bins)],
                by_dest_phase=[Rate.of(ok[db == b]) for b in range(bins)],
                by_contacts={label: Rate.of(ok[labels == label]) for label in sorted(set(labels.tolist()))},
                fall_after_s=sorted(float(t) for t in falls[np.isfinite(falls)]),
                touches=Rate.of(s.longest_touch[rows] > 0),
            )
        )
    return maps


def fall_time_quantile(maps: list[PairMap], q: float = 0.99) -> float | None:
    """The time after the switch by which a fraction ``q`` of all recorded switch-caused falls have happened, s
    (``None`` without any)."""
    times = [t for m in maps for t in m.fall_after_s]
    return float(np.quantile(times, q)) if times else None


def write_map_json(maps: list[PairMap], path: Path, *, source: str, falls: Falls) -> Path:
    """Write the maps (with the 99% fall time, the definition of a fall and the file they were read from) as JSON,
    atomically."""
    body = {
        "source": source,
        "falls": falls,
        "fall_after_s_q99": fall_time_quantile(maps),
        "pairs": [asdict(m) for m in maps],
    }
    return write_json(path, null_for_nan(body), indent=1)


def write_map_plot(maps: list[PairMap], path: Path, *, title: str | None = None) -> Path:
    """One row per pair: the source x destination phase heatmap with sample counts, and the success per source
    and destination phase bin with 95% intervals; a PNG, written atomically."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(maps), 2, figsize=(9.5, 3.6 * len(maps)), squeeze=False)
    for (heat, lines), m in zip(axes, maps, strict=True):
        edges = np.linspace(0.0, 1.0, m.bins + 1)
        image = heat.pcolormesh(edges, edges, np.array(m.grid_success, dtype=float).T, vmin=0, vmax=1, cmap="RdYlGn")
        centres = (edges[:-1] + edges[1:]) / 2
        for i, x in enumerate(centres):
            for j, y in enumerate(centres):
                heat.text(x, y, str(m.grid_samples[i][j]), ha="center", va="center", fontsize=6)
        heat.set_xlabel("source phase φm")
        heat.set_ylabel("destination phase φn")
        heat.set_title(f"{m.pair.replace('-', ' → ')}: {m.overall.rate:.0%} of {m.overall.samples}")
        fig.colorbar(image, ax=heat, label="success")
        for rates, label in ((m.by_source_phase, "source phase"), (m.by_dest_phase, "destination phase")):
            rate = [r.rate for r in rates]
            lines.errorbar(
                centres, rate, yerr=[np.subtract(rate, [r.ci95[0] for r in rates]),
                                     np.subtract([r.ci95[1] for r in rates], rate)],
                marker="o", markersize=3, capsize=2, label=label,
            )
        lines.set_ylim(-0.02, 1.02)
        lines.set_xlabel("phase (cycles)")
        lines.set_ylabel("success")
        lines.grid(alpha=0.3)
        lines.legend(fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return save_figure(fig, path)
