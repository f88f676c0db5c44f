"""The guard's files held like the rest of a library's: recorded states with a number no recording writes refused
where they are read, an estimate that is not finite never written, loaded or exported, ``survival.pt`` checksummed
in ``switching/checksums.json`` and a damaged one refused by every command, its writers holding the library for
their whole run and following one default rule, and estimates chosen on too little refused."""

from __future__ import annotations

import io
import json
import shutil

import h5py
import numpy as np
import pytest
import torch

from gaitlib.atomic import file_sha256, torch_bytes
from gaitlib.collection.survival import SurvivalRecording, read_survival_states, record_survival
from gaitlib.errors import GaitlibError
from gaitlib.library import Library
from gaitlib.library.layout import shipped_library_dir
from gaitlib.meta import load_switching
from gaitlib.strategies.survival import load_survival, save_survival
from gaitlib.strategies.survival_fit import fit_survival
from tests.cli_runner import gaitlib_quick
from tests.conftest import copy_library
from tests.test_guard import _forced

SMALL = {"num_worlds": 6, "settle_s": 0.4, "after_s": 0.6, "record_from_s": 0.3, "impulse_max_ns": 60.0}
FIT = ("--horizons", "0.2", "--epochs", "2", "--margin", "0.1")
"""A tiny fit: its margin given (twelve episodes hold far less than a minute of unshoved running to choose one on)."""


@pytest.fixture(scope="module")
def recorded(switching_library, tmp_path_factory):
    path = tmp_path_factory.mktemp("survival-files") / "states.h5"
    record_survival(path, load_switching(switching_library), SurvivalRecording(episodes=12, **SMALL))
    return path


def _guarded(switching_library, tmp_path, stay=None) -> Library:
    """A copy of the switching library with a forced estimate saved as the library saves one."""
    library = copy_library(Library(switching_library), tmp_path / "library")
    (tmp_path / "forced.h5").write_bytes(b"forced")
    setup = load_switching(library.root)
    save_survival(library, _forced(setup, stay or {"trot": 1e-4, "stand": 1 - 1e-6}), data=tmp_path / "forced.h5")
    return library


def _edited(source, target, column: str, row: int, value) -> None:
    shutil.copy2(source, target)
    with h5py.File(target, "r+") as f:
        values = f[column][()]
        values.reshape(len(values), -1)[row, 0] = value
        f[column][...] = values


def _one_line(run, code: int = 2) -> str:
    """The refusal's one line (after the progress lines of a measurement refused at its end)."""
    *progress, line = run.stderr.splitlines() or [""]
    assert run.returncode == code and all(p.endswith(" rollouts") for p in progress), (run.returncode, run.stderr)
    assert line.startswith("gaitlib: error: ") and run.stderr.endswith("\n"), run.stderr
    assert "Error:" not in line and "Traceback" not in line  # gaitlib's line, not a library's internals
    return line


def test_a_recording_with_a_number_no_recording_writes_is_refused_where_it_is_read(recorded, switching_library,
                                                                                    tmp_path):
    library = _guarded(switching_library, tmp_path)
    estimate = library.switching_dir / "survival.pt"
    before = file_sha256(estimate)
    for column, value, says in (("latent", np.nan, "latent nan at row 3, column 0"), ("imu", np.inf, "imu inf"),
                                ("time_s", np.nan, "time_s nan"), ("gait", 99, "gait 99 at row 3"),
                                ("offer", 7.0, "offer 7.0"), ("fall_s", np.nan, "fall_s nan")):
        bad = tmp_path / f"{column}.h5"
        _edited(recorded, bad, column, 3, value)
        with pytest.raises(GaitlibError, match=says):
            read_survival_states(bad)
        run = gaitlib_quick("survival", "fit", str(bad), "--library", str(library.root), *FIT)
        assert says in _one_line(run) and run.stdout == ""
        assert file_sha256(estimate) == before  # nothing written
    with pytest.raises(GaitlibError, match="latent nan"):  # nor resumed
        record_survival(tmp_path / "latent.h5", load_switching(library.root), SurvivalRecording(episodes=18, **SMALL))


def test_an_estimate_that_is_not_finite_is_never_written_loaded_or_exported(recorded, switching_library, tmp_path):
    library = copy_library(Library(switching_library), tmp_path / "library")
    setup = load_switching(library.root)
    nan = _forced(setup, {"trot": 0.5, "stand": 0.5})
    with torch.no_grad():
        nan.net.mlp[0].weight[0, 0] = float("nan")
    with pytest.raises(GaitlibError, match=r"mlp\.0\.weight holds a number that is not finite"):
        save_survival(library, nan, data=recorded)
    assert not (library.switching_dir / "survival.pt").exists()
    header, data = read_survival_states(recorded)
    huge = dict(data) | {"latent": np.full_like(data["latent"], 3e38)}  # finite, but its spread overflows float32
    with pytest.raises(GaitlibError, match="the fit is not finite"):
        fit_survival(huge, gaits=setup.gaits, identities=header["identities"], dt=header["dt"], horizons_s=(0.2,),
                     epochs=1, margin=0.1)
    # As another writer could leave it, its checksum listed: refused by the reader, and by the export.
    save_survival(library, _forced(setup, {"trot": 0.5, "stand": 0.5}), data=recorded)
    saved = torch.load(library.switching_dir / "survival.pt", weights_only=True)
    saved["state_dict"]["mlp.0.weight"][0, 0] = float("nan")
    (library.switching_dir / "survival.pt").write_bytes(torch_bytes(saved))
    library.write_checksums(library.switching_dir, survival=file_sha256(library.switching_dir / "survival.pt"))
    with pytest.raises(GaitlibError, match=r"is damaged .*not finite"):
        load_survival(library, setup.gaits)
    shown = gaitlib_quick("library", "--library", str(library.root), "--json")
    assert json.loads(shown.stdout)["survival"]["state"] == "damaged"  # not "nothing stale"
    run = gaitlib_quick("survival", "export", "--library", str(library.root), "--out", str(tmp_path / "guard"))
    assert "not finite" in _one_line(run) and not (tmp_path / "guard").exists()


def test_the_estimate_is_checksummed_and_a_damaged_one_is_refused_by_every_command(switching_library, tmp_path):
    library = copy_library(Library(switching_library), tmp_path / "library")
    identity = library.switching_identity()
    library = _guarded(switching_library, tmp_path / "guarded")
    path = library.switching_dir / "survival.pt"
    pristine = path.read_bytes()
    weights = torch.load(path, weights_only=True)["state_dict"]["mlp.0.weight"].numpy().tobytes()
    at = pristine.find(weights[:64])
    assert at > 0
    flipped = bytearray(pristine)
    flipped[at + 2] ^= 0x10  # a weight changed: torch loads it as another estimate
    assert torch.load(io.BytesIO(bytes(flipped)), weights_only=True)["metadata"]["gaits"] == ["stand", "trot"]
    plot = str(tmp_path / "p.png")
    commands = tmp_path / "c.csv"
    commands.write_text("time_s,forward,lateral,yaw_rate\n0,1.45,0,0\n0.3,1.45,0,0\n")
    for damaged in (bytes(flipped), pristine[: len(pristine) // 2]):
        path.write_bytes(damaged)
        with pytest.raises(GaitlibError, match="does not match its checksum"):
            load_survival(library, ("stand", "trot"))
        for args in (("run", "--from", "trot", "--to", "stand", "--request-at", "0.3", "--hold", "0.8", "--plot",
                      plot), ("drive", "--commands", str(commands), "--plot", plot),
                     ("eval", "trot", "--impulses", "6", "--episodes", "2", "--guard")):
            run = gaitlib_quick(*args, "--library", str(library.root), "--backend", "mujoco")
            assert "survival.pt is damaged: it does not match its checksum" in _one_line(run), args
            assert run.stdout == ""
        assert not (tmp_path / "p.png").exists()
    path.write_bytes(pristine)
    assert library.listed_checksums()["survival.pt"] == file_sha256(path)
    assert library.switching_identity() == identity  # the models' identity: a route table measured with them holds
    shipped = Library(shipped_library_dir())
    assert shipped.listed_checksums()["survival.pt"] == file_sha256(shipped.switching_dir / "survival.pt")
    path.unlink()  # no estimate at all: unguarded, and said
    run = gaitlib_quick("run", "--from", "trot", "--to", "stand", "--request-at", "0.3", "--hold", "0.8", "--plot",
                        plot, "--library", str(library.root), "--backend", "mujoco", "--json")
    assert run.returncode == 0 and json.loads(run.stdout)["guard"]["on"] is False


def test_writers_of_the_guard_hold_the_library_for_their_whole_run(recorded, switching_library, tmp_path,
                                                                   monkeypatch):
    import gaitlib.benchmark.catches as catches
    import gaitlib.strategies.survival_fit as survival

    library = _guarded(switching_library, tmp_path, stay={"trot": 0.5, "stand": 0.5})
    second, started = [], []

    def fit_while_another_writes(fit):
        def fitting(*args, **kwargs):
            if len(started) < 2:  # once per writer below (where the library is left open it would nest again)
                started.append(True)
                second.append(gaitlib_quick("survival", "fit", str(recorded), "--library", str(library.root), *FIT))
            return fit(*args, **kwargs)
        return fitting

    monkeypatch.setattr(survival, "fit_survival", fit_while_another_writes(survival.fit_survival))
    first = gaitlib_quick("survival", "fit", str(recorded), "--library", str(library.root), *FIT)
    assert first.returncode == 0, first.stderr
    assert "is being written by" in _one_line(second[0])  # the second fit, started during the first: refused
    monkeypatch.undo()
    fitted = file_sha256(library.switching_dir / "survival.pt")
    monkeypatch.setattr(catches, "fit_catch_table", fit_while_another_writes(catches.fit_catch_table))
    measured = gaitlib_quick("survival", "catches", "--episodes", "16", "--impulse", "30", "--library",
                             str(library.root), "--json")
    assert measured.returncode == 0, measured.stderr
    assert "is being written by" in _one_line(second[1])  # a refit while the table is measured: refused
    table = json.loads(measured.stdout)
    assert load_survival(library, ("stand", "trot")).info["catches"] == table  # on the estimate it measured
    assert file_sha256(library.switching_dir / "survival.pt") != fitted
    monkeypatch.undo()
    refit = gaitlib_quick("survival", "fit", str(recorded), "--library", str(library.root), *FIT)
    assert refit.returncode == 0, refit.stderr
    assert "catches" not in load_survival(library, ("stand", "trot")).info  # a refit drops the table


def test_a_table_is_never_written_into_an_estimate_replaced_while_it_was_measured(switching_library, tmp_path,
                                                                                 monkeypatch):
    import gaitlib.benchmark.catches as catches

    library = _guarded(switching_library, tmp_path, stay={"trot": 0.5, "stand": 0.5})
    setup = load_switching(library.root)
    measure = catches.fit_catch_table

    def replaced_meanwhile(*args, **kwargs):  # by a writer that takes no lock
        table = measure(*args, **kwargs)
        save_survival(Library(library.root), _forced(setup, {"trot": 0.4, "stand": 0.4}), data=tmp_path / "forced.h5")
        return table

    monkeypatch.setattr(catches, "fit_catch_table", replaced_meanwhile)
    run = gaitlib_quick("survival", "catches", "--episodes", "16", "--library", str(library.root))
    assert "changed while its catch table was measured" in _one_line(run)
    assert "catches" not in load_survival(library, setup.gaits).info


def test_the_documented_sequence_writes_one_library_by_one_default_rule(recorded, switching_library, tmp_path,
                                                                        monkeypatch):
    import gaitlib.library.layout as layout
    import gaitlib.library.target as target

    shipped = copy_library(Library(switching_library), tmp_path / "shipped").root  # stands in for library/
    for module in (layout, target):
        monkeypatch.setattr(module, "shipped_library_dir", lambda: shipped)
    monkeypatch.delenv("GAITLIB_LIBRARY", raising=False)
    monkeypatch.chdir(tmp_path)
    fit = gaitlib_quick("survival", "fit", str(recorded), *FIT)
    assert fit.returncode == 0, fit.stderr
    assert fit.stdout.startswith("runs/library/switching/survival.pt: horizon 0.2 s, margin 0.1 (given), floor 0")
    catch = gaitlib_quick("survival", "catches", "--episodes", "16", "--impulse", "30")
    assert catch.returncode == 0, catch.stderr
    assert catch.stdout.startswith("runs/library/switching/survival.pt: falls at 30 N s")
    assert "catches" in load_survival(Library("runs/library"), ("stand", "trot")).info
    assert not (shipped / "switching" / "survival.pt").exists()  # the shipped library is never written
    refused = gaitlib_quick("survival", "catches", "--episodes", "16", "--library", str(shipped))
    assert "writes to your own library by default (runs/library" in _one_line(refused)


def test_estimates_chosen_on_too_little_are_refused_before_any_work(recorded, switching_library, tmp_path):
    library = _guarded(switching_library, tmp_path)
    before = file_sha256(library.switching_dir / "survival.pt")
    common = ("survival", "fit", str(recorded), "--library", str(library.root), "--epochs", "2")
    unshoved = gaitlib_quick(*common, "--horizons", "0.2")  # the margin to be chosen on 12 episodes
    assert "unshoved minutes; a margin is chosen on at least 1" in _one_line(unshoved)
    floor = gaitlib_quick(*common, "--horizons", "0.2", "--margin", "0.1", "--floor", "auto")
    assert "a floor is chosen on at least 1" in _one_line(floor)
    step = gaitlib_quick(*common, "--horizons", "1e-300", "--margin", "0.1")
    assert "the horizon 1e-300 s is shorter than one control step" in _one_line(step)
    few = gaitlib_quick("survival", "catches", "--episodes", "2", "--library", str(library.root))
    assert "--episodes must be a whole number in [16, 1000000]" in _one_line(few)
    assert file_sha256(library.switching_dir / "survival.pt") == before


def test_options_that_change_nothing_or_misname_a_value_are_refused_or_named_as_given(recorded, switching_library,
                                                                                      tmp_path):
    library = _guarded(switching_library, tmp_path)
    run = ("run", "--from", "trot", "--to", "stand", "--request-at", "0.3", "--hold", "0.8", "--plot",
           str(tmp_path / "p.png"), "--library", str(library.root), "--backend", "mujoco")
    ignored = gaitlib_quick(*run, "--no-guard", "--guard-margin", "0.5")
    assert "--guard-margin has no effect with --no-guard" in _one_line(ignored)
    close = gaitlib_quick(*run, "--guard-margin", "0.9999999999999999")
    assert close.returncode == 0, close.stderr
    assert "guard on (margin 0.9999999999999999, horizon 0.2 s)" in close.stdout
    given = gaitlib_quick("survival", "fit", str(recorded), "--library", str(library.root), *FIT)
    assert given.returncode == 0 and "margin 0.1 (given), floor 0\n" in given.stdout
    (tmp_path / "afile").write_text("kept")
    for args in (("survival", "fit", str(recorded), *FIT), ("survival", "export"), ("run", "--from", "trot", "--to",
                                                                                   "stand")):
        refused = gaitlib_quick(*args, "--library", str(tmp_path / "afile"))
        assert "is a file, not a library folder" in _one_line(refused), args
    export = gaitlib_quick("survival", "export", "--library", str(library.root), "--out", str(tmp_path / "afile"))
    assert "--out" in _one_line(export) and (tmp_path / "afile").read_text() == "kept"
    unwritable = gaitlib_quick("survival", "export", "--library", str(library.root), "--out", "/proc/guard")
    assert "--out /proc/guard cannot be written" in _one_line(unwritable)
