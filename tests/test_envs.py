"""The imitation environment on the real MuJoCo backend, a handful of worlds."""

from __future__ import annotations

import dataclasses
import itertools
import math

import pytest
import torch

from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs import observations as obs_fn
from gaitlib.envs.randomization import (
    PushConfig,
    PushSchedule,
    RandomizationConfig,
    sample_world_parameters,
)
from gaitlib.envs.terminations import orientation_lost
from gaitlib.gaits import clip_from_description, get_gait
from gaitlib.rotations import quat_from_yaw, quat_multiply
from gaitlib.sim import make_backend
from gaitlib.training import get_preset


@pytest.fixture(scope="module")
def clips():
    return {name: clip_from_description(get_gait(name)) for name in ("trot", "stand", "pace")}


def make_env(clips, names=("trot",), n=4, **cfg):
    backend = make_backend("mujoco", num_worlds=n)
    return ImitationEnv(backend, [clips[g] for g in names], EnvConfig(**cfg), seed=3)


def test_vec_env_contract(clips) -> None:
    env = make_env(clips, n=3)
    obs = env.get_observations()
    assert obs.policy.shape == (3, obs_fn.ObservationConfig().actor_dim) == (3, 159)
    assert obs.privileged.shape == (3, obs_fn.PRIVILEGED_DIM)
    assert obs.policy.dtype == torch.float32
    assert env.num_actions == 12 and env.max_episode_length == 300
    obs, reward, dones, extras = env.step(torch.zeros(3, 12))
    assert reward.shape == (3,) and reward.dtype == torch.float32
    assert dones.shape == (3,) and dones.dtype == torch.bool
    assert extras["time_outs"].shape == (3,)
    assert set(extras["log"]) >= {f"/reward/{t}" for t in ("pose", "joint_velocity", "end_effector", "root_pose")}
    assert torch.all((reward >= 0) & (reward <= 1))


def test_time_outs_are_kept_apart_from_terminations(clips) -> None:
    env = make_env(clips, names=("stand",), n=2, episode_seconds=0.5, randomization=RandomizationConfig(enabled=False))
    steps = env.max_episode_length
    assert steps == 15
    for i in range(steps):
        _, _, dones, extras = env.step(torch.zeros(2, 12))
        if i < steps - 1:
            assert not dones.any()
    assert dones.all() and extras["time_outs"].all()
    assert torch.all(env.episode_length_buf == 0) and torch.all(env.last_episode_length == steps)


def test_a_fall_terminates_without_time_out(clips) -> None:
    env = make_env(clips, names=("stand",), n=2, randomization=RandomizationConfig(enabled=False))
    env.backend.set_trunk_force(torch.tensor([1]), torch.tensor([[0.0, 800.0, 0.0]]))
    terminated = torch.zeros(2, dtype=torch.bool)
    for _ in range(20):
        _, _, dones, extras = env.step(torch.zeros(2, 12))
        assert not extras["time_outs"].any()
        terminated |= dones
    assert terminated.tolist() == [False, True]


def test_standing_reference_held_by_zero_residual_earns_high_reward(clips) -> None:
    env = make_env(clips, names=("stand",), n=2, randomization=RandomizationConfig(enabled=False))
    rewards = [env.step(torch.zeros(2, 12))[1] for _ in range(30)]
    assert torch.stack(rewards[-10:]).mean() > 0.7


def test_reference_state_initialization_matches_the_clip(clips) -> None:
    env = make_env(clips, n=4, randomization=RandomizationConfig(enabled=False))
    ref = env.reference.frame()
    state = env.sim_state
    assert torch.allclose(state.joint_pos, ref.joint_pos, atol=1e-5)
    assert torch.allclose(state.root_pos[:, 2], ref.root_pos[:, 2], atol=1e-5)
    assert env.phase.unique().numel() == 4  # random start phases


def test_world_parameters_are_resampled_at_reset_within_table_1(clips) -> None:
    env = make_env(clips, names=("stand",), n=4, episode_seconds=0.1)
    before = dataclasses.replace(env.world_parameters)
    before = {k: v.clone() for k, v in vars(before).items()}
    for _ in range(env.max_episode_length):
        env.step(torch.zeros(4, 12))
    after = vars(env.world_parameters)
    cfg = RandomizationConfig()
    for name in ("gravity_scale", "mass_scale", "friction", "latency", "kp", "kd"):
        low, high = getattr(cfg, name)
        assert torch.all((after[name] >= low) & (after[name] <= high)), name
        assert not torch.equal(after[name], before[name]), name


def test_table_1_ranges_are_covered() -> None:
    params = sample_world_parameters(RandomizationConfig(), 20000, torch.Generator().manual_seed(0))
    expected = {
        "gravity_scale": (0.8, 1.2),
        "mass_scale": (0.85, 1.15),
        "friction": (0.25, 1.5),
        "latency": (0.0, 0.020),
        "kp": (45.0, 75.0),
        "kd": (0.9, 1.8),
    }
    for name, (low, high) in expected.items():
        values = getattr(params, name)
        span = high - low
        assert values.min() >= low and values.max() <= high, name
        assert values.min() < low + 0.01 * span and values.max() > high - 0.01 * span, name
    cfg = RandomizationConfig()
    assert cfg.action_noise == 0.03 and cfg.observation_noise == 0.03


def test_push_schedule_pushes_with_the_configured_force_and_duration() -> None:
    dt = 1 / 30
    schedule = PushSchedule(
        PushConfig(max_force=200.0, fixed_force=True, duration=(0.2, 0.2), interval=(0.5, 0.5)),
        3,
        dt,
        torch.Generator().manual_seed(0),
    )
    pushing = []
    for _ in range(90):  # 3 s: quiet 0.5 s, push 0.2 s, quiet 0.5 s, ...
        schedule.advance()
        norms = schedule.force.norm(dim=1)
        assert torch.all((norms == 0) | ((norms - 200.0).abs() < 1e-3))
        assert torch.all(schedule.force[:, 2] == 0)
        pushing.append(bool(norms[0] > 0))
    runs = [len(list(group)) for _, group in itertools.groupby(pushing)]
    push_runs, quiet_runs = runs[1:-1:2], runs[2:-1:2]  # complete runs only (the first is quiet)
    assert len(push_runs) >= 3 and all(n == 6 for n in push_runs)  # 0.2 s at 30 Hz
    assert all(abs(n - 15) <= 1 for n in quiet_runs)  # 0.5 s


def test_observations_are_deterministic_without_randomization(clips) -> None:
    a = make_env(clips, n=2, randomization=RandomizationConfig(enabled=False), random_start_phase=False)
    b = make_env(clips, n=2, randomization=RandomizationConfig(enabled=False), random_start_phase=False)
    actions = 0.3 * torch.ones(2, 12)
    for _ in range(5):
        oa = a.step(actions)[0]
        ob = b.step(actions)[0]
    assert torch.equal(oa.policy, ob.policy)
    # s_t holds the last three frames, newest first, with the previous action at the end of each frame.
    frame = oa.policy[:, : obs_fn.FRAME_DIM]
    assert torch.allclose(frame[:, -12:], actions)


def test_switch_reanchors_the_reference_at_the_chosen_phase(clips) -> None:
    env = make_env(clips, names=("trot", "pace"), n=2, randomization=RandomizationConfig(enabled=False))
    for _ in range(10):
        env.step(torch.zeros(2, 12))
    state = env.sim_state
    env.switch(torch.tensor([1]), torch.tensor([1]), torch.tensor([0.25]))
    assert env.gait.tolist() == [0, 1]
    assert env.phase[1].item() == pytest.approx(0.25)
    ref = env.reference.frame()
    assert torch.allclose(ref.root_pos[1, :2], state.root_pos[1, :2], atol=1e-5)
    assert torch.allclose(ref.joint_pos[1], clips["pace"].frame(torch.tensor([0.25])).joint_pos[0], atol=1e-5)
    env.step(torch.zeros(2, 12))
    assert env.phase[1].item() == pytest.approx(0.25 + env.dt * clips["pace"].phase_rate, abs=1e-5)


def test_disabled_pushes_let_a_push_under_way_run_out_and_start_no_other() -> None:
    schedule = PushSchedule(
        PushConfig(max_force=100.0, fixed_force=True, duration=(0.3, 0.3), interval=(0.2, 0.2)),
        2,
        1 / 30,
        torch.Generator().manual_seed(0),
    )
    for _ in range(8):  # quiet for 6 steps, then pushing
        schedule.advance()
    assert torch.all(schedule.force.norm(dim=1) > 0)
    schedule.enable(torch.tensor([0]), False)
    forces = []
    for _ in range(60):
        schedule.advance()
        forces.append(schedule.force.norm(dim=1))
    forces = torch.stack(forces)
    assert forces[0, 0] > 0  # the push under way goes on ...
    assert torch.all(forces[8:, 0] == 0)  # ... until its 0.3 s are over; none starts after it
    assert (forces[:, 1] > 0).sum() > 20  # world 1 is still pushed now and then
    schedule.enable(torch.tensor([0]), True)
    for _ in range(10):
        schedule.advance()
    assert schedule.force[0].norm() > 0


def test_preview_switch_shows_the_observations_a_switch_would_give_and_changes_nothing(clips) -> None:
    env = make_env(clips, names=("trot", "pace"), n=3, randomization=RandomizationConfig(enabled=False))
    for _ in range(5):
        env.step(torch.zeros(3, 12))
    before = env.get_observations().policy.clone()
    phase_before, gait_before = env.phase.clone(), env.gait.clone()
    candidates = torch.tensor([0.1, 0.6])
    ids = torch.tensor([0, 2])
    preview = env.preview_switch(ids, torch.tensor([1, 1]), candidates)
    assert len(preview) == 4
    assert torch.equal(env.get_observations().policy, before)
    assert torch.equal(env.phase, phase_before) and torch.equal(env.gait, gait_before)
    env.switch(torch.tensor([2]), torch.tensor([1]), torch.tensor([0.6]))
    after = env.get_observations()
    for key in ("policy", "privileged"):  # world 2 at the second candidate: rows are world-major
        assert torch.allclose(getattr(preview, key)[3], getattr(after, key)[2], atol=1e-5)
    assert not torch.allclose(preview.policy[2], preview.policy[3])


def test_observation_layout_is_what_the_shipped_policies_were_trained_on(clips) -> None:
    # Library entries store layout() and are refused on load when it is none of these: a change means retraining.
    old = {
        "frame": ["joint_pos:12", "projected_gravity:3", "ang_vel_trunk:3", "foot_contact:4", "prev_action:12"],
        "history": 3,
        "reference_offsets": [1, 2, 10, 30],
        "reference_frame": ["joint_pos:12", "root_height:1", "forward_speed:1"],
        "actor_dim": 158,
        "privileged_dim": 14,
    }
    assert obs_fn.layout(obs_fn.ObservationConfig(heading=False)) == old  # gaitlib 0.1's libraries
    assert obs_fn.layout() == old | {"actor_dim": 159, "heading": ["heading_error:1"]}
    assert obs_fn.observation_config(old) == obs_fn.ObservationConfig(heading=False)
    assert obs_fn.observation_config(old | {"actor_dim": 160}) is None
    # The critic sees kp in units of the default stiffness and the push in units of 100 N, at the declared columns.
    env = make_env(clips, n=2, pushes=PushConfig(max_force=150.0, fixed_force=True, interval=(0.03, 0.04)))
    for _ in range(3):
        privileged = env.step(torch.zeros(2, 12))[0].privileged
    columns = itertools.accumulate([0, *(f.width for f in obs_fn.PRIVILEGED)])
    where = {f.name: slice(a, a + f.width) for f, a in zip(obs_fn.PRIVILEGED, columns, strict=False)}
    assert torch.allclose(privileged[:, where["kp"]].squeeze(1), env.world_parameters.kp / 60.0)
    assert torch.allclose(privileged[:, where["push_force"]] * 100.0, env.push_force)
    assert torch.allclose(env.push_force.norm(dim=1), torch.full((2,), 150.0))


def _still(delay: tuple[int, int]) -> RandomizationConfig:
    """Randomization on, but every range a single value and no noise: only the action delay acts."""
    nominal = sample_world_parameters(RandomizationConfig(enabled=False), 1, torch.Generator())
    return RandomizationConfig(
        gravity_scale=(1.0, 1.0), action_noise=0.0, observation_noise=0.0, mass_scale=(1.0, 1.0),
        friction=(nominal.friction.item(),) * 2, latency=(0.0, 0.0), kp=(nominal.kp.item(),) * 2,
        kd=(nominal.kd.item(),) * 2, action_delay_steps=delay,
    )


def test_the_actor_sees_its_heading_error(clips) -> None:
    """Robots turned away from the reference by +0.4 and -0.2 rad read heading errors of -0.4 and +0.2 rad as the
    last value; without the option the observation is the same less that value (gaitlib 0.1's layout)."""
    envs = [
        make_env(clips, ("stand",), n=2, random_start_phase=False, randomization=RandomizationConfig(enabled=False),
                 observation=obs_fn.ObservationConfig(heading=heading))
        for heading in (True, False)
    ]
    for env in envs:
        start = env.reference.frame()
        start.root_quat = quat_multiply(quat_from_yaw(torch.tensor([0.4, -0.2])), start.root_quat)
        env.backend.reset(torch.arange(2), start)
    with_heading, without = (env.step(torch.zeros(2, 12))[0].policy for env in envs)
    assert with_heading.shape == (2, 159) and without.shape == (2, 158)
    torch.testing.assert_close(with_heading[:, -1], torch.tensor([-0.4, 0.2]), atol=0.01, rtol=0)
    torch.testing.assert_close(with_heading[:, :-1], without)


def test_a_delayed_action_reaches_the_servos_a_control_step_later(clips) -> None:
    env = make_env(clips, ("trot",), n=2, random_start_phase=False, randomization=_still((0, 1)))
    env.world_parameters.action_delay[:] = torch.tensor([0.0, 1.0])  # world 0 acts at once, world 1 a step late
    start_pose = env.reference.frame().joint_pos
    sent = []
    set_targets = env.backend.set_pd_targets
    env.backend.set_pd_targets = lambda targets: (sent.append(targets.clone()), set_targets(targets))[1]
    for _ in range(3):
        env.step(torch.ones(2, 12))
    torch.testing.assert_close(sent[0][1], start_pose[1])  # nothing reached world 1's servos yet: it holds the start
    for step in (1, 2):  # then each target world 0 got, one step late (both worlds run the same reference)
        torch.testing.assert_close(sent[step][1], sent[step - 1][0])


def test_the_push_curriculum_grows_to_its_largest_push() -> None:
    preset = get_preset("cpu")
    ramp = preset.push_ramp_iterations(1500)
    assert ramp == 600  # the first 40% of a run
    assert [preset.push_limit(i, 1500) for i in (0, ramp // 2, ramp, 1499)] == pytest.approx(
        [0.0, preset.push_max / 2, preset.push_max, preset.push_max]
    )
    schedule = PushSchedule(PushConfig(max_force=0.0, fixed_force=True, interval=(0.03, 0.04)), 3, 1 / 30,
                            torch.Generator().manual_seed(0))
    schedule.set_max_force(120.0)
    for _ in range(3):
        schedule.advance()
    torch.testing.assert_close(schedule.force.norm(dim=1), torch.full((3,), 120.0))


def test_a_fall_in_evaluation_is_a_tilt_not_a_turn() -> None:
    level = torch.tensor([[1.0, 0.0, 0.0, 0.0]])
    turned = quat_from_yaw(torch.tensor([2.0]))  # 115 degrees about z
    rolled = torch.tensor([[math.cos(0.9), math.sin(0.9), 0.0, 0.0]])  # 103 degrees about x
    assert orientation_lost(turned, level, max_error=math.pi / 2, heading=True)
    assert not orientation_lost(turned, level, max_error=math.pi / 2, heading=False)
    for heading in (True, False):
        assert orientation_lost(rolled, level, max_error=math.pi / 2, heading=heading)
        assert not orientation_lost(level, turned, max_error=math.pi / 2, heading=False)


def _same_reading(together: torch.Tensor, alone: torch.Tensor, name: str) -> None:
    """Rows read in one batch are the rows read alone: contacts exactly, numbers to float32's relative 1e-6 (1e-6 m,
    rad or m/s near zero). Not to the bit: a batch and its rows alone fall differently on torch's vector loops and
    their scalar tails, whose split follows the processor's vector width (AVX2 or AVX-512)."""
    assert together.dtype == alone.dtype and together.shape == alone.shape, name
    torch.testing.assert_close(together, alone, rtol=1e-6, atol=1e-6, msg=lambda problem: f"{name}: {problem}")


def test_references_read_together_are_the_references_read_one_by_one() -> None:
    from gaitlib.envs.reference import ReferenceTracker

    clips = [clip_from_description(get_gait(name)) for name in ("pace", "stand", "trot")]
    tracker = ReferenceTracker(clips, 7, torch.device("cpu"))
    generator = torch.Generator().manual_seed(3)
    root_quat = quat_from_yaw(torch.rand(7, generator=generator) * 6.0 - 3.0)
    root_pos = torch.rand(7, 3, generator=generator)
    tracker.start(torch.arange(7), torch.tensor([0, 1, 2, 2, 0, 1, 2]), torch.rand(7, generator=generator) * 3.0,
                  root_pos, root_quat)
    offsets = [0.0, 1 / 30, 2 / 30, 10 / 30, 1.0]
    for together, alone in zip(tracker.frames(offsets), [tracker.frame(dt) for dt in offsets], strict=True):
        for name in alone.__dataclass_fields__:
            _same_reading(getattr(together, name), getattr(alone, name), name)


def test_clips_read_in_one_bank_are_each_clip_read_alone() -> None:
    from gaitlib.envs.reference import ReferenceTracker
    from gaitlib.gaits.clip import ReferenceClip, clip_bank

    walk = clip_from_description(get_gait("walk"))
    held = ReferenceClip.from_frames(name="held", frame_duration=walk.frame_duration, loop=False,
                                     root_pos=walk.root_pos, root_quat=walk.root_quat, joint_pos=walk.joint_pos,
                                     contact=walk.contact)  # not looping: its phase clamps
    clips = (clip_from_description(get_gait("trot_left")), walk, held, clip_from_description(get_gait("turn_left")))
    assert [clip.cycle_yaw != 0.0 for clip in clips] == [True, False, False, True]
    generator = torch.Generator().manual_seed(5)
    gait = torch.randint(0, len(clips), (64,), generator=generator)
    phase = torch.rand(64, generator=generator) * 8.0 - 3.0  # whole cycles on both sides of 0
    together = clip_bank(clips, torch.device("cpu")).frame(gait, phase)
    for g, clip in enumerate(clips):
        rows = (gait == g).nonzero().squeeze(1)
        alone = clip.frame(phase[rows])
        for name in alone.__dataclass_fields__:
            _same_reading(getattr(together, name)[rows], getattr(alone, name), f"{clip.name}.{name}")

    tracker = ReferenceTracker(list(clips), 64, torch.device("cpu"))
    tracker.gait[:], tracker.phase[:] = gait, phase
    _same_reading(tracker.joint_pos(1 / 30), tracker.frame(1 / 30).joint_pos, "joint_pos")
