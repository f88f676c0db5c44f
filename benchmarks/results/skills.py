"""The tables of the skills beyond the six gaits, each in the library that holds it with its evaluation: every
skill against the quality bar for a skill that steers, and under shoves, from the evidence stored for each folder
(``docs/results/steer`` for ``library-steer/``, staged; ``docs/results/mirror`` for ``library-mirror/``, the
mirror images of staged skills; ``docs/results/catch`` for ``library-catch/``, the catch skill trained without a
reference motion; ``docs/results/recover`` for the shipped ``library/``'s recovery skill)."""

from __future__ import annotations

import json
from pathlib import Path

from benchmarks.results.evidence import (
    BAR_FALLS,
    BAR_HEADING_DEG,
    BAR_SPEED,
    ROOT,
    interval,
    not_yet,
    pct,
    read_evidence,
    shown,
)
from gaitlib.stats import wilson_interval

__all__ = ["STAGED", "STILL", "skill_misses", "skills_bar", "skills_shoves"]

STAGED = {"steer": "library-steer", "mirror": "library-mirror", "catch": "library-catch", "recover": "library"}
"""Each skill folder's evidence folder (under ``docs/results``) and the library that holds its skills (under the
repository)."""
STILL = 0.05
"""Where the reference's forward or lateral speed or yaw rate is 0, how far the skill's may stray: m/s, rad/s."""


def _staged(results: Path) -> list[tuple[str, Path, Path, dict]]:
    """Every staged skill with an evaluation: its name, its evidence folder, its staging folder and its evaluation's
    evidence, in the order of :data:`STAGED`, then by name."""
    found = []
    for evidence_folder, staging in STAGED.items():
        for path in sorted((Path(results) / evidence_folder).glob("eval-*.json")):
            found.append((path.stem.removeprefix("eval-"), path.parent, ROOT / staging, read_evidence(path)))
    return found


def _figures(result: dict) -> dict[str, tuple[float, float, str]]:
    """forward, lateral and yaw: (measured, reference, unit); lateral and yaw only where the evaluation measured them
    (a skill whose reference turns or steps aside)."""
    figures = {"forward": (result["forward_speed"], result["reference_speed"], "m/s")}
    steering = result.get("steering")
    if steering:
        figures["lateral"] = (steering["lateral_speed"], steering["reference_lateral_speed"], "m/s")
        figures["yaw rate"] = (steering["yaw_rate"], steering["reference_yaw_rate"], "rad/s")
    return figures


def _heading(result: dict) -> float:
    """The median heading error against the reference's heading, deg: the turning heading's where the evaluation
    measured it, else the change from the starting heading (a straight reference's heading)."""
    steering = result.get("steering")
    return steering["median_heading_error_deg"] if steering else result["median_heading_change_deg"]


def skill_misses(result: dict) -> list[str]:
    """What of the bar an evaluation misses: falls over 1%, a speed or yaw rate more than 10% from the reference's
    (more than :data:`STILL` where the reference's is 0), the median heading error over 15 degrees."""
    misses = [f"falls {pct(result['fall_rate'])}%"] if result["fall_rate"] > BAR_FALLS else []
    for name, (value, reference, unit) in _figures(result).items():
        allowed = STILL if abs(reference) < 1e-3 else BAR_SPEED * abs(reference)
        if abs(value - reference) > allowed:
            misses.append(f"{name} {value:.3f} {unit} against {reference:.3f}")
    if _heading(result) > BAR_HEADING_DEG:
        misses.append(f"heading {_heading(result):.2f} deg")
    return misses


def _cell(value: float, reference: float, unit: str) -> str:
    off = "" if abs(reference) < 1e-3 else f" ({pct(abs(value - reference) / abs(reference))}%)"
    return f"{value:.3f} {unit}{off}"


def skills_bar(results: Path = ROOT / "docs" / "results") -> str:
    """Each staged skill against the bar: its reference, its training, falls, speeds, yaw rate and heading."""
    staged = _staged(results)
    if not staged:
        return not_yet(Path(results) / "steer" / "eval-SKILL.json")
    lines = ["| skill | folder | reference | trained | falls [95%] | forward | lateral | yaw rate | median heading "
             "error | meets the bar |", "|---|---|---|---|---|---|---|---|---|---|"]
    for name, _, folder, evidence in staged:
        result = evidence["result"]
        meta = json.loads((folder / name / "metadata.json").read_text(encoding="utf-8"))
        ref, training = meta["description"], meta["training"]
        reference = (f"{ref['forward_speed']:g} m/s, {ref.get('lateral_speed', 0.0):g} m/s lateral, "
                     f"{ref.get('yaw_rate', 0.0):g} rad/s")
        figures = _figures(result)
        cells = [_cell(*figures[k]) if k in figures else "-" for k in ("forward", "lateral", "yaw rate")]
        falls = round(result["fall_rate"] * result["episodes"])
        misses = skill_misses(result)
        made = (f"mirror of `{training['mirror']['source']}`" if "mirror" in training
                else f"{training['iterations']:,} iterations, {training['wall_clock_s'] / 60:.1f} min")
        lines.append(f"| `{name}` | `{folder.name}/` | {reference} | {made} | {falls} of {result['episodes']} "
                     f"{interval(*result['fall_ci95'])} | {' | '.join(cells)} | {_heading(result):.2f} deg "
                     f"| {'no: ' + '; '.join(misses) if misses else 'yes'} |")
    meeting = sum(not skill_misses(e["result"]) for *_, e in staged)
    return "\n".join([*lines, "", f"{meeting} of {len(staged)} skills meet the bar: at most {pct(BAR_FALLS)}% falls "
                      f"in {staged[0][3]['result']['episodes']} episodes of {staged[0][3]['result']['seconds']:g} s; "
                      f"forward speed, lateral speed and yaw rate each within {pct(BAR_SPEED)}% of the reference, or "
                      f"within {STILL} m/s and {STILL} rad/s where the reference's is 0; a median heading error of at "
                      f"most {BAR_HEADING_DEG:g} deg (a turning reference's heading where it turns, else the "
                      "starting one). Training time is the entry's own record, the cores often shared with other "
                      "work.", "", "Evidence: " + "; ".join(
                          f"`{shown(Path(results) / f)}/eval-SKILL.json`" for f in STAGED)
                      + ", each with its command (`gaitlib eval SKILL --library FOLDER --episodes 256 --seconds 20 "
                      "--seed 0 --backend mujoco --record --json`)."])


def skills_shoves(results: Path = ROOT / "docs" / "results") -> str:
    """Each staged skill under one shove of each impulse, and under the paper's pushes of up to 50 N."""
    rows, impulses = [], None
    for name, folder, _, _ in _staged(results):
        shoves, pushes = read_evidence(folder / f"shove-{name}.json"), read_evidence(folder / f"push50-{name}.json")
        if shoves is None or pushes is None:
            continue
        points = {p["impulse_ns"]: p for p in shoves["result"]["points"]}
        impulses = impulses or list(points)
        cells = [f"{pct(p['fall_rate'])}% {interval(*wilson_interval(p['falls'], p['episodes']))}"
                 for p in points.values()]
        sectors = points[12.0]["by_sector"]
        side, (fell, of) = max(sectors.items(), key=lambda kv: (kv[1][0] / max(kv[1][1], 1), kv[0]))
        worst = f"{side}, {fell} of {of}" if fell else "none"
        push = pushes["result"]
        rows.append(f"| `{name}` | " + " | ".join(cells) + f" | {worst} "
                    f"| {round(push['fall_rate'] * push['episodes'])} of {push['episodes']} |")
    if not rows:
        return not_yet(Path(results) / "steer" / "shove-SKILL.json")
    header = " | ".join(f"{i:g} N s [95%]" for i in impulses)
    return "\n".join([f"| skill | {header} | worst direction at 12 N s | `--push-max 50` |",
                      "|---|" + "---|" * (len(impulses) + 2), *rows, "",
                      "One 0.1 s shove per episode in a random direction, 1,024 episodes a point, and 256 episodes of "
                      "20 s under the paper's random pushes of up to 50 N; falls by the `trunk` definition, 95% Wilson "
                      "intervals. Evidence: " + "; ".join(f"`{shown(Path(results) / f)}/shove-SKILL.json` and "
                                                           f"`push50-SKILL.json`" for f in STAGED)
                      + " (`gaitlib eval SKILL --impulses 0,6,12,18,24,30 --episodes 1024 --library FOLDER --seed 0 "
                      "--backend mujoco --json`; `--push-max 50 --episodes 256 --seconds 20`)."])
