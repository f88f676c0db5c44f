"""Mirror skills at tiny sizes on the real simulator: the A1's symmetry against its MJCF, the observation map against
the environment's own observations, the mirrored policy against its source, the mirrored clips against the mirror
descriptions' clips, and ``gaitlib mirror`` end to end."""

from __future__ import annotations

import dataclasses
import json

import mujoco
import numpy as np
import pytest
import torch
from cli_runner import gaitlib, gaitlib_quick
from conftest import copy_library

from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs.mirror import mirror_maps
from gaitlib.envs.observations import ObservationBatch, ObservationConfig
from gaitlib.envs.randomization import RandomizationConfig
from gaitlib.gaits import clip_from_description, get_gait
from gaitlib.gaits.mirror import mirror_description, mirror_frame, mirror_shift
from gaitlib.library import Library
from gaitlib.library.layout import shipped_library_dir
from gaitlib.library.mirror import mirror_state
from gaitlib.library.policy import GaitPolicy
from gaitlib.robots import get_robot
from gaitlib.robots.a1 import constants as c
from gaitlib.rotations import quat_from_yaw, quat_multiply, quat_rotate, yaw_of
from gaitlib.sim import make_backend

S = np.diag(c.MIRROR_VECTOR)  # the reflection y -> -y


def test_symmetry_constants_are_the_mjcf_s() -> None:
    """Each leg body sits where its mirror's reflection does, and each joint's mirror turns about the reflected axis
    with the sign the constants give (an axis in the plane reverses, one normal to it keeps), over the same range."""
    model = mujoco.MjModel.from_xml_path(str(c.MJCF_PATH))
    for j, name in enumerate(c.JOINT_NAMES):
        mirror = c.JOINT_NAMES[c.MIRROR_JOINTS[j]]
        a, b = model.joint(name), model.joint(mirror)
        sign = c.MIRROR_JOINT_SIGNS[j]
        np.testing.assert_array_equal(model.jnt_axis[b.id], -sign * S @ model.jnt_axis[a.id])
        np.testing.assert_array_equal(np.sort(sign * model.jnt_range[a.id]), model.jnt_range[b.id])
        body, image = model.jnt_bodyid[a.id], model.jnt_bodyid[b.id]
        np.testing.assert_allclose(model.body_pos[image], S @ model.body_pos[body], atol=1e-12)
        np.testing.assert_allclose(model.body_ipos[image], S @ model.body_ipos[body], atol=1e-12)
        assert model.body_mass[image] == model.body_mass[body]
    for leg, foot in enumerate(c.FOOT_NAMES):
        np.testing.assert_allclose(model.body(c.FOOT_NAMES[c.MIRROR_LEGS[leg]]).pos, S @ model.body(foot).pos)
    assert model.body(c.TRUNK_BODY).ipos[1] == pytest.approx(0.0041)  # the asymmetry the constants name


def _symmetric_a1():
    """The A1 with its trunk's centre of mass and inertia made symmetric (the one asymmetry of a1.xml), so that a
    world and its mirror image step alike."""
    text = c.MJCF_PATH.read_text()
    asymmetric = ('<inertial mass="4.713" pos="0 0.0041 -0.0005"\n'
                  '        fullinertia="0.0158533 0.0377999 0.0456542 -3.66e-05 -6.11e-05 -2.75e-05"/>')
    assert asymmetric in text
    text = text.replace(asymmetric, '<inertial mass="4.713" pos="0 0 -0.0005" diaginertia="0.0158533 0.0377999 '
                                    '0.0456542"/>')
    return dataclasses.replace(get_robot("a1"), build_model=lambda: mujoco.MjModel.from_xml_string(text))


def _env(clips, robot, worlds: int = 3) -> ImitationEnv:
    # Randomized worlds without the noises (drawn per joint, they are not their own mirror image).
    cfg = EnvConfig(randomization=RandomizationConfig(action_noise=0.0, observation_noise=0.0))
    return ImitationEnv(make_backend("mujoco", num_worlds=worlds, robot=robot), clips, cfg, seed=3)


def _close(mirrored: ObservationBatch, source: ObservationBatch, shift: float, atol: float) -> None:
    maps = mirror_maps(ObservationConfig(), shift=shift)
    torch.testing.assert_close(mirrored.policy, maps.policy.apply(source.policy), atol=atol, rtol=0)
    torch.testing.assert_close(mirrored.privileged, maps.privileged.apply(source.privileged), atol=atol, rtol=0)


def test_observation_map_against_the_environment() -> None:
    """Worlds in a state and in its mirror image observe what the maps say, through the environment's own code:
    after reference state initialization (history, contacts, reference, critic extras), after a switch to the
    mirror description half a cycle on (the critic's phase), and over control steps of mirrored actions on the
    symmetric robot (the heading error, the previous actions and the history as they run)."""
    source = get_gait("turn_left")
    exact = mirror_description(source, name="turn_left_image")  # the mirror image at no phase shift
    robot = _symmetric_a1()
    env = _env([clip_from_description(source)], robot)
    image = _env([clip_from_description(exact), clip_from_description(get_gait("turn_right"))], robot)
    _close(image.get_observations(), env.get_observations(), 0.0, 1e-5)
    ids = torch.arange(image.num_envs)
    image.switch(ids, torch.ones_like(ids), torch.remainder(env.phase + 0.5, 1.0))
    _close(image.get_observations(), env.get_observations(), 0.5, 1e-5)
    actions = mirror_maps(ObservationConfig()).action
    generator = torch.Generator().manual_seed(0)
    for _ in range(6):
        a = 0.5 * torch.randn(env.num_envs, 12, generator=generator)
        env.step(a)
        image.step(actions.apply(a))
    assert env.get_observations().policy[:, -1].abs().max() > 1e-3  # a heading error to mirror
    _close(image.get_observations(), env.get_observations(), 0.5, 1e-5)


def test_mirrored_policy_acts_as_the_mirror_image(tiny_library) -> None:
    """pi'(M o) = A pi(o) and V'(M o) = V(o) for random observations, at the phase shifts the maps allow."""
    entry = tiny_library.entry("trot")
    state = torch.load(tiny_library.root / "trot" / "policy.pt", weights_only=True)
    nets = entry.metadata["networks"]
    generator = torch.Generator().manual_seed(1)
    o = ObservationBatch(torch.randn(256, 159, generator=generator), torch.randn(256, 14, generator=generator))
    for shift in (0.0, 0.25, 0.5):
        maps = mirror_maps(entry.observation, shift=shift)
        image = GaitPolicy.from_state(mirror_state(state, maps), actor_hidden=nets["actor_hidden"],
                                      critic_hidden=nets["critic_hidden"], activation=nets["activation"],
                                      num_actions=12, observation=entry.observation)
        mo = ObservationBatch(maps.policy.apply(o.policy), maps.privileged.apply(o.privileged))
        torch.testing.assert_close(image.act(mo), maps.action.apply(entry.policy.act(o)), atol=1e-5, rtol=1e-5)
        torch.testing.assert_close(image.value(mo), entry.policy.value(o), atol=1e-5, rtol=1e-5)
        assert not torch.allclose(image.act(o), maps.action.apply(entry.policy.act(o)), atol=1e-3)


def test_mirroring_twice_gives_the_weights_back(tiny_library) -> None:
    state = torch.load(tiny_library.root / "trot" / "policy.pt", weights_only=True)
    cfg = tiny_library.entry("trot").observation
    for there, back in ((0.5, 0.5), (0.25, 0.75), (0.0, 0.0)):
        twice = mirror_state(mirror_state(state, mirror_maps(cfg, shift=there)), mirror_maps(cfg, shift=back))
        assert all(torch.equal(twice[part][key], value) for part in state for key, value in state[part].items())
    with pytest.raises(ValueError, match="no signed permutation"):
        mirror_maps(cfg, shift=0.1)


@pytest.mark.parametrize(("source", "target"), [("turn_left", "turn_right"), ("sidestep_right", "sidestep_left"),
                                                ("trot_left", "trot_right"), ("stand", "stand")])
def test_mirrored_clip_is_the_mirror_description_s(source: str, target: str) -> None:
    """The mirror description's clip at phase p + shift is the source clip at p reflected: joints, feet, contacts,
    trunk-frame velocities and tilt exactly (to float32), the trunk's path from where it starts."""
    a, b = get_gait(source), get_gait(target)
    shift = mirror_shift(a, b)
    assert shift == (0.0 if source == "stand" else 0.5)
    phase = torch.linspace(0.0, 3.0, 601, dtype=torch.float64)
    image = mirror_frame(clip_from_description(a).frame(phase))
    own = clip_from_description(b).frame(phase + shift)
    for name in ("joint_pos", "foot_pos_local", "root_ang_vel", "contact"):
        torch.testing.assert_close(getattr(own, name), getattr(image, name), atol=2e-6, rtol=0)
    torch.testing.assert_close(own.joint_vel, image.joint_vel, atol=1e-4, rtol=1e-5)

    def path(f):
        unturn = quat_from_yaw(-yaw_of(f.root_quat[:1])).expand(len(phase), 4)
        return (quat_rotate(unturn, f.root_pos - f.root_pos[:1]), quat_multiply(unturn, f.root_quat),
                quat_rotate(unturn, f.root_lin_vel))

    for ours, theirs in zip(path(own), path(image), strict=True):
        torch.testing.assert_close(ours, theirs, atol=2e-6, rtol=0)


def test_mirror_shift_refuses_what_is_no_mirror_image() -> None:
    assert mirror_shift(get_gait("turn_left"), get_gait("turn_left")) is None
    assert mirror_shift(get_gait("trot"), get_gait("pace")) is None
    assert mirror_shift(get_gait("trot_left"), get_gait("turn_right")) is None
    assert mirror_shift(get_gait("trot"), get_gait("trot")) == 0.5


def test_cli_writes_a_mirrored_entry(tiny_library, tmp_path) -> None:
    """``gaitlib mirror`` writes an entry that loads, names its source, acts as its mirror image and reads as valid
    and not stale; then gets an evaluation as any entry does."""
    target = tmp_path / "mirrored"
    made = gaitlib("mirror", "trot", "--as", "trot", "--from", str(tiny_library.root), "--library", str(target))
    assert made.returncode == 0, made.stderr
    meta = json.loads((target / "trot" / "metadata.json").read_text())
    source = tiny_library.entry("trot")
    record = meta["training"]["mirror"]
    assert (record["source"], record["source_sha256"], record["phase_shift"]) == ("trot", source.identity, 0.5)
    assert record["command"].startswith("gaitlib mirror trot --as trot --from ")
    assert set(meta["training"]) == {"mirror", "randomization"} and meta["evaluation"] == {}
    entry = Library(target).entry("trot")
    maps = mirror_maps(entry.observation, shift=0.5)
    o = ObservationBatch(torch.randn(8, 159), torch.randn(8, 14))
    mo = ObservationBatch(maps.policy.apply(o.policy), maps.privileged.apply(o.privileged))
    torch.testing.assert_close(entry.policy.act(mo), maps.action.apply(source.policy.act(o)), atol=1e-5, rtol=1e-5)
    shown = json.loads(gaitlib_quick("library", "--library", str(target), "--json").stdout)
    assert shown["gaits"]["trot"]["problem"] is None and shown["gaits"]["trot"]["mirror_of"] == "trot"
    assert shown["problems"] == []
    evaluated = gaitlib_quick("eval", "trot", "--library", str(target), "--episodes", "2", "--seconds", "0.5",
                              "--record", "--json")
    assert evaluated.returncode == 0, evaluated.stderr
    assert Library(target).entry("trot").metadata["evaluation"]["episodes"] == 2


def test_cli_refusals_are_one_line(tiny_library, tmp_path) -> None:
    library = copy_library(tiny_library, tmp_path / "copy").root
    src = str(tiny_library.root)
    cases = {
        ("moonwalk", "--as", "trot"): "no library entry for gait 'moonwalk'",
        ("trot", "--as", "moonwalk"): "unknown gait 'moonwalk'",
        ("trot", "--as", "pace"): "gait 'pace' is not the mirror image of trot",
        ("stand", "--as", "stand", "--library", str(library)): f"{library} already holds an entry stand",
        ("trot", "--as", "trot", "--library", str(shipped_library_dir())): "of the shipped library",
    }
    for args, message in cases.items():
        words = ["mirror", *args, "--from", src]
        if "--library" not in args:
            words += ["--library", str(tmp_path / "new")]
        result = gaitlib_quick(*words)
        lines = result.stderr.strip().splitlines()
        assert result.returncode == 2 and len(lines) == 1 and message in lines[0], (args, result.stderr)
    assert not (tmp_path / "new").exists()
    replaced = gaitlib_quick("mirror", "stand", "--as", "stand", "--from", src, "--library", str(library),
                             "--replace")
    assert replaced.returncode == 0, replaced.stderr
    assert Library(library).entry("stand").metadata["training"]["mirror"]["phase_shift"] == 0.0
