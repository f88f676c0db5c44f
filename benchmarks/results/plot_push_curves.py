"""Plot single-push curves of several gaits (or libraries) on one figure, from ``gaitlib eval GAIT --impulses ...
--json`` outputs: fall rate against impulse with 95% intervals, one line per file (labelled by the file's name).

Usage: python -m benchmarks.results.plot_push_curves OUT.png CURVE.json [CURVE.json ...]
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from gaitlib.evaluation import PushPoint, write_push_plot


def main() -> None:
    out, files = Path(sys.argv[1]), [Path(f) for f in sys.argv[2:]]
    curves = {}
    for path in files:
        points = json.loads(path.read_text())["points"]
        curves[path.stem] = [PushPoint.from_dict(p) for p in points]
    write_push_plot(curves, out)
    print(out)


if __name__ == "__main__":
    main()
