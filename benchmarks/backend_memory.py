"""Does a process that builds MuJoCo backend after backend keep its memory flat? A benchmark runs each group (a
strategy at a push magnitude) on a fresh backend; this builds ``--backends`` of ``--worlds`` worlds one after the
other, steps each ``--steps`` times and closes it, and prints the resident memory after each close, with the heap
trimmed at close (gaitlib's) and, as the reference measured in the same run, without, each in a fresh interpreter.
Results go into docs/benchmarks.md.

    python benchmarks/backend_memory.py --backends 8 --worlds 256
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys


def _resident_mb() -> float:
    with open("/proc/self/status", encoding="ascii") as status:
        kib = next(int(line.split()[1]) for line in status if line.startswith("VmRSS:"))
    return kib / 1024


def churn(backends: int, worlds: int, steps: int, *, trim: bool) -> list[float]:
    """Resident memory (MB) after each backend's close, in this process."""
    from gaitlib.sim import make_backend, mujoco_backend

    if not trim:
        mujoco_backend._trim_heap = lambda: None
    after = []
    for _ in range(backends):
        sim = make_backend("mujoco", num_worlds=worlds, device="cpu")
        for _ in range(steps):
            sim.step()
        sim.close()
        after.append(round(_resident_mb(), 1))
    return after


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--backends", type=int, default=8)
    parser.add_argument("--worlds", type=int, default=256)
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--child", choices=("trim", "keep"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(churn(args.backends, args.worlds, args.steps, trim=args.child == "trim")))
        return
    runs = {}
    for mode in ("keep", "trim"):
        command = [sys.executable, __file__, "--child", mode, "--backends", str(args.backends), "--worlds",
                   str(args.worlds), "--steps", str(args.steps)]
        runs[mode] = json.loads(subprocess.run(command, capture_output=True, text=True, check=True).stdout)
    growth = {mode: round(after[-1] - after[0], 1) for mode, after in runs.items()}
    print(json.dumps({"backends": args.backends, "worlds": args.worlds, "steps": args.steps,
                      "resident_mb_after_each_close": runs,
                      "growth_mb_first_to_last": growth,
                      "growth_trimmed_vs_kept": round(growth["trim"] / growth["keep"], 3) if growth["keep"] else None}))


if __name__ == "__main__":
    main()
