"""The guard in the meta-controller: it catches a world whose gait the survival estimate gives up on into the gait
the calibrated net offers, holds it, returns to the requested gait; it never switches where staying is safe; a
library without a survival estimate runs unguarded and says so; a margin out of range is refused before work."""

from __future__ import annotations

import json

import pytest
import torch

from gaitlib.envs import EnvConfig
from gaitlib.errors import GaitlibError
from gaitlib.evaluation import SECTORS
from gaitlib.library import Library
from gaitlib.meta import load_switching
from gaitlib.meta.guard import Guard
from gaitlib.sim import make_backend
from gaitlib.strategies import get_strategy
from gaitlib.strategies.survival import SurvivalEstimate, SurvivalNet, save_survival
from tests.cli_runner import gaitlib_quick
from tests.conftest import copy_library


def _forced(setup, stay: dict[str, float], *, horizon_s: float = 0.2) -> SurvivalEstimate:
    """An estimate that reads ``stay[gait]`` whatever the state (Platt slope 0, intercept its logit)."""
    platt = {setup.gaits.index(g): (0.0, float(torch.logit(torch.tensor(p)))) for g, p in stay.items()}
    dim = len(setup.gaits) + 2
    return SurvivalEstimate(setup.gaits, setup.resources.library.identities(setup.gaits), ("phase",), horizon_s,
                            0.0, platt, SurvivalNet(dim))


def _run(setup, estimate: SurvivalEstimate, steps: int, *, margin: float):
    sim = make_backend("mujoco", num_worlds=2)
    try:
        env = setup.make_env(sim, EnvConfig(episode_seconds=30.0), seed=0)
        trot = setup.gait_index("trot")
        env.reset_worlds(torch.arange(2), gait=torch.full((2,), trot))
        guard = Guard(estimate, get_strategy("net-lookahead", setup.resources), margin=margin)
        ctl = setup.controller(env, "net-lookahead", guard=guard)
        catches, gaits = [], []
        for _ in range(steps):
            result = ctl.step()
            catches += result.catches
            gaits.append(env.gait.clone())
        return catches, torch.stack(gaits), ctl
    finally:
        sim.close()


def test_guard_catches_a_failing_gait_and_returns(switching_library):
    setup = load_switching(switching_library)
    stand, trot = setup.gait_index("stand"), setup.gait_index("trot")
    catches, gaits, ctl = _run(setup, _forced(setup, {"trot": 1e-4, "stand": 1 - 1e-6}), 45, margin=0.0)
    first = [c for c in catches if c.step == 0]
    assert {c.world for c in first} == {0, 1}  # both caught at once, at the first step
    assert all((c.source, c.dest, c.requested) == (trot, stand, trot) for c in first)
    assert all(c.stay == pytest.approx(1e-4, rel=1e-3) and 0 < c.offer <= 1 for c in first)
    assert (gaits[0] == stand).all()
    hold = round(0.2 / ctl.env.dt)
    assert (gaits[1:hold] == stand).all()  # held for the horizon, not caught again meanwhile
    back = [c for c in first if c.back_step is not None]
    assert back and all(c.back_step > hold for c in back)  # returned to trot through the normal switch
    assert (gaits[:, [c.world for c in back]] == trot).any()
    for c in back:  # back through the strategy's switch: caught again, but only a horizon after it
        again = [d.step for d in catches if d.world == c.world and d.step > c.back_step]
        assert again and again[0] >= c.back_step + hold


def test_below_the_floor_the_guard_catches_even_just_after_a_chosen_switch(switching_library):
    setup = load_switching(switching_library)
    estimate = _forced(setup, {"trot": 1e-4, "stand": 1 - 1e-6})
    estimate.floor = 0.5
    catches, _, _ = _run(setup, estimate, 45, margin=0.0)
    back = [c for c in catches if c.step == 0 and c.back_step is not None]
    assert back
    for c in back:  # the strategy's switch back to the trot: caught again at once, below the floor
        again = [d.step for d in catches if d.world == c.world and d.step >= c.back_step]
        assert again and again[0] == c.back_step  # without a floor: a horizon later (tested above)


def test_guard_never_switches_where_staying_is_safe(switching_library):
    setup = load_switching(switching_library)
    estimate = _forced(setup, {"trot": 1 - 1e-6, "stand": 1 - 1e-6})
    estimate.floor = 0.5  # staying reads above it
    catches, gaits, _ = _run(setup, estimate, 15, margin=0.05)
    assert catches == []
    assert (gaits == setup.gait_index("trot")).all()


_cli = gaitlib_quick
"""In-process: these tests are about the guard's reports, not the process boundary (run, eval and benchmark each
run in a fresh process in their own test files)."""


def test_run_without_estimate_is_unguarded_and_says_so(switching_library, tmp_path):
    common = ["run", "--from", "trot", "--to", "stand", "--request-at", "0.3", "--hold", "0.8", "--backend",
              "mujoco", "--library", str(switching_library), "--plot", str(tmp_path / "run.png")]
    run = _cli(*common, "--json")
    assert run.returncode == 0, run.stderr
    guard = json.loads(run.stdout)["guard"]
    assert guard["on"] is False and "no survival estimate" in guard["why_off"] and guard["catches"] == []
    text = _cli(*common)
    assert text.returncode == 0 and text.stdout.splitlines()[0].startswith("unguarded: ")
    refused = _cli(*common, "--guard-margin", "1.5")
    assert refused.returncode == 2 and "margin" in refused.stderr and refused.stderr.count("\n") == 1


def test_guarded_run_reports_and_plots(switching_library, tmp_path):
    library = copy_library(Library(switching_library), tmp_path / "library")
    setup = load_switching(library.root)
    (tmp_path / "states.h5").write_bytes(b"forced")
    save_survival(library, _forced(setup, {"trot": 1e-4, "stand": 1 - 1e-6}), data=tmp_path / "states.h5")
    with pytest.raises(GaitlibError, match="margin"):
        setup.guard(margin=-0.5)
    run = _cli("run", "--from", "trot", "--to", "stand", "--request-at", "0.3", "--hold", "0.8", "--backend",
               "mujoco", "--library", str(library.root), "--plot", str(tmp_path / "run.png"), "--json")
    assert run.returncode == 0, run.stderr
    guard = json.loads(run.stdout)["guard"]
    assert guard["on"] is True and guard["margin"] == 0.0
    first = guard["catches"][0]
    assert (first["from"], first["to"], first["time_s"]) == ("trot", "stand", 0.0)
    assert (tmp_path / "run.png").stat().st_size > 0


def test_eval_impulses_guarded_beside_unguarded(switching_library, tmp_path):
    args = ["eval", "trot", "--impulses", "6", "--episodes", "2", "--backend", "mujoco", "--guard", "--json"]
    refused = _cli(*args, "--library", str(switching_library))
    assert refused.returncode == 2 and "no survival estimate" in refused.stderr
    assert refused.stderr.count("\n") == 1
    library = copy_library(Library(switching_library), tmp_path / "library")
    setup = load_switching(library.root)
    (tmp_path / "states.h5").write_bytes(b"forced")
    save_survival(library, _forced(setup, {"trot": 1e-4, "stand": 1 - 1e-6}), data=tmp_path / "states.h5")
    run = _cli(*args, "--library", str(library.root), "--guard-margin", "0")
    assert run.returncode == 0, run.stderr
    out = json.loads(run.stdout)
    off, on = out["unguarded_points"][0], out["points"][0]
    assert off["guard"]["on"] is False and off["guard"]["catches"] == []
    assert on["guard"]["on"] is True and on["guard"]["margin"] == 0.0
    assert {c["world"] for c in on["guard"]["catches"] if c["time_s"] == 0} == {0, 1}
    assert on["guard"]["false_catches"] >= 2  # caught before the shove: no estimate that low is right
    assert on["guard"]["measured_gait_share"] < 1.0


def test_benchmark_guard_refused_without_estimate_and_counted_with_one(switching_library, tmp_path):
    args = ["benchmark", "--strategies", "net-lookahead", "--magnitudes", "0", "--samples", "2", "--pairs",
            "trot-stand", "--worlds", "2", "--backend", "mujoco", "--guard", "--json"]
    refused = _cli(*args, "--library", str(switching_library), "--out", str(tmp_path / "refused"))
    assert refused.returncode == 2 and "no survival estimate" in refused.stderr
    assert not (tmp_path / "refused").exists()
    library = copy_library(Library(switching_library), tmp_path / "library")
    setup = load_switching(library.root)
    (tmp_path / "states.h5").write_bytes(b"forced")
    save_survival(library, _forced(setup, {"trot": 1e-4, "stand": 1 - 1e-6}), data=tmp_path / "states.h5")
    run = _cli(*args, "--library", str(library.root), "--out", str(tmp_path / "bench"), "--guard-margin", "0")
    assert run.returncode == 0, run.stderr
    guard = json.loads(run.stdout)["guard"]
    assert guard["on"] is True and guard["margin"] == 0.0
    (group,) = guard["catches"].values()
    assert group["catches"] >= 2 and group["by_pair"].get("trot-stand", 0) >= 2
    again = _cli(*args, "--library", str(library.root), "--out", str(tmp_path / "bench"), "--guard-margin", "0")
    assert again.returncode == 0 and json.loads(again.stdout)["guard"] == guard  # resumed: read back, checked


def test_eval_push_max_guarded_counts_catches_per_minute(switching_library, tmp_path):
    library = copy_library(Library(switching_library), tmp_path / "library")
    setup = load_switching(library.root)
    (tmp_path / "states.h5").write_bytes(b"forced")
    save_survival(library, _forced(setup, {"trot": 1e-4, "stand": 1 - 1e-6}), data=tmp_path / "states.h5")
    args = ["eval", "trot", "--push-max", "0", "--seconds", "1", "--episodes", "2", "--backend", "mujoco", "--guard",
            "--library", str(library.root)]
    refused = _cli(*args, "--action-delay", "1")
    assert refused.returncode == 2 and "--action-delay" in refused.stderr and refused.stderr.count("\n") == 1
    run = _cli(*args, "--guard-margin", "0", "--json")
    assert run.returncode == 0, run.stderr
    out = json.loads(run.stdout)
    assert out["unguarded"]["guard"]["catches"] == [] and out["unguarded"]["catches_per_min"] == 0
    on = out["guarded"]
    assert len(on["guard"]["catches"]) >= 2 and on["catches_per_min"] > 0  # at 0 N each is a false catch
    assert on["guard"]["measured_gait_share"] < 1.0


def test_the_catch_table_is_measured_on_training_draws_and_written_into_the_estimate(switching_library, tmp_path):
    from gaitlib.strategies.survival import load_survival

    library = copy_library(Library(switching_library), tmp_path / "library")
    setup = load_switching(library.root)
    (tmp_path / "states.h5").write_bytes(b"states")
    save_survival(library, _forced(setup, {"trot": 0.5, "stand": 0.5}), data=tmp_path / "states.h5")
    before = load_survival(library, setup.gaits)
    assert before.catch_into is None
    done = gaitlib_quick("survival", "catches", "--episodes", "16", "--impulse", "30", "--library", str(library.root),
                         "--json")
    assert done.returncode == 0, done.stderr
    table = json.loads(done.stdout)
    other = {"stand": "trot", "trot": "stand"}
    assert table["seed"] == 1000 and list(table["falls"]) == ["stand", "trot"]
    for g, by_sector in table["falls"].items():
        assert list(by_sector) == list(SECTORS) and sum(table["worlds"][g].values()) == 16  # each world read once
        for s, row in by_sector.items():
            assert set(row) == {"stay", other[g]} and all(0 <= k <= table["worlds"][g][s] for k in row.values())
            # A gait shoved this way is caught into the other only where catching fell less than staying, on at
            # least 4 worlds.
            chosen = row[other[g]] < row["stay"] and table["worlds"][g][s] >= 4
            assert table["catch_into"].get(g, {}).get(s) == (other[g] if chosen else None)
    assert all(0 <= a <= 1 for a in table["sector_agreement"].values())  # read sector = shoved sector, a share
    after = load_survival(library, setup.gaits)
    expected = torch.full((2, len(SECTORS)), -1)
    for g, row in table["catch_into"].items():
        for s, d in row.items():
            expected[setup.gait_index(g), SECTORS.index(s)] = setup.gait_index(d)
    assert torch.equal(after.catch_into, expected)
    assert (after.horizon_s, after.margin, after.platt) == (before.horizon_s, before.margin, before.platt)
    assert after.info["catches"] == table
    # Measured again, every destination is still offered: the table the estimate now holds does not hide them.
    from gaitlib.benchmark.catches import TimedCatch

    guarded = load_switching(library.root).guard()
    shove = {"impulse": 1.0, "duration_s": 0.1, "cycle_s": 0.5, "seed": 0}
    assert TimedCatch(guarded, delay=2, dest=0, shove=shove).estimate.catch_into is None
    assert torch.equal(TimedCatch(guarded, delay=2, dest=None, shove=shove).estimate.catch_into, after.catch_into)
    bare = copy_library(Library(switching_library), tmp_path / "bare")
    refused = gaitlib_quick("survival", "catches", "--library", str(bare.root))
    assert refused.returncode != 0 and refused.stderr.count("\n") == 1 and "no survival estimate" in refused.stderr


def test_a_gait_the_catch_table_lacks_is_never_caught(switching_library):
    setup = load_switching(switching_library)
    estimate = _forced(setup, {"trot": 1e-4, "stand": 1 - 1e-6})  # the trot would be caught at once
    estimate.info["catches"] = {"catch_into": {"stand": "trot"}}  # ... but the table never catches it
    catches, gaits, _ = _run(setup, estimate, 5, margin=0.0)
    assert catches == [] and (gaits == setup.gait_index("trot")).all()



def test_the_catch_table_catches_by_the_direction_the_trunk_is_pushed(switching_library):
    setup = load_switching(switching_library)
    estimate = _forced(setup, {"trot": 1e-4, "stand": 1 - 1e-6})  # the trot would be caught at once ...
    estimate.info["catches"] = {"catch_into": {"trot": {"left": "stand"}}}  # ... when pushed toward its left only
    sim = make_backend("mujoco", num_worlds=4)
    try:
        env = setup.make_env(sim, EnvConfig(episode_seconds=30.0), seed=0)
        env.reset_worlds(torch.arange(4), gait=torch.full((4,), setup.gait_index("trot")))
        guard = Guard(estimate, get_strategy("net-lookahead", setup.resources), margin=0.0)
        ctl = setup.controller(env, "net-lookahead")
        # Pushed left, front, back and right: the trunk-frame acceleration (x forward, y left), m/s^2.
        env.trunk_acceleration = torch.tensor([[0.5, 9.0, 0.0], [9.0, 0.5, 0.0], [-9.0, 0.5, 0.0], [0.5, -9.0, 0.0]])
        reading = guard.read(env, ctl.policies, torch.arange(4), ctl.candidates)
    finally:
        sim.close()
    assert guard.fires(reading).tolist() == [True, False, False, False]
    assert reading.best()[1][0] == setup.gait_index("stand")
