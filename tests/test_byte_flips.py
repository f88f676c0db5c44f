"""benchmarks/byte_flips.py end to end at a few flips per kind of file: every kind is read back, and no flip is
accepted with a different result or ends in a traceback (docs/failures.md has the 100-flip run)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "byte_flips.py"


def test_no_flipped_byte_is_used_silently() -> None:
    done = subprocess.run([sys.executable, str(SCRIPT), "--flips", "4", "--seed", "1"], capture_output=True, text=True,
                          timeout=600, check=False)
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    assert done.returncode == 0, done.stderr
    assert len(lines) == 12 and {line["file"].split()[0] for line in lines} >= {"entry", "switching", "transition"}
    for line in lines:
        assert line["different"] == 0 and line["crashed"] == 0, line
        assert line["refused"] + line["same"] == 4 and line["bytes"] > 0
