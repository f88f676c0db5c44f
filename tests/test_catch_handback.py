"""The catch skill in the guard: the catch table measured into given gaits only (``survival catches --into``); a
world caught into a catch skill holds it until the trunk is calm (tilt, speed and rates, read on the real
simulator), at most :data:`CALM_WAIT_S`, then returns to the requested gait; other catches hold the horizon alone."""

from __future__ import annotations

import json

import pytest
import torch

import gaitlib.meta.controller as controller
from gaitlib.envs import EnvConfig
from gaitlib.envs.catch import CALM_WAIT_S, is_calm
from gaitlib.library import Library
from gaitlib.meta import load_switching
from gaitlib.meta.controller import MetaController
from gaitlib.meta.guard import Guard
from gaitlib.sim import make_backend
from gaitlib.strategies import get_strategy
from gaitlib.strategies.survival import save_survival
from tests.cli_runner import gaitlib_quick
from tests.conftest import copy_library
from tests.test_guard import _forced


def test_a_standing_robot_reads_calm_and_a_shoved_one_does_not(switching_library):
    setup = load_switching(switching_library)
    sim = make_backend("mujoco", num_worlds=2)
    try:
        env = setup.make_env(sim, EnvConfig(episode_seconds=30.0), seed=0)
        stand = setup.gait_index("stand")
        env.reset_worlds(torch.arange(2), gait=torch.full((2,), stand))
        policies = [e.policy for e in setup.entries]
        with torch.inference_mode():
            for _ in range(15):
                env.step(policies[stand].act(env.get_observations()))
            assert is_calm(env.sim_state).tolist() == [True, True]
            env.shove(torch.tensor([1]), torch.tensor([[0.0, 300.0, 0.0]]), 3)  # 300 N sideways for 0.1 s: 30 N s
            for _ in range(3):
                env.step(policies[stand].act(env.get_observations()))
            assert is_calm(env.sim_state).tolist() == [True, False]
    finally:
        sim.close()


def _caught(setup, *, catchers: tuple[int, ...], calm_after: int | None, monkeypatch, steps: int = 110):
    """Two trotting worlds caught into the stand at once (forced estimate, horizon 0.2 s); ``calm_after``: the calm
    test reads False for this many of its calls, then the real one (``None``: never calm)."""
    calls = {"n": 0}

    def delayed(state):
        calls["n"] += 1
        real = is_calm(state)
        return real if calm_after is not None and calls["n"] > calm_after else torch.zeros_like(real)

    monkeypatch.setattr(controller, "is_calm", delayed)
    sim = make_backend("mujoco", num_worlds=2)
    try:
        env = setup.make_env(sim, EnvConfig(episode_seconds=30.0), seed=0)
        trot = setup.gait_index("trot")
        env.reset_worlds(torch.arange(2), gait=torch.full((2,), trot))
        estimate = _forced(setup, {"trot": 1e-4, "stand": 1 - 1e-6})
        guard = Guard(estimate, get_strategy("net-lookahead", setup.resources), margin=0.0)
        ctl = MetaController(env, [e.policy for e in setup.entries], get_strategy("net-lookahead", setup.resources),
                             guard=guard, catchers=catchers)
        gaits, catches = [], []
        for _ in range(steps):
            result = ctl.step()
            catches += result.catches
            gaits.append(env.gait.clone())
        return torch.stack(gaits), [c for c in catches if c.step == 0], ctl
    finally:
        sim.close()


def test_a_world_caught_into_a_catch_skill_holds_it_until_calm(switching_library, monkeypatch):
    setup = load_switching(switching_library)
    stand = setup.gait_index("stand")
    hold = round(0.2 * 30)
    unsettled = 20  # calm reads False on 20 checks, one a step once the horizon's hold is over
    gaits, first, _ = _caught(setup, catchers=(stand,), calm_after=unsettled, monkeypatch=monkeypatch)
    assert {c.world for c in first} == {0, 1} and all(c.dest == stand for c in first)
    assert (gaits[: hold + unsettled] == stand).all()  # held past the horizon while not calm
    back = [c.back_step for c in first if c.back_step is not None]
    assert back and min(back) >= hold + unsettled  # returned to the trot once calm
    _, plain_first, _ = _caught(setup, catchers=(), calm_after=unsettled, monkeypatch=monkeypatch)
    plain_back = [c.back_step for c in plain_first if c.back_step is not None]
    assert plain_back and min(plain_back) < min(back)  # not a catch skill: the horizon's hold alone


def test_a_catch_skill_that_never_calms_the_robot_hands_it_back_after_the_longest_wait(switching_library,
                                                                                       monkeypatch):
    setup = load_switching(switching_library)
    stand = setup.gait_index("stand")
    wait = round(CALM_WAIT_S * 30)
    gaits, first, _ = _caught(setup, catchers=(stand,), calm_after=None, monkeypatch=monkeypatch, steps=wait + 70)
    assert (gaits[:wait] == stand).all()  # never calm: held for the longest wait ...
    back = [c.back_step for c in first if c.back_step is not None]
    assert back and all(wait <= b for b in back)  # ... then back to the trot


def test_setup_marks_the_catch_skills_of_its_library(switching_library):
    setup = load_switching(switching_library)
    sim = make_backend("mujoco", num_worlds=1)
    try:
        ctl = setup.controller(setup.make_env(sim, EnvConfig(episode_seconds=1.0)), "net-lookahead")
    finally:
        sim.close()
    assert ctl.catchers.tolist() == [e.description.task == "catch" for e in setup.entries] == [False, False]


def test_the_catch_table_into_given_gaits_measures_those_alone(switching_library, tmp_path):
    library = copy_library(Library(switching_library), tmp_path / "library")
    setup = load_switching(library.root)
    (tmp_path / "states.h5").write_bytes(b"states")
    save_survival(library, _forced(setup, {"trot": 0.5, "stand": 0.5}), data=tmp_path / "states.h5")
    done = gaitlib_quick("survival", "catches", "--episodes", "16", "--impulse", "30", "--into", "stand",
                         "--library", str(library.root), "--json")
    assert done.returncode == 0, done.stderr
    table = json.loads(done.stdout)
    assert table["into"] == ["stand"] and list(table["falls"]) == ["trot"]  # the stand has no other gait to go to
    assert all(set(row) == {"stay", "stand"} for row in table["falls"]["trot"].values())
    assert set(table["catch_into"]) <= {"trot"}
    for bad, said in ((["--into", "gallop"], "gallop"), (["--into", ","], "--into")):
        refused = gaitlib_quick("survival", "catches", "--episodes", "16", *bad, "--library", str(library.root))
        assert refused.returncode == 2 and refused.stderr.count("\n") == 1 and said in refused.stderr
    assert json.loads(gaitlib_quick("survival", "catches", "--episodes", "16", "--impulse", "30", "--library",
                                    str(library.root), "--json").stdout)["into"] is None


@pytest.mark.parametrize("tilt_deg, calm", [(5.0, True), (20.0, False)])
def test_calm_reads_the_tilt(tilt_deg, calm, switching_library):
    setup = load_switching(switching_library)
    sim = make_backend("mujoco", num_worlds=1)
    try:
        env = setup.make_env(sim, EnvConfig(episode_seconds=30.0), seed=0)
        state = env.sim_state
        half = torch.deg2rad(torch.tensor(tilt_deg)) / 2
        state.root_quat[:] = torch.tensor([torch.cos(half), torch.sin(half), 0.0, 0.0])  # rolled about x
        state.root_lin_vel[:], state.root_ang_vel[:] = 0.0, 0.0
        assert is_calm(state).tolist() == [calm]
    finally:
        sim.close()
