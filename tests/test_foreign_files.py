"""No silent wrong answers: a file that is not what it claims, a second writer, a failing disk and odd
paths each get one line before any work, and nothing already written is lost."""

from __future__ import annotations

import dataclasses
import errno
import json
import os
import shutil

import pytest
from cli_runner import gaitlib_quick
from conftest import copy_library, write_foreign_json
from test_benchmark import TINY
from test_transitions import GAITS, QUICK

from gaitlib.atomic import json_text, release_lock, take_lock, write_json
from gaitlib.benchmark.sweep import run_sweep
from gaitlib.collection import collect
from gaitlib.errors import GaitlibError, TransitionDataError
from gaitlib.library import Library
from gaitlib.library.layout import shipped_library_dir
from gaitlib.library.store import LibraryError
from gaitlib.meta import load_switching
from gaitlib.strategies import SwitchResources, get_strategy
from gaitlib.transitions import schema, validate


def one_line(result) -> str:
    assert result.returncode == 2 and result.stdout == "" and result.stderr.count("\n") == 1, result.stderr
    return result.stderr


def test_an_entry_holding_another_gaits_policy_is_refused(tmp_path) -> None:
    root = tmp_path / "library"
    shutil.copytree(shipped_library_dir(), root)
    for name in ("metadata.json", "policy.pt", "policy.onnx"):
        shutil.copy(root / "trot" / name, root / "stand" / name)
    with pytest.raises(LibraryError, match=r"^library entry 'stand' holds gait \['trot'\] by its metadata"):
        Library(root).entry("stand")
    assert "holds gait ['trot']" in one_line(gaitlib_quick("eval", "stand", "--library", str(root)))


def test_a_nan_in_the_calibration_is_refused(switching_library, tmp_path) -> None:
    library = copy_library(Library(switching_library), tmp_path / "library")
    payload = json.loads(library.calibration_path.read_text())
    payload["pairs"]["trot-stand"]["a"] = float("nan")  # as another writer could leave it, checksums and all
    write_foreign_json(library.calibration_path, payload)
    library.write_checksums(library.switching_dir)
    with pytest.raises(TransitionDataError, match=r"damaged net calibration .*not a finite number"):
        get_strategy("net-lookahead", SwitchResources(library=library, gaits=("stand", "trot")))


def test_a_nan_is_refused_by_the_writer_and_the_old_file_kept(tmp_path) -> None:
    path = write_json(tmp_path / "accuracy.json", {"latent": {"trot-stand": 0.8}}, checksum=True)
    before = path.read_bytes()
    for bad, where in (({"latent": {"trot-stand": float("nan")}}, "latent.trot-stand"),
                       ({"rows": [[1, 0.5], [2, float("inf")]]}, r"rows\[1\]\[1\]")):
        with pytest.raises(GaitlibError, match=rf"^refusing to write .*accuracy.json: {where} is not a finite number"):
            write_json(path, bad, checksum=True)
        assert path.read_bytes() == before
    assert list(tmp_path.iterdir()) == [path]  # no temporary left either


def test_printed_json_writes_an_undefined_number_as_null_and_refuses_an_infinity() -> None:
    assert json_text({"cell": {"rate": float("nan"), "rows": (1, 0.5)}}) == '{"cell": {"rate": null, "rows": [1, 0.5]}}'
    with pytest.raises(GaitlibError, match=r"^refusing to print JSON: cell.rate is not a finite number"):
        json_text({"cell": {"rate": float("inf")}})


def test_a_second_benchmark_into_one_out_is_refused_and_a_killed_ones_leftover_removed(switching_library, tmp_path):
    setup, out = load_switching(switching_library), tmp_path / "bench"
    out.mkdir()
    leftover = out / ".results.json.abc123.tmp.json"  # what a run killed inside a write leaves
    leftover.write_text("{")
    lock = out / "results.json.lock"
    fd = take_lock(lock, writing="test", error=GaitlibError)
    try:
        with pytest.raises(GaitlibError, match=r"results.json is being written by process \d+"):
            run_sweep(out, setup, dataclasses.replace(TINY, magnitudes=(0.0,), strategies=("random",)))
    finally:
        release_lock(lock, fd)
    assert not (out / "results.json").exists() and leftover.exists()
    results = run_sweep(out, setup, dataclasses.replace(TINY, magnitudes=(0.0,), strategies=("random",)))
    assert list(results["groups"]) == ["random@0"] and not leftover.exists()


def test_a_failing_disk_during_collect_is_one_line_and_keeps_the_committed_samples(
    tiny_library, tmp_path, monkeypatch
) -> None:
    path, real, calls = tmp_path / "t.h5", schema.write_part, []

    def full_after_one(*args, **kwargs):
        calls.append(1)
        if len(calls) > 1:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))  # Python's own write of the part's bytes
        return real(*args, **kwargs)

    monkeypatch.setattr(schema, "write_part", full_after_one)
    full = r"could not write .*t.h5: no space left on device; the 8 samples committed before"
    with pytest.raises(TransitionDataError, match=full):
        collect(path, library=tiny_library, gaits=GAITS, config=dataclasses.replace(QUICK, samples=16))
    assert validate(path).count == 8


@pytest.mark.parametrize("out", ["", "."])
def test_collect_into_an_empty_or_folder_path_is_one_line(out) -> None:
    assert "--out must name a file" in one_line(gaitlib_quick("collect", "--samples", "8", "--out", out))


def test_a_refused_collect_creates_nothing(tiny_library, tmp_path) -> None:
    out = tmp_path / "new" / "t.h5"
    refused = gaitlib_quick("collect", "--samples", "8", "--pairs", "trot-trot", "--out", str(out), "--library",
                            str(tiny_library.root))
    one_line(refused)
    assert not (tmp_path / "new").exists()
    missing = gaitlib_quick("collect", "--samples", "8", "--library", str(tmp_path / "nowhere"), "--out", str(out))
    assert f"no library at {tmp_path / 'nowhere'}" in one_line(missing)


def test_a_repeated_magnitude_and_a_folder_for_a_plot_are_refused_before_any_work(tmp_path) -> None:
    assert "a value is given twice" in one_line(gaitlib_quick("benchmark", "--magnitudes", "0,-0"))
    assert "--plot must name a file" in one_line(gaitlib_quick("run", "--plot", str(tmp_path)))


def test_a_truncated_or_foreign_policy_onnx_is_refused(tmp_path) -> None:
    root = tmp_path / "library"
    shutil.copytree(shipped_library_dir(), root)
    onnx = root / "stand" / "policy.onnx"
    onnx.write_bytes(onnx.read_bytes()[:1000])  # truncated: the file a user deploys
    assert "policy.onnx is missing or does not match its checksum" in one_line(
        gaitlib_quick("eval", "stand", "--library", str(root))
    )
    shutil.copy(root / "trot" / "policy.onnx", onnx)  # another gait's model
    with pytest.raises(LibraryError, match=r"policy.onnx is missing or does not match"):
        Library(root).entry("stand")


def test_a_fit_on_some_pairs_names_the_pairs_it_leaves_uncovered(switching_library, tmp_path) -> None:
    from gaitlib.gaits import get_gait
    from gaitlib.training import get_preset
    from gaitlib.training.trainer import TrainRequest, train_gait

    library = copy_library(Library(switching_library), tmp_path / "library")
    train_gait(TrainRequest(description=get_gait("pace"), preset=get_preset("tiny"), iterations=1,
                            library=library.root, run_dir=tmp_path / "runs", backend="mujoco", eval_episodes=1,
                            eval_seconds=0.3))
    data = switching_library.parent / "samples.h5"  # stand and trot only
    fitted = gaitlib_quick("fit", "--data", str(data), "--epochs", "2", "--library", str(library.root),
                           "--min-per-label", "0")
    assert fitted.returncode == 0, fitted.stderr
    assert "pairs of the library it does not cover: pace-stand, pace-trot, stand-pace, trot-pace" in fitted.stdout

    # A pair whose switches all succeed is covered, as `gaitlib library` counts it (the TMT always switches it),
    # with no accuracy to report: the six-gait fit once called walk -> stand uncovered while the library said covered.
    from gaitlib.strategies.fitting import fit_library
    from gaitlib.transitions import read_all

    samples = read_all([data], current=Library(library.root).identities())
    stand_trot = samples.samples.source == samples.header.gaits.index("stand")
    samples.samples.success[stand_trot] = 1
    report = fit_library(Library(library.root), samples, sources=[data], epochs=2, min_per_label=0)
    assert report.uncovered == ("pace-stand", "pace-trot", "stand-pace", "trot-pace")
    assert set(report.accuracy()["latent"]) == {"trot-stand"}
    status = json.loads(gaitlib_quick("library", "--library", str(library.root), "--json").stdout)
    covered = {p for p, v in status["switching"]["pairs"].items() if v["state"] == "covered"}
    assert covered == {"stand-trot", "trot-stand"}
