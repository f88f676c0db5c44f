"""The transition-net's learning curve: held-out balanced accuracy per ordered pair against the samples it is
fitted on, to see when more collection stops paying.

    python benchmarks/net_learning_curve.py --data data/transitions.h5 [--data more.h5] \
        [--sizes 20000,50000,100000,200000] [--test-fraction 0.2] [--input latent] [--epochs 100] [--out curve.json]

The last ``--test-fraction`` of the samples (in file order: the latest chunks) is the test set, scored balanced per
pair as ``gaitlib fit --evaluate`` does; each fit uses the first N of the others (the file's first chunks, as a
collection stopped at N would have them), with the fit's own settings (`gaitlib fit`: 128-64-32, dropout 0.4,
AdamW 5e-4, 100 epochs, label-balanced per pair). One JSON line per size, then a markdown table.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from gaitlib.atomic import write_json
from gaitlib.transition_net import FitConfig, evaluate_net, fit
from gaitlib.transitions import TransitionData, read_all


def _rows(data: TransitionData, index: slice) -> TransitionData:
    """The samples ``index`` of ``data``, with its header."""
    return TransitionData(data.info, data.samples.select(index))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, action="append", required=True, help="transition file (repeatable)")
    parser.add_argument("--sizes", default="20000,50000,100000,200000", help="training sizes, comma-separated")
    parser.add_argument("--test-fraction", type=float, default=0.2)
    parser.add_argument("--input", default="latent", help="latent, phase or explicit")
    parser.add_argument("--epochs", type=int, default=100)
    parser.add_argument("--out", type=Path, default=None, help="also write the curve here as JSON")
    args = parser.parse_args()
    data = read_all(args.data)
    total = len(data.samples)
    first_test = total - round(args.test_fraction * total)
    test = _rows(data, slice(first_test, total))
    sizes = [int(float(s)) for s in args.sizes.split(",")]
    rows = []
    for size in (s for s in sizes if s <= first_test):
        start = time.perf_counter()
        result = fit(_rows(data, slice(0, size)), FitConfig(kind=args.input, epochs=args.epochs))
        accuracy = {f"{m}-{n}": a for (m, n), a in evaluate_net(result.net, test).items()}
        row = {"samples": size, "test_samples": total - first_test, "input": args.input,
               "fit_s": round(time.perf_counter() - start, 1), "test_balanced_accuracy": accuracy}
        rows.append(row)
        print(json.dumps(row), flush=True)
    if args.out is not None:
        write_json(args.out, {"data": [str(p) for p in args.data], "curve": rows})
    pairs = sorted({p for r in rows for p in r["test_balanced_accuracy"]})
    print("\n| samples | " + " | ".join(pairs) + " |")
    print("|---" * (len(pairs) + 1) + "|")
    for r in rows:
        cells = " | ".join(f"{100 * r['test_balanced_accuracy'].get(p, float('nan')):.1f}" for p in pairs)
        print(f"| {r['samples']:,} | {cells} |")


if __name__ == "__main__":
    main()
