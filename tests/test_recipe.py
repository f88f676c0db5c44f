"""The training recipe's robustness levers on the real simulator: a velocity kick changes the trunk's speed by what
it says, trunk-only terminations ride a leg's touch through and its penalty costs reward, and a run records every
lever in its entry."""

from __future__ import annotations

import dataclasses
import json

import pytest
import torch
from cli_runner import gaitlib_quick

from gaitlib.defaults import Falls
from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs import observations as obs_fn
from gaitlib.envs.randomization import PushConfig, PushSchedule
from gaitlib.errors import GaitlibError
from gaitlib.gaits import clip_from_description, get_gait
from gaitlib.library import Library
from gaitlib.robots import get_robot
from gaitlib.robots.a1.constants import TOTAL_MASS
from gaitlib.sim import make_backend, standing_state
from gaitlib.training import get_preset
from gaitlib.training.recipe import PAPER_RECIPE, Recipe


def test_a_kick_changes_the_trunks_speed_by_the_drawn_amount() -> None:
    """In the air, a kick of the largest size gives the nominal A1 ``kick_max`` of horizontal speed within the one
    control step it lasts (the trunk's own speed within a few percent of it: the legs, held by their PD loops,
    take some of the momentum)."""
    recipe = Recipe(push_kind="kick", kick_max=1.0, kick_interval=(0.1, 0.1))
    sim = make_backend("mujoco", num_worlds=4)
    try:
        cfg = recipe.env_config(EnvConfig(episode_seconds=5.0), control_dt=sim.control_dt)
        force = recipe.push_limit(get_preset("cpu"), 10**6, 10, control_dt=sim.control_dt)
        assert force == pytest.approx(TOTAL_MASS * 1.0 / sim.control_dt)
        state = standing_state(get_robot("a1"), 4)
        state.root_pos[:, 2] = 2.0  # far above the ground: only the kick and gravity act
        sim.reset(torch.arange(4), state)
        force_xy = torch.tensor([[force, 0.0, 0.0], [0.0, force, 0.0], [0.0, 0.0, 0.0], [force, 0.0, 0.0]])
        sim.set_trunk_force(torch.arange(4), force_xy)
        sim.step()
        speed = sim.state().root_lin_vel[:, :2].norm(dim=1)
        assert speed[:2].tolist() == pytest.approx([1.0, 1.0], abs=0.05) and speed[2] < 1e-3
        assert cfg.pushes.duration == (sim.control_dt, sim.control_dt) and cfg.pushes.interval == (0.1, 0.1)
    finally:
        sim.close()


def test_kicks_are_drawn_per_axis_as_the_field_draws_them() -> None:
    """``axes`` (the default): each horizontal axis uniform in +-max, so about 1 - pi/4 of the kicks are larger than
    max and none beyond sqrt(2) max; ``disk``: a random direction with a magnitude of at most max."""
    pushes = {}
    for draw in ("axes", "disk"):
        cfg = Recipe(push_kind="kick", kick_draw=draw).env_config(EnvConfig(), control_dt=1 / 30).pushes
        assert cfg.draw == draw
        generator = torch.Generator().manual_seed(0)
        schedule = PushSchedule(dataclasses.replace(cfg, max_force=1.0), 20_000, 1 / 30, generator)
        schedule._steps_left[:] = 1  # every world's kick is due at the next step
        schedule.advance()
        pushes[draw] = schedule.force
    axes, disk = pushes["axes"], pushes["disk"]
    assert axes[:, :2].abs().max() <= 1.0 and (axes[:, 2] == 0).all()
    assert (axes[:, :2] < -0.9).any(0).all() and (axes[:, :2] > 0.9).any(0).all()
    beyond = (axes.norm(dim=1) > 1.0).float().mean()
    assert beyond == pytest.approx(1 - torch.pi / 4, abs=0.02)
    assert disk.norm(dim=1).max() <= 1.0 + 1e-6 and disk.norm(dim=1).mean() == pytest.approx(0.5, abs=0.02)
    with pytest.raises(ValueError, match="fixed_force with 'disk' only"):
        PushConfig(max_force=1.0, fixed_force=True, draw="axes")


def test_a_recipe_recorded_before_the_kick_draw_and_cycle_sync_existed_reads_as_it_was_trained() -> None:
    recorded = {"push_kind": "kick", "kick_max": 1.0, "kick_interval": [1.0, 3.0], "terminate": "contact",
                "contact_penalty": 0.0, "gamma": None, "lam": None, "action_delay": None, "critic_delay": False}
    assert Recipe.from_record(recorded) == dataclasses.replace(PAPER_RECIPE, push_kind="kick", kick_draw="disk")
    recipe = Recipe(push_kind="kick", falls=Falls.TRUNK, contact_penalty=1.0, cycle_sync=True)
    assert Recipe.from_record(json.loads(json.dumps(recipe.as_dict()))) == recipe


def test_trunk_only_terminations_ride_a_touch_through_and_the_penalty_costs_reward() -> None:
    clip = clip_from_description(get_gait("stand"))
    rewards = {}
    for terminate, penalty in ((Falls.CONTACT, 0.0), (Falls.TRUNK, 0.0), (Falls.TRUNK, 0.5)):
        sim = make_backend("mujoco", num_worlds=1)
        try:
            recipe = Recipe(falls=terminate, contact_penalty=penalty, action_delay=0)
            cfg = recipe.env_config(EnvConfig(episode_seconds=5.0), control_dt=sim.control_dt)
            cfg = dataclasses.replace(cfg, randomization=dataclasses.replace(cfg.randomization, enabled=False))
            env = ImitationEnv(sim, [clip], cfg, seed=0)
            kneel = torch.tensor([[0.0, 0.0, -2.7] * 4])  # on its knees, the trunk up: a leg's touch
            state = standing_state(get_robot("a1"), 1)
            state.joint_pos[:], state.root_pos[0, 2] = kneel, 0.3
            sim.reset(torch.arange(1), state)
            for _ in range(10):
                sim.set_pd_targets(kneel)
                sim.step()
            assert bool(sim.state().body_contact[0]) and not bool(sim.state().trunk_contact[0])
            hold = (kneel - env.reference.frame(env.dt).joint_pos) / cfg.action_scale  # targets: the kneel
            _, reward, dones, extras = env.step(hold)
            rewards[(terminate, penalty)] = float(reward[0])
            assert bool(extras["touch"][0])
            assert bool(dones[0]) == (terminate == "contact")
        finally:
            sim.close()
    assert rewards[("trunk", 0.5)] == pytest.approx(rewards[("trunk", 0.0)] - 0.5, abs=1e-5)


def test_cycle_sync_forgives_a_displacement_at_the_next_cycle_and_only_then() -> None:
    """A standing robot whose reference is anchored 0.4 m away (as after a shove) loses the trunk-position reward;
    with cycle sync the reference moves to the robot at the next cycle start, its heading kept; without, never."""
    clip = clip_from_description(get_gait("stand"))
    root_pose = {}
    for sync in (False, True):
        sim = make_backend("mujoco", num_worlds=1)
        try:
            cfg = Recipe(cycle_sync=sync, action_delay=0).env_config(EnvConfig(episode_seconds=5.0),
                                                                      control_dt=sim.control_dt)
            cfg = dataclasses.replace(cfg, randomization=dataclasses.replace(cfg.randomization, enabled=False),
                                      random_start_phase=False)
            env = ImitationEnv(sim, [clip], cfg, seed=0)
            env.step(torch.zeros(1, 12))
            env.reference.start(torch.arange(1), torch.zeros(1, dtype=torch.long), env.reference.phase.clone(),
                                env.sim_state.root_pos + torch.tensor([[0.4, 0.0, 0.0]]), env.sim_state.root_quat)
            yaw = float(env.reference.frame().root_quat[0, 0])
            values, synced_at = [], None
            for step in range(round(1.3 / (clip.phase_rate * env.dt))):  # 1.3 cycles
                before = float(env.reference.phase[0])
                env.step(torch.zeros(1, 12))
                values.append(float(env._terms["root_pose"][0]))
                if synced_at is None and int(env.reference.phase[0]) > int(before):
                    synced_at = step
                    gap = env.reference.frame().root_pos[0, :2] - env.sim_state.root_pos[0, :2]
                    assert (gap.norm() < 1e-5) == sync
            assert synced_at is not None and float(env.reference.frame().root_quat[0, 0]) == pytest.approx(yaw)
            root_pose[sync] = (max(values[:synced_at]), min(values[synced_at:]))
        finally:
            sim.close()
    assert root_pose[False][1] < 0.1 and root_pose[True][0] < 0.1  # both displaced until the cycle starts
    assert root_pose[True][1] > 0.5  # then only the synced one is near its reference again


def test_every_lever_is_an_option_recorded_in_the_entry(tmp_path) -> None:
    library = tmp_path / "library"
    trained = gaitlib_quick(
        "train", "stand", "--preset", "tiny", "--iterations", "1", "--eval-episodes", "2", "--eval-seconds", "0.5",
        "--backend", "mujoco", "--library", str(library), "--run-dir", str(tmp_path / "runs"), "--push-kind", "kick",
        "--kick-max", "0.5", "--kick-interval", "1:2", "--terminate", "trunk", "--contact-penalty", "0.2",
        "--gamma", "0.99", "--lam", "0.9", "--action-delay", "1", "--critic-delay", "--cycle-sync",
    )
    assert trained.returncode == 0, trained.stderr
    training = json.loads((library / "stand" / "metadata.json").read_text())["training"]
    assert training["recipe"] == {"push_kind": "kick", "kick_max": 0.5, "kick_draw": "axes",
                                  "kick_interval": [1.0, 2.0], "terminate": "trunk", "contact_penalty": 0.2,
                                  "gamma": 0.99, "lam": 0.9,
                                  "action_delay": 1, "critic_delay": True, "cycle_sync": True}
    assert training["preset"]["gamma"] == 0.99 and training["preset"]["lam"] == 0.9
    assert training["randomization"]["action_delay_steps"] == [1, 1]
    entry = Library(library).entry("stand")  # the critic reads the delay after the other privileged extras
    assert entry.observation.critic_delay and entry.observation.privileged_dim == obs_fn.PRIVILEGED_DIM + 1
    assert json.loads((library / "stand" / "metadata.json").read_text())["observation"]["critic_delay"] == [
        "action_delay:1"
    ]
    share = min(1.0, 1 / get_preset("tiny").push_ramp_iterations(1))  # of the kick curriculum after one iteration
    assert training["push_max_n"] == pytest.approx(TOTAL_MASS * 0.5 * share * 30, rel=1e-5)  # m dv / dt, dt 1/30 s


def test_the_defaults_are_the_shipped_librarys_recipe(tmp_path) -> None:
    """``gaitlib train`` without a lever option trains with :class:`Recipe`'s defaults, and they are the recipe every
    gait of the shipped library was trained with, so a gait added to it is trained as its gaits were (its recovery
    skill with larger kicks, its one lever changed; its catch skill without kicks, from shoved starts; its mirrored
    sidestep_left trained not at all, but made from the trained sidestep_right)."""
    shipped = Library()
    training = {gait: shipped.entry(gait).metadata["training"] for gait in shipped.gaits()}
    assert training.pop("sidestep_left")["mirror"]["source"] == "sidestep_right"
    recipes = {gait: Recipe.from_record(record["recipe"]) for gait, record in training.items()}
    assert recipes.pop("trot_in_place") == dataclasses.replace(Recipe(), kick_max=1.5)
    assert recipes.pop("catch") == dataclasses.replace(Recipe(), kick_max=0.0)
    assert len(recipes) == 11 and set(recipes.values()) == {Recipe()}
    library = tmp_path / "library"
    trained = gaitlib_quick("train", "stand", "--preset", "tiny", "--iterations", "1", "--eval-episodes", "2",
                            "--eval-seconds", "0.5", "--backend", "mujoco", "--library", str(library),
                            "--run-dir", str(tmp_path / "runs"))
    assert trained.returncode == 0, trained.stderr
    recorded = json.loads((library / "stand" / "metadata.json").read_text())["training"]["recipe"]
    assert Recipe.from_record(recorded) == Recipe() and Recipe() != PAPER_RECIPE


@pytest.mark.parametrize(
    ("fields", "line"),
    [
        ({"push_kind": "shove"}, "--push-kind takes force or kick, got 'shove'"),
        ({"kick_draw": "ring"}, "--kick-draw takes disk or axes, got 'ring'"),
        ({"kick_interval": (3.0, 1.0)}, "--kick-interval LOW:HIGH with 0 < LOW <= HIGH <= 60 s"),
        ({"contact_penalty": -1.0}, "--contact-penalty must lie in [0, 10] per step, got -1"),
        ({"gamma": 0.0}, "--gamma must lie in (0, 1], got 0"),
        ({"action_delay": 7}, "--action-delay must be 0-3 control steps, got 7"),
    ],
)
def test_an_impossible_lever_is_one_line(fields, line) -> None:
    with pytest.raises(GaitlibError, match=line.replace("(", r"\(").replace(")", r"\)").replace("[", r"\[")):
        Recipe(**fields)


def test_switching_in_from_recorded_states_counts_falls_and_touches(tmp_path) -> None:
    """The stand takes over robots recorded while the trot ran, at random moments: every handed-over world is
    judged once; a source the states do not hold is one line."""
    from gaitlib.envs.handover import load_states
    from gaitlib.evaluation import switch_in
    from gaitlib.library.layout import shipped_library_dir

    recorded = gaitlib_quick("states", "--gaits", "trot,stand", "--per-gait", "16", "--worlds", "8", "--backend",
                             "mujoco", "--out", str(tmp_path / "s.npz"))
    assert recorded.returncode == 0, recorded.stderr
    states, _ = load_states(tmp_path / "s.npz")
    library = Library(shipped_library_dir())
    stand = library.entry("stand")
    env_cfg = library.shared_policy_settings(["stand"]).env_config(EnvConfig())
    result = switch_in(stand.policy, stand.clip, env_cfg=env_cfg, states=states, source="trot", episodes=12,
                       horizon_s=1.0, backend="mujoco", seed=3)
    assert result.episodes == 12 and 0 <= result.fell <= 12 and 0 <= result.touched <= 12
    assert result.fall_ci95[0] <= result.fell / 12 <= result.fall_ci95[1] and result.falls == "trunk"
    with pytest.raises(GaitlibError, match="the states hold none recorded while 'walk' ran"):
        switch_in(stand.policy, stand.clip, env_cfg=env_cfg, states=states, source="walk", episodes=2)


def test_an_ablation_row_measures_a_fixed_delay_variant_at_its_trained_delay(tmp_path) -> None:
    """``benchmarks/robust_ablation.py`` on a stand trained with every action one step late: 0 N at that delay and
    one step later, pushes while walking at Table 1's random delay like every other figure; its recipe, training
    time and every figure recorded."""
    from benchmarks import robust_ablation as ablation

    library = tmp_path / "library"
    trained = gaitlib_quick("train", "stand", "--preset", "tiny", "--iterations", "1", "--eval-episodes", "2",
                            "--backend", "mujoco", "--library", str(library), "--run-dir", str(tmp_path / "runs"),
                            "--action-delay", "1", "--eval-seconds", "0.5")
    assert trained.returncode == 0, trained.stderr
    states = tmp_path / "s.npz"
    recorded = gaitlib_quick("states", "--gaits", "trot", "--per-gait", "8", "--worlds", "8", "--backend", "mujoco",
                             "--out", str(states))
    assert recorded.returncode == 0, recorded.stderr
    row = ablation.ablation_row(Library(library), "stand", states=states, sources=["trot"], impulses=[0.0, 12.0],
                                episodes=4, switches=4, seconds=1.0, backend="mujoco", seed=0)
    figures = row["figures"]
    assert (figures["zero_n"]["action_delay_steps"], figures["zero_n"]["late_steps"]) == (1, 0)
    assert (figures["one_step_late"]["action_delay_steps"], figures["one_step_late"]["late_steps"]) == (1, 1)
    assert figures["push_50n"]["action_delay_steps"] is None and figures["push_50n"]["push_max"] == 50.0
    assert [p["impulse_ns"] for p in figures["single_shove"]] == [0.0, 12.0]
    assert figures["switch_in_from_trot"]["episodes"] == 4 and row["recipe"]["action_delay"] == 1
    assert row["training_minutes"] >= 0 and row["iterations"] == 1 and len(row["states"]["sha256"]) == 64
    assert set(figures["quality_bar"]) == {"speed_error", "speed_within_10_percent", "median_heading_change_deg",
                                       "heading_within_15_deg"}
