"""A fit's identity is the content of its data: the same samples read twice, under any name, are counted once and
the note says which and why; collections without --seed draw their own samples; a fit on too few samples per pair to
validate is refused; a refit keeps the route table, which `gaitlib library` then names stale with the command that
measures it again."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil

import pytest
from cli_runner import gaitlib_quick
from conftest import copy_library

from gaitlib.collection import CollectConfig, collect
from gaitlib.defaults import MIN_PER_LABEL
from gaitlib.library import Library
from gaitlib.meta import TrialProtocol
from gaitlib.transitions import read, read_all, validate
from gaitlib.transitions.schema import parts_folder

SMALL = CollectConfig(samples=8, num_worlds=4, chunk=4, push_max=400.0, backend="mujoco",
                      protocol=TrialProtocol.collection(horizon_s=0.6, warmup_s=0.3, source_extra_s=0.3))
QUICK = ["--worlds", "4", "--chunk", "4", "--horizon", "0.6", "--push-max", "400", "--backend", "mujoco"]


def _copy(path, to, *, link: bool = False):
    """The transition file ``path`` (index and parts) as ``to``: copied, or hard-linked file by file."""
    how = os.link if link else shutil.copy2
    how(path, to)
    shutil.copytree(parts_folder(path), parts_folder(to), copy_function=how)
    return to


@pytest.fixture(scope="module")
def samples(switching_library):
    """The switching library's own transition file (32 samples of stand and trot)."""
    return switching_library.parent / "samples.h5"


def test_one_file_under_any_name_is_counted_once(samples, tmp_path) -> None:
    copy = _copy(samples, tmp_path / "copy.h5")
    linked = _copy(samples, tmp_path / "linked.h5", link=True)
    once = read(samples)
    for paths in ([samples, samples], [samples, copy], [samples, linked], [samples, copy, linked]):
        merged = read_all(paths)
        assert len(merged.samples) == len(once.samples) == 32
        for later in paths[1:]:
            assert f"{later} holds the same 32 samples as {samples}" in merged.info.note
        assert "counted once" in merged.info.note
        assert [content for _, content in merged.info.files] == [once.info.files[0][1]] * len(paths)


def test_fit_on_the_same_data_twice_fits_once_and_records_its_content(switching_library, samples, tmp_path) -> None:
    library = copy_library(Library(switching_library), tmp_path / "library")
    copy = _copy(samples, tmp_path / "copy.h5")
    args = ["fit", "--data", str(samples), "--epochs", "1", "--library", str(library.root), "--min-per-label", "0"]
    twice = gaitlib_quick(*args, "--data", str(copy), "--json")
    assert twice.returncode == 0, twice.stderr
    report = json.loads(twice.stdout)
    alone = json.loads(gaitlib_quick(*args, "--json").stdout)
    assert report["samples"] == alone["samples"] == 32
    assert report["balanced_samples"] == alone["balanced_samples"]
    assert f"{copy} holds the same 32 samples as {samples}" in report["data_note"]
    content = read(samples).info.files[0][1]
    assert report["data_sha256"] == [content, content] and alone["data_sha256"] == [content]


def test_two_collections_with_one_seed_are_counted_once(tiny_library, tmp_path) -> None:
    first, second, third = tmp_path / "a.h5", tmp_path / "b.h5", tmp_path / "c.h5"
    collect(first, library=tiny_library, config=SMALL)
    collect(second, library=tiny_library, config=SMALL)  # the same samples, the same parts
    collect(third, library=tiny_library, config=dataclasses.replace(SMALL, samples=12))  # and four more
    merged = read_all([first, second, third])
    assert len(merged.samples) == 12
    assert f"{second} holds the same 8 samples as {first}" in merged.info.note
    assert f"{third}: 8 of its 12 samples are byte for byte samples of {first}" in merged.info.note


def test_collections_without_a_seed_draw_their_own_and_a_resume_keeps_it(tiny_library, tmp_path) -> None:
    lib = str(tiny_library.root)
    runs = [gaitlib_quick("collect", "--samples", "4", "--out", str(tmp_path / f"{k}.h5"), "--library", lib, *QUICK)
            for k in "ab"]
    assert all(run.returncode == 0 for run in runs), runs[0].stderr
    seeds = [validate(tmp_path / f"{k}.h5").header.settings["seed"] for k in "ab"]
    assert seeds[0] != seeds[1] and all(f"seed {s}, drawn for this collection" in r.stderr
                                        for s, r in zip(seeds, runs, strict=True))
    merged = read_all([tmp_path / "a.h5", tmp_path / "b.h5"])
    assert len(merged.samples) == 8 and merged.info.note is None
    resumed = gaitlib_quick("collect", "--samples", "8", "--out", str(tmp_path / "a.h5"), "--library", lib, *QUICK)
    assert resumed.returncode == 0, resumed.stderr
    assert "drawn" not in resumed.stderr and validate(tmp_path / "a.h5").header.settings["seed"] == seeds[0]


def test_a_fit_too_small_to_validate_is_refused_before_any_write(switching_library, samples, tmp_path) -> None:
    library = copy_library(Library(switching_library), tmp_path / "library")
    before = {p.name: p.read_bytes() for p in library.switching_dir.iterdir()}
    refused = gaitlib_quick("fit", "--data", str(samples), "--epochs", "1", "--library", str(library.root))
    assert refused.returncode == 2 and refused.stderr.count("\n") == 1, refused.stderr
    assert (f"too few samples to validate a fit: each ordered pair needs {MIN_PER_LABEL} successful and "
            f"{MIN_PER_LABEL} failed switches") in refused.stderr
    assert "stand-trot (" in refused.stderr and "--min-per-label 0" in refused.stderr
    assert {p.name: p.read_bytes() for p in library.switching_dir.iterdir()} == before
    fresh = tmp_path / "mine"
    assert gaitlib_quick("fit", "--data", str(samples), "--library", str(fresh)).returncode == 2
    assert not fresh.exists()  # nothing copied either


def test_a_refit_leaves_the_route_table_stale_with_the_command_that_measures_it(switching_library, samples,
                                                                                 tmp_path) -> None:
    library = copy_library(Library(switching_library), tmp_path / "library")
    root = str(library.root)
    measured = gaitlib_quick("routes", "--samples", "2", "--worlds", "4", "--backend", "mujoco", "--library", root,
                             "--out", str(tmp_path / "bench"))
    assert measured.returncode == 0, measured.stderr
    assert "nothing stale" in gaitlib_quick("library", "--library", root).stdout
    refit = gaitlib_quick("fit", "--data", str(samples), "--epochs", "1", "--seed", "3", "--library", root,
                          "--min-per-label", "0")
    assert refit.returncode == 0, refit.stderr
    assert "stale now: the route table" in refit.stdout
    shown = gaitlib_quick("library", "--library", root).stdout
    assert "nothing stale" not in shown and "other switching models" in shown
    command = (f"fix: gaitlib routes --library {root} --strategy net-lookahead --push 0 --max-legs 2 --samples 2 "
               "--worlds 4 --seed 0 --falls trunk")
    assert command in " ".join(shown.split())
    routes = json.loads(gaitlib_quick("library", "--library", root, "--json").stdout)["routes"]
    assert routes["state"] == "stale" and routes["fix"] == command.removeprefix("fix: ")
