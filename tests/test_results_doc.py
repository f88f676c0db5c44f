"""The results pages' generated tables are what ``python -m benchmarks.results`` makes of the stored evidence, and a
figure changed by hand is caught; the tables themselves from small evidence files made here."""

from __future__ import annotations

import dataclasses
import itertools
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from benchmarks.results import doc as tables
from benchmarks.results import robustness
from benchmarks.results import switches as switching
from benchmarks.results.evidence import pct
from gaitlib.atomic import CHECKSUM_KEY, json_checksum
from gaitlib.defaults import Falls
from gaitlib.stats import wilson_interval
from gaitlib.strategies.fitting import PAPER_PAIRS
from gaitlib.training.recipe import PAPER_RECIPE

ROOT = Path(__file__).resolve().parents[1]
GAITS = ("bound", "pace", "pronk", "stand", "trot", "walk")


def _store(folder: Path, name: str, result: dict, command: str = "gaitlib made-up") -> Path:
    path = folder / f"{name}.json"
    path.write_text(json.dumps({"command": command, "made": "2026-12-03", "result": result}))
    return path


def _eval(gait: str, *, falls: int = 0, heading: float = 3.0, speed: float = 1.0, reference: float = 1.0) -> dict:
    low, high = wilson_interval(falls, 256)
    return {"gait": gait, "episodes": 256, "seconds": 20.0, "fall_rate": falls / 256, "fall_ci95": [low, high],
            "touch_rate": 4 / 256, "touch_ci95": list(wilson_interval(4, 256)), "longest_touch_s": 0.1,
            "median_heading_change_deg": heading, "forward_speed": speed, "reference_speed": reference,
            "speed_error": abs(speed - reference) / reference if reference else abs(speed), "falls": "trunk"}


def _cell(successes: int, samples: int = 1000) -> dict:
    return {"samples": samples, "successes": successes, "forced": 0, "wait_s": 0.0, "switched": samples,
            "source_falls": 0, "touched": 12, "longest_touch_s": 0.1}


def _benchmark(cells: dict[str, dict[str, dict]], *, seed: int = 0, routes: dict | None = None,
               magnitude: float = 0.0, samples: int = 1000, **settings) -> dict:
    """A benchmark results.json: strategy -> pair -> cell, all at ``magnitude`` N."""
    settings = {"samples": samples, "seed": seed, "falls": "trunk"} | ({"routes": routes} if routes else {}) | settings
    groups = {f"{s}@{magnitude:g}": {"strategy": s, "magnitude_n": magnitude, "backend": "mujoco", "elapsed_s": 1.0,
                                     "cells": c} for s, c in cells.items()}
    return {"format": "gaitlib.benchmark", "format_version": 3, "settings": settings, "library_identities": {},
            "groups": groups, "checksum": "0" * 64}


def _pairs() -> list[str]:
    return [f"{m}-{n}" for m, n in itertools.permutations(GAITS, 2)]


@pytest.fixture
def evidence(tmp_path: Path) -> Path:
    """Evidence of every kind in ``tmp_path/evidence``: the pace misses the bar by its heading alone; at 0 N
    net-lookahead reaches 99% on the ten pairs into the stand and the walk, random on none; routed, one of two
    detour pairs reaches it."""
    folder = tmp_path / "evidence"
    folder.mkdir()
    for gait in GAITS:
        result = _eval(gait, heading=16.8 if gait == "pace" else 3.0, reference=0.0 if gait == "stand" else 1.0,
                       speed=0.002 if gait == "stand" else 0.95)
        _store(folder, f"eval-{gait}", result, f"gaitlib eval {gait} --episodes 256 --json")
    high = {p for p in _pairs() if p.endswith(("stand", "walk"))}
    _store(folder, "bench-0n", _benchmark({
        "net-lookahead": {p: _cell(995 if p in high else 970) for p in _pairs()},
        "random": {p: _cell(900) for p in _pairs()},
    }), "gaitlib benchmark --strategies random,net-lookahead --magnitudes 0 --samples 1000")
    routes = {"trot-pace": ["trot", "stand", "pace"], "pronk-trot": ["pronk", "walk", "trot"]}
    _store(folder, "routes", {"format": "gaitlib.routes", "strategy": "net-lookahead", "detours": routes,
                              "rates": {"trot-pace": [920, 1000], "trot-stand": [998, 1000], "stand-pace": [990, 1000],
                                        "pronk-trot": [950, 1000], "pronk-walk": [990, 1000],
                                        "walk-trot": [980, 1000]},
                              "measured_with": {"samples": 1000, "seed": 0, "falls": "trunk"}})
    _store(folder, "bench-direct", _benchmark({"net-lookahead": {"trot-pace": _cell(930), "pronk-trot": _cell(950)}},
                                              seed=1))
    _store(folder, "bench-routed", _benchmark({"net-lookahead": {"trot-pace": _cell(991), "pronk-trot": _cell(975)}},
                                              seed=1, routes=routes))
    return folder


def _accuracy(path: Path, *, latent: float = 0.75, explicit: float = 0.74, phase: float = 0.6) -> Path:
    pairs = _pairs()
    report = {"format": "gaitlib.accuracy", "format_version": 2, "data": ["data/a.h5", "data/b.h5"], "samples": 1234,
              "input_written": "latent", "falls": "trunk",
              "balanced_validation_accuracy": {k: dict.fromkeys(pairs, v) for k, v in
                                               (("latent", latent), ("phase", phase), ("explicit", explicit))},
              "paper_table_3": {"latent": dict.fromkeys(PAPER_PAIRS, 0.8915)}}
    path.write_text(json.dumps(report))
    return path


def _doc(path: Path) -> Path:
    """A results page at ``path`` (its file name one of the pages) with every block it holds, each out of date."""
    blocks = "\n\n".join(f"## {name}\n\n<!-- table: {name} -->\nold\n<!-- /table -->"
                         for name in tables.page_tables(path))
    path.write_text(f"# Results\n\nProse stays as written.\n\n{blocks}\n\nThe end.\n")
    return path


def test_every_page_is_what_the_stored_evidence_makes() -> None:
    made = tables.render_tables()
    assert {doc.name: tables.check_doc(doc, tables=made) for doc in tables.DOCS} == dict.fromkeys(
        (doc.name for doc in tables.DOCS), None), "python -m benchmarks.results rewrites them"


def test_every_stored_result_with_a_checksum_matches_it() -> None:
    """A result gaitlib wrote carries the checksum of its content; an edit of the stored copy (such as naming the
    robot model by its repository path) is followed by a new checksum, so a reader that checks it accepts the file."""
    results = []
    for path in sorted((ROOT / "docs" / "results").rglob("*.json")):
        stored = json.loads(path.read_text())
        found = stored.get("result") if isinstance(stored, dict) else None
        results += [(path, r) for r in (found if isinstance(found, list) else [found])
                    if isinstance(r, dict) and CHECKSUM_KEY in r]
    assert len(results) >= 20
    stale = [str(path) for path, result in results
             if result[CHECKSUM_KEY] != json_checksum({k: v for k, v in result.items() if k != CHECKSUM_KEY})]
    assert stale == []


def test_a_figure_changed_by_hand_is_caught(tmp_path: Path) -> None:
    copy = tmp_path / "results.md"
    shutil.copy(tables.DOC, copy)
    text = copy.read_text()
    start = text.index("<!-- table: quality-bar -->")
    row = text.index("| pace |", start)
    heading = re.search(r"(\d+)\.(\d) deg", text[row:])
    assert heading is not None
    edited = text[:row] + text[row:].replace(heading.group(0), f"{int(heading.group(1)) + 1}.{heading.group(2)} deg", 1)
    assert edited != text
    copy.write_text(edited)
    assert tables.check_doc(copy) == "quality-bar"
    done = subprocess.run([sys.executable, "-m", "benchmarks.results", "--check", "--doc", str(copy)], cwd=ROOT,
                          capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 1 and "'quality-bar'" in done.stderr
    assert tables.main(["--doc", str(copy)]) == 0 and tables.check_doc(copy) is None
    assert copy.read_text() == text  # the rewrite puts the figure back, and nothing else moves


def _flat(text: str) -> str:
    """``text`` with every run of white space one space: what the wrapping of the tables' prose leaves alone."""
    return " ".join(text.split())


def test_the_tables_from_small_evidence(tmp_path: Path, evidence: Path) -> None:
    accuracy = _accuracy(tmp_path / "accuracy.json")
    (tmp_path / "earlier-lib" / "switching").mkdir(parents=True)
    earlier = _accuracy(tmp_path / "earlier-lib" / "switching" / "accuracy.json", latent=0.8, explicit=0.85)
    _drive(tmp_path / "drive", "square-net-lookahead", [_drive_run(k) for k in range(100)])
    made = tables.render_tables(evidence, accuracy, earlier)
    assert list(made) == list(tables.TABLES)
    assert all(len(line) <= tables.WIDTH for body in made.values() for line in body.splitlines()
               if not line.startswith("|") and "`gaitlib" not in line)
    made = {name: _flat(body) for name, body in made.items()}
    quality = made["quality-bar"]
    assert "5 of 6 gaits meet the bar" in quality and "The pace misses it: heading within 15 deg: 16.8 deg." in quality
    assert "0.002 m/s drift" in quality and "`gaitlib eval GAIT --episodes 256 --json`" in quality
    pairs = made["pairs-0n"]
    low, high = wilson_interval(995, 1000)
    assert f"| stand → walk | 90.0 [{100 * wilson_interval(900, 1000)[0]:.1f}" in pairs
    assert f"**99.5** [{100 * low:.1f}, {100 * high:.1f}]" in pairs
    assert "| pairs at 99.0% or more | 0 of 30 | | 10 of 30 | |" in pairs  # random first, then the net
    assert "seed 0; falls by the `trunk` definition" in pairs
    routes = made["routes"]
    assert "| trot → pace | stand | 92.0 | 98.8 | 93.0 [" in routes  # predicted: 0.998 x 0.990
    assert "| at 99.5% or more | | | | 0 of 2 | 0 of 2 |" in routes  # the shipped library's goal, the robust recipe's
    net = made["net-accuracy"]
    assert "| latent, paper | 89.2 | 89.2 |" in net  # the paper's 0.8915, rounded as written
    assert "latent >= explicit holds (75.0 against 74.0)" in net and "--ablation --falls trunk" in net
    earlier_net = made["net-accuracy-switch-start"]  # another library's net: its fit names the library
    assert "latent >= explicit does not hold (80.0 against 85.0)" in earlier_net
    assert f"`gaitlib fit --library {tmp_path / 'earlier-lib'} --data data/a.h5 --data data/b.h5 --ablation" \
        in earlier_net
    drives = made["drive-seeds"]  # the other eight drives not stored
    assert "| `square.csv` | net-lookahead, guarded | 100 of 100 | 100 of 100 | 0.200 m | 0.190 m (0.190 m) |" in drives
    assert "| `figure.csv` | random | not measured |" in drives and "met by all 1 drives" in drives


def test_missing_evidence_says_not_yet_measured(tmp_path: Path, evidence: Path) -> None:
    for name in ("bench-0n", "bench-routed"):
        (evidence / f"{name}.json").unlink()
    made = tables.render_tables(evidence, tmp_path / "no-accuracy.json", tmp_path / "none" / "accuracy.json")
    assert made["pairs-0n"].startswith("Not yet measured:") and "bench-0n.json" in made["pairs-0n"]
    assert made["net-accuracy-switch-start"].startswith("Not yet measured:")
    assert made["routes"].startswith("Not yet measured:") and "bench-routed.json" in made["routes"]
    assert "bench-direct" not in made["routes"] and made["net-accuracy"].startswith("Not yet measured:")
    assert "| pace |" in made["quality-bar"]


def test_rewriting_touches_only_the_blocks(tmp_path: Path, evidence: Path) -> None:
    accuracy = _accuracy(tmp_path / "accuracy.json", latent=0.7, explicit=0.72)
    doc = _doc(tmp_path / "results.md")
    assert tables.check_doc(doc, evidence, accuracy) == "quality-bar"
    assert tables.write_doc(doc, evidence, accuracy) and not tables.write_doc(doc, evidence, accuracy)
    text = doc.read_text()
    assert text.startswith("# Results\n\nProse stays as written.\n\n## quality-bar\n\n<!-- table: quality-bar -->\n\n")
    assert text.endswith("<!-- /table -->\n\nThe end.\n") and "latent >= explicit does not hold" in _flat(text)
    assert tables.check_doc(doc, evidence, accuracy) is None
    stored = json.loads((evidence / "bench-0n.json").read_text())
    stored["result"]["groups"]["random@0"]["cells"]["trot-pace"]["successes"] = 901
    (evidence / "bench-0n.json").write_text(json.dumps(stored))
    assert tables.check_doc(doc, evidence, accuracy) == "switches"  # a stored result replaced, the doc not rewritten
    assert list(tmp_path.glob(".results.md.*")) == []  # no temporary left beside the doc


def test_a_doc_without_a_tables_block_is_refused(tmp_path: Path, evidence: Path) -> None:
    doc = tmp_path / "results.md"
    quality = tables.render_tables(evidence, tmp_path / "accuracy.json")["quality-bar"]
    doc.write_text(f"# Results\n\n<!-- table: quality-bar -->\n\n{quality}\n\n<!-- /table -->\n")
    with pytest.raises(ValueError, match="shove-curves"):
        tables.write_doc(doc, evidence, tmp_path / "accuracy.json")
    assert tables.check_doc(doc, evidence, tmp_path / "accuracy.json") == "shove-curves"  # the first block agrees
    doc.write_text("<!-- table: quality-bar -->\n<!-- /table -->\n<!-- table: quality-bar -->\n<!-- /table -->\n")
    with pytest.raises(ValueError, match="repeated"):
        tables.check_doc(doc, evidence, tmp_path / "accuracy.json")


def test_each_table_is_on_its_own_page(tmp_path: Path, evidence: Path, capsys) -> None:
    """Every table belongs to one page; a block on another page, or a file that is no results page, is refused in
    one line before anything is written, and the page's other blocks are written as on the results page."""
    assert sorted(tables.TABLES) == sorted(set(tables.TABLES))
    ablation = _doc(tmp_path / "ablation.md")
    assert tables.write_doc(ablation, evidence, tmp_path / "accuracy.json")
    assert "Not yet measured:" in ablation.read_text() and "<!-- table: robust-library -->" in ablation.read_text()
    switching_page = _doc(tmp_path / "switching_results.md")
    assert tables.write_doc(switching_page, evidence, tmp_path / "accuracy.json")
    assert "| trot → pace | stand | 92.0 | 98.8 |" in switching_page.read_text()
    misplaced = tmp_path / "results.md"
    misplaced.write_text("<!-- table: routes -->\nold\n<!-- /table -->\n")
    with pytest.raises(ValueError, match=r"the table marker 'routes' is for docs/switching_results\.md"):
        tables.write_doc(misplaced, evidence, tmp_path / "accuracy.json")
    other = tmp_path / "notes.md"
    other.write_text("<!-- table: quality-bar -->\nold\n<!-- /table -->\n")
    assert tables.main(["--doc", str(ablation), "--doc", str(other)]) == 2  # ``python -m``: the test above
    assert "notes.md is not a results page" in capsys.readouterr().err
    assert other.read_text() == "<!-- table: quality-bar -->\nold\n<!-- /table -->\n"


def _shove(impulse: float, falls: dict[str, int], *, per_sector: int = 256, touches: int = 5) -> dict:
    """One point of a single-shove curve (``benchmarks/robust_ablation.py``'s ``single_shove``)."""
    episodes, total = per_sector * len(falls), sum(falls.values())
    return {"impulse_ns": impulse, "force_n": 10 * impulse, "episodes": episodes, "falls": total,
            "fall_rate": total / episodes, "ci95": list(wilson_interval(total, episodes)),
            "by_sector": {s: [f, per_sector] for s, f in falls.items()}, "touches": touches,
            "touch_ci95": list(wilson_interval(touches, episodes)), "longest_touch_s": 0.03,
            "falls_definition": "trunk"}


def _run(falls: int, *, push_max: float = 0.0, late: int = 0, episodes: int = 1024, touches: int = 3) -> dict:
    """One ``gaitlib eval`` of an ablation row (its fields the table reads, and a few beside)."""
    return {"episodes": episodes, "seconds": 20.0, "fall_rate": falls / episodes,
            "fall_ci95": list(wilson_interval(falls, episodes)), "touch_rate": touches / episodes,
            "touch_ci95": list(wilson_interval(touches, episodes)), "longest_touch_s": 0.03,
            "median_heading_change_deg": 4.26, "forward_speed": 0.88, "reference_speed": 0.9, "speed_error": 0.0222,
            "push_max": push_max, "action_delay_steps": None, "late_steps": late, "falls": "trunk"}


def _ablation(gait: str, sources: tuple[str, str], *, shove: dict[str, int], push: int, zero: int, late: int,
              minutes: float | None) -> dict:
    """An ablation row shaped like ``benchmarks/robust_ablation.py``'s, 1,024 episodes a figure, 1,000 switches."""
    quiet = dict.fromkeys(("front", "left", "back", "right"), 0)
    figures = {"single_shove": [_shove(0.0, quiet), _shove(6.0, quiet), _shove(12.0, shove),
                                _shove(18.0, dict.fromkeys(quiet, 5))],
               "push_50n": _run(push, push_max=50.0), "zero_n": _run(zero), "one_step_late": _run(late, late=1)}
    for source, falls in zip(sources, (7, 12), strict=True):
        figures[f"switch_in_from_{source}"] = {
            "source": source, "episodes": 1000, "horizon_s": 2.5, "falls": falls,
            "fall_ci95": list(wilson_interval(falls, 1000)), "touches": 40,
            "touch_ci95": list(wilson_interval(40, 1000)), "longest_touch_s": 0.07, "falls_definition": "trunk"}
    return {"gait": gait, "library": "/x/library", "identity": "0" * 64, "recipe": "today's",
            "training_minutes": minutes, "iterations": 1500,
            "states": {"path": "data/states-0n.npz", "sha256": "1" * 64},
            "settings": {"episodes": 1024, "switches": 1000, "seconds": 20.0, "impulses_ns": [0.0, 6.0, 12.0, 18.0],
                         "backend": "mujoco", "seed": 0, "falls": "trunk"},
            "made": "2026-12-04T10:00:00+00:00", "seconds_per_part": {}, "figures": figures}


def _prose_fits(body: str) -> bool:
    return all(len(line) <= tables.WIDTH for line in body.splitlines()
               if not line.startswith("|") and "`gaitlib" not in line and "`python" not in line)


def test_the_gaits_robustness_from_small_ablation_rows(tmp_path: Path, evidence: Path) -> None:
    folder = tmp_path / "ablation"  # beside the evidence folder, as docs/results/ablation is beside library/
    folder.mkdir()
    made = tables.render_tables(evidence, tmp_path / "no-accuracy.json")["robustness-gaits"]
    assert _flat(made) == f"Not yet measured: `{folder / 'GAIT-today.json'}` not stored yet."
    # the pace: 0.4% overall at 12 N s but 4 of its 256 shoves to the left (1.6%), and 2.9% one step late
    pace = _ablation("pace", ("trot", "stand"), shove={"front": 0, "left": 4, "back": 0, "right": 0}, push=10,
                     zero=1, late=30, minutes=83.3)
    command = "python benchmarks/robust_ablation.py --gait pace --states data/states-0n.npz --out pace-today.json"
    (folder / "pace-today.json").write_text(json.dumps({"command": command, "result": pace}))
    made = _flat(robustness.robustness_table(folder))
    assert "pace, today: meets 5 of the 7 bars (pushes up to 50 N, 0 N, touches at 0 N, speed within 10%, heading " \
           "within 15 deg); misses single shove: 1.6% in the left direction (4 of 256) at 12 N s; one step late: " \
           "2.9%." in made
    assert f"Not yet measured: `{folder / 'trot-today.json'}` not stored yet." in made
    assert f"`{folder / 'pace-today.json'}` (made 2026-12-04): `{command}`" in made  # the row's own date
    # the trot: 2 of 256 in every direction at 12 N s (0.8%) meets the shove's bar; 2.9% under pushes misses its own
    trot = _ablation("trot", ("pace", "stand"), shove=dict.fromkeys(("front", "left", "back", "right"), 2), push=30,
                     zero=0, late=5, minutes=None)
    (folder / "trot-today.json").write_text(json.dumps({"command": "python benchmarks/robust_ablation.py --gait trot",
                                                         "result": trot}))
    body = tables.render_tables(evidence, tmp_path / "no-accuracy.json")["robustness-gaits"]
    assert _prose_fits(body) and "Not yet measured" not in body
    made = _flat(body)
    assert "trot, today: meets 6 of the 7 bars (single shove, 0 N, one step late, touches at 0 N, speed within " \
           "10%, heading within 15 deg); misses pushes up to 50 N: 2.9%." in made
    header = next(line for line in body.splitlines() if line.startswith("| gait, recipe | shove 6 N s [95%] | worst"))
    assert header.endswith("| switch in from trot [95%] | switch in from stand [95%] | switch in from pace [95%] |")
    shove = f"0.4 {_interval(4, 1024)} | left 4/256"
    assert f"| pace, today | 0.0 {_interval(0, 1024)} | none | {shove} | 2.0 {_interval(20, 1024)} " \
           "| front 5/256 |" in made
    assert f"| 1.0 {_interval(10, 1024)} | 0.1 {_interval(1, 1024)} | 2.9 {_interval(30, 1024)} " \
           f"| 0.7 {_interval(7, 1000)} | 1.2 {_interval(12, 1000)} | - |" in made  # no switch in from itself
    assert f"| trot, today | 0.0 {_interval(0, 1024)} | none | 0.8 {_interval(8, 1024)} | front 2/256 |" in made
    switches = f"4.0 {_interval(40, 1000)} | 4.0 {_interval(40, 1000)}"
    assert f"| 0.3 {_interval(3, 1024)} | {switches} | - | 2.2% | 4.3 deg | 83.3 |" in made
    assert f"| 0.3 {_interval(3, 1024)} | - | {switches} | 2.2% | 4.3 deg | - |" in made  # the trot's time not recorded
    assert "1,024 episodes of 20 s a figure, 1,000 switches from each source; seed 0" in made
    assert "- pace, today: today's recipe, 1,500 iterations" in made
    # a variant of the pace: its row after today's, its recipe as the train options that set it apart
    kick = _ablation("pace", ("trot", "stand"), shove=dict.fromkeys(("front", "left", "back", "right"), 0), push=0,
                     zero=0, late=0, minutes=50.2)
    kick["recipe"] = dataclasses.replace(PAPER_RECIPE, push_kind="kick", falls=Falls.TRUNK, contact_penalty=1.0,
                                         gamma=0.99).as_dict()  # today's recipe, four levers changed
    (folder / "pace-kick.json").write_text(json.dumps({"command": "python benchmarks/robust_ablation.py --gait pace",
                                                        "result": kick}))
    made = _flat(robustness.robustness_table(folder))
    assert made.index("| pace, today |") < made.index("| pace, kick |") < made.index("| trot, today |")
    assert "- pace, kick: `--push-kind kick --kick-max 1 --kick-draw axes --kick-interval 1:3 --terminate trunk " \
           "--contact-penalty 1 --gamma 0.99`, 1,500 iterations" in made
    del kick["recipe"]["kick_draw"]  # recorded before kicks could be drawn per axis: the disk, named
    (folder / "pace-kick.json").write_text(json.dumps({"command": "python benchmarks/robust_ablation.py --gait pace",
                                                        "result": kick}))
    made = _flat(robustness.robustness_table(folder))
    assert "- pace, kick: `--push-kind kick --kick-max 1 --kick-draw disk --kick-interval 1:3 --terminate" in made
    assert "pace, kick: meets 7 of the 7 bars (single shove, pushes up to 50 N, 0 N, one step late, touches at 0 N, " \
           "speed within 10%, heading within 15 deg)." in made
    # its legs touching at 0 N in 60 of 1,024 episodes, past today's 3 of 1,024 with both intervals; a heading off
    kick["figures"]["zero_n"] = _run(0, touches=60) | {"median_heading_change_deg": 16.4}
    (folder / "pace-kick.json").write_text(json.dumps({"command": "python benchmarks/robust_ablation.py --gait pace",
                                                        "result": kick}))
    made = _flat(robustness.robustness_table(folder))
    assert f"pace, kick: meets 5 of the 7 bars (single shove, pushes up to 50 N, 0 N, one step late, speed within " \
           f"10%); misses touches at 0 N: 5.9% {_interval(60, 1024)} against today's 0.3% {_interval(3, 1024)}; " \
           "heading within 15 deg: 16.4 deg." in made
    # a gait without today's row stored is not judged on its touches
    (folder / "trot-today.json").unlink()
    trot = _ablation("trot", ("pace", "stand"), shove=dict.fromkeys(("front", "left", "back", "right"), 0), push=0,
                     zero=0, late=0, minutes=40.0)
    (folder / "trot-kick.json").write_text(json.dumps({"command": "python benchmarks/robust_ablation.py --gait trot",
                                                        "result": trot}))
    made = _flat(robustness.robustness_table(folder))
    assert "trot, kick: meets 6 of the 6 bars (single shove, pushes up to 50 N, 0 N, one step late, speed within " \
           "10%, heading within 15 deg)." in made


def _interval(count: int, total: int) -> str:
    low, high = wilson_interval(count, total)
    return f"[{pct(low)}, {pct(high)}]"


def test_the_shipped_librarys_switches_beside_the_switch_start_ones_from_small_evidence(tmp_path: Path,
                                                                                        evidence: Path) -> None:
    earlier = tmp_path / "switch-start"  # beside the evidence folder, as docs/results/switch-start is beside library/
    earlier.mkdir()
    shutil.move(evidence / "bench-0n.json", earlier / "bench-0n.json")  # the fixture's 0 N: the earlier library's
    made = _flat(tables.render_tables(evidence, tmp_path / "no-accuracy.json")["switches"])
    assert made.startswith("Not yet measured:")
    assert "evidence/bench-0n.json" in made and "evidence/bench-50n.json" in made
    # the shipped library: random 98% on every pair but trot -> walk (96%), net-lookahead 99.6% but trot -> pace (99%)
    _store(evidence, "bench-0n", _benchmark({
        "net-lookahead": {p: _cell(990 if p == "trot-pace" else 996) for p in _pairs()},
        "random": {p: _cell(960 if p == "trot-walk" else 980) for p in _pairs()},
    }), "gaitlib benchmark --library library-robust --strategies random,net-lookahead --magnitudes 0")
    body = tables.render_tables(evidence, tmp_path / "no-accuracy.json")["switches"]
    assert _prose_fits(body)
    made = _flat(body)
    assert ("| pair | random, 0 N: switch-start [95%] | random, 0 N: robust [95%] | net-lookahead, 0 N: switch-start "
            "[95%] | net-lookahead, 0 N: robust [95%] |") in made and "50 N:" not in made.split("Not yet")[0]
    # the goals: random 97%, net-lookahead 99.5% (the switch-start 99.5% into the walk meets it; the robust 99.0% not)
    assert (f"| trot → walk | 90.0 {_interval(900, 1000)} | 96.0 {_interval(960, 1000)} "
            f"| **99.5** {_interval(995, 1000)} | **99.6** {_interval(996, 1000)} |") in made
    assert f"| trot → pace | 90.0 {_interval(900, 1000)} | **98.0** {_interval(980, 1000)} | 97.0 " in made
    assert f"| **98.0** {_interval(980, 1000)} | 97.0 {_interval(970, 1000)} | 99.0 {_interval(990, 1000)} |" in made
    assert "| pairs at the goal or more | 0 of 30 | 29 of 30 | 10 of 30 | 29 of 30 |" in made
    assert f"| all pairs (touches) | 90.0 {_interval(27000, 30000)} (1.2%) | 97.9 {_interval(29380, 30000)} (1.2%) |" \
        in made
    assert ("random, 0 N (goal 97.0% on every pair): switch-start 0 of 30, robust 29 of 30; each library: 1,000 "
            "transitions a cell, seed 0; falls by the `trunk` definition.") in made
    assert "net-lookahead, 0 N (goal 99.5% on every pair): switch-start 10 of 30, robust 29 of 30;" in made
    assert "Not yet measured: `" in made and "evidence/bench-50n.json`, `" in made
    assert "switch-start/bench-50n" not in made
    assert made.count("(made 2026-12-03)") == 2 and "--library library-robust" in made
    # at 50 N only the shipped library is stored: the switch-start column is "-" throughout
    _store(evidence, "bench-50n", _benchmark({"net-lookahead": {p: _cell(390, 400) for p in _pairs()}},
                                             magnitude=50.0, samples=400))
    made = _flat(tables.render_tables(evidence, tmp_path / "no-accuracy.json")["switches"])
    assert f"| - | **97.5** {_interval(390, 400)} |" in made and "| 29 of 30 | - | 30 of 30 |" in made
    assert "net-lookahead, 50 N (goal 95.0% on every pair): robust 30 of 30; robust: 400 transitions" in made
    _store(evidence, "bench-50n", _benchmark({"random": {p: _cell(390, 400) for p in _pairs()}}, magnitude=50.0))
    with pytest.raises(ValueError, match=r"bench-50n\.json holds no net-lookahead group at 50 N"):
        switching.switches_table(earlier, evidence)


def test_every_gaits_single_shove_curve_in_both_libraries_from_small_rows(tmp_path: Path, evidence: Path) -> None:
    """The curves table takes each library's curve of a gait from its ablation row (today's recipe: the switch-start
    library; the chosen one: the shipped library), names the rows not stored, and reads the verdict against the bar
    from the worst direction."""
    folder = tmp_path / "ablation"
    folder.mkdir()
    assert _flat(robustness.shove_table(folder)).startswith("Not yet measured:")
    quiet = dict.fromkeys(("front", "left", "back", "right"), 0)
    rows = {"pace-today": {"front": 0, "left": 4, "back": 0, "right": 0}, f"pace-{robustness.CHOSEN}": quiet,
            f"walk-{robustness.CHOSEN}": {**quiet, "right": 1}}
    for name, shove in rows.items():
        row = _ablation(name.split("-")[0], ("trot", "stand"), shove=shove, push=0, zero=0, late=0, minutes=50.0)
        (folder / f"{name}.json").write_text(json.dumps({"command": f"robust_ablation {name}", "result": row}))
    body = tables.render_tables(evidence, tmp_path / "no-accuracy.json")["shove-curves"]
    assert _prose_fits(body)
    made = _flat(body)
    assert made.index("| pace | switch-start |") < made.index("| pace | robust |") < made.index("| walk | robust |")
    assert f"| pace | switch-start | 0.0 {_interval(0, 1024)} | 0.0 {_interval(0, 1024)} | 0.4 {_interval(4, 1024)} " \
           f"| 2.0 {_interval(20, 1024)} | left 4/256 |" in made
    assert "| no: 1.6% in the left direction (4 of 256) at 12 N s |" in made
    assert f"| walk | robust | 0.0 {_interval(0, 1024)} | 0.0 {_interval(0, 1024)} | 0.1 {_interval(1, 1024)} " in made
    assert "Gaits meeting the bar: switch-start 0 of 1; robust 2 of 2 (pace, walk)." in made
    assert "(made 2026-12-04): `robust_ablation pace-today`" in made
    assert f"`{folder / 'walk-today.json'}`" in made and f"`{folder / f'trot-{robustness.CHOSEN}.json'}`" in made


def test_the_shipped_library_beside_the_switch_start_one_from_small_rows(tmp_path: Path, evidence: Path) -> None:
    """Each gait's switch-start row beside its row with the chosen recipe (the shipped library), every bar counted,
    the touches of both judged against the switch-start gait's; a gait without its chosen row is named, not judged."""
    folder = tmp_path / "ablation"
    folder.mkdir()
    made = tables.render_tables(evidence, tmp_path / "no-accuracy.json")["robust-library"]
    assert _flat(made).startswith("Not yet measured:") and f"stand-{robustness.CHOSEN}.json" in made
    quiet = dict.fromkeys(("front", "left", "back", "right"), 0)
    rows = {"today": _ablation("stand", ("pace", "trot"), shove={**quiet, "left": 4}, push=30, zero=0, late=2,
                               minutes=11.7),
            robustness.CHOSEN: _ablation("stand", ("pace", "trot"), shove=quiet, push=0, zero=0, late=0, minutes=9.4)}
    rows[robustness.CHOSEN]["figures"]["zero_n"] = _run(0, touches=60)  # past the switch-start 3 of 1,024
    for variant, row in rows.items():
        (folder / f"stand-{variant}.json").write_text(json.dumps({"command": f"robust_ablation {variant}",
                                                                   "result": row}))
    body = tables.render_tables(evidence, tmp_path / "no-accuracy.json")["robust-library"]
    assert _prose_fits(body)
    made = _flat(body)
    assert made.index("| stand | switch-start |") < made.index("| stand | robust |")
    assert f"| stand | switch-start | 0.4 {_interval(4, 1024)} | left 4/256 | 2.9 {_interval(30, 1024)} | 0.0 " \
           f"{_interval(0, 1024)} | 0.2 {_interval(2, 1024)} | 0.3 {_interval(3, 1024)} | 5 of 7 |" in made
    assert f"| stand | robust | 0.0 {_interval(0, 1024)} | none |" in made
    assert f"| 5.9 {_interval(60, 1024)} | 6 of 7 |" in made
    assert "stand, robust: meets 6 of the 7 bars (single shove, pushes up to 50 N, 0 N, one step late, " \
           f"speed within 10%, heading within 15 deg); misses touches at 0 N: 5.9% {_interval(60, 1024)} against " \
           f"today's 0.3% {_interval(3, 1024)}." in made
    assert "With the robust recipe 0 of the 1 gaits measured meet every bar." in made
    named = f"`{folder / 'stand-today.json'}`"
    assert f"pace-{robustness.CHOSEN}.json" in made and f"{named}," not in made and f"{named} not" not in made
    rows[robustness.CHOSEN]["figures"]["zero_n"] = _run(0)
    (folder / f"stand-{robustness.CHOSEN}.json").write_text(json.dumps({"command": "x", "result": rows[
        robustness.CHOSEN]}))
    made = _flat(robustness.library_table(folder))
    assert "1 of the 1 gaits measured meet every bar (stand)." in made and "| 7 of 7 |" in made


def _sweep(successes: dict[str, dict[float, int]], *, static: dict[str, dict[float, int]] | None = None) -> dict:
    """A sweep of 50 transitions a cell: strategy -> magnitude -> successes on every pair (``static``: on pace -> stand
    and trot -> stand instead)."""
    result = _benchmark({}, samples=50)
    for strategy, by_magnitude in successes.items():
        for magnitude, count in by_magnitude.items():
            own = (static or {}).get(strategy, {})
            cells = {p: _cell(own.get(magnitude, count) if p in ("pace-stand", "trot-stand") else count, 50)
                     for p in _pairs()}
            result["groups"][f"{strategy}@{magnitude:g}"] = {"strategy": strategy, "magnitude_n": magnitude,
                                                             "backend": "mujoco", "elapsed_s": 1.0, "cells": cells}
    return result


def test_the_papers_sweep_for_both_libraries_from_small_evidence(tmp_path: Path, evidence: Path) -> None:
    earlier = tmp_path / "switch-start"
    earlier.mkdir()
    made = _flat(tables.render_tables(evidence, tmp_path / "no-accuracy.json")["sweep"])
    assert made.startswith("Not yet measured:") and "evidence/sweep.json" in made and "switch-start/sweep.json" in made
    # the switch-start library: net 45 of 50 at 0 N and 25 at 500 N, but 50 and 40 on the two pairs into the stand
    earlier_sweep = _sweep({"random": {0.0: 40, 500.0: 20}, "tmt": {0.0: 42, 500.0: 22}, "net": {0.0: 45, 500.0: 25}},
                     static={"net": {0.0: 50, 500.0: 40}})
    _store(earlier, "sweep", earlier_sweep, "gaitlib benchmark --magnitudes 0:500:500 --samples 50")
    body = tables.render_tables(evidence, tmp_path / "no-accuracy.json")["sweep"]
    assert _prose_fits(body)
    made = _flat(body)
    assert ("| strategy | switch-start: all pairs, 0-500 N [95%] (touches) | switch-start: pace → stand, trot → stand "
            "[95%] (touches) |") in made
    assert f"| `random` | 60.0 {_interval(1800, 3000)} (24.0%) | 60.0 {_interval(120, 200)} (24.0%) |" in made
    assert f"| `net` | 71.3 {_interval(2140, 3000)} (24.0%) | 90.0 {_interval(180, 200)} (24.0%) |" in made
    assert ("Switch-start: ranked by success over 0-500 N: `net`, `tmt`, `random`; on pace → stand, trot → stand, "
            "`net` is +26.0 points from the best of the paper's other strategies, `tmt`.") in made
    assert f"| push, N | `random` | `tmt` | `net` | |---|---|---|---| | 0 | 80.0 {_interval(1200, 1500)} |" \
        in made
    assert f"| 500 | 40.0 {_interval(600, 1500)} | 44.0 {_interval(660, 1500)} | 52.0 {_interval(780, 1500)} |" in made
    assert "evidence/sweep.json` not stored yet." in made and "switch-start: 50 transitions a cell, seed 0" in made
    # the shipped robust library sweeps two strategies only: the switch-start ones it lacks are "-"
    _store(evidence, "sweep", _sweep({"random": {0.0: 45, 500.0: 45}, "net-lookahead": {0.0: 50, 500.0: 50}}))
    made = _flat(tables.render_tables(evidence, tmp_path / "no-accuracy.json")["sweep"])
    assert f"| `tmt` | 64.0 {_interval(1920, 3000)} (24.0%) | - | 64.0 {_interval(128, 200)} (24.0%) | - |" in made
    assert f"| `net-lookahead` | - | 100.0 {_interval(3000, 3000)} (24.0%) | - |" in made
    assert "Robust: ranked by success over 0-500 N: `net-lookahead`, `random`." in made and "not stored" not in made
    assert "in parentheses; each library: 50 transitions a cell, seed 0; falls by the `trunk` definition." in made
    assert made.count("(made 2026-12-03)") == 2
    del earlier_sweep["groups"]["tmt@500"]
    _store(earlier, "sweep", earlier_sweep)
    with pytest.raises(ValueError, match=r"switch-start/sweep\.json does not sweep every strategy over the same push"):
        tables.render_tables(evidence, tmp_path / "no-accuracy.json")


def _rates(successes: list[int], samples: int = 100) -> list[dict]:
    return [{"samples": samples, "successes": k, "rate": k / samples, "ci95": list(wilson_interval(k, samples))}
            for k in successes]


def test_where_the_shipped_librarys_switches_fail_from_a_small_map(tmp_path: Path, evidence: Path) -> None:
    made = _flat(tables.render_tables(evidence, tmp_path / "no-accuracy.json")["map"])
    assert made == f"Not yet measured: `{evidence / 'map-0n.json'}` not stored yet."
    # two pairs, four phase bins each: trot -> walk worst at its source's second bin (60 of 100), best at its
    # destination's last (99 of 100); an empty bin is never the best or the worst
    pairs = []
    for pair, source, dest, falls in (("trot-walk", [90, 60, 95, 90], [70, 80, 86, 99], [0.4, 0.9, 1.2]),
                                      ("stand-pace", [100, 99, 98, 100], [100, 99, 98, 100], [0.5])):
        ok = sum(source)
        pairs.append({"pair": pair, "overall": _rates([ok], 400)[0], "bins": 4, "grid_samples": [], "grid_success": [],
                      "by_source_phase": [*_rates(source),
                                          {"samples": 0, "successes": 0, "rate": None, "ci95": [0.0, 1.0]}],
                      "by_dest_phase": _rates(dest), "by_contacts": {}, "fall_after_s": falls,
                      "touches": _rates([20], 400)[0]})
    _store(evidence, "map-0n", {"source": "data/robust-0n.h5", "falls": "trunk", "fall_after_s_q99": 1.23,
                              "pairs": pairs}, "gaitlib map data/robust-0n.h5 --out runs/robust-map-0n")
    body = tables.render_tables(evidence, tmp_path / "no-accuracy.json")["map"]
    assert _prose_fits(body)
    made = _flat(body)
    assert made.index("| stand → pace |") < made.index("| trot → walk |")
    assert (f"| trot → walk | 83.8 {_interval(335, 400)} of 400 | 95.0 {_interval(95, 100)} of 100 "
            f"| 60.0 {_interval(60, 100)} of 100 | 99.0 {_interval(99, 100)} of 100 "
            f"| 70.0 {_interval(70, 100)} of 100 | 5.0% |") in made
    assert "a bin is 1/4 of the source's" in made and "falls by the `trunk` definition" in made
    assert "4 switch-caused falls with a recorded time, 99% of them within 1.23 s of the switch." in made
    assert "(made 2026-12-03): `gaitlib map data/robust-0n.h5 --out runs/robust-map-0n`" in made


def test_each_librarys_routes_are_counted_against_its_own_goal(tmp_path: Path, evidence: Path) -> None:
    earlier = tmp_path / "switch-start"
    earlier.mkdir()
    for name in ("routes", "bench-direct", "bench-routed"):
        shutil.copy(evidence / f"{name}.json", earlier / f"{name}.json")
    made = tables.render_tables(evidence, tmp_path / "no-accuracy.json")
    # trot -> pace routed: 99.1%, the switch-start library's goal (99%) met, the shipped one's (99.5%) not
    assert f"| **99.1** {_interval(991, 1000)} |" in made["routes-switch-start"]
    assert "| at 99.0% or more | | | | 0 of 2 | 1 of 2 |" in made["routes-switch-start"]
    assert f"| 99.1 {_interval(991, 1000)} |" in made["routes"]
    assert "| at 99.5% or more | | | | 0 of 2 | 0 of 2 |" in made["routes"]
    assert "Routed, 0 of 2 pairs reach 99.5%; directly, 0." in _flat(made["routes"])


def test_every_strategy_on_another_a1_from_small_evidence(tmp_path: Path, evidence: Path) -> None:
    made = _flat(tables.render_tables(evidence, tmp_path / "no-accuracy.json")["strategies-menagerie"])
    assert made.startswith("Not yet measured:") and "evidence/menagerie-strategies.json" in made
    robot = "MENAGERIE/unitree_a1/scene_nomesh.xml"
    held = _sweep({"random": {0.0: 45}, "net": {0.0: 48}})
    held["settings"]["robot"] = robot
    _store(evidence, "menagerie-strategies", held, f"gaitlib benchmark --robot {robot} --magnitudes 0 --samples 50")
    body = tables.render_tables(evidence, tmp_path / "no-accuracy.json")["strategies-menagerie"]
    assert _prose_fits(body)
    made = _flat(body)
    assert "| strategy | robust: all pairs, 0 N [95%] (touches) | robust: pace → stand, trot → stand [95%] " \
           "(touches) |" in made
    assert f"| `net` | 96.0 {_interval(1440, 1500)} (24.0%) | 96.0 {_interval(96, 100)} (24.0%) |" in made
    assert f"robust: 50 transitions a cell, seed 0; falls by the `trunk` definition, robot `{robot}`." in made
    assert "Robust: ranked by success at 0 N: `net`, `random`; on pace → stand, trot → stand, `net` is +6.0 " \
           "points from the best of the paper's other strategies, `random`." in made
    assert "| push, N |" not in made and "switch-start/menagerie-strategies.json` not stored yet." in made
    # a sweep of other pairs only: no margin on the dynamic-to-static pairs, their columns "-"
    for group in held["groups"].values():
        for pair in ("pace-stand", "trot-stand"):
            del group["cells"][pair]
    _store(evidence, "menagerie-strategies", held)
    made = _flat(tables.render_tables(evidence, tmp_path / "no-accuracy.json")["strategies-menagerie"])
    assert f"| `net` | 96.0 {_interval(1344, 1400)} (24.0%) | - |" in made and "`net` is" not in made


def test_a_skill_is_held_to_each_line_of_the_bar() -> None:
    """A staged skill's evaluation misses the bar on each line alone: falls over 1%, a speed or yaw rate more than 10%
    from a moving reference's or more than 0.05 from a zero one, a median heading error over 15 degrees."""
    from benchmarks.results.skills import skill_misses

    steering = {"lateral_speed": 0.0, "reference_lateral_speed": 0.0, "yaw_rate": 0.5, "reference_yaw_rate": 0.5,
                "median_heading_error_deg": 11.0}
    good = {"fall_rate": 0.0, "forward_speed": 0.5, "reference_speed": 0.5, "median_heading_change_deg": 60.0,
            "steering": steering}
    assert skill_misses(good) == []  # a turning skill's heading is the turning reference's, not the starting one
    assert skill_misses(good | {"fall_rate": 0.012}) == ["falls 1.2%"]
    assert skill_misses(good | {"forward_speed": 0.56}) == ["forward 0.560 m/s against 0.500"]
    assert skill_misses(good | {"forward_speed": 0.54}) == []
    assert skill_misses(good | {"steering": steering | {"lateral_speed": 0.051}}) == ["lateral 0.051 m/s against 0.000"]
    assert skill_misses(good | {"steering": steering | {"yaw_rate": 0.44}}) == ["yaw rate 0.440 rad/s against 0.500"]
    assert skill_misses(good | {"steering": steering | {"median_heading_error_deg": 15.05}}) == ["heading 15.05 deg"]
    still = {"fall_rate": 0.0, "forward_speed": -0.014, "reference_speed": 0.0, "median_heading_change_deg": 3.9}
    assert skill_misses(still) == [] and skill_misses(still | {"median_heading_change_deg": 16.0}) == [
        "heading 16.00 deg"]


def _guarded_shove(falls: int, sectors: dict[str, int], catches: list[int], *, impulse: float = 12.0) -> dict:
    """One guarded point of ``gaitlib eval --impulses --guard`` (256 episodes a direction); ``catches`` their delays
    in control steps, a negative one before the shove."""
    guard = {"on": True, "catches": [{"delay_steps": d} for d in catches], "false_catches": sum(d < 0 for d in catches),
             "delay_steps_median": float(sorted(catches)[len(catches) // 2]) if catches else None,
             "measured_gait_share": 0.97}
    return {"impulse_ns": impulse, "episodes": 1024, "falls": falls, "guard": guard,
            "by_sector": {name: [sectors.get(name, 0), 256] for name in ("front", "left", "back", "right")}}


def test_the_guard_tables_from_small_evidence(tmp_path: Path) -> None:
    """Each gait guarded beside unguarded on the same draws, the shipped gaits first and a skill after them, bold
    only within the goal; a tag with no evaluation stored says so."""
    from benchmarks.results.guard import guard_pushes, guard_shoves

    unguarded = _guarded_shove(40, {"left": 30}, []) | {"guard": {"on": False}}
    _store(tmp_path, "shove-12-trot_in_place-t", {"points": [_guarded_shove(0, {}, [])],
                                                  "unguarded_points": [unguarded]})
    _store(tmp_path, "shove-12-pace-t", {"points": [_guarded_shove(10, {"left": 3, "right": 7}, [-2, 1, 3, 3])],
                                         "unguarded_points": [unguarded]})
    _store(tmp_path, "shove-18-pace-t", {"points": [_guarded_shove(110, {"back": 110}, [1], impulse=18.0)],
                                         "unguarded_points": [unguarded]})
    _store(tmp_path, "shove-12-pace-other", {"points": [], "unguarded_points": []})  # another guard's: not read
    rows = guard_shoves("t", tmp_path).splitlines()[2:5]
    assert rows == [
        "| pace | 12 N s | 40 (3.9% [2.9, 5.3]) | **10 (1.0% [0.5, 1.8])** | right, 7 of 256 | 4 (1) | 3 steps "
        "| 97.0% |",
        "| trot_in_place | 12 N s | 40 (3.9% [2.9, 5.3]) | **0 (0.0% [0.0, 0.4])** | none | 0 (0) | - | 97.0% |",
        "| pace | 18 N s | 40 (3.9% [2.9, 5.3]) | 110 (10.7% [9.0, 12.8]) | back, 110 of 256 | 1 (0) | 1 step "
        "| 97.0% |",
    ]
    run = {"episodes": 1024, "seconds": 20.0, "falls": 11, "minutes": 338.6, "catches_per_min": 0.5,
           "guard": {"catches": [{}] * 3, "measured_gait_share": 0.9996}}
    _store(tmp_path, "push50-walk-t", {"guarded": run | {"push_max_n": 50.0},
                                       "unguarded": run | {"push_max_n": 50.0, "falls": 30}})
    _store(tmp_path, "pace-0n-t", {"guarded": run | {"push_max_n": 0.0, "falls": 0},
                                   "unguarded": run | {"push_max_n": 0.0, "falls": 0}})
    assert guard_pushes("t", tmp_path).splitlines()[2:4] == [
        "| walk | up to 50 N, 339 minutes | 30 (2.9% [2.1, 4.2]) | 11 (1.1% [0.6, 1.9]) | 3 (0.50 /min) | 99.96% |",
        "| pace | none, 339 minutes | 0 (0.0% [0.0, 0.4]) | 0 (0.0% [0.0, 0.4]) | 3 (0.50 /min, every one false) "
        "| 99.96% |",
    ]
    assert guard_shoves("none", tmp_path).startswith("Not yet measured:")
    assert guard_pushes("none", tmp_path).startswith("Not yet measured:")


def _bench_arm(magnitude: float, successes: dict[str, int], samples: int, *, catches: dict[str, int] | None) -> dict:
    """A ``gaitlib benchmark`` result of one net-lookahead group (``catches``: the guard's, by caught pair)."""
    group = {"strategy": "net-lookahead", "magnitude_n": magnitude, "cells": {
        pair: {"samples": samples, "successes": s, "touched": 0} for pair, s in successes.items()}}
    if catches is not None:
        group["guard"] = {"catches": sum(catches.values()), "by_pair": catches, "back_after_s_median": 0.5}
    return {"settings": {"samples": samples, "seed": 0, "falls": "trunk"}, "groups": {"g": group}}


def test_the_guard_pairs_table_from_small_evidence(tmp_path: Path) -> None:
    """Every pair unguarded beside guarded at each stored magnitude, bold at its goal, pooled over the shipped gaits'
    pairs and over all, each magnitude's pooled goal and the pairs the guard made worse named."""
    from benchmarks.results.guard import guard_pairs

    zero = {"pace-trot": 1000, "trot-pace": 990, "pace-trot_in_place": 1000}
    _store(tmp_path, "bench-0n-unguarded-t", _bench_arm(0.0, zero, 1000, catches=None))
    _store(tmp_path, "bench-0n-guarded-t", _bench_arm(0.0, zero | {"trot-pace": 970}, 1000,
                                                      catches={"pace-trot": 3, "walk-bound": 5}))
    pushed = {"pace-trot": 390, "trot-pace": 370, "pace-trot_in_place": 400}
    _store(tmp_path, "bench-50n-unguarded-t", _bench_arm(50.0, pushed, 400, catches=None))
    _store(tmp_path, "bench-50n-guarded-t", _bench_arm(50.0, pushed | {"trot-pace": 385}, 400, catches={}))
    lines = guard_pairs("t", tmp_path).splitlines()
    assert lines[0] == "| pair | 0 N, unguarded | 0 N, guarded | 50 N, unguarded | 50 N, guarded |"
    assert lines[2:8] == [
        "| pace → trot | **100.0** [99.6, 100.0] | **100.0** [99.6, 100.0] | **97.5** [95.5, 98.6] "
        "| **97.5** [95.5, 98.6] |",
        "| pace → trot_in_place | **100.0** [99.6, 100.0] | **100.0** [99.6, 100.0] | **100.0** [99.0, 100.0] "
        "| **100.0** [99.0, 100.0] |",
        "| trot → pace | 99.0 [98.2, 99.5] | 97.0 [95.7, 97.9] | 92.5 [89.5, 94.7] | **96.3** [93.9, 97.7] |",
        "| the 2 pairs of the six shipped gaits | 99.5 [99.1, 99.7] | 98.5 [97.9, 98.9] | 95.0 [93.3, 96.3] "
        "| 96.9 [95.4, 97.9] |",
        "| all 3 pairs | 99.7 [99.4, 99.8] | 99.0 [98.6, 99.3] | 96.7 [95.5, 97.5] | 97.9 [96.9, 98.6] |",
        "| pairs at the goal | 2 of 3 | 2 of 3 | 2 of 3 | 3 of 3 |",
    ]
    assert lines[9] == ("- 0 N: 30 falls in 3,000 switches guarded (300.0 per 30,000, short of the goal of 15; "
                        "unguarded 10, 100.0 per 30,000); pairs guarded below their unguarded interval: trot → pace; 8 "
                        "catches (walk → bound 5, pace → trot 3).")
    assert lines[10] == ("- 50 N: 97.9% pooled guarded, within the goal of 97.0% (unguarded 96.7%); pairs guarded "
                         "below their unguarded interval: none; 0 catches.")
    assert guard_pairs("none", tmp_path).startswith("Not yet measured:")
    assert guard_pairs("t", tmp_path, robot="menagerie").startswith("Not yet measured:")
    _store(tmp_path, "bench-menagerie-0n-unguarded-t", _bench_arm(0.0, zero, 1000, catches=None))
    _store(tmp_path, "bench-menagerie-0n-guarded-t", _bench_arm(0.0, zero | {"trot-pace": 970}, 1000, catches={}))
    lines = guard_pairs("t", tmp_path, robot="menagerie").splitlines()
    assert lines[0] == "| pair | 0 N, unguarded | 0 N, guarded |"
    assert lines[4] == "| trot → pace | **99.0** [98.2, 99.5] | **97.0** [95.7, 97.9] |"  # the goal there: 97%
    assert lines[9] == ("- 0 N: 99.0% pooled guarded, within the goal of 99.0% (unguarded 99.7%); pairs guarded "
                        "below their unguarded interval: trot → pace; 0 catches.")
    assert lines[11].startswith("On MuJoCo Menagerie's A1, each cell 1,000 transitions at 0 N, seed 0 both ways")


def _drive_run(seed: int, *, up: bool = True, closest: tuple | None = (0.19, 0.2), duration: float = 20.0,
               switches: int = 6, end: float = 0.19, wall: float = 2.0) -> dict:
    """One seed of ``benchmarks/drive_seeds.py`` (``closest``: each waypoint's closest approach, ``None`` for a
    command timeline)."""
    row = {"seed": seed, "stayed_up": up, "fell_s": None if up else 2.2, "duration_s": duration, "switches": switches,
           "forced": 0, "wait_s_max": 0.0, "catches": 0, "touches": 0, "end_error_m": end, "wall_s": wall}
    if closest is not None:
        row |= {"reached_all": all(c is not None and c <= 0.2 for c in closest), "closest_m": list(closest),
                "reached_s": [None if c is None or c > 0.2 else 5.0 for c in closest],
                "within_goal_all": all(c is not None and c <= 0.25 for c in closest)}
    return row


def _drive(folder: Path, name: str, runs: list[dict], *, strategy: str = "net-lookahead", why_off: str | None = None,
           wall: float = 200.0) -> Path:
    """A stored drive over seeds, ``name`` the input's and the run's (``square-net-lookahead``)."""
    folder.mkdir(exist_ok=True)
    example = name.split("-")[0]
    result = {"library": "library", "switching_checksum": None, "input": f"examples/drive/{example}.csv",
              "strategy": strategy, "guard": why_off is None, "guard_why_off": why_off, "goal_m": 0.25,
              "summary": {"seeds": len(runs), "stayed_up": sum(r["stayed_up"] for r in runs), "wall_s": wall},
              "runs": runs}
    return _store(folder, name, result, f"python -m benchmarks.drive_seeds --seeds {len(runs)} --out {name}.json")


def test_the_drive_table_from_small_evidence(tmp_path: Path) -> None:
    """Each stored drive a row in the table's order (a drive not stored says so), the end error for waypoints alone,
    and the goal missed by a drive with too few seeds up or a waypoint beyond 0.25 m, by how much."""
    from benchmarks.results.drive import drive_table

    folder = tmp_path / "drive"
    assert drive_table(folder).startswith("Not yet measured:")
    _drive(folder, "square-net-lookahead", [_drive_run(k, end=0.18 if k < 60 else 0.21, switches=15 if k == 7 else 6,
                                                       duration=20.0 if k % 2 else 30.0) for k in range(100)])
    _drive(folder, "slalom-net-lookahead", [_drive_run(k, up=k > 1, closest=(0.19, 0.31 if k == 5 else 0.2 if k > 1
                                                                             else None)) for k in range(100)])
    _drive(folder, "figure-random", [_drive_run(k, closest=None, end=1.4, duration=19.0, switches=8, wall=1.5)
                                     for k in range(100)], strategy="random", why_off="unguarded (--no-guard)",
           wall=150.0)
    lines = drive_table(folder).splitlines()
    assert lines[0].startswith("| input | strategy, guard | stayed up | every waypoint within 0.25 m | closest")
    assert lines[0].endswith("| end error, median (max) | drive, median (max) | switches, median (max) "
                             "| wall per drive | 100 seeds |")
    assert lines[2:11] == [
        "| `square.csv` | net-lookahead, guarded | 100 of 100 | 100 of 100 | 0.200 m | 0.180 m (0.210 m) "
        "| 25.0 s (30.0 s) | 6 (15) | 2.00 s | 3.3 min |",
        "| `slalom.csv` | net-lookahead, guarded | 98 of 100 | 97 of 100 | 0.310 m; a waypoint never approached on 2 "
        "seeds | 0.190 m (0.190 m) | 20.0 s (20.0 s) | 6 (6) | 2.00 s | 3.3 min |",
        "| `figure.csv` | net-lookahead | not measured | | | | | | | |",
        "| `square.csv` | net-lookahead-unguarded | not measured | | | | | | | |",
        "| `slalom.csv` | net-lookahead-unguarded | not measured | | | | | | | |",
        "| `figure.csv` | net-lookahead-unguarded | not measured | | | | | | | |",
        "| `square.csv` | random | not measured | | | | | | | |",
        "| `slalom.csv` | random | not measured | | | | | | | |",
        "| `figure.csv` (commands) | random, unguarded | 100 of 100 | - | - | - | 19.0 s (19.0 s) | 8 (8) | 1.50 s "
        "| 2.5 min |",
    ]
    text = _flat("\n".join(lines[12:]))
    assert ("The goal, up on at least 99 of 100 seeds and every waypoint within 0.25 m on the seeds up: met by 2 of 3 "
            "drives, missed by `slalom.csv` net-lookahead, guarded: up 98 of 100, 1 short of 99, and 1 of the seeds "
            "up with a waypoint beyond 0.25 m, the farthest 0.310 m (0.060 m over). Not measured: "
            "`figure-net-lookahead.json`,") in text
    assert (f"Evidence: `{folder / 'square-net-lookahead.json'}` (made 2026-12-03): "
            "`python -m benchmarks.drive_seeds --seeds 100 --out square-net-lookahead.json`;") in text
    assert text.endswith("`python -m benchmarks.drive_seeds --seeds 100 --out figure-random.json`.")


def test_a_stored_drive_edited_is_caught(tmp_path: Path) -> None:
    """docs/driving.md's table is what the stored drives make: a copy of the page written from copies of them, one seed
    edited (a waypoint beyond the goal), ``--check`` fails naming the table, and the rewrite shows the goal missed."""
    shutil.copytree(ROOT / "docs" / "results" / "drive", tmp_path / "drive")
    copy = tmp_path / "driving.md"
    shutil.copy(ROOT / "docs" / "driving.md", copy)
    library = tmp_path / "library"  # the evidence folder beside the drives (the other pages' tables: not read here)
    assert tables.check_doc(copy, library) == "drive-seeds"  # the copies cite their own paths
    assert tables.main(["--doc", str(copy), "--evidence", str(library)]) == 0
    assert tables.check_doc(copy, library) is None
    assert "| `square.csv` | random, unguarded | 100 of 100 | 100 of 100 | 0.200 m |" in copy.read_text()
    path = tmp_path / "drive" / "square-random.json"
    stored = json.loads(path.read_text())
    run = stored["result"]["runs"][3]
    run["closest_m"][1], run["within_goal_all"] = 0.31, False
    path.write_text(json.dumps(stored))
    assert tables.check_doc(copy, library) == "drive-seeds"
    done = subprocess.run([sys.executable, "-m", "benchmarks.results", "--check", "--doc", str(copy), "--evidence",
                           str(library)], cwd=ROOT, capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 1 and "'drive-seeds'" in done.stderr
    assert tables.main(["--doc", str(copy), "--evidence", str(library)]) == 0
    assert tables.check_doc(copy, library) is None
    text = _flat(copy.read_text())
    assert "| `square.csv` | random, unguarded | 100 of 100 | 99 of 100 | 0.310 m |" in text
    assert ("met by 8 of 9 drives, missed by `square.csv` random, unguarded: 1 of the seeds up with a waypoint beyond "
            "0.25 m, the farthest 0.310 m (0.060 m over).") in text
