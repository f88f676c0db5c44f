"""docs/results.md's generated tables are what benchmarks/results_tables.py makes of the stored evidence, and a
figure changed by hand is caught; the tables themselves from small evidence files made here."""

from __future__ import annotations

import importlib.util
import itertools
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from gaitlib.stats import wilson_interval

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "benchmarks" / "results_tables.py"
GAITS = ("bound", "pace", "pronk", "stand", "trot", "walk")


def _load():
    spec = importlib.util.spec_from_file_location("results_tables", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


tables = _load()


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


def _benchmark(cells: dict[str, dict[str, dict]], *, seed: int = 0, routes: dict | None = None) -> dict:
    """A benchmark results.json: strategy -> pair -> cell, all at 0 N."""
    settings = {"samples": 1000, "seed": seed, "falls": "trunk"} | ({"routes": routes} if routes else {})
    groups = {f"{s}@0": {"strategy": s, "magnitude_n": 0.0, "backend": "mujoco", "elapsed_s": 1.0, "cells": c}
              for s, c in cells.items()}
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
              "paper_table_3": {"latent": dict.fromkeys(tables.PAPER_PAIRS, 0.8915)}}
    path.write_text(json.dumps(report))
    return path


def _doc(path: Path) -> Path:
    blocks = "\n\n".join(f"## {name}\n\n<!-- table: {name} -->\nold\n<!-- /table -->" for name in tables.TABLES)
    path.write_text(f"# Results\n\nProse stays as written.\n\n{blocks}\n\nThe end.\n")
    return path


def test_the_doc_is_what_the_stored_evidence_makes() -> None:
    assert tables.check_doc() is None, "python benchmarks/results_tables.py rewrites docs/results.md"


def test_a_figure_changed_by_hand_is_caught(tmp_path: Path) -> None:
    copy = tmp_path / "results.md"
    shutil.copy(tables.DOC, copy)
    text = copy.read_text()
    start = text.index("<!-- table: quality-bar -->")
    row = text.index("| pace |", start)
    edited = text[:row] + text[row:].replace("16.8 deg", "14.8 deg", 1)
    assert edited != text
    copy.write_text(edited)
    assert tables.check_doc(copy) == "quality-bar"
    done = subprocess.run([sys.executable, str(SCRIPT), "--check", "--doc", str(copy)], capture_output=True,
                          text=True, timeout=60, check=False)
    assert done.returncode == 1 and "'quality-bar'" in done.stderr
    assert tables.main(["--doc", str(copy)]) == 0 and tables.check_doc(copy) is None
    assert copy.read_text() == text  # the rewrite puts the figure back, and nothing else moves


def _flat(text: str) -> str:
    """``text`` with every run of white space one space: what the wrapping of the tables' prose leaves alone."""
    return " ".join(text.split())


def test_the_tables_from_small_evidence(tmp_path: Path, evidence: Path) -> None:
    accuracy = _accuracy(tmp_path / "accuracy.json")
    made = tables.render_tables(evidence, accuracy)
    assert list(made) == list(tables.TABLES)
    assert all(len(line) <= tables.WIDTH for body in made.values() for line in body.splitlines()
               if not line.startswith("|") and "`gaitlib" not in line)
    made = {name: _flat(body) for name, body in made.items()}
    quality = made["quality-bar"]
    assert "5 of 6 gaits meet the bar" in quality and "The pace misses it: median heading change 16.8 deg" in quality
    assert "0.002 m/s drift" in quality and "`gaitlib eval GAIT --episodes 256 --json`" in quality
    pairs = made["pairs-0n"]
    low, high = wilson_interval(995, 1000)
    assert f"| stand → walk | 90.0 [{100 * wilson_interval(900, 1000)[0]:.1f}" in pairs
    assert f"**99.5** [{100 * low:.1f}, {100 * high:.1f}]" in pairs
    assert "| pairs at 99.0% or more | 0 of 30 | | 10 of 30 | |" in pairs  # random first, then the net
    assert "seed 0; falls by the `trunk` definition" in pairs
    routes = made["routes"]
    assert "| trot → pace | stand | 92.0 | 98.8 | 93.0 [" in routes  # predicted: 0.998 x 0.990
    assert "| at 99.0% or more | | | | 0 of 2 | 1 of 2 |" in routes
    net = made["net-accuracy"]
    assert "| latent, paper | 89.2 | 89.2 |" in net  # the paper's 0.8915, rounded as written
    assert "latent >= explicit holds (75.0 against 74.0)" in net and "--ablation --falls trunk" in net


def test_missing_evidence_says_not_yet_measured(tmp_path: Path, evidence: Path) -> None:
    for name in ("bench-0n", "bench-routed"):
        (evidence / f"{name}.json").unlink()
    made = tables.render_tables(evidence, tmp_path / "no-accuracy.json")
    assert made["pairs-0n"].startswith("Not yet measured:") and "bench-0n.json" in made["pairs-0n"]
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
    _store(evidence, "bench-direct", _benchmark({"net-lookahead": {"trot-pace": _cell(931), "pronk-trot": _cell(950)}},
                                                seed=1))
    assert tables.check_doc(doc, evidence, accuracy) == "routes"  # a stored result replaced, the doc not rewritten
    assert list(tmp_path.glob(".results.md.*")) == []  # no temporary left beside the doc


def test_a_doc_without_a_tables_block_is_refused(tmp_path: Path, evidence: Path) -> None:
    doc = tmp_path / "results.md"
    quality = tables.render_tables(evidence, tmp_path / "accuracy.json")["quality-bar"]
    doc.write_text(f"# Results\n\n<!-- table: quality-bar -->\n\n{quality}\n\n<!-- /table -->\n")
    with pytest.raises(ValueError, match="pairs-0n"):
        tables.write_doc(doc, evidence, tmp_path / "accuracy.json")
    assert tables.check_doc(doc, evidence, tmp_path / "accuracy.json") == "pairs-0n"  # the first block agrees
    doc.write_text("<!-- table: quality-bar -->\n<!-- /table -->\n<!-- table: quality-bar -->\n<!-- /table -->\n")
    with pytest.raises(ValueError, match="repeated"):
        tables.check_doc(doc, evidence, tmp_path / "accuracy.json")
