"""Add a gait to an existing library and extend the transition data: train the new gait alone, collect only the
pairs that involve it, and refit the transition-net and TMT on the old and the new samples together. No existing
policy is retrained or changed.

    python examples/grow_library.py --library examples_library --old-data data/examples_transitions.h5

(build ``examples_library`` first with ``examples/build_library.py``; the shipped ``library/`` can be grown the
same way, into a copy.)
"""

from __future__ import annotations

import argparse
from pathlib import Path

from gaitlib.collection import CollectConfig, collect
from gaitlib.gaits import get_gait
from gaitlib.library import Library
from gaitlib.strategies.fitting import fit_library
from gaitlib.training import get_preset
from gaitlib.training.trainer import TrainRequest, train_gait
from gaitlib.transitions import read_all


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--library", type=Path, required=True)
    parser.add_argument("--old-data", type=Path, required=True, help="the transition file(s) of the library")
    parser.add_argument("--gait", default="bound", help="a shipped gait description to add")
    parser.add_argument("--minutes", type=float, default=20.0)
    parser.add_argument("--samples", type=int, default=20_000)
    args = parser.parse_args()

    before = Library(args.library).identities()
    train_gait(
        TrainRequest(
            description=get_gait(args.gait),
            preset=get_preset("cpu"),
            iterations=10**6,
            time_limit_s=60 * args.minutes,
            library=args.library,
            run_dir=Path("runs") / "examples" / args.gait,
            eval_episodes=32,
        )
    )
    library = Library(args.library)  # read afresh: it now holds the new gait
    gaits = library.gaits()
    assert all(library.identities()[g] == i for g, i in before.items())  # old policies untouched

    new_pairs = tuple((m, n) for m in gaits for n in gaits if m != n and args.gait in (m, n))
    new_data = args.old_data.with_name(f"{args.old_data.stem}_{args.gait}.h5")
    collect(new_data, library=library, config=CollectConfig(samples=args.samples, push_max=400, pairs=new_pairs))
    files = [args.old_data, new_data]
    report = fit_library(library, read_all(files, current=library.identities()), sources=files)  # merged by gait
    for pair, accuracy in sorted(report.accuracy()["latent"].items()):
        print(f"{pair}: {100 * accuracy:.1f}%")


if __name__ == "__main__":
    main()
