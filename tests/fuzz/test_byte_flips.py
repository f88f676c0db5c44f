"""tests/fuzz/byte_flips.py end to end at a few flips and structured edits per kind of file: every kind is read back,
and no flip or edit is accepted with a different result or ends in a traceback; a resume with a changed input is
refused and the same samples given twice are counted once (docs/failures.md has the full runs: 100 flips, 100 edits
per kind)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parent / "byte_flips.py"
EDITED = {"route table", "handover states", "entry metadata.json", "benchmark results.json", "resume identity"}
CONTROLS = {"(the keys in another order)", "(the derived detours left out)", "(the name left to the file's)"}
"""The edits of content that changes nothing read (a kind has one or two): the only ones that may be accepted."""
IDENTITY_FLIPS = {"resume: its gait file", "resume: its states file", "data overlap: a copy's index",
                  "data overlap: a copy's part"}


def test_no_flipped_byte_or_edited_field_is_used_silently() -> None:
    done = subprocess.run([sys.executable, str(SCRIPT), "--flips", "4", "--edits", "8", "--seed", "1"],
                          capture_output=True, text=True, timeout=600, check=False)
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    assert done.returncode == 0, done.stderr
    flips, edits = [x for x in lines if "flips" in x], [x for x in lines if "edits" in x]
    assert len(flips) == 17 and {line["file"].split()[0] for line in flips} >= {"entry", "switching", "transition"}
    assert "switching survival.pt" in {line["file"] for line in flips}
    assert {line["file"] for line in flips} >= IDENTITY_FLIPS
    for line in flips:
        assert line["different"] == 0 and line["crashed"] == 0, line
        assert line["refused"] + line["same"] == 4 and line["bytes"] > 0
    assert {line["edits"] for line in edits} == EDITED | {"data overlap"}
    for line in edits:
        assert line["wrong"] == 0 and line["crashed"] == 0 and not line["bad_edits"], line
        if line["edits"] == "data overlap":  # each guise of the same samples is read, every sample counted once
            assert line["harmless"] == 8 and len(set(line["harmless_edits"])) == 8, line
            continue
        assert line["refused"] + line["harmless"] == 8 and len(line["harmless_edits"]) == line["harmless"], line
        assert set(line["harmless_edits"]) <= CONTROLS and line["refused"] >= 6, line
