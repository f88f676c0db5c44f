"""The catch task: its reward terms, its starts from single-shove states, its episode ends, and its training into a
library entry, on the real simulator at tiny sizes."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch
from cli_runner import gaitlib

from gaitlib.defaults import Falls
from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs import catch as c
from gaitlib.envs.catch import CATCH_EPISODE_S, CATCH_REWARD, CatchStep, catch_reward
from gaitlib.envs.handover import load_states
from gaitlib.envs.randomization import RandomizationConfig
from gaitlib.envs.terminations import TerminationConfig
from gaitlib.errors import GaitError, GaitlibError
from gaitlib.gaits import GaitDescription, clip_from_description, get_gait
from gaitlib.library import Library
from gaitlib.rotations import quat_from_yaw
from gaitlib.sim import SimState, make_backend
from gaitlib.training import get_preset
from gaitlib.training.trainer import TrainRequest, train_gait
from gaitlib.transitions.states import StatesConfig, record_states

DT = 1 / 30
SHOVES = StatesConfig(per_gait=8, num_worlds=4, warmup_s=0.2, spacing_s=0.1, shove_max_ns=30.0, backend="mujoco")


def stance_step(n: int = 2, **changes) -> CatchStep:
    """N robots standing still in the catch clip's stance, upright; ``changes``: fields of the state or the step."""
    clip = clip_from_description(get_gait("catch"))
    frame = clip.frame(torch.zeros(n))
    quat = torch.zeros(n, 4)
    quat[:, 0] = 1.0
    root = frame.root_pos.clone()
    state = {
        "root_pos": root, "root_quat": quat, "root_lin_vel": torch.zeros(n, 3), "root_ang_vel": torch.zeros(n, 3),
        "joint_pos": frame.joint_pos, "joint_vel": torch.zeros(n, 12), "foot_contact": torch.ones(n, 4, dtype=bool),
        "foot_pos": frame.foot_pos_world, "body_contact": torch.zeros(n, dtype=bool),
        "trunk_contact": torch.zeros(n, dtype=bool),
    }
    state |= {k: v for k, v in changes.items() if k in state}
    from gaitlib.envs.reference import ReferenceFrame

    rel = frame.foot_pos_world - frame.root_pos.unsqueeze(1)
    ref = ReferenceFrame(root_pos=root, root_quat=quat, root_lin_vel=torch.zeros(n, 3),
                         root_ang_vel=torch.zeros(n, 3), heading_lin_vel=torch.zeros(n, 3),
                         joint_pos=frame.joint_pos, joint_vel=torch.zeros(n, 12), foot_pos_heading=rel,
                         contact=torch.ones(n, 4, dtype=bool))
    step = {"action": torch.zeros(n, 12), "last_action": torch.zeros(n, 12), "torque": torch.zeros(n, 12),
            "terminated": torch.zeros(n, dtype=bool)}
    step |= {k: v for k, v in changes.items() if k in step}
    return CatchStep(state=SimState(**state), ref=ref, **step)


def values(step: CatchStep) -> dict[str, torch.Tensor]:
    return catch_reward(CATCH_REWARD, step, dt=DT)[1]


def test_a_calm_stance_scores_every_kernel_at_its_maximum_and_every_cost_at_zero() -> None:
    got = values(stance_step())
    for name in ("alive", "still", "calm_rates", "stance"):
        assert got[name].tolist() == pytest.approx([1.0, 1.0], abs=1e-6), name
    for name in ("tilt", "action_rate", "torque", "termination"):
        assert got[name].tolist() == pytest.approx([0.0, 0.0], abs=1e-6), name
    reward, _ = catch_reward(CATCH_REWARD, stance_step(), dt=DT)
    best = DT * sum(t.weight for t in CATCH_REWARD if t.weight > 0)
    assert reward.tolist() == pytest.approx([best, best], rel=1e-5)  # dt * (5 + 10 + 5 + 3)


def test_an_upright_still_robot_scores_higher_than_a_tilted_moving_one() -> None:
    tilted = torch.tensor([[math.cos(0.3), math.sin(0.3), 0.0, 0.0]] * 2)  # rolled 0.6 rad
    moving = stance_step(root_quat=tilted, root_lin_vel=torch.tensor([[0.8, -0.3, 0.0]] * 2),
                         root_ang_vel=torch.tensor([[1.5, 0.0, 2.0]] * 2))
    calm, _ = catch_reward(CATCH_REWARD, stance_step(), dt=DT)
    shoved, terms = catch_reward(CATCH_REWARD, moving, dt=DT)
    assert (calm > shoved).all()
    assert terms["tilt"].tolist() == pytest.approx([math.sin(0.6) ** 2] * 2, rel=1e-4)  # sin^2 of the tilt
    assert terms["still"].tolist() == pytest.approx([math.exp(-(0.64 + 0.09) / 0.25)] * 2, rel=1e-4)
    assert terms["calm_rates"].tolist() == pytest.approx([math.exp(-(2.25 + 4.0) / 1.0)] * 2, rel=1e-4)


def test_the_stance_term_falls_as_a_foot_leaves_its_hip_and_ignores_the_heading() -> None:
    base = stance_step()
    feet = base.state.foot_pos.clone()
    feet[:, 0, 0] += 0.1  # one foot 10 cm forward
    assert values(stance_step(foot_pos=feet))["stance"].tolist() == pytest.approx([math.exp(-40 * 0.01)] * 2,
                                                                                    rel=1e-4)
    turned = quat_from_yaw(torch.tensor([1.0, -2.0]))  # the robot turned, its feet with it
    rel = base.state.foot_pos - base.state.root_pos.unsqueeze(1)
    from gaitlib.rotations import quat_rotate

    turned_feet = base.state.root_pos.unsqueeze(1) + quat_rotate(turned.unsqueeze(1).expand(-1, 4, -1), rel)
    assert values(stance_step(root_quat=turned, foot_pos=turned_feet))["stance"].tolist() == pytest.approx([1, 1])


def test_the_costs_count_action_changes_torques_and_a_fall() -> None:
    step = stance_step(action=torch.full((2, 12), 0.5), last_action=torch.zeros(2, 12),
                       torque=torch.tensor([[10.0] * 12, [0.0] * 12]), terminated=torch.tensor([True, False]))
    got = values(step)
    assert got["action_rate"].tolist() == pytest.approx([3.0, 3.0])  # 12 * 0.5^2
    assert got["torque"].tolist() == pytest.approx([1200.0, 0.0])
    assert got["termination"].tolist() == [1.0, 0.0]
    reward, _ = catch_reward(CATCH_REWARD, step, dt=DT)
    assert reward[1] - reward[0] == pytest.approx(DT * (100 + 0.0002 * 1200), rel=1e-4)


def test_the_pd_torque_is_the_servo_law_clipped_at_the_motor_limit() -> None:
    targets, q, qd = torch.full((2, 12), 0.1), torch.zeros(2, 12), torch.ones(2, 12)
    torque = c.pd_torque(targets, q, qd, torch.tensor([60.0, 600.0]), torch.tensor([1.0, 1.0]), limit=33.5)
    assert torque[0].tolist() == pytest.approx([5.0] * 12) and torque[1].tolist() == pytest.approx([33.5] * 12)


def test_a_catch_description_is_a_stance_and_is_recorded_as_one() -> None:
    catch = get_gait("catch")
    assert catch.task == "catch" and catch.record()["task"] == "catch"
    assert "task" not in get_gait("stand").record()  # an imitation records as before
    with pytest.raises(GaitError, match="catch task's clip is the stance"):
        GaitDescription(**{**get_gait("trot").record(), "task": "catch"})
    with pytest.raises(GaitError, match="task must be one of"):
        GaitDescription(**{**catch.record(), "task": "dance"})


@pytest.fixture(scope="module")
def shoved(tiny_library, tmp_path_factory):
    """Single-shove states of the tiny library's stand and trot."""
    path = tmp_path_factory.mktemp("catch") / "shoves.npz"
    record_states(tiny_library, config=SHOVES).save(path)
    return path


def test_single_shove_states_hold_the_push_under_way(shoved) -> None:
    states, _ = load_states(shoved)
    assert len(states) == 16 and sorted(set(states.source.tolist())) == [0, 1]
    force = np.linalg.norm(states.push_force, axis=1)
    assert set(states.push_steps.tolist()) <= {0.0, 1.0, 2.0}  # 1-3 steps into a shove of 3 (0.1 s)
    assert force.max() <= 300.0 + 1e-3 and (force > 1.0).any()  # 30 N s over 0.1 s at most
    assert (force[states.push_steps == 0] == 0).all()  # a shove that is over pushes no more
    assert np.abs(states.push_force[:, 2]).max() == 0.0  # horizontal
    assert states.settings["shove_max_ns"] == 30.0 and "shove" in states.settings["recorded"]


def catch_env(states, *, n: int = 4, seed: int = 0) -> ImitationEnv:
    cfg = EnvConfig(task="catch", episode_seconds=CATCH_EPISODE_S, randomization=RandomizationConfig(enabled=False),
                    termination=TerminationConfig().counting(Falls.TRUNK, heading=False))
    clips = [clip_from_description(get_gait("catch"))]
    return ImitationEnv(make_backend("mujoco", num_worlds=n), clips, cfg, seed=seed, handover=states,
                        handover_share=1.0)


def test_catch_episodes_start_from_the_given_states_shoved_ones_with_their_push(shoved) -> None:
    states, _ = load_states(shoved)
    pushed = states.select(np.flatnonzero(states.push_steps == 2)[:1].repeat(2))
    env = catch_env(pushed, n=2)
    s = env.sim_state
    assert s.joint_pos.numpy() == pytest.approx(pushed.joint_pos, abs=1e-5)
    assert s.root_lin_vel.numpy() == pytest.approx(pushed.root_lin_vel, abs=1e-5)
    assert env.push_force.numpy() == pytest.approx(pushed.push_force, abs=1e-3)  # the shove goes on
    env.step(torch.zeros(2, 12))
    env.step(torch.zeros(2, 12))
    assert env.push_force.abs().max() > 0  # its last two steps
    env.step(torch.zeros(2, 12))
    assert env.push_force.abs().max() == 0  # then it is over


def test_a_catch_episode_ends_on_a_trunk_fall_and_times_out_at_its_length(shoved) -> None:
    states, _ = load_states(shoved)
    calm = np.flatnonzero(np.linalg.norm(states.push_force, axis=1) == 0)
    env = catch_env(states.select(calm), n=2)
    up = torch.tensor([0, 1])
    limp = torch.zeros(2, 12)
    ended, fell, steps = torch.zeros(2, dtype=bool), torch.zeros(2, dtype=bool), 0
    while not ended.all():
        _, _, dones, extras = env.step(limp)
        steps += 1
        first = dones & ~ended
        fell |= first & ~extras["time_outs"]
        ended |= dones
    assert steps == round(CATCH_EPISODE_S * 30)  # a robot that stays up times out at 75 control steps
    assert not fell.any()
    # a trunk tipped over ends the episode at once, with the termination cost
    env.reset_worlds(up)
    from gaitlib.sim import KinematicState

    s = env.sim_state
    over = quat_from_yaw(torch.zeros(2))
    over[:, 0], over[:, 1] = math.cos(1.0), math.sin(1.0)  # rolled 2 rad
    env.backend.reset(up, KinematicState(root_pos=s.root_pos, root_quat=over, root_lin_vel=s.root_lin_vel,
                                         root_ang_vel=s.root_ang_vel, joint_pos=s.joint_pos, joint_vel=s.joint_vel))
    _, reward, dones, extras = env.step(limp)
    assert dones.all() and not extras["time_outs"].any() and extras["fall_causes"]["orientation_lost"].all()
    assert (reward < 0).all()


def test_catch_training_needs_states(tmp_path) -> None:
    with pytest.raises(GaitlibError, match="catch task starts its episodes from recorded states"):
        train_gait(TrainRequest(description=get_gait("catch"), preset=get_preset("tiny"), iterations=1,
                                library=tmp_path / "lib", run_dir=tmp_path / "run", backend="mujoco"))


def test_one_iteration_of_gaitlib_train_catch_writes_a_loadable_entry_naming_its_recipe(shoved, tmp_path) -> None:
    lib = tmp_path / "lib"
    result = gaitlib("train", "catch", "--preset", "tiny", "--iterations", "1", "--seed", "7", "--backend", "mujoco",
                     "--states", str(shoved), "--kick-max", "0", "--library", str(lib), "--run-dir",
                     str(tmp_path / "run"), "--eval-episodes", "2", "--eval-seconds", "0.5")
    assert result.returncode == 0, result.stderr
    entry = Library(lib).entry("catch")
    meta = entry.metadata
    assert entry.description.task == "catch" and meta["description"]["task"] == "catch"
    training = meta["training"]
    assert training["seed"] == 7 and training["episode_seconds"] == CATCH_EPISODE_S
    assert training["recipe"]["kick_max"] == 0 and training["recipe"]["terminate"] == "trunk"
    start = training["switch_start"]
    assert start["share"] == 1.0 and start["states_sha256"] == load_states(shoved)[1]
    assert start["from_gaits"] == ["stand", "trot"] and start["shoves"]["shove_max_ns"] == 30.0
    obs = catch_env(load_states(shoved)[0], n=2).get_observations()  # the layout of every other entry
    assert obs.policy.shape[1] == entry.observation.actor_dim and entry.policy.act(obs).shape == (2, 12)
    assert json.loads((lib / "catch" / "metadata.json").read_text())["gait"] == "catch"
