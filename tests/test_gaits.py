"""Tests of gaitlib.gaits: A1 leg kinematics, gait descriptions and their registry, reference clips, motion files."""

from __future__ import annotations

import copy
import dataclasses
import json
import math

import mujoco
import numpy as np
import pytest
import torch

from gaitlib.errors import GaitError, UnknownNameError
from gaitlib.gaits import (
    GaitDescription,
    clip_from_description,
    contact_schedule,
    foot_trajectory,
    forward_kinematics,
    gait_names,
    get_gait,
    inverse_kinematics,
    leg_forward_kinematics,
    leg_inverse_kinematics,
    load_gait_file,
    load_motion_file,
    register_gait,
    registry,
    save_motion_file,
    synthesis,
    trunk_height,
    trunk_sway,
)
from gaitlib.robots.a1 import constants as c

FR, FL, RR, RL = range(4)
SHIPPED = ("bound", "pace", "pronk", "stand", "trot", "walk")


def _gait(name: str) -> GaitDescription:
    """A registered gait; ``NAME+sway`` that gait with its trunk swaying, ``NAME-sway`` with it straight."""
    for suffix, sway in (("+sway", True), ("-sway", False)):
        if name.endswith(suffix):
            return dataclasses.replace(get_gait(name.removesuffix(suffix)), trunk_sway=sway)
    return get_gait(name)


def _phases(start: float, stop: float, count: int) -> torch.Tensor:
    return torch.linspace(start, stop, count, dtype=torch.float64)


# --- kinematics -------------------------------------------------------------------------------------------------


def test_forward_kinematics_hand_computed() -> None:
    straight = forward_kinematics(np.zeros(12))
    # Leg hanging straight down: hip offset, thigh offset sideways, two 0.2 m links down.
    np.testing.assert_allclose(straight[FR], [0.183, -0.047 - 0.08505, -0.4], atol=1e-12)
    np.testing.assert_allclose(straight[RL], [-0.183, 0.047 + 0.08505, -0.4], atol=1e-12)
    # Default pose (0, 0.9, -1.8): the foot is straight below the thigh joint, 2 * 0.2 * cos(0.9) down.
    default = forward_kinematics(np.array(c.DEFAULT_JOINT_POS))
    np.testing.assert_allclose(default[:, 0], [0.183, 0.183, -0.183, -0.183], atol=1e-12)
    np.testing.assert_allclose(default[:, 2], -0.4 * math.cos(0.9), atol=1e-12)
    assert -default[0, 2] + c.FOOT_RADIUS == pytest.approx(c.STANDING_HEIGHT, abs=1e-4)
    # Abduction by +90 degrees swings the right leg's foot from below the hip to the side, up to the hip's height.
    abducted = leg_forward_kinematics(np.array([math.pi / 2, 0.0, 0.0]), leg="FR")
    np.testing.assert_allclose(abducted, [0.183, -0.047 + 0.4, -0.08505], atol=1e-12)


def test_forward_kinematics_matches_mujoco() -> None:
    model = mujoco.MjModel.from_xml_path(str(c.MJCF_PATH))
    data = mujoco.MjData(model)
    rng = np.random.default_rng(0)
    joint_pos = rng.uniform(c.JOINT_LOWER, c.JOINT_UPPER, size=(20, 12))
    ours = forward_kinematics(joint_pos)
    for sample, angles in enumerate(joint_pos):
        data.qpos[:] = 0.0
        data.qpos[3] = 1.0  # trunk at the origin with identity orientation: trunk frame = world frame
        for name, angle in zip(c.JOINT_NAMES, angles, strict=True):
            data.qpos[model.jnt_qposadr[model.joint(name).id]] = angle
        mujoco.mj_kinematics(model, data)
        for leg, foot in enumerate(c.FOOT_NAMES):
            np.testing.assert_allclose(ours[sample, leg], data.site(foot).xpos, atol=1e-6)
            one_leg = leg_forward_kinematics(angles[3 * leg : 3 * leg + 3], leg=c.LEG_NAMES[leg])
            np.testing.assert_allclose(one_leg, ours[sample, leg], atol=1e-12)


def test_inverse_kinematics_round_trip() -> None:
    rng = np.random.default_rng(1)
    angles = np.stack(
        [
            rng.uniform(*c.ABDUCTION_LIMITS, size=(500, 4)),
            rng.uniform(-1.0, 2.5, size=(500, 4)),
            rng.uniform(*c.CALF_LIMITS, size=(500, 4)),
        ],
        axis=-1,
    )
    # The IK serves feet below the hip (every standing and walking pose); keep those samples.
    below = (np.cos(angles[..., 1]) + np.cos(angles[..., 1] + angles[..., 2]) > 1e-3).all(axis=-1)
    joint_pos = angles[below].reshape(-1, 12)
    assert len(joint_pos) > 100
    np.testing.assert_allclose(inverse_kinematics(forward_kinematics(joint_pos)), joint_pos, atol=1e-9)
    one_leg = leg_inverse_kinematics(forward_kinematics(joint_pos)[:, RL], leg="RL")
    np.testing.assert_allclose(one_leg, joint_pos[:, 9:12], atol=1e-9)
    with pytest.raises(UnknownNameError, match="unknown leg 'XX'"):
        leg_inverse_kinematics(np.zeros(3), leg="XX")


# --- descriptions and registry ----------------------------------------------------------------------------------


def test_registry_ships_gaits_and_rejects_unknown_names() -> None:
    assert set(SHIPPED) <= set(gait_names())
    trot = get_gait("trot")
    assert trot.stride_length == pytest.approx(trot.forward_speed / trot.stride_frequency)
    assert trot.period == pytest.approx(1.0 / trot.stride_frequency)
    with pytest.raises(UnknownNameError, match=r"unknown gait 'moonwalk'.*trot"):
        get_gait("moonwalk")


def test_new_gait_from_a_toml_file(tmp_path, monkeypatch) -> None:
    monkeypatch.setattr(registry, "_GAITS", copy.deepcopy(registry._GAITS))
    path = tmp_path / "amble.toml"
    path.write_text(
        "duty_factor = 0.7\nstride_frequency = 1.5\nforward_speed = 0.3\nswing_height = 0.05\n"
        "body_height = 0.25\nfoot_lateral_offset = 0.02\ntrunk_sway = true\n"
        "[phase_offsets]\nFR = 0.0\nFL = 0.5\nRR = 0.25\nRL = 0.75\n"
    )
    desc = load_gait_file(path)
    assert desc.name == "amble" and desc.trunk_sway  # the name from the file name
    register_gait(desc)
    assert "amble" in gait_names() and get_gait("amble") is desc
    clip = clip_from_description(get_gait("amble"))
    assert clip.period == pytest.approx(1.0 / 1.5)
    frame = clip.frame(torch.tensor([0.0, 0.8]))
    # Leg phases (phase - offset) mod 1 against duty 0.7: at phase 0 only RR (0.75) swings, at 0.8 only FR (0.8).
    assert frame.contact.tolist() == [[True, True, False, True], [False, True, True, True]]
    # Feet sit 2 cm outward of their thigh joints, on the straight path: against the sway in the trunk frame.
    lateral = np.array([-0.15205, 0.15205, -0.15205, 0.15205]) - frame.root_pos[0, 1].item()
    np.testing.assert_allclose(frame.foot_pos_local[0, :, 1].numpy(), lateral, atol=1e-5)


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("duty_factor = = 0.5", "cannot read gait file"),
        ("duty_factor = 0.5\n", "missing key"),
        (
            "duty_factr = 0.5\nstride_frequency = 2.0\nforward_speed = 0.5\nswing_height = 0.06\nbody_height = 0.26\n",
            "unknown key",
        ),
        (
            "duty_factor = 1.5\nstride_frequency = 2.0\nforward_speed = 0.5\nswing_height = 0.06\nbody_height = 0.26\n"
            "[phase_offsets]\nFR = 0.0\nFL = 0.5\nRR = 0.5\nRL = 0.0\n",
            "duty_factor must be in",
        ),
        (
            "duty_factor = 0.5\nstride_frequency = 2.0\nforward_speed = 0.5\nswing_height = 0.06\nbody_height = 0.26\n"
            "[phase_offsets]\nFR = 0.0\nFL = 0.5\nRR = 0.5\n",
            "phase_offsets",
        ),
        (
            "duty_factor = 0.5\nstride_frequency = 2.0\nforward_speed = 0.5\nswing_height = 0.06\nbody_height = 0.26\n"
            "[phase_offsets]\nFR = 0.0\nFL = 0.5\nRR = 1.5\nRL = 0.0\n",
            "phase offset of RR",
        ),
        (
            "duty_factor = 0.5\nstride_frequency = 2.0\nforward_speed = 0.5\nswing_height = 0.06\nbody_height = 0.26\n"
            "trunk_sway = 1\n[phase_offsets]\nFR = 0.0\nFL = 0.5\nRR = 0.5\nRL = 0.0\n",
            "trunk_sway must be true or false",
        ),
        (
            "duty_factor = 0.5\nstride_frequency = 2.0\nforward_speed = 0.5\nswing_height = 0.06\nbody_height = 0.26\n"
            "trunk_bounce = \"yes\"\n[phase_offsets]\nFR = 0.0\nFL = 0.5\nRR = 0.5\nRL = 0.0\n",
            "trunk_bounce must be true or false",
        ),
    ],
)
def test_malformed_gait_file_gives_a_one_line_error(tmp_path, text: str, problem: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(GaitError, match=problem) as caught:
        load_gait_file(path)
    assert "bad.toml" in str(caught.value) and "\n" not in str(caught.value)


def test_impossible_gaits_are_rejected() -> None:
    trot = get_gait("trot")
    with pytest.raises(GaitError, match="cannot move"):
        dataclasses.replace(trot, duty_factor=1.0)
    too_tall = dataclasses.replace(trot, name="tall", body_height=0.45)
    with pytest.raises(GaitError, match="out of the A1's reach"):
        clip_from_description(too_tall)


# --- reference clips from descriptions --------------------------------------------------------------------------


@pytest.mark.parametrize("name", [*SHIPPED, "pace-sway"])
def test_clip_is_periodic_and_inside_joint_limits(name: str) -> None:
    desc = _gait(name)
    clip = clip_from_description(desc)
    assert clip.period == pytest.approx(desc.period)
    assert clip.phase_rate == pytest.approx(desc.stride_frequency)
    assert (clip.joint_pos >= np.array(c.JOINT_LOWER)).all() and (clip.joint_pos <= np.array(c.JOINT_UPPER)).all()
    start, end = clip.frame(torch.tensor([0.0])), clip.frame(torch.tensor([1.0]))
    torch.testing.assert_close(end.joint_pos[0], start.joint_pos[0])
    torch.testing.assert_close(end.joint_vel[0], start.joint_vel[0])
    # The trunk advances one stride per cycle.
    torch.testing.assert_close(
        end.root_pos[0] - start.root_pos[0], torch.tensor([desc.stride_length, 0.0, 0.0]), atol=1e-6, rtol=0
    )
    # Seamless across the wrap: successive samples over two cycles move no more than the joint velocities allow.
    phase = _phases(0.0, 2.0, 4001)
    frames = clip.frame(phase)
    step = (phase[1] - phase[0]).item() * desc.period
    jumps = (frames.joint_pos[1:] - frames.joint_pos[:-1]).abs()
    assert (jumps <= step * frames.joint_vel.abs().max() * 1.05 + 1e-5).all()
    # Interpolated joint velocities are the derivative of the interpolated joint angles, to within how much the
    # velocity changes over one stored frame (the clip's velocities are central differences of its frames).
    derivative = (frames.joint_pos[2:] - frames.joint_pos[:-2]) / (2 * step)
    accel = ((frames.joint_vel[2:] - frames.joint_vel[:-2]) / (2 * step)).abs().max().item()
    assert (derivative - frames.joint_vel[1:-1]).abs().max() <= clip.frame_duration * accel + 1e-6


@pytest.mark.parametrize("name", ["trot", "pace", "bound", "walk", "pace-sway"])
def test_clip_feet_follow_the_described_trajectories(name: str) -> None:
    desc = _gait(name)
    clip = clip_from_description(desc)
    phase = _phases(0.0, 1.0, 997)[:-1]
    frames = clip.frame(phase)
    feet = forward_kinematics(frames.joint_pos.double().numpy())
    np.testing.assert_allclose(feet, foot_trajectory(desc, phase.numpy()), atol=1e-4)
    np.testing.assert_allclose(frames.foot_pos_local.numpy(), feet, atol=1e-4)
    grid = np.arange(clip.num_frames) / (clip.num_frames - 1)
    np.testing.assert_array_equal(clip.contact, contact_schedule(desc, grid))
    for leg in range(4):
        offset = desc.phase_offsets[leg]
        # Stance: the foot stays put in the world, on the ground.
        stance = clip.frame(_phases(offset + 0.01, offset + desc.duty_factor - 0.01, 200))
        world = stance.root_pos[:, None, :] + torch.from_numpy(
            forward_kinematics(stance.joint_pos.double().numpy())
        ).float()
        spread = world[:, leg].max(dim=0).values - world[:, leg].min(dim=0).values
        assert spread.max() < 1e-4, (leg, spread)
        assert world[:, leg, 2].sub(c.FOOT_RADIUS).abs().max() < 1e-3
        assert stance.contact[:, leg].all()
        # Swing: the foot lifts to the swing height at mid-swing and lands one stride further on.
        lift_off = offset + desc.duty_factor
        swing = clip.frame(_phases(lift_off, offset + 1.0, 201))
        swing_world = swing.foot_pos_world[:, leg]
        assert swing_world[:, 2].max() - c.FOOT_RADIUS == pytest.approx(desc.swing_height, abs=1e-3)
        assert swing_world[100, 2] - c.FOOT_RADIUS == pytest.approx(desc.swing_height, abs=1e-3)
        assert swing_world[-1, 0] - swing_world[0, 0] == pytest.approx(desc.stride_length, abs=1e-3)
        assert not swing.contact[3:-3, leg].any()


def test_trunk_sway_is_the_periodic_inverted_pendulum_over_the_stance_feet() -> None:
    # A pace of duty 0.5: the support line alternates between y = -b and +b, b = hip y + thigh offset. The periodic
    # solution of y'' = w^2 (y - p) is y + b = C cosh(w (t - T/4)) over the right side's half cycle, y(0) = 0:
    # the trunk reaches b (1 - 1 / cosh(w T / 4)) toward the feet at mid-stance (Kajita et al. 2001).
    pace = dataclasses.replace(get_gait("pace"), trunk_sway=True, duty_factor=0.5)
    b, omega = 0.047 + 0.08505, math.sqrt(9.81 / pace.body_height)
    reach = b * (1 - 1 / math.cosh(omega * pace.period / 4))
    phase = np.linspace(0.0, 1.0, 2001)
    sway = trunk_sway(pace, phase)
    assert sway.min() == pytest.approx(-reach, abs=1e-5) and sway.max() == pytest.approx(reach, abs=1e-5)
    assert phase[sway.argmin()] == pytest.approx(0.25, abs=0.002)  # toward the right feet (FR, RR) mid-stance
    assert abs(trunk_sway(pace, np.array([0.0, 0.5]))).max() < 1e-4  # over the centre at each side change
    clip = clip_from_description(pace)
    frames = clip.frame(torch.from_numpy(phase[:-1]))
    np.testing.assert_allclose(frames.root_pos[:, 1].numpy(), sway[:-1], atol=1e-5)
    # The shipped pace sways 4.4 cm each way; straight without the option, and straight with it where the support
    # line passes under the trunk.
    assert abs(trunk_sway(get_gait("pace"), phase)).max() == pytest.approx(0.044, abs=0.001)
    assert not trunk_sway(_gait("pace-sway"), phase).any()
    for name in ("bound", "pronk", "stand"):
        assert abs(trunk_sway(_gait(f"{name}+sway"), phase)).max() < 1e-9, name


def test_a_trot_sways_over_where_its_diagonal_line_runs() -> None:
    # The diagonal pair's line crosses under the trunk at mid-stance and lies to one side at touchdown (the front
    # foot d/2 ahead of its hip), the other side at lift-off: the pendulum's push is odd about mid-stance, so is the
    # sway, which crosses the straight path at mid-stance (phases 0.2, 0.7) and reaches 1.4 cm each way.
    trot = _gait("trot+sway")
    sway = trunk_sway(trot, np.linspace(0.0, 1.0, 2001))
    assert abs(sway).max() == pytest.approx(0.0136, abs=0.0005)
    assert abs(trunk_sway(trot, np.array([0.2, 0.7]))).max() < 2e-4
    after = np.linspace(0.0, 0.2, 9)
    np.testing.assert_allclose(trunk_sway(trot, 0.2 + after), -trunk_sway(trot, 0.2 - after), atol=2e-4)
    # The line's sideways point at touchdown, by hand: FR at x = 0.183 + d/2, y = -b; RL at -0.183 + d/2, +b.
    d, b = trot.duty_factor * trot.stride_length, 0.047 + 0.08505
    along = (0.183 + d / 2) / 0.366
    stance = contact_schedule(trot, np.array([1e-6]))
    assert synthesis._support_centre(trot, np.array([1e-6]), stance)[0] == pytest.approx(-b + along * 2 * b, abs=1e-4)


def test_a_bouncing_trunk_falls_freely_in_flight_and_is_thrown_up_by_its_feet() -> None:
    pronk = get_gait("pronk")
    assert pronk.trunk_bounce and not any(get_gait(name).trunk_bounce for name in SHIPPED if name != "pronk")
    # On the 512-point grid the height is integrated on: second differences are its vertical acceleration.
    phase = np.arange(513) / 512
    height = trunk_height(pronk, phase)
    step = pronk.period / 512
    accel = (height[2:] - 2 * height[1:-1] + height[:-2]) / step**2
    inner = phase[1:-1]
    flight = ~contact_schedule(pronk, inner).any(-1)
    np.testing.assert_allclose(accel[flight], -9.81, rtol=0.02)  # free fall, all 60% of the cycle in the air
    # In stance the four feet push together as one half-sine carrying the weight over the whole cycle: at
    # mid-stance its peak, g pi / (2 duty), less gravity.
    mid = np.argmin(abs(inner - pronk.duty_factor / 2))
    assert accel[mid] == pytest.approx(9.81 * (math.pi / (2 * pronk.duty_factor) - 1), rel=0.02)
    assert height[:-1].mean() == pytest.approx(pronk.body_height, abs=1e-9)
    assert np.ptp(height) == pytest.approx(0.059, abs=0.001)
    assert height.argmax() == pytest.approx(0.7 * 512, abs=2)  # the top of the flight, halfway through it
    # Level without the option; a stand with it does not move (its feet never lift).
    level = trunk_height(dataclasses.replace(pronk, trunk_bounce=False), phase)
    assert (level == pronk.body_height).all()
    assert (trunk_height(dataclasses.replace(get_gait("stand"), trunk_bounce=True), phase) == 0.26).all()
    # The clip carries it: the trunk rises and falls, the stance feet stay on the ground, the swing lifts them
    # swing_height above the ground (not the trunk).
    frames = clip_from_description(pronk).frame(torch.from_numpy(phase[:-1]))
    np.testing.assert_allclose(frames.root_pos[:, 2].numpy(), height[:-1], atol=5e-5)
    feet_z = frames.foot_pos_world[..., 2].numpy()
    stance = contact_schedule(pronk, phase[:-1])
    np.testing.assert_allclose(feet_z[stance], c.FOOT_RADIUS, atol=5e-5)
    assert feet_z.max() - c.FOOT_RADIUS == pytest.approx(pronk.swing_height, abs=1e-3)


def test_trot_foot_positions_hand_computed() -> None:
    # Trot: duty 0.6, stride 0.25 m, body 0.26 m. At phase 0 FR touches down at the front of its stance stroke:
    # x = hip x + 0.6 * 0.25 / 2, z = foot radius - body height.
    trot = get_gait("trot")
    frame = clip_from_description(trot).frame(torch.tensor([0.0]))
    expected_x = 0.183 + trot.duty_factor * trot.stride_length / 2
    np.testing.assert_allclose(
        frame.foot_pos_local[0, FR].numpy(), [expected_x, -0.13205, c.FOOT_RADIUS - trot.body_height], atol=1e-5
    )
    assert frame.root_height.item() == pytest.approx(trot.body_height)
    torch.testing.assert_close(frame.root_lin_vel[0], torch.tensor([trot.forward_speed, 0.0, 0.0]))


@pytest.mark.parametrize(
    ("name", "together", "apart", "flight"),
    [
        ("trot", [(FR, RL), (FL, RR)], [(FR, FL), (FR, RR), (FL, RL), (RR, RL)], 0.2),
        ("pace", [(FR, RR), (FL, RL)], [(FR, FL), (FR, RL), (FL, RR), (RR, RL)], 0.0),
        ("trot_slow", [(FR, RL), (FL, RR)], [(FR, FL), (FR, RR), (FL, RL), (RR, RL)], 0.0),
        ("pace_slow", [(FR, RR), (FL, RL)], [(FR, FL), (FR, RL), (FL, RR), (RR, RL)], 0.0),
    ],
)
def test_leg_pairs_move_together(name: str, together, apart, flight: float) -> None:
    clip = clip_from_description(get_gait(name))
    contact = clip.frame(_phases(0.0, 1.0, 1001)).contact
    for a, b in together:
        assert torch.equal(contact[:, a], contact[:, b]), (a, b)
    for a, b in apart:
        # One lands as the other lifts (half a cycle apart), or after a flight where all four feet are up.
        assert (contact[:, a] != contact[:, b]).float().mean() > 0.5
    # The fraction of the cycle with no foot down: twice (0.5 - duty) for a trot of duty 0.4, none for the others.
    assert (~contact.any(dim=1)).float().mean().item() == pytest.approx(flight, abs=0.01)
    # The second pair repeats the first half a cycle later (up to one frame of rounding at the switches).
    shifted = clip.frame(_phases(0.5, 1.5, 1001)).contact
    assert (shifted[:, together[1][0]] != contact[:, together[0][0]]).float().mean() < 0.01


def test_trot_and_pace_run_at_the_timing_of_the_papers_clips() -> None:
    """dog_trot and dog_pace of motion_imitation at A1 scale: trot 0.533 s cycles at 1.45 m/s with 33-83 ms of
    flight at each diagonal change, pace 0.633 s cycles at 0.90 m/s with none."""
    trot, pace = get_gait("trot"), get_gait("pace")
    assert trot.period == pytest.approx(0.533, abs=0.001) and trot.forward_speed == pytest.approx(1.45)
    assert 0.033 <= (0.5 - trot.duty_factor) * trot.period <= 0.083
    assert pace.period == pytest.approx(0.633, abs=0.001) and pace.forward_speed == pytest.approx(0.90)
    assert 0.5 < pace.duty_factor <= 0.7
    for slow in ("trot_slow", "pace_slow"):  # the first library's gaits, kept under their own names
        assert get_gait(slow).forward_speed == pytest.approx(0.5)


def test_a_gait_name_may_not_hold_the_pair_separator() -> None:
    with pytest.raises(GaitError, match="may not hold"):
        GaitDescription(**(dataclasses.asdict(get_gait("trot")) | {"name": "trot-fast"}))


def test_stand_has_all_feet_down_and_no_motion() -> None:
    stand = get_gait("stand")
    frames = clip_from_description(stand).frame(_phases(-1.0, 3.0, 401))
    assert frames.contact.all()
    assert frames.joint_vel.abs().max() == 0.0
    assert frames.root_lin_vel.abs().max() == 0.0 and frames.root_ang_vel.abs().max() == 0.0
    assert (frames.joint_pos - frames.joint_pos[0]).abs().max() == 0.0
    torch.testing.assert_close(frames.root_height, torch.full((401,), stand.body_height))
    torch.testing.assert_close(frames.root_pos[:, :2], torch.zeros(401, 2))


def test_clip_frame_shapes() -> None:
    clip = clip_from_description(get_gait("pace"))
    frame = clip.frame(torch.rand(7))
    shapes = {
        "root_pos": (7, 3),
        "root_quat": (7, 4),
        "root_lin_vel": (7, 3),
        "root_ang_vel": (7, 3),
        "joint_pos": (7, 12),
        "joint_vel": (7, 12),
        "foot_pos_local": (7, 4, 3),
        "foot_pos_world": (7, 4, 3),
        "contact": (7, 4),
        "root_height": (7,),
    }
    for name, shape in shapes.items():
        assert tuple(getattr(frame, name).shape) == shape, name
    assert frame.contact.dtype == torch.bool and frame.joint_pos.dtype == torch.float32
    torch.testing.assert_close(frame.root_quat, torch.tensor([[1.0, 0.0, 0.0, 0.0]]).expand(7, 4))


# --- motion_imitation files -------------------------------------------------------------------------------------


def test_motion_file_round_trip(tmp_path) -> None:
    original = clip_from_description(get_gait("pace"), frame_rate=120.0)
    path = tmp_path / "pace_clip.txt"
    save_motion_file(original, path)
    loaded = load_motion_file(path)
    assert loaded.name == "pace_clip" and loaded.loop
    assert loaded.period == pytest.approx(original.period)
    for field in ("root_pos", "root_quat", "root_lin_vel", "root_ang_vel", "joint_pos", "joint_vel",
                  "foot_pos_local", "foot_pos_world", "cycle_displacement"):
        np.testing.assert_allclose(getattr(loaded, field), getattr(original, field), atol=1e-9, err_msg=field)
    # Contacts are estimated from foot heights: every planned stance frame is found, no high foot is called down.
    assert loaded.contact[original.contact].all()
    high = original.foot_pos_world[..., 2] > c.FOOT_RADIUS + 0.011
    assert not loaded.contact[high].any()


def test_motion_file_hand_computed(tmp_path) -> None:
    # Three frames 0.1 s apart: the trunk yaws at 1 rad/s and the FR thigh opens at 2 rad/s; "Clamp" plays once.
    frames = []
    for k in range(3):
        yaw = 0.1 * k
        joints = list(c.DEFAULT_JOINT_POS)
        joints[1] += 0.2 * k
        frames.append([0.05 * k, 0.0, 0.27, 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2), *joints])
    path = tmp_path / "turn.txt"
    path.write_text(json.dumps({"LoopMode": "Clamp", "FrameDuration": 0.1, "Frames": frames}))
    clip = load_motion_file(path)
    assert not clip.loop and clip.period == pytest.approx(0.2)
    np.testing.assert_allclose(clip.root_quat[2], [math.cos(0.1), 0.0, 0.0, math.sin(0.1)], atol=1e-12)
    np.testing.assert_allclose(clip.root_ang_vel, [[0.0, 0.0, 1.0]] * 3, atol=1e-9)
    np.testing.assert_allclose(clip.root_lin_vel, [[0.5, 0.0, 0.0]] * 3, atol=1e-9)
    np.testing.assert_allclose(clip.joint_vel[:, 1], 2.0, atol=1e-9)
    # Past the end the clip holds its last frame.
    late = clip.frame(torch.tensor([1.7]))
    np.testing.assert_allclose(late.joint_pos[0].numpy(), clip.joint_pos[2], atol=1e-6)
    np.testing.assert_allclose(late.root_pos[0].numpy(), [0.1, 0.0, 0.27], atol=1e-6)


@pytest.mark.parametrize(
    ("content", "problem"),
    [
        ("{not json", "cannot read motion file"),
        ("[1, 2, 3]", "JSON object"),
        ('{"LoopMode": "Wrap", "FrameDuration": 0.01}', "missing key"),
        ('{"LoopMode": "Bounce", "FrameDuration": 0.01, "Frames": []}', "LoopMode"),
        ('{"LoopMode": "Wrap", "FrameDuration": 0, "Frames": []}', "FrameDuration"),
        ('{"LoopMode": "Wrap", "FrameDuration": 0.01, "Frames": [[0, 0, 0.27]]}', "at least 3 frames"),
        ('{"LoopMode": "Clamp", "FrameDuration": 0.01, "Frames": [FRAME, FRAME_SHORT]}', "frame 1 must be 19"),
        ('{"LoopMode": "Clamp", "FrameDuration": 0.01, "Frames": [FRAME, FRAME_TEXT]}', "frame 1 must be 19"),
        ('{"LoopMode": "Clamp", "FrameDuration": 0.01, "Frames": [FRAME, FRAME_ZERO_QUAT]}', "zero root quaternion"),
    ],
)
def test_malformed_motion_file_gives_a_one_line_error(tmp_path, content: str, problem: str) -> None:
    frame = [0.0, 0.0, 0.27, 0.0, 0.0, 0.0, 1.0, *c.DEFAULT_JOINT_POS]
    content = (
        content.replace("FRAME_SHORT", json.dumps(frame[:-1]))
        .replace("FRAME_TEXT", json.dumps([*frame[:-1], "x"]))
        .replace("FRAME_ZERO_QUAT", json.dumps([*frame[:3], 0, 0, 0, 0, *frame[7:]]))
        .replace("FRAME", json.dumps(frame))
    )
    path = tmp_path / "broken.txt"
    path.write_text(content)
    with pytest.raises(GaitError, match=problem) as caught:
        load_motion_file(path)
    assert "broken.txt" in str(caught.value) and "\n" not in str(caught.value)
