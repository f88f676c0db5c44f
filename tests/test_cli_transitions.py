"""``gaitlib collect`` and ``gaitlib fit`` end to end on a library of tiny one-iteration policies."""

from __future__ import annotations

import json

import h5py
import pytest
from cli_runner import gaitlib, gaitlib_quick
from conftest import copy_library

from gaitlib.cli.options import parse_pairs
from gaitlib.library import Library
from gaitlib.strategies.fitting import evaluate_library
from gaitlib.transitions import read_all, validate

QUICK = ["--worlds", "16", "--horizon", "1.0", "--push-max", "400", "--backend", "mujoco"]  # a sample a world


@pytest.fixture
def library(tiny_library, tmp_path):
    """A writable copy of the tests' tiny library (fit writes into it)."""
    return copy_library(tiny_library, tmp_path / "library").root


def test_pairs_accept_ordered_pairs_and_whole_gaits() -> None:
    gaits = ["pace", "stand", "trot"]
    assert parse_pairs("trot-stand,pace-stand", gaits) == (("trot", "stand"), ("pace", "stand"))
    assert set(parse_pairs("trot", gaits)) == {("trot", "pace"), ("trot", "stand"), ("pace", "trot"), ("stand", "trot")}
    assert parse_pairs(None, gaits) is None


def test_collect_resume_fit_and_evaluate(library, tmp_path) -> None:
    data = str(tmp_path / "samples.h5")
    lib = str(library)
    first = gaitlib("collect", "--samples", "16", "--out", data, "--library", lib, *QUICK)
    assert first.returncode == 0, first.stderr
    assert validate(data).count == 16
    resumed = gaitlib_quick("collect", "--samples", "3.2e1", "--out", data, "--library", lib, *QUICK)
    assert resumed.returncode == 0, resumed.stderr
    assert validate(data).count == 32 and "16 new" in resumed.stderr

    more = str(tmp_path / "more.h5")  # a second file (as after growing the library): fitted together
    # Gaits named out of order are stored in the canonical order (before 0.2.0 the user's order was kept, the net
    # was fitted for ['trot', 'stand'] and `gaitlib run` refused it).
    named = gaitlib_quick("collect", "--samples", "16", "--gaits", "trot,stand", "--out", more, "--library", lib,
                          "--seed", "1", *QUICK)
    assert named.returncode == 0, named.stderr
    assert validate(more).header.gaits == ("stand", "trot")
    fitted = gaitlib_quick("fit", "--data", data, "--data", more, "--epochs", "3", "--library", lib, "--json",
                           "--min-per-label", "0")
    assert fitted.returncode == 0, fitted.stderr
    report = json.loads(fitted.stdout)
    assert set(report["balanced_validation_accuracy"]) == {"latent"} and report["samples"] == 48
    assert 0 < report["balanced_samples"]["latent"] <= 48
    assert sorted(p.name for p in (library / "switching").iterdir()) == [
        "accuracy.json", "calibration.json", "checksums.json", "net.pt", "tmt.json"
    ]
    written = json.loads((library / "switching" / "accuracy.json").read_text())
    assert written == report | {"checksum": written["checksum"]}

    before = {p.name: p.read_bytes() for p in (library / "switching").iterdir()}
    curve = gaitlib_quick("fit", "--curve", "4,16", "--data", data, "--epochs", "3", "--library", lib, "--json")
    assert curve.returncode == 0, curve.stderr
    points = json.loads(curve.stdout)["points"]
    assert [p["samples_per_pair"] for p in points] == [4, 16] and points[0]["trained_on"] <= points[1]["trained_on"]
    assert {p.name: p.read_bytes() for p in (library / "switching").iterdir()} == before  # it writes nothing
    for bad in (["--curve", "0"], ["--curve", "8", "--replace"]):
        refused = gaitlib_quick("fit", *bad, "--data", data, "--library", lib)
        assert refused.returncode != 0 and refused.stderr.count("\n") == 1, refused.stderr

    scored = gaitlib_quick("fit", "--evaluate", "--data", data, "--library", lib, "--json")
    assert scored.returncode == 0, scored.stderr
    accuracy = json.loads(scored.stdout)["accuracy"]
    assert set(accuracy) <= {"stand-trot", "trot-stand"} and accuracy
    assert accuracy == evaluate_library(Library(library), read_all([data]), sources=[data])["accuracy"]

    ran = gaitlib_quick(
        "run", "--from", "trot", "--to", "stand", "--strategy", "net", "--hold", "0.7", "--request-at", "0.3",
        "--plot", str(tmp_path / "run.png"), "--backend", "mujoco", "--library", lib, "--json",
    )
    assert ran.returncode == 0, ran.stderr
    assert json.loads(ran.stdout)["strategy"] == "net" and (tmp_path / "run.png").is_file()


def test_foreign_hdf5_is_one_error_line(tiny_library, tmp_path) -> None:
    library = copy_library(tiny_library, tmp_path / "library")  # a library to fit into: the data alone is wrong
    path = tmp_path / "foreign.h5"
    with h5py.File(path, "w") as f:
        f["images"] = [1, 2, 3]
    result = gaitlib_quick("fit", "--data", str(path), "--library", str(library.root))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gaitlib: error:") and "foreign.h5" in lines[0]

