"""Print the shipped library's training records as markdown: time, samples, evaluation, reward vs wall-clock.

    python -m benchmarks.results.library_report [--library library]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from gaitlib.library import Library


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--library", type=Path, default=None, help="library folder (default: the shipped one)")
    library = Library(parser.parse_args().library)
    metas = {entry.name: entry.metadata for entry in library.entries()}
    columns = "training time (min) | iterations | samples | fall rate | joint RMSE (rad) | speed (m/s) | reference"
    print(f"| gait | {columns} (m/s) | episodes |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, meta in metas.items():
        t, e = meta["training"], meta["evaluation"]
        print(
            f"| {name} | {t['wall_clock_s'] / 60:.1f} | {t['iterations']} | {t['samples']:,} | {e['fall_rate']:.3f} | "
            f"{e['joint_rmse']:.3f} | {e['forward_speed']:.2f} | {e['reference_speed']:.2f} | {e['episodes']} |"
        )
    print("\nMean reward per step against training wall-clock time (min):\n")
    for name, meta in metas.items():
        rows = meta["training"]["curve"]["rows"]  # iteration, wall-clock s, mean reward, mean episode s
        marks = [next(r for r in rows if r[1] >= minute * 60) for minute in range(0, int(rows[-1][1] // 60) + 1, 5)]
        points = ", ".join(f"{r[1] / 60:.0f} min {r[2]:.3f}" for r in marks + rows[-1:])
        print(f"- {name}: {points}")


if __name__ == "__main__":
    main()
