"""How long does loading a library entry take? Every command that runs a policy loads its entries, and each load checks
the entry's metadata: its free-form numbers finite, its deployment block the one its own settings give (about 11,600
numbers an entry, most in the reference table). This times ``--loads`` loads of each entry of a library with those
checks in one loop each (gaitlib's), against, as the reference measured in the same run, the same loads with every
check made by the walk that names each field. It prints one JSON line per entry: the milliseconds a load takes each
way and their ratio. Results go into docs/benchmarks.md.

    python -m benchmarks.entry_load [--library library] [--loads 40]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path


def load_ms(library: Path, gait: str, *, loads: int) -> float:
    """Mean time of ``loads`` loads of the entry ``gait`` of ``library`` (after one untimed), ms."""
    from gaitlib.library.store import _load_entry

    _load_entry(library, gait)
    start = time.perf_counter()
    for _ in range(loads):
        _load_entry(library, gait)
    return (time.perf_counter() - start) / loads * 1000


def main() -> None:
    from gaitlib import checks
    from gaitlib.library import Library, validate
    from gaitlib.library.layout import shipped_library_dir

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--library", type=Path, default=shipped_library_dir(), help="the library (default: shipped)")
    parser.add_argument("--loads", type=int, default=40, help="timed loads of each entry each way")
    args = parser.parse_args()
    one_loop = (checks._all_finite, validate._agrees)
    for gait in Library(args.library).gaits():
        fast = load_ms(args.library, gait, loads=args.loads)
        checks._all_finite = validate._agrees = lambda *_: False  # every check by the walk that names the field
        try:
            walk = load_ms(args.library, gait, loads=args.loads)
        finally:
            checks._all_finite, validate._agrees = one_loop
        print(json.dumps({"gait": gait, "loads": args.loads, "load_ms": round(fast, 1),
                          "reference_walk_ms": round(walk, 1), "ratio": round(fast / walk, 3)}))


if __name__ == "__main__":
    main()
