"""Nothing a user runs rewrites the shipped library, writers of one library exclude each other, a run folder belongs
to one training run, and a resumed or reused measurement is the same measurement (gaitlib.library.target)."""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import pytest
from cli_runner import gaitlib_quick
from conftest import copy_library

from gaitlib.atomic import command_line, release_lock, take_lock
from gaitlib.errors import GaitlibError
from gaitlib.library import Library
from gaitlib.library.layout import shipped_library_dir
from gaitlib.library.target import WRITER_LOCK, library_writer

SHIPPED = shipped_library_dir()


def tree_sha256(folder: Path) -> str:
    """One digest of every file under ``folder`` (names and bytes)."""
    digest = hashlib.sha256()
    for path in sorted(p for p in folder.rglob("*") if p.is_file()):
        digest.update(str(path.relative_to(folder)).encode() + path.read_bytes())
    return digest.hexdigest()


@pytest.fixture
def own_cwd(tmp_path, monkeypatch) -> Path:
    """A working folder of a user without $GAITLIB_LIBRARY."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("GAITLIB_LIBRARY", raising=False)
    return tmp_path


@pytest.mark.parametrize(
    "command",
    [
        ("fit", "--data", "nowhere.h5"),
        ("routes", "--samples", "2"),
        ("eval", "stand", "--record", "--episodes", "2"),
    ],
)
def test_writing_the_shipped_library_is_refused_in_one_line_before_any_work(command, own_cwd) -> None:
    before = tree_sha256(SHIPPED)
    refused = gaitlib_quick(*command, "--library", str(SHIPPED))
    assert refused.returncode == 2 and refused.stdout == ""
    assert refused.stderr.count("\n") == 1 and "of the shipped library" in refused.stderr
    assert "--replace" in refused.stderr
    assert tree_sha256(SHIPPED) == before and not (own_cwd / "runs").exists()


def test_fit_writes_into_your_own_library_by_default_and_leaves_the_shipped_one_alone(own_cwd) -> None:
    before = tree_sha256(SHIPPED)
    data = own_cwd / "t.h5"
    collected = gaitlib_quick("collect", "--library", str(SHIPPED), "--pairs", "trot-stand,stand-trot", "--samples",
                              "32", "--worlds", "32", "--horizon", "1.0", "--push-max", "1500", "--backend", "mujoco",
                              "--out", str(data))
    assert collected.returncode == 0, collected.stderr
    fitted = gaitlib_quick("fit", "--data", str(data), "--epochs", "1", "--min-per-label", "0")
    assert fitted.returncode == 0, fitted.stderr
    mine = Library(Path("runs") / "library")
    assert f"wrote {mine.switching_dir}" in fitted.stdout
    assert mine.gaits() == Library(SHIPPED).gaits() and mine.identities() == Library(SHIPPED).identities()
    assert json.loads(mine.accuracy_path.read_text())["samples"] == 32
    assert tree_sha256(SHIPPED) == before  # the shipped models, its route table included, untouched
    assert not (mine.root / WRITER_LOCK).exists()


def test_a_second_writer_of_a_library_is_refused_while_one_writes(switching_library, tmp_path) -> None:
    library = copy_library(Library(switching_library), tmp_path / "library")
    with library_writer(library.root, command="gaitlib fit"):
        refused = gaitlib_quick("routes", "--library", str(library.root), "--samples", "2", "--worlds", "2")
        assert refused.returncode == 2 and refused.stderr.count("\n") == 1
        holder = f"process {os.getpid()} ({command_line()})"
        assert refused.stderr == (f"gaitlib: error: gaitlib routes refused: library {library.root} is being written "
                                  f"by {holder}\n")
        busy = r"^gaitlib train refused: .* is being written by process"
        with pytest.raises(GaitlibError, match=busy), library_writer(library.root, command="gaitlib train"):
            pass
    assert not (library.root / WRITER_LOCK).exists()


def test_a_measurement_of_other_switching_models_is_not_resumed_or_reused(switching_library, own_cwd) -> None:
    """routes, then a refit, then routes again into the same folder: the second may not take the first's rates
    (measured with the old net) and stamp them with the new fit's checksum."""
    tmp_path = own_cwd
    library = copy_library(Library(switching_library), tmp_path / "library")
    out = tmp_path / "measured"
    args = ("routes", "--library", str(library.root), "--samples", "2", "--worlds", "4", "--backend", "mujoco",
            "--out", str(out))
    first = gaitlib_quick(*args)
    assert first.returncode == 0, first.stderr
    table = json.loads((library.switching_dir / "routes.json").read_text())
    assert table["switching"] == library.switching_identity()
    from gaitlib.strategies.fitting import fit_library
    from gaitlib.transitions import read

    data = Path(switching_library).parent / "samples.h5"  # the fixture's collection: both labels on some pair
    fit_library(library, read(data), sources=[data], epochs=1, seed=7, min_per_label=0)  # other switching models
    assert library.switching_identity() != table["switching"]
    again = gaitlib_quick(*args)
    assert again.returncode == 2 and again.stderr.count("\n") == 1
    assert "holds a benchmark with other settings (switching)" in again.stderr
    # Without --out, each library's policies and switching models get a folder of their own, whatever its name.
    assert gaitlib_quick(*args[:-2]).returncode == 0
    twin = copy_library(library, tmp_path / "elsewhere" / "library")  # the same models under another path
    assert gaitlib_quick(*args[:-2], "--library", str(twin.root)).returncode == 0
    assert len(list((tmp_path / "runs").iterdir())) == 1  # one measurement, reused as it may be


def test_a_run_folder_belongs_to_one_training_run(tmp_path) -> None:
    run_dir, library = tmp_path / "runs" / "stand", tmp_path / "library"
    args = ("train", "stand", "--preset", "tiny", "--iterations", "1", "--eval-episodes", "2", "--backend",
            "mujoco", "--run-dir", str(run_dir), "--eval-seconds", "0.5")
    first = gaitlib_quick(*args, "--library", str(library), "--seed", "0")
    assert first.returncode == 0, first.stderr
    entry = json.loads((library / "stand" / "metadata.json").read_text())
    second = gaitlib_quick(*args, "--library", str(tmp_path / "other"), "--seed", "9")
    assert second.returncode == 2 and second.stderr.count("\n") == 1
    assert f"{run_dir} belongs to another training run" in second.stderr and not (tmp_path / "other").exists()
    resumed = gaitlib_quick(*args, "--library", str(library), "--seed", "9", "--resume", "--iterations", "2")
    assert resumed.returncode == 2 and "is of another training run: --seed: seed 0 then, 9 now" in resumed.stderr
    elsewhere = gaitlib_quick(*args, "--library", str(tmp_path / "other"), "--resume", "--iterations", "2")
    assert elsewhere.returncode == 2 and "is of another training run: --library: library" in elsewhere.stderr
    assert json.loads((library / "stand" / "metadata.json").read_text()) == entry
    fd = take_lock(run_dir / ".run.lock", writing="test", error=GaitlibError)  # a run under way
    try:
        busy = gaitlib_quick(*args, "--library", str(library), "--resume", "--iterations", "2")
        assert busy.returncode == 2 and f"training run folder {run_dir} is being written by" in busy.stderr
    finally:
        release_lock(run_dir / ".run.lock", fd)


@pytest.mark.parametrize("command", ["library", "states"])
def test_an_empty_library_is_one_line(command, tmp_path) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    extra = ("--out", str(tmp_path / "s.npz")) if command == "states" else ("--json",)
    result = gaitlib_quick(command, "--library", str(empty), *extra)
    line = f"library {empty} has no gait entries; train a gait into it first"
    if command == "library":  # the status reads it and names the problem
        assert result.returncode == 0 and line in json.loads(result.stdout)["problems"][0]["text"]
    else:
        assert result.returncode == 2 and result.stderr.count("\n") == 1 and line in result.stderr


def test_routed_runs_say_what_their_table_was_measured_with(switching_library, tmp_path) -> None:
    library = copy_library(Library(switching_library), tmp_path / "library")
    made = gaitlib_quick("routes", "--library", str(library.root), "--samples", "2", "--worlds", "4",
                         "--backend", "mujoco", "--out", str(tmp_path / "m"))
    assert made.returncode == 0, made.stderr
    ran = gaitlib_quick("run", "--library", str(library.root), "--from", "trot", "--to", "stand", "--routed",
                        "--strategy", "random", "--push", "300", "--backend", "mujoco", "--plot",
                        str(tmp_path / "run.png"))
    assert ran.returncode == 0, ran.stderr
    assert "measured with net-lookahead at 0 N, falls counted the trunk way" in ran.stderr
    assert "warning: this run differs from what the routes were measured with: strategy random; pushes of 300 N" in (
        ran.stderr.replace("\n", " ")
    )


def test_the_next_writer_clears_a_killed_writers_temporary(switching_library, tmp_path) -> None:
    library = copy_library(Library(switching_library), tmp_path / "library")
    leftover = library.switching_dir / ".routes.json.x1y2.tmp.json"
    leftover.write_text("{")
    made = gaitlib_quick("routes", "--library", str(library.root), "--samples", "2", "--worlds", "4",
                         "--backend", "mujoco", "--out", str(tmp_path / "m"))
    assert made.returncode == 0, made.stderr
    assert not leftover.exists() and (library.switching_dir / "routes.json").is_file()
