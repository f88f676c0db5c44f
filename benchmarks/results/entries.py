"""The generated table of ``library/README.md``, "How each gait does": each entry's training record (its
``metadata.json``, beside the same gait's entry in ``library-switch-start/``) and its stored evaluation
(``docs/results/library/eval-GAIT.json``, the recovery skill's in ``docs/results/recover/``)."""

from __future__ import annotations

import json
from pathlib import Path

from benchmarks.results.evidence import EVIDENCE, GAITS, ROOT, not_yet, pct, read_evidence, shown

__all__ = ["EARLIER", "LIBRARY", "RECOVER", "SKILL", "entries_table"]

LIBRARY = ROOT / "library"
"""The shipped library, whose entries' training records the table reads."""
EARLIER = ROOT / "library-switch-start"
"""The library shipped before it, whose entries' training times stand beside."""
RECOVER = ROOT / "docs" / "results" / "recover"
"""The recovery skill's stored results."""
SKILL = "trot_in_place"
"""The recovery skill, the table's last row."""


def _training(entry: Path) -> dict | None:
    path = entry / "metadata.json"
    return json.loads(path.read_text(encoding="utf-8"))["training"] if path.is_file() else None


def _trained(gait: str, library: Path, earlier: Path) -> str:
    record, before = _training(library / gait), _training(earlier / gait)
    if record is None:
        return "-"
    text = f"{record['iterations']:,} iterations, {record['wall_clock_s'] / 60:.1f} min"
    return text + (f" (the switch-start {gait}: {before['wall_clock_s'] / 60:.1f} min)" if before else "")


def _row(gait: str, result: dict, trained: str) -> str:
    episodes = result["episodes"]
    falls, touches = round(result["fall_rate"] * episodes), round(result["touch_rate"] * episodes)
    still = abs(result["reference_speed"]) < 1e-6  # the speed error is then the drift in m/s
    error = f"{result['speed_error']:.3f} m/s drift" if still else f"{pct(result['speed_error'])}%"
    touched = f"{pct(result['touch_rate'])}%" if touches else f"0 of {episodes}"
    return (f"| `{gait}` | {trained} | {falls} of {episodes} | {touched} | {error} "
            f"| {result['median_heading_change_deg']:.1f} deg |")


def entries_table(evidence_dir: Path = EVIDENCE, recover: Path = RECOVER, *, library: Path = LIBRARY,
                  earlier: Path = EARLIER) -> str:
    """Each shipped gait, then the recovery skill: iterations and training time (the switch-start entry's beside),
    falls, touches, speed error (the drift, for a gait standing still) and median heading change of its stored
    evaluation; the stored evaluations cited, and those not stored yet named."""
    paths = [*(Path(evidence_dir) / f"eval-{gait}.json" for gait in GAITS), Path(recover) / f"eval-{SKILL}.json"]
    found = {path: read_evidence(path) for path in paths}
    stored = {path: evidence for path, evidence in found.items() if evidence is not None}
    if not stored:
        return not_yet(*paths)
    rows = ["| gait | trained | falls | touches | speed error | median heading change |", "|---|---|---|---|---|---|"]
    for path, evidence in stored.items():
        gait = path.stem.removeprefix("eval-")
        rows.append(_row(gait, evidence["result"], _trained(gait, Path(library), Path(earlier))))
    commands = sorted({evidence["command"].replace(f"eval {path.stem.removeprefix('eval-')} ", "eval GAIT ")
                       for path, evidence in stored.items()})
    missing = [path for path, evidence in found.items() if evidence is None]
    return "\n".join([*rows, "", f"Trained: `{shown(Path(library))}/GAIT/metadata.json` and "
                      f"`{shown(Path(earlier))}/GAIT/metadata.json`, `training`. Evaluated: "
                      + ", ".join(f"`{shown(path)}`" for path in stored) + " (made "
                      + ", ".join(sorted({e['made'] for e in stored.values()})) + "), the output of "
                      + " and ".join(f"`{c}`" for c in commands) + "."
                      + (f" {not_yet(*missing)}" if missing else "")])
