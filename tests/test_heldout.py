"""The stand-in for the real robot (paper Fig. 4, bottom): another A1 model adapted in memory, what a fall is there, a
fixed action delay and the motor strength, and the benchmark on it; real simulator, tiny sizes."""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import mujoco
import numpy as np
import pytest
import torch
from cli_runner import gaitlib_quick

from gaitlib.benchmark.gap import DeploymentGap
from gaitlib.envs import EnvConfig
from gaitlib.envs.terminations import TerminationConfig, fallen
from gaitlib.errors import GaitlibError, SimulationError
from gaitlib.meta import load_switching
from gaitlib.robots import get_robot
from gaitlib.robots.a1 import constants as a1
from gaitlib.robots.variant import load_variant, model_sha256
from gaitlib.sim import make_backend, standing_state

SOFT_FOOT = (0.015, 1.0, 0.02, 0.5, 2.0)  # MuJoCo Menagerie's unitree_a1 foot solimp (midpoint, power: defaults)


def _menagerie_like_spec() -> mujoco.MjSpec:
    """gaitlib's A1 changed the ways MuJoCo Menagerie's unitree_a1 differs from it: a 0.002 s step, Euler, elliptic
    cones with impratio 100, soft unnamed feet, calf capsules that reach the foot centre, kp-100 / kv-0 position
    servos, joint damping 0.5 N m s/rad (gaitlib: 1-2), no sensors."""
    spec = mujoco.MjSpec.from_file(str(a1.MJCF_PATH))
    spec.option.timestep = 0.002
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_EULER
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = 100
    for sensor in list(spec.sensors):
        spec.delete(sensor)
    for geom in spec.geoms:
        if geom.name in a1.FOOT_NAMES:
            geom.name, geom.solimp, geom.margin = "", list(SOFT_FOOT), 0.001
        elif geom.type == mujoco.mjtGeom.mjGEOM_CAPSULE and geom.size[0] == pytest.approx(0.01):
            geom.fromto = [0, 0, 0, 0, 0, -a1.LINK_LENGTH]  # the calf capsule now ends at the foot centre
    for actuator in spec.actuators:
        actuator.set_to_position(kp=100, kv=0)
    for joint in spec.joints:  # other joint damping, as an independently written model has
        if joint.type == mujoco.mjtJoint.mjJNT_HINGE:
            joint.damping = np.array([0.5, *np.asarray(joint.damping).ravel()[1:]])
    return spec


@pytest.fixture
def variant_file(tmp_path) -> Path:
    path = tmp_path / "variant" / "a1_variant.xml"
    path.parent.mkdir()
    path.write_text(_menagerie_like_spec().to_xml())
    return path


def test_a_foreign_model_is_adapted_in_memory_as_specified(variant_file) -> None:
    before = model_sha256(variant_file)
    robot = load_variant(variant_file)
    assert model_sha256(variant_file) == before and os.listdir(variant_file.parent) == [variant_file.name]
    assert robot.joint_names == a1.JOINT_NAMES and robot.foot_names == a1.FOOT_NAMES
    assert robot.standing_height == pytest.approx(a1.STANDING_HEIGHT, abs=1e-4)
    assert robot.stance_contact_geoms == tuple(f"{leg}_calf_stance0" for leg in a1.LEG_NAMES)
    model = robot.build_model()
    assert model.opt.timestep == pytest.approx(1 / 240) and pytest.approx(8 * model.opt.timestep) == 1 / 30
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC and model.opt.impratio == 100  # kept
    original = mujoco.MjModel.from_xml_path(str(variant_file))
    np.testing.assert_array_equal(model.dof_damping, original.dof_damping)  # joints and masses kept
    np.testing.assert_array_equal(model.body_mass, original.body_mass)
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    for name in a1.FOOT_NAMES:
        foot = model.geom(name)
        assert foot.type[0] == mujoco.mjtGeom.mjGEOM_SPHERE and tuple(foot.solimp) == pytest.approx(SOFT_FOOT)
        np.testing.assert_allclose(data.site(name).xpos, data.geom(name).xpos, atol=1e-12)  # a site at its centre
    # gaitlib's servo replaced the kp-100 / kv-0 one, joint by joint in gaitlib's order
    assert [model.joint(model.actuator_trnid[i, 0]).name for i in range(model.nu)] == list(a1.JOINT_NAMES)
    np.testing.assert_allclose(model.actuator_gainprm[:, 0], a1.KP_DEFAULT)
    np.testing.assert_allclose(model.actuator_biasprm[:, :3], [[0, -a1.KP_DEFAULT, -a1.KD_DEFAULT]] * 12)
    np.testing.assert_allclose(model.actuator_forcerange, [[-a1.TORQUE_LIMIT, a1.TORQUE_LIMIT]] * 12)
    np.testing.assert_allclose(model.actuator_ctrlrange, model.jnt_range[1:])
    # gaitlib's own A1 through the adapter: the same robot, no stance geoms (its calves end above the feet)
    own = load_variant(a1.MJCF_PATH)
    assert own.stance_contact_geoms == () and own.joint_lower == a1.JOINT_LOWER


def test_calves_on_the_ground_in_stance_are_no_fall_but_lying_on_the_back_is(variant_file) -> None:
    robot = load_variant(variant_file)
    for stance_geoms, standing_falls in ((robot.stance_contact_geoms, False), ((), True)):
        sim = make_backend("mujoco", num_worlds=2, robot=dataclasses.replace(robot, stance_contact_geoms=stance_geoms))
        state = standing_state(robot, 2)
        state.root_quat[1] = torch.tensor([0.0, 1.0, 0.0, 0.0])  # world 1 upside down, on its back
        state.root_pos[1, 2] = 0.08
        sim.reset(torch.arange(2), state)
        for _ in range(30):
            assert not sim.step().any()
        s = sim.state()
        sim.close()
        assert s.foot_contact[0].all() and s.root_pos[0, 2] > 0.2  # standing on its four soft feet
        assert s.foot_pos[0, :, 2].max() < a1.FOOT_RADIUS - 0.005  # which sink more than 5 mm
        assert s.body_contact.tolist() == [standing_falls, True]
        upright = torch.tensor([[1.0, 0.0, 0.0, 0.0]]).repeat(2, 1)
        fell = fallen(s.body_contact, s.trunk_contact, s.root_pos[:, 2], s.root_quat, upright,
                      TerminationConfig(heading=False))
        assert fell.tolist() == [standing_falls, True]  # without its stance geoms, the standing robot's calves fall
        # ... by gaitlib's strict definition; by the field's (the default) a calf's touch is no fall, the back is.
        assert s.trunk_contact.tolist() == [False, True]
        trunk = TerminationConfig(heading=False).counting("trunk")
        fell = fallen(s.body_contact, s.trunk_contact, s.root_pos[:, 2], s.root_quat, upright, trunk)
        assert fell.tolist() == [False, True]


def _rename_knee(spec: mujoco.MjSpec) -> None:
    spec.joint("RL_calf_joint").name = "RL_knee"
    spec.actuator("RL_calf").target = "RL_knee"


def _flatten_front_right_foot(spec: mujoco.MjSpec) -> None:
    foot = spec.body("FR_foot").first_geom()
    foot.type, foot.size = mujoco.mjtGeom.mjGEOM_BOX, [0.02, 0.02, 0.02]


@pytest.mark.parametrize(
    ("change", "line"),
    [
        (_rename_knee, "has no hinge joint RL_calf_joint"),
        (_flatten_front_right_foot, "has no foot sphere below FR_calf_joint"),
        (lambda spec: spec.delete(spec.geom("floor")), "has no ground: a plane geom in the worldbody"),
    ],
    ids=["joint", "foot", "ground"],
)
def test_a_model_without_the_a1s_joints_feet_or_ground_is_refused_in_one_line(change, line, tmp_path) -> None:
    spec = _menagerie_like_spec()
    change(spec)
    path = tmp_path / "bad.xml"
    path.write_text(spec.to_xml())
    with pytest.raises(SimulationError, match=line) as refused:
        load_variant(path)
    assert "\n" not in str(refused.value)
    with pytest.raises(SimulationError, match="does not exist or is not a file"):
        load_variant(tmp_path / "missing.xml")


def test_the_motor_strength_scales_gains_and_torque_limit(variant_file) -> None:
    sim = make_backend("mujoco", num_worlds=1, robot=load_variant(variant_file, motor_strength=0.5))
    try:
        model = sim._models[0]
        np.testing.assert_allclose(model.actuator_forcerange, [[-16.75, 16.75]] * 12)
        np.testing.assert_allclose(model.actuator_gainprm[:, 0], 0.5 * a1.KP_DEFAULT)
        np.testing.assert_allclose(model.actuator_biasprm[:, 2], -0.5 * a1.KD_DEFAULT)
    finally:
        sim.close()


MENAGERIE = Path(os.environ.get("GAITLIB_MENAGERIE_A1", ""))
"""MuJoCo Menagerie's unitree_a1 scene (github.com/google-deepmind/mujoco_menagerie), where a machine has it: the
test below then runs on it too."""


@pytest.mark.parametrize("model", ["variant", *(["menagerie"] if MENAGERIE.is_file() else [])])
def test_an_independent_a1_stands_on_its_calves_without_falling(model, variant_file) -> None:
    """A model whose calf capsules reach the feet (as Menagerie's do) stands on feet and calves: the calves are
    stance contacts, not falls."""
    robot = load_variant(variant_file if model == "variant" else MENAGERIE)
    assert len(robot.stance_contact_geoms) == 4
    sim = make_backend("mujoco", num_worlds=1, robot=robot)
    try:
        for _ in range(30):
            assert not sim.step().any()
        s = sim.state()
        calves = sim._sensors[0, sim._stance_contact_adr]
    finally:
        sim.close()
    assert s.foot_contact.all() and not s.body_contact.any() and (calves > 0).all()


def test_an_action_delay_of_two_reaches_the_servos_two_steps_late(switching_library) -> None:
    setup = load_switching(switching_library)
    for delay in (0, 2):
        sim = make_backend("mujoco", num_worlds=2)
        env = DeploymentGap(action_delay=delay).make_env(setup, sim, EnvConfig(), seed=0)
        sent: list[torch.Tensor] = []

        def record(targets: torch.Tensor, sent=sent, forward=sim.set_pd_targets) -> None:
            sent.append(targets.clone())
            forward(targets)

        sim.set_pd_targets = record
        for step in range(6):  # one kick at step 2: +4 action units push the hips past their upper limit
            env.step(torch.full((2, 12), 4.0 if step == 2 else 0.0))
        sim.close()
        at_limit = [bool((t[:, 0] == torch.tensor(a1.JOINT_UPPER[0])).all()) for t in sent]
        assert at_limit == [step == 2 + delay for step in range(6)]
        assert (env.world_parameters.action_delay == delay).all()


def test_a_sweep_on_another_model_records_it_and_resumes_only_with_it(switching_library, variant_file, tmp_path):
    out = tmp_path / "bench"
    args = ["benchmark", "--strategies", "random", "--magnitudes", "0", "--samples", "1", "--pairs", "trot-stand",
            "--worlds", "2", "--library", str(switching_library), "--out", str(out), "--json"]
    first = gaitlib_quick(*args, "--robot", str(variant_file), "--action-delay", "1", "--motor-strength", "0.9")
    assert first.returncode == 0, first.stderr
    results = json.loads((out / "results.json").read_text())
    settings = results["settings"]
    assert settings["robot"] == str(variant_file.resolve()) and settings["robot_sha256"] == model_sha256(variant_file)
    assert (settings["action_delay"], settings["motor_strength"]) == (1, 0.9)
    assert results["groups"]["random@0"]["backend"] == "mujoco"
    assert results["groups"]["random@0"]["cells"]["trot-stand"]["samples"] == 1
    before = (out / "results.json").read_bytes()
    other = tmp_path / "other.xml"
    other.write_text(variant_file.read_text() + "<!-- another model -->\n")
    for robot, differ in ((["--robot", str(other)], "robot, robot_sha256"), ([], "robot, robot_sha256")):
        refused = gaitlib_quick(*args, *robot, "--action-delay", "1", "--motor-strength", "0.9")
        assert refused.returncode == 2 and refused.stderr == (
            f"gaitlib: error: {out} holds a benchmark with other settings ({differ}); use another --out or delete it\n"
        )
    assert (out / "results.json").read_bytes() == before


def test_a_gap_without_the_mujoco_backend_is_refused() -> None:
    with pytest.raises(GaitlibError, match="mujoco backend only, not on 'newton'"):
        DeploymentGap(motor_strength=0.8).backend_name("newton")
    assert DeploymentGap(motor_strength=0.8).backend_name("auto") == "mujoco"
    assert DeploymentGap(action_delay=2).settings() == {"action_delay": 2} and DeploymentGap().settings() == {}


def test_an_adapted_robot_is_refused_by_the_newton_backend() -> None:
    spec = dataclasses.replace(get_robot("a1"), motor_strength=0.8)
    with pytest.raises(SimulationError, match="runs on the mujoco backend only"):
        make_backend("newton", num_worlds=1, robot=spec)
