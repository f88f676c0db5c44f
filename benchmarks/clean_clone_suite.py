"""The test suite as CI runs it: ``git clone`` of a commit into a fresh folder, then ``CI=true bash .ci/run`` there
(its venv, its install, the whole suite), timed. Prints one JSON line, the row of ``docs/benchmarks.md``'s "The test
suite": the commit, pytest's summary, the time of the install, the tests and the whole run, s, and the machine's
speed that moment: the time of a fixed reference computation (:func:`reference_seconds`) just before the clone, so
that runs on days the machine is slower or faster can be told apart.

    python benchmarks/clean_clone_suite.py [--repo .] [--commit main] [--empty-warp-cache] [--out suite.json]

Run it with nothing else on the cores. "tests" is the time pytest reports on its last line; "install" the rest of the
run (the venv, ``pip install``, pytest's start). The Newton tests compile Warp's kernels into Warp's kernel cache
(``~/.cache/warp``), which a clone does not reset: ``--empty-warp-cache`` gives the run a cache folder of its own,
empty at its start (``WARP_CACHE_PATH``), as on a fresh CI machine; the row's ``warp_cache`` says which it was.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["REFERENCE", "SUMMARY", "clean_clone_run", "main", "reference_seconds"]

SUMMARY = re.compile(r"(\d+ (?:passed|failed|error).*?) in ([0-9.]+)s")
"""pytest's last line, e.g. ``==== 445 passed, 3 skipped in 203.12s (0:03:23) ====``: the counts and the tests'
time, s."""


REFERENCE = (
    "import time, torch\n"
    "torch.set_num_threads(1)\n"
    "a = torch.randn(256, 256, generator=torch.Generator().manual_seed(0))\n"
    "start = time.perf_counter()\n"
    "for _ in range(2000):\n"
    "    a = torch.tanh(a @ a.T / 16.0)\n"
    "print(time.perf_counter() - start)\n"
)
"""The reference computation: 2,000 products of two 256 x 256 float32 matrices on one thread, the same on every
commit (it uses none of gaitlib's code), timed inside a fresh interpreter."""


def reference_seconds(runs: int = 3) -> float:
    """The median time of :data:`REFERENCE` over ``runs`` fresh interpreters, s."""
    times = sorted(float(subprocess.run([sys.executable, "-c", REFERENCE], capture_output=True, text=True,
                                        check=True).stdout) for _ in range(runs))
    return round(times[len(times) // 2], 3)


def _git(*args: str) -> str:
    done = subprocess.run(["git", *args], capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"clean_clone_suite: git {' '.join(args)}: {done.stderr.strip().splitlines()[-1]}")
    return done.stdout.strip()


def clean_clone_run(repo: Path, commit: str, *, empty_warp_cache: bool = False) -> dict:
    """``repo`` at ``commit`` cloned into a temporary folder and ``CI=true bash .ci/run`` run there: the commit, the
    exit code, pytest's summary, the install's, the tests' and the whole run's time, s, and ``warp_cache``: ``empty``
    (a fresh folder of the clone's as ``WARP_CACHE_PATH``) or ``warm`` (the machine's own cache)."""
    known = subprocess.run(["git", "-C", str(repo), "rev-parse", "--verify", "--quiet", "--short",
                            f"{commit}^{{commit}}"], capture_output=True, text=True, check=False)
    if known.returncode != 0:
        raise SystemExit(f"clean_clone_suite: {repo} has no commit '{commit}'")
    sha = known.stdout.strip()
    with tempfile.TemporaryDirectory(prefix="clean-clone-") as folder:
        clone = Path(folder) / "clone"
        _git("clone", "--quiet", "--no-checkout", str(Path(repo).resolve()), str(clone))
        _git("-C", str(clone), "checkout", "--quiet", sha)
        env = os.environ | {"CI": "true"}
        if empty_warp_cache:
            (cache := Path(folder) / "warp-cache").mkdir()
            env["WARP_CACHE_PATH"] = str(cache)
        start = time.perf_counter()
        done = subprocess.run(["bash", ".ci/run"], cwd=clone, env=env, capture_output=True, text=True, check=False)
        total = time.perf_counter() - start
    found = [m for line in done.stdout.splitlines() if (m := SUMMARY.search(line))]
    summary, tests = (found[-1].group(1), float(found[-1].group(2))) if found else (None, None)
    return {"commit": sha, "returncode": done.returncode, "summary": summary, "install_s": None if tests is None
            else round(total - tests, 1), "tests_s": tests, "total_s": round(total, 1),
            "warp_cache": "empty" if empty_warp_cache else "warm"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repo", type=Path, default=Path(__file__).resolve().parents[1], help="the repository")
    parser.add_argument("--commit", default="main", help="the commit to clone (default: main)")
    parser.add_argument("--empty-warp-cache", action="store_true",
                        help="give the run an empty Warp kernel cache of its own, as on a fresh CI machine")
    parser.add_argument("--out", type=Path, default=None, help="also write the run here as JSON")
    args = parser.parse_args()
    reference = reference_seconds()  # before the clone's run, on the same idle cores
    run = clean_clone_run(args.repo, args.commit, empty_warp_cache=args.empty_warp_cache) | {"reference_s": reference}
    print(json.dumps(run))
    if args.out is not None:
        from gaitlib.atomic import write_json

        write_json(args.out, run, indent=1)
    sys.exit(0 if run["returncode"] == 0 else 1)


if __name__ == "__main__":
    main()
