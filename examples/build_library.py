"""Build a complete gait library from gait descriptions: train each gait, collect switch samples, fit the
transition-net and the TMT. The result is a library folder that ``gaitlib run --library DIR`` can use.

    python examples/build_library.py --minutes 20 --samples 20000     # about 1.5 h on a 2-core CPU
    python examples/build_library.py --minutes 0.5 --samples 500 --min-per-label 0  # a smoke run of a few minutes

The shipped ``library/`` was built the same way with the CLI (see docs/results.md for its sizes).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from gaitlib.collection import CollectConfig, collect
from gaitlib.defaults import MIN_PER_LABEL
from gaitlib.gaits import get_gait
from gaitlib.library import Library
from gaitlib.strategies.fitting import fit_library
from gaitlib.training import get_preset
from gaitlib.training.trainer import TrainRequest, train_gait
from gaitlib.transitions import read_all

GAITS = ("pace", "stand", "trot")  # shipped descriptions (gaitlib/gaits/descriptions/*.toml)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=20.0, help="training time per gait")
    parser.add_argument("--samples", type=int, default=20_000, help="transition samples to collect")
    parser.add_argument("--library", type=Path, default=Path("examples_library"))
    parser.add_argument("--min-per-label", type=int, default=MIN_PER_LABEL,
                        help="successes and failures each pair needs for the fit to be validated (0: any)")
    args = parser.parse_args()
    library = Library(args.library)

    for gait in GAITS:  # each gait is trained alone: adding one never touches the others
        result = train_gait(
            TrainRequest(
                description=get_gait(gait),
                preset=get_preset("cpu"),
                iterations=10**6,
                time_limit_s=60 * args.minutes,
                library=args.library,
                run_dir=Path("runs") / "examples" / gait,
                eval_episodes=32,
            )
        )
        print(f"{gait}: fall rate {result.evaluation.fall_rate:.2f} after {args.minutes:g} min")

    data = Path("data") / "examples_transitions.h5"  # rerunning resumes the collection
    collect(data, library=library, gaits=GAITS, config=CollectConfig(samples=args.samples, push_max=400))
    report = fit_library(library, read_all([data]), sources=[data], min_per_label=args.min_per_label)
    for pair, accuracy in report.accuracy()["latent"].items():
        print(f"transition-net {pair}: {100 * accuracy:.1f}% balanced validation accuracy")


if __name__ == "__main__":
    main()
