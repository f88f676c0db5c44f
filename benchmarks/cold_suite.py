"""The test suite on a machine whose Warp kernel cache is empty (a fresh CI machine): its wall-clock time under each
pytest-xdist ``--dist`` mode given, the first the measured one (the suite's: ``loadfile``, each file on one worker),
the second the reference, each run with a cache folder of its own, empty at its start.

    python benchmarks/cold_suite.py [--runs loadfile,loadgroup] [--out cold_suite.json]

Run it from a clean clone with its venv installed (`.ci/run`'s environment), nothing else on the cores. Prints
one JSON line per run, then the ratio of the suite's time to the reference's.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def cold_run(dist: str) -> dict:
    """The whole suite with ``--dist dist`` and an empty Warp kernel cache: its time, s, and its last line."""
    with tempfile.TemporaryDirectory(prefix="warp-cache-") as cache:
        env = os.environ | {"WARP_CACHE_PATH": cache}
        start = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--dist", dist],
                              cwd=REPO, env=env, capture_output=True, text=True)
        elapsed = time.perf_counter() - start
    last = (done.stdout.strip().splitlines() or [""])[-1]
    return {"dist": dist, "seconds": round(elapsed, 1), "returncode": done.returncode, "summary": last}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", default="loadfile,loadgroup", help="pytest-xdist --dist modes, the first measured")
    parser.add_argument("--out", type=Path, default=None, help="also write the runs here as JSON")
    args = parser.parse_args()
    runs = [cold_run(dist) for dist in args.runs.split(",")]
    for run in runs:
        print(json.dumps(run))
    if len(runs) > 1:
        print(f"{runs[0]['dist']} / {runs[1]['dist']}: {runs[0]['seconds'] / runs[1]['seconds']:.2f}")
    if args.out is not None:
        from gaitlib.atomic import write_json

        write_json(args.out, {"runs": runs}, indent=1)


if __name__ == "__main__":
    main()
