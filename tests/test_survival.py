"""The guard's survival estimate: recorded states (resumable), the fit, its calibration and choices, the file in the
library's switching folder, and the one-line refusals."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gaitlib.collection.survival import SurvivalRecording, read_survival_states, record_survival
from gaitlib.errors import GaitlibError
from gaitlib.library import Library
from gaitlib.meta import load_switching
from gaitlib.strategies.survival import (
    FALSE_ALARMS_PER_MIN,
    FLOORS,
    check_guard,
    load_survival,
    save_survival,
)
from gaitlib.strategies.survival_fit import fit_survival
from tests.cli_runner import gaitlib_quick
from tests.conftest import copy_library

SMALL = {"num_worlds": 6, "settle_s": 0.4, "after_s": 0.6, "record_from_s": 0.3, "impulse_max_ns": 60.0}


@pytest.fixture(scope="module")
def recorded(switching_library, tmp_path_factory):
    """Twelve episodes recorded in two runs (the second resumes the first's file)."""
    path = tmp_path_factory.mktemp("survival") / "states.h5"
    setup = load_switching(switching_library)
    first = record_survival(path, setup, SurvivalRecording(episodes=6, **SMALL))
    data = record_survival(path, setup, SurvivalRecording(episodes=12, **SMALL))
    return path, setup, first, data


def test_recorded_states_resume_and_label(recorded):
    path, setup, first, data = recorded
    assert len(np.unique(data["episode"])) == 12
    for column, values in first.items():  # resuming keeps what was recorded and adds to it
        np.testing.assert_array_equal(data[column][: len(values)], values)
    header, read = read_survival_states(path)
    assert header["gaits"] == list(setup.gaits) and header["dt"] > 0
    assert len(read["gait"]) == len(data["gait"])
    own = data["offer"][np.arange(len(data["gait"])), data["gait"]]
    assert np.isnan(own).all()  # no offer to switch to the gait that runs
    other = data["offer"][np.arange(len(data["gait"])), 1 - data["gait"]]
    assert ((other >= 0) & (other <= 1)).all()
    fell = np.isfinite(data["fall_s"])
    assert (data["time_s"][fell] < data["fall_s"][fell]).all()  # only states of a robot still up
    with pytest.raises(GaitlibError, match="other settings"):
        record_survival(path, setup, SurvivalRecording(episodes=14, **(SMALL | {"impulse_max_ns": 5.0})))


def test_recorded_switches_take_the_nets_best_phase_or_a_uniform_one(recorded, tmp_path):
    setup = recorded[1]
    switched = {"switch_share": 1.0, "calm_share": 1.0}
    uniform = record_survival(tmp_path / "u.h5", setup, SurvivalRecording(episodes=6, switch_phase="uniform",
                                                                          **(SMALL | switched)))
    best = record_survival(tmp_path / "b.h5", setup, SurvivalRecording(episodes=6, **(SMALL | switched)))
    assert read_survival_states(tmp_path / "b.h5")[0]["settings"]["switch_phase"] == "best"
    first = np.unique(best["episode"], return_index=True)[1]  # each episode's first state: just after its switch
    assert not np.allclose(best["phase"][first], uniform["phase"][first])  # the same draws, another phase
    with pytest.raises(GaitlibError, match="other settings"):  # never resumed with the other rule
        record_survival(tmp_path / "u.h5", setup, SurvivalRecording(episodes=12, **(SMALL | switched)))
    with pytest.raises(GaitlibError, match="must be one of best, uniform, not 'nearest'"):
        SurvivalRecording(switch_phase="nearest")


def test_fit_choose_save_load(recorded, switching_library, tmp_path):
    path, setup, _, data = recorded
    library = copy_library(Library(switching_library), tmp_path / "library")
    identities = library.identities(setup.gaits)
    dt = read_survival_states(path)[0]["dt"]
    estimate = fit_survival(data, gaits=setup.gaits, identities=identities, dt=dt, horizons_s=(0.2, 0.4), epochs=2,
                            floor=None, min_unshoved_minutes=0)  # the floor chosen too (by default none: 0)
    report = estimate.info["report"]
    assert estimate.horizon_s in (0.2, 0.4) and 0 <= estimate.margin < 1 and estimate.floor in FLOORS
    assert report["floor"] == estimate.floor and report["floor_false_alarms_per_min"] <= FALSE_ALARMS_PER_MIN
    assert sum(row["states"] for row in report["reliability"]) > 0
    assert {c["horizon_s"] for c in estimate.info["choices"]} == {0.2, 0.4}
    save_survival(library, estimate, data=path)
    loaded = load_survival(library, setup.gaits)
    assert (loaded.horizon_s, loaded.margin, loaded.floor, loaded.platt) == (
        estimate.horizon_s, estimate.margin, estimate.floor, estimate.platt)
    shown = gaitlib_quick("library", "--library", str(library.root), "--json")
    assert shown.returncode == 0, shown.stderr
    assert json.loads(shown.stdout)["survival"]["state"] == "current"
    stale = dict(identities) | {setup.gaits[0]: "0" * 64}
    estimate.identities = stale
    save_survival(library, estimate, data=path)
    with pytest.raises(GaitlibError, match="other policies"):
        load_survival(library, setup.gaits)


def test_bad_horizon_or_margin_refused_before_work(recorded, tmp_path):
    path = recorded[0]
    for bad in ({"horizon_s": 0.0}, {"horizon_s": 6.0}, {"margin": 1.0}, {"margin": -0.1}, {"floor": 1.0}):
        with pytest.raises(GaitlibError, match=r"horizon|margin|floor"):
            check_guard(**bad)
    run = gaitlib_quick("survival", "fit", str(path), "--library", str(tmp_path / "nothing"), "--margin", "1.5")
    assert run.returncode == 2 and run.stderr.count("\n") == 1 and "margin" in run.stderr
    assert not (tmp_path / "nothing").exists()
    for horizons, says in (("0,1", "--horizons must be a finite number in (0, 5] s, got 0"),
                           ("0.5,x", "--horizons '0.5,x': give START:STOP:STEP (e.g. 0.5:1.5:0.5) or a list"),
                           ("1,1", "--horizons '1,1': a value is given twice")):
        run = gaitlib_quick("survival", "fit", str(path), "--library", str(tmp_path / "nothing"), "--horizons",
                            horizons)
        assert run.returncode == 2 and run.stderr == f"gaitlib: error: {says}\n" and run.stdout == ""
    for floor, says in (("1", "the guard's floor (1) must lie in [0, 1)"),
                        ("low", "--floor must be a number in [0, 1) or auto, got 'low'")):
        run = gaitlib_quick("survival", "fit", str(path), "--library", str(tmp_path / "nothing"), "--floor", floor)
        assert run.returncode == 2 and run.stderr == f"gaitlib: error: {says}\n" and run.stdout == ""
    assert not (tmp_path / "nothing").exists()
    assert not (tmp_path / "nothing").exists()


def test_the_imu_input_is_recorded_and_fitted_and_an_older_file_is_refused_for_it(recorded, tmp_path):
    import h5py

    path, setup, _, data = recorded
    assert data["imu"].shape == (len(data["gait"]), 3) and np.isfinite(data["imu"]).all()
    shoved = (data["time_s"] >= data["shove_s"]) & (data["time_s"] < data["shove_s"] + 0.1) & (data["impulse_ns"] > 40)
    calm = data["impulse_ns"] == 0
    # A shove of 40-60 N s over 0.1 s is 32-48 m/s^2 on the A1's 12.5 kg: the trunk reads far more than when calm.
    assert np.median(np.linalg.norm(data["imu"][shoved, :2], axis=1)) > 3 * np.median(
        np.linalg.norm(data["imu"][calm, :2], axis=1))
    identities = Library(setup.resources.library.root).identities(setup.gaits)
    dt = read_survival_states(path)[0]["dt"]
    estimate = fit_survival(data, gaits=setup.gaits, identities=identities, dt=dt, inputs=("latent", "phase", "imu"),
                            horizons_s=(0.2,), epochs=2, min_unshoved_minutes=0)
    assert estimate.inputs == ("latent", "phase", "imu") and estimate.armed_from_s == pytest.approx(0.3)
    older = tmp_path / "older.h5"  # as recorded before the column existed
    with h5py.File(path, "r") as source, h5py.File(older, "w") as copy:
        copy.attrs["header"] = source.attrs["header"]
        for name in source:
            if name != "imu":
                source.copy(name, copy)
    _, read = read_survival_states(older)
    assert "imu" not in read
    with pytest.raises(GaitlibError, match=r"^these survival states hold no imu \(recorded before it existed\)"):
        fit_survival(read, gaits=setup.gaits, identities=identities, dt=dt, inputs=("latent", "imu"), epochs=2)
    with pytest.raises(GaitlibError, match="recorded before its imu column existed; record into a new file"):
        record_survival(older, setup, SurvivalRecording(episodes=18, **SMALL))

