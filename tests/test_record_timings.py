"""The timings ``python -m benchmarks.record_timings`` measures: each table of ``docs/benchmarks.md`` made from small
evidence files written here (nothing is measured), what is not stored yet named, and the evidence a measurement writes
(its command, the day it was made and the command's JSON output)."""

from __future__ import annotations

import datetime
import json
import sys
from pathlib import Path

import pytest

from benchmarks import record_timings
from benchmarks.results import doc, speeds

SIM = {"backend": "mujoco", "device": "cpu", "worlds": 256, "threads": 2, "control_hz": 30.0, "substeps": 8,
       "seconds": 10.0, "env_steps_per_s": 11839.4, "raw_steps_per_s": 14893.0, "raw_mj_step_per_s": 12485.2,
       "raw_rollout_per_s": 14893.0, "ratio": 0.79495}
COLLECT = {"worlds": 512, "seconds": 40.0, "push_max": 400.0, "env_steps_per_s": 7647.3, "samples_per_s": 58.94,
           "steps_per_sample": 106.12, "allowed_samples_per_s": 72.06, "ratio": 0.8171}
MEMORY = {"backends": 8, "worlds": 256, "steps": 30,
          "resident_mb_after_each_close": {"keep": [409.2, *[600.0] * 6, 799.4], "trim": [250.1, *[250.5] * 6, 251.3]},
          "growth_mb_first_to_last": {"keep": 390.2, "trim": 1.2}, "growth_trimmed_vs_kept": 0.003}
WRITES = {"samples": 199936, "appends": 781, "gaitlib_append_ms": {"median": 10.0, "mean": 18.7, "max": 852},
          "in_place_append_ms": {"median": 5.1, "mean": 5.4, "max": 11}, "ratio_of_totals": 3.49, "files": 17,
          "read_whole_s": 0.5}
LOADS = [{"gait": "trot", "loads": 40, "load_ms": 32.3, "reference_walk_ms": 54.0, "ratio": 0.598},
         {"gait": "bound", "loads": 40, "load_ms": 34.8, "reference_walk_ms": 51.2, "ratio": 0.68}]


def _store(folder: Path, name: str, result: object) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    speeds.evidence_path(name, folder).write_text(json.dumps(
        {"command": speeds.MEASURES[name].command, "made": "2026-12-08", "result": result}))


def test_every_table_says_not_yet_measured_without_its_evidence(tmp_path: Path) -> None:
    for table in (speeds.sim_throughput_table, speeds.collect_throughput_table, speeds.memory_table,
                  speeds.writes_table, speeds.entry_load_table):
        text = table(tmp_path)
        assert text.startswith("Not yet measured: ") and text.endswith(" not stored yet."), text
        assert "|" not in text


def test_the_simulation_table_from_small_evidence_names_the_runs_not_stored(tmp_path: Path) -> None:
    _store(tmp_path, "sim-mujoco-256", SIM)
    _store(tmp_path, "sim-newton-16", SIM | {"backend": "newton", "worlds": 16, "env_steps_per_s": 300.2,
                                             "ratio": 0.0247})
    text = speeds.sim_throughput_table(tmp_path)
    assert "| mujoco | cpu | 256 | 11,839 | 12,485 | 14,893 | **0.795** |" in text
    assert "| newton | cpu | 16 | 300 | 12,485 | 14,893 | 0.025 |" in text  # the goal is the mujoco backend's
    assert "(made 2026-12-08): `gaitlib throughput sim --backend mujoco --worlds 256 --seconds 10 --json`" in text
    assert text.endswith("Not yet measured: " + ", ".join(
        f"`{speeds.evidence_path(n, tmp_path)}`" for n in ("sim-mujoco-1024", "sim-newton-64")) + " not stored yet.")


def test_the_collection_memory_writes_and_load_tables_from_small_evidence(tmp_path: Path) -> None:
    _store(tmp_path, "collect-512", COLLECT)
    _store(tmp_path, "backend-memory", MEMORY)
    _store(tmp_path, "transition-writes-2e5", WRITES)
    _store(tmp_path, "transition-writes-2e6", WRITES | {"samples": 1999872, "files": 43})
    _store(tmp_path, "entry-load", LOADS)
    assert "| 512 | 7,647 | 106.1 | 72.1 | 58.9 | **0.817** |" in speeds.collect_throughput_table(tmp_path)
    memory = speeds.memory_table(tmp_path)
    assert memory.startswith("| backends of 256 worlds, built, stepped 30 times and closed in turn | resident after "
                             "the first close | after the last (8) | growth |")
    assert "| heap kept (the reference) | 409 MB | 799 MB | 390.2 MB |" in memory
    assert "| heap trimmed at close (gaitlib's) | 250 MB | 251 MB | 1.2 MB (0.003 of the reference) |" in memory
    writes = speeds.writes_table(tmp_path)
    assert "| 199,936 | 10.0 / 18.7 / 852 ms | 5.1 / 5.4 / 11 ms | 3.49 | 17 | 0.5 s |" in writes
    assert "| 1,999,872 |" in writes and "Not yet measured" not in writes
    loads = speeds.entry_load_table(tmp_path)
    assert loads.index("| bound | 34.8 ms | 51.2 ms | 0.68 |") < loads.index("| trot | 32.3 ms | 54.0 ms | 0.60 |")
    assert "`python -m benchmarks.entry_load --library library --loads 40`" in loads


def test_the_tables_are_the_benchmarks_pages_blocks() -> None:
    assert set(speeds.BLOCKS) <= set(doc.PAGES["docs/benchmarks.md"])
    assert {measure.block for measure in speeds.MEASURES.values()} == set(speeds.BLOCKS)
    assert all(block in doc.render_tables() for block in speeds.BLOCKS)


def test_a_measurement_stores_its_command_its_date_and_the_commands_json(tmp_path: Path) -> None:
    ran = []

    def run(argv: list[str]) -> str:
        ran.append(argv)
        return "Warp 1.19.0 initialized\n" + json.dumps(SIM) + "\n"

    path = record_timings.record("sim-mujoco-256", folder=tmp_path, run=run)
    evidence = json.loads(path.read_text())
    assert path == tmp_path / "sim-mujoco-256.json"
    assert evidence == {"command": speeds.MEASURES["sim-mujoco-256"].command,
                        "made": datetime.date.today().isoformat(), "result": SIM}
    assert ran == [[sys.executable, "-m", "gaitlib.cli", "throughput", "sim", "--backend", "mujoco", "--worlds", "256",
                    "--seconds", "10", "--json"]]
    lines = "\n".join(json.dumps(line) for line in LOADS)
    path = record_timings.record("entry-load", folder=tmp_path, run=lambda argv: lines,
                                 made=datetime.date(2026, 12, 8))
    assert json.loads(path.read_text())["result"] == LOADS and "made 2026-12-08" in speeds.entry_load_table(tmp_path)
    with pytest.raises(ValueError, match="no JSON"):
        record_timings.record("collect-512", folder=tmp_path, run=lambda argv: "nothing\n")
    assert not (tmp_path / "collect-512.json").exists()


def test_one_table_or_one_measurement_runs_alone_and_a_cut_run_resumes(tmp_path: Path, capsys) -> None:
    assert record_timings.selected(["transition-writes"]) == ["transition-writes-2e5", "transition-writes-2e6"]
    assert record_timings.selected(["entry-load", "sim-newton-64"]) == ["sim-newton-64", "entry-load"]
    assert record_timings.selected(None) == list(speeds.MEASURES)
    _store(tmp_path, "transition-writes-2e5", WRITES)
    assert record_timings.selected(["transition-writes"], missing=True, folder=tmp_path) == ["transition-writes-2e6"]
    with pytest.raises(ValueError, match="no measurement or table sims"):
        record_timings.selected(["sims"])
    assert record_timings.main(["--list", "--only", "collect-throughput"]) == 0
    assert capsys.readouterr().out == "collect-512: gaitlib throughput collect --worlds 512 --seconds 40 --json\n"
