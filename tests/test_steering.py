"""Gaits that turn, sidestep and go backward: their descriptions, references, physical check, and the imitation
environment on the real MuJoCo backend following a reference that turns over many cycles."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch
from cli_runner import gaitlib_quick

from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs import observations as obs_fn
from gaitlib.envs import rewards as rew_fn
from gaitlib.envs.randomization import RandomizationConfig
from gaitlib.errors import GaitError
from gaitlib.gaits import (
    GaitDescription,
    clip_from_description,
    get_gait,
    load_gait_file,
    load_motion_file,
    save_motion_file,
)
from gaitlib.gaits.feasibility import check_reference
from gaitlib.library import Library
from gaitlib.robots.a1 import constants as c
from gaitlib.rotations import quat_from_yaw, quat_multiply, yaw_of
from gaitlib.sim import make_backend

STEERING = {  # gait: (forward m/s, lateral m/s, yaw rad/s)
    "trot_left": (0.5, 0.0, 0.5),
    "trot_right": (0.5, 0.0, -0.5),
    "sidestep_left": (0.0, 0.3, 0.0),
    "sidestep_right": (0.0, -0.3, 0.0),
    "trot_back": (-0.5, 0.0, 0.0),
    "turn_left": (0.0, 0.0, 1.0),
}
# Every array of each straight description's clip and 101 frames read from it over nine cycles, in float32 (what the
# simulator reads), as the shipped library's references were built; written by running this file. They are compared
# to float32's relative 1e-6 (and 1e-6 of the array's scale, at least 1 m, rad or s, near zero): the last bits follow
# the processor (NumPy's and torch's SIMD kernels, AVX2 or AVX-512, and the BLAS kernel of the trunk sway's linear
# solve), a reference that moves by more is another reference.
STRAIGHT_CLIPS = Path(__file__).parent / "references" / "straight_clips.npz"
STRAIGHT_GAITS = ("bound", "pace", "pace_slow", "pronk", "stand", "trot", "trot_slow", "walk")
_CLIP_ARRAYS = ("root_pos", "root_quat", "root_lin_vel", "root_ang_vel", "joint_pos", "joint_vel", "foot_pos_local",
                "foot_pos_world", "contact", "cycle_displacement")
_RTOL = 1e-6


def _clip_arrays(clip) -> dict[str, np.ndarray]:
    """The clip's arrays (float ones in float32) and its frames at 101 phases over nine cycles, by name."""
    arrays = {}
    for name in _CLIP_ARRAYS:
        array = np.asarray(getattr(clip, name))
        arrays[name] = array.astype(np.float32) if array.dtype.kind == "f" else array
    # phases in NumPy's float64, the same on every processor (torch.linspace's last bits follow its CPU kernel, and a
    # phase one float32 step apart moves a joint velocity read by up to 1e-4)
    frame = clip.frame(torch.from_numpy(np.linspace(-1.3, 7.7, 101, dtype=np.float32)))
    for name in frame.__dataclass_fields__:
        arrays[f"frame.{name}"] = getattr(frame, name).numpy()
    return arrays


def _wrap(angle: torch.Tensor) -> torch.Tensor:
    return torch.remainder(angle + math.pi, 2 * math.pi) - math.pi


@pytest.mark.parametrize("name", STRAIGHT_GAITS)
def test_straight_descriptions_build_the_clips_they_always_built(name: str) -> None:
    clip = clip_from_description(get_gait(name))
    assert clip.cycle_yaw == 0.0
    with np.load(STRAIGHT_CLIPS) as stored:
        expected = {key.split("/", 1)[1]: stored[key] for key in stored.files if key.startswith(f"{name}/")}
    arrays = _clip_arrays(clip)
    assert arrays.keys() == expected.keys()
    for key, value in arrays.items():
        want = expected[key]
        assert value.shape == want.shape and value.dtype == want.dtype, key
        if want.dtype == bool:
            np.testing.assert_array_equal(value, want, err_msg=key)
        else:
            scale = max(1.0, float(np.abs(want).max()))
            np.testing.assert_allclose(value, want, rtol=_RTOL, atol=_RTOL * scale, err_msg=key)


def test_the_new_fields_are_optional_and_recorded_only_when_they_move(tmp_path) -> None:
    for name, (forward, lateral, yaw) in STEERING.items():
        desc = get_gait(name)
        assert (desc.forward_speed, desc.lateral_speed, desc.yaw_rate) == (forward, lateral, yaw)
        assert desc.cycle_yaw == pytest.approx(yaw / desc.stride_frequency)
        assert GaitDescription(**desc.record()) == desc
    trot = get_gait("trot")
    assert "lateral_speed" not in trot.record() and "yaw_rate" not in trot.record()
    new = ("lateral_speed", "yaw_rate", "task")  # each recorded only where it is not its default
    assert get_gait("catch").record()["task"] == "catch"
    assert trot.record() == {k: v for k, v in dataclasses.asdict(trot).items() if k not in new}
    assert get_gait("trot_left").record()["yaw_rate"] == 0.5
    assert GaitDescription(**trot.record()) == trot  # an old record reads back as lateral_speed = yaw_rate = 0


@pytest.mark.parametrize(
    ("change", "problem"),
    [
        ({"yaw_rate": float("nan")}, "yaw_rate must be a finite number"),
        ({"lateral_speed": "fast"}, "lateral_speed must be a finite number"),
        ({"yaw_rate": True}, "yaw_rate must be a finite number"),
        ({"duty_factor": 1.0, "forward_speed": 0.0, "yaw_rate": 0.3}, "cannot move or turn"),
        ({"duty_factor": 1.0, "forward_speed": 0.0, "lateral_speed": 0.1}, "cannot move or turn"),
        ({"yaw_rate": 6.5}, "less than half a turn"),
    ],
)
def test_bad_steering_fields_are_refused_in_one_line(change: dict, problem: str) -> None:
    with pytest.raises(GaitError, match=problem) as caught:
        dataclasses.replace(get_gait("trot_slow"), **change)
    assert "\n" not in str(caught.value)


@pytest.mark.parametrize(
    ("change", "problem"),
    [
        ({"yaw_rate": 4.0}, "trunk midline"),  # a spin whose stance feet sweep under the trunk
        ({"yaw_rate": 2.0, "stride_frequency": 1.0}, "trunk midline"),  # a slower spin at half the steps
        ({"lateral_speed": 1.0}, "trunk midline"),  # a sidestep too long for its stride
        ({"forward_speed": -2.0}, "hip of the other leg"),  # a stride that sweeps a foot past the other hip
        ({"forward_speed": -1.5}, "beyond the A1's limits"),
    ],
)
def test_a_motion_the_feet_cannot_carry_is_refused_before_any_work(tmp_path, change: dict, problem: str) -> None:
    desc = dataclasses.replace(get_gait("turn_left"), name="bad", **change)
    with pytest.raises(GaitError, match=problem):
        clip_from_description(desc)
    path = tmp_path / "bad.toml"
    lines = [f"{k} = {getattr(desc, k)}" for k in ("duty_factor", "stride_frequency", "forward_speed",
                                                    "lateral_speed", "yaw_rate", "swing_height", "body_height")]
    path.write_text("\n".join(lines) + "\n[phase_offsets]\nFR = 0.0\nFL = 0.5\nRR = 0.5\nRL = 0.0\n")
    assert load_gait_file(path).yaw_rate == desc.yaw_rate
    library = tmp_path / "library"
    for command in (("gaits", "--gait-file", str(path)),
                    ("train", "bad", "--gait-file", str(path), "--library", str(library), "--iterations", "1")):
        run = gaitlib_quick(*command)
        assert run.returncode != 0 and problem in run.stderr and len(run.stderr.strip().splitlines()) == 1, run.stderr
    assert not library.exists()


@pytest.mark.parametrize("name", sorted(STEERING))
def test_a_steering_clip_moves_as_described_over_many_cycles(name: str) -> None:
    desc = get_gait(name)
    forward, lateral, yaw_rate = STEERING[name]
    clip = clip_from_description(desc)
    assert clip.cycle_yaw == pytest.approx(yaw_rate / desc.stride_frequency)
    phase = torch.linspace(0.0, 12.0, 4801, dtype=torch.float64)
    frames = clip.frame(phase)
    # The trunk faces where it has turned, and runs at the described velocity in its own frame, on every cycle.
    time = (phase * desc.period).float()
    yaw = yaw_of(frames.root_quat)
    torch.testing.assert_close(_wrap(yaw - yaw_rate * time), torch.zeros_like(yaw), atol=2e-4, rtol=0)
    heading_vel = torch.stack([torch.cos(yaw) * frames.root_lin_vel[:, 0] + torch.sin(yaw) * frames.root_lin_vel[:, 1],
                               torch.cos(yaw) * frames.root_lin_vel[:, 1] - torch.sin(yaw) * frames.root_lin_vel[:, 0]],
                              dim=-1)
    torch.testing.assert_close(heading_vel, torch.tensor([[forward, lateral]]).expand_as(heading_vel), atol=2e-3,
                               rtol=0)
    torch.testing.assert_close(frames.root_ang_vel[:, 2], torch.full_like(time, yaw_rate), atol=1e-4, rtol=0)
    # Positions are continuous across every seam, and their rate is the stated velocity.
    step = (phase[1] - phase[0]).item() * desc.period
    rate = (frames.root_pos[2:] - frames.root_pos[:-2]) / (2 * step)
    torch.testing.assert_close(rate[:, :2], frames.root_lin_vel[1:-1, :2], atol=2e-2, rtol=0)
    # A stance foot stays put in the world for its whole stance, in every cycle, and on the ground.
    for leg in range(4):
        for cycle in (0, 5, 11):
            start = cycle + desc.phase_offsets[leg]
            stance = clip.frame(torch.linspace(start + 0.01, start + desc.duty_factor - 0.01, 50, dtype=torch.float64))
            feet = stance.foot_pos_world[:, leg]
            assert (feet.max(0).values - feet.min(0).values).max() < 2e-4, (leg, cycle)
            assert (feet[:, 2] - c.FOOT_RADIUS).abs().max() < 1e-4
    # The touchdown and lift-off points lie symmetrically about the neutral point, in the trunk frame.
    local = clip.foot_pos_local
    touchdown = local[0, 0, :2]
    lift_off = local[round(desc.duty_factor * (clip.num_frames - 1)), 0, :2]
    neutral = np.array([c.HIP_OFFSETS[0][0], c.HIP_OFFSETS[0][1] + c.THIGH_OFFSET_Y[0]])
    middle = local[round(0.5 * desc.duty_factor * (clip.num_frames - 1)), 0, :2]
    np.testing.assert_allclose(middle, neutral, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(touchdown - neutral), np.linalg.norm(lift_off - neutral), atol=1e-3)


def test_left_and_right_are_mirror_images_and_their_checks_agree() -> None:
    left, right = (check_reference(clip_from_description(get_gait(n))) for n in ("trot_left", "trot_right"))
    assert left.tilt_deg[0] == pytest.approx(right.tilt_deg[0], abs=0.2)
    straight = check_reference(clip_from_description(get_gait("trot_slow")))
    assert left.tilt_deg[0] == pytest.approx(straight.tilt_deg[0], abs=0.5)  # a gentle turn asks little more
    for n in STEERING:
        assert check_reference(clip_from_description(get_gait(n))).followable


def test_gaits_lists_the_steering_fields() -> None:
    table = gaitlib_quick("gaits", "trot_left", "sidestep_right", "trot_back")
    assert table.returncode == 0, table.stderr
    assert "lateral" in table.stdout and "yaw" in table.stdout and "-0.30" in table.stdout
    shown = gaitlib_quick("gaits", "trot_left", "sidestep_right", "trot_back", "--json")
    assert shown.returncode == 0, shown.stderr
    rows = {d["name"]: (d["forward_speed"], d["lateral_speed"], d["yaw_rate"])
            for d in (json.loads(line)["description"] for line in shown.stdout.splitlines())}
    assert rows == {name: STEERING[name] for name in ("trot_left", "sidestep_right", "trot_back")}


# --- the imitation environment, real MuJoCo ------------------------------------------------------------------


def test_a_robot_on_a_turning_reference_earns_the_full_reward_and_no_heading_error_over_many_turns() -> None:
    """Four robots put exactly on a fast-turning reference (set from the clip, read back by MuJoCo), started
    facing different ways, over 13 cycles and two full turns: every reward term stays at its maximum, the heading
    error at 0, and the forward speed the policy sees is the gait's; a robot that keeps its start heading reads a
    heading error that grows with the reference's turn."""
    spin = dataclasses.replace(get_gait("turn_left"), name="spin", forward_speed=0.3, yaw_rate=2.0)
    clip = clip_from_description(spin)
    n = 4
    backend = make_backend("mujoco", num_worlds=n)
    env = ImitationEnv(backend, [clip], EnvConfig(random_start_phase=False,
                                                  randomization=RandomizationConfig(enabled=False)), seed=1)
    ids = torch.arange(n)
    start = env.reference.frame()
    start.root_quat = quat_multiply(quat_from_yaw(torch.tensor([0.0, 1.5, -2.5, 3.1])), start.root_quat)
    start.root_pos[:, :2] += torch.tensor([[0.0, 0.0], [1.0, -2.0], [-3.0, 0.5], [0.2, 4.0]])
    env.reference.start(ids, env.reference.gait.clone(), torch.zeros(n), start.root_pos, start.root_quat)
    start_quat = start.root_quat.clone()
    dt, steps = 0.05, 130  # 6.5 s: 13 cycles, 13 rad of turning
    for k in range(steps):
        ref = env.reference.frame()
        backend.reset(ids, ref)
        state = backend.state()
        reward, terms = rew_fn.reward(env.cfg.reward, state, ref)
        assert reward.min() > 0.999, (k, terms)
        error = obs_fn.heading_error(state.root_quat, ref.root_quat)
        assert error.abs().max() < 1e-3, k
        assert obs_fn.reference_features([ref])[:, c.NUM_JOINTS + 1].sub(0.3).abs().max() < 1e-3
        # A robot that does not turn: its heading error is the reference's turn so far, wrapped.
        still = obs_fn.heading_error(start_quat, ref.root_quat).squeeze(-1)
        turned = torch.full((n,), spin.yaw_rate * env.reference.phase[0].item() * spin.period)
        torch.testing.assert_close(still, _wrap(turned), atol=2e-3, rtol=0)
        env.reference.advance(dt)
    assert env.reference.phase[0].item() * spin.cycle_yaw > 2 * 2 * math.pi  # two full turns and more


def test_a_turning_gait_trains_in_a_short_smoke_run(tmp_path) -> None:
    run = gaitlib_quick("train", "trot_left", "--preset", "tiny", "--iterations", "2", "--eval-episodes", "1",
                        "--eval-seconds", "0.5", "--backend", "mujoco", "--library", str(tmp_path / "lib"),
                        "--run-dir", str(tmp_path / "run"))
    assert run.returncode == 0, run.stderr
    entry = Library(tmp_path / "lib").entry("trot_left")  # read back and checked, its deployment block included
    assert entry.description == get_gait("trot_left") and entry.clip.cycle_yaw == pytest.approx(0.25)
    assert entry.metadata["description"]["yaw_rate"] == 0.5 and "lateral_speed" not in entry.metadata["description"]
    assert entry.metadata["deployment"]["reference"]["cycle_yaw"]["value"] == pytest.approx(0.25)


def test_a_turning_clip_survives_a_motion_file(tmp_path) -> None:
    clip = clip_from_description(get_gait("trot_left"))
    path = tmp_path / "trot_left.txt"
    save_motion_file(clip, path)
    loaded = load_motion_file(path)
    assert loaded.cycle_yaw == pytest.approx(clip.cycle_yaw, abs=1e-9)
    np.testing.assert_allclose(loaded.cycle_displacement, clip.cycle_displacement, atol=1e-9)
    phase = torch.tensor([0.3, 4.7, 9.1])
    torch.testing.assert_close(loaded.frame(phase).root_pos, clip.frame(phase).root_pos, atol=1e-5, rtol=0)
    torch.testing.assert_close(loaded.frame(phase).root_quat, clip.frame(phase).root_quat, atol=1e-5, rtol=0)


if __name__ == "__main__":  # writes the straight clips' references from the code as it is
    STRAIGHT_CLIPS.parent.mkdir(exist_ok=True)
    clips = {gait: clip_from_description(get_gait(gait)) for gait in STRAIGHT_GAITS}
    np.savez_compressed(STRAIGHT_CLIPS, **{f"{gait}/{key}": value for gait, clip in clips.items()
                                           for key, value in _clip_arrays(clip).items()})
