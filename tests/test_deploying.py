"""The deployment contract: the loop of docs/deploying.md, run from an entry folder alone, sees what the environment
sees and keeps the A1 up; the doc shows exactly that loop."""

from __future__ import annotations

import importlib.util
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest
import torch
from conftest import rsl_rl_models

from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs import observations as obs_fn
from gaitlib.envs.randomization import RandomizationConfig, sample_world_parameters
from gaitlib.gaits import GaitDescription, clip_from_description, get_gait
from gaitlib.library.deployment import deployment_block
from gaitlib.library.export import export_onnx
from gaitlib.library.layout import shipped_library_dir
from gaitlib.library.onnx_graph import graph_signature
from gaitlib.library.validate import deployment_difference
from gaitlib.robots import get_robot
from gaitlib.sim import make_backend

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "deploy_onnx.py"


def _load_example():
    spec = importlib.util.spec_from_file_location("deploy_onnx", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _words(block: object) -> object:
    """``block`` with every number replaced by ``None``: its names, prose and shape."""
    if isinstance(block, dict):
        return {key: _words(value) for key, value in block.items()}
    if isinstance(block, list):
        return [_words(value) for value in block]
    return None if isinstance(block, (int, float)) and not isinstance(block, bool) else block


def _block(folder: Path, onnx_path: Path) -> dict:
    meta = json.loads((folder / "metadata.json").read_text())
    clip = clip_from_description(GaitDescription(**meta["description"]))
    observation = obs_fn.observation_config(meta["observation"])
    delay = tuple(meta["training"].get("randomization", {}).get("action_delay_steps", (0, 0)))
    return deployment_block(
        clip=clip, action=meta["action"], observation=observation, onnx_path=onnx_path, action_delay_steps=delay
    )


@pytest.fixture(scope="module", params=["shipped", "tiny"])
def trot_entry(request, tmp_path_factory) -> Path:
    """A trot policy.onnx beside a metadata.json holding nothing but the deployment block: the shipped trot and the
    tests' tiny trot (both reading 159 values, the heading error included)."""
    source = shipped_library_dir() if request.param == "shipped" else request.getfixturevalue("tiny_library").root
    entry = tmp_path_factory.mktemp("entry") / "trot"
    entry.mkdir()
    shutil.copy(source / "trot" / "policy.onnx", entry / "policy.onnx")
    block = _block(source / "trot", entry / "policy.onnx")
    description = json.loads((source / "trot" / "metadata.json").read_text())["description"]
    (entry / "metadata.json").write_text(
        json.dumps({"deployment": block, "source": request.param, "description": description})
    )
    return entry


def test_the_doc_shows_the_example_verbatim() -> None:
    doc = (ROOT / "docs" / "deploying.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", doc, flags=re.DOTALL)
    assert EXAMPLE.read_text() in blocks


def test_the_loop_sees_what_the_environment_sees_and_the_robot_stays_up(trot_entry: Path) -> None:
    """From the environment's start state (no randomization, phase 0), the loop's observations equal the
    environment's while both take the loop's actions; over two seconds the shipped trot's trunk stays high and
    upright (the tiny trot is untrained: only its observations are compared)."""
    block = json.loads((trot_entry / "metadata.json").read_text())
    shipped = block["source"] == "shipped"
    clip = clip_from_description(GaitDescription(**block["description"]))
    sim = make_backend("mujoco", num_worlds=1)
    cfg = EnvConfig(
        episode_seconds=100.0,
        randomization=RandomizationConfig(enabled=False),
        random_start_phase=False,
        observation=obs_fn.ObservationConfig(heading="heading" in block["deployment"]["observation"]),
    )
    env = ImitationEnv(sim, [clip], cfg)
    try:
        s = env.sim_state
        model = mujoco.MjModel.from_xml_path(str(get_robot("a1").mjcf_path))
        data = mujoco.MjData(model)
        data.qpos[:] = torch.cat([s.root_pos[0], s.root_quat[0], s.joint_pos[0]]).double().numpy()
        data.qvel[:] = torch.cat([s.root_lin_vel[0], s.root_ang_vel[0], s.joint_vel[0]]).double().numpy()
        heights, uprightness = [], []
        for step, (obs, action) in enumerate(_load_example().deploy(model, data, trot_entry, 2.0)):
            if step < 10:
                expected = env.get_observations().policy[0].numpy()
                np.testing.assert_allclose(obs, expected, atol=1e-5, err_msg=f"control step {step}")
                env.step(torch.as_tensor(action, dtype=torch.float32).unsqueeze(0))
            heights.append(data.qpos[2])
            uprightness.append(-obs[14])  # projected gravity z of the newest frame
        assert step + 1 == 60
        if shipped:
            assert min(heights) > 0.2 and min(uprightness) > 0.9
            assert data.qpos[0] > 0.5  # it trots forward (0.5 m/s reference or faster)
    finally:
        sim.close()


def test_the_block_states_the_numbers_the_environment_uses(trot_entry: Path) -> None:
    block = json.loads((trot_entry / "metadata.json").read_text())["deployment"]
    env_cfg = EnvConfig()
    robot = get_robot("a1")
    assert block["control"]["rate_hz"] * block["control"]["substeps"] * block["control"]["physics_timestep_s"] == 1
    model = mujoco.MjModel.from_xml_path(str(robot.mjcf_path))
    assert block["control"]["physics_timestep_s"] == pytest.approx(model.opt.timestep, abs=1e-12)
    nominal = sample_world_parameters(RandomizationConfig(enabled=False), 1, torch.Generator())
    assert (block["control"]["kp"], block["control"]["kd"]) == pytest.approx((nominal.kp.item(), nominal.kd.item()))
    assert (block["action"]["scale"], block["action"]["clip"]) == (env_cfg.action_scale, env_cfg.action_clip)
    assert block["robot"]["joint_names"] == [model.joint(model.actuator_trnid[i, 0]).name for i in range(model.nu)]
    assert block["observation"]["gravity"]["upright_value"] == [0.0, 0.0, -1.0]
    assert block["onnx"]["inputs"][0]["shape"][-1] == block["observation"]["size"]
    assert block["onnx"]["outputs"][0]["shape"][-1] == len(block["robot"]["joint_names"])


def test_the_signature_reader_agrees_with_onnx_on_every_model_in_the_repository(tmp_path) -> None:
    """Every ``policy.onnx`` of the repository's libraries, shipped and staged, reads as the ``onnx`` package reads
    it; bytes that are not a whole model raise :class:`ValueError`."""
    import onnx

    def by_onnx(values) -> list[dict]:
        return [{"name": v.name, "shape": [d.dim_value or d.dim_param for d in v.type.tensor_type.shape.dim],
                 "dtype": onnx.helper.tensor_dtype_to_np_dtype(v.type.tensor_type.elem_type).name} for v in values]

    models = sorted(ROOT.glob("library*/**/*.onnx"))
    assert len(models) >= 13  # the six gaits' policies and the staged skills' at least
    for path in models:
        graph = onnx.load(str(path)).graph
        assert graph_signature(path) == {"inputs": by_onnx(graph.input), "outputs": by_onnx(graph.output)}, path
    whole = models[0].read_bytes()
    for cut in (whole[:40], whole[: len(whole) // 2], b"\x0a\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\x01"):
        (tmp_path / "cut.onnx").write_bytes(cut)
        with pytest.raises(ValueError, match="protobuf"):
            graph_signature(tmp_path / "cut.onnx")


def test_loading_the_library_does_not_import_onnx() -> None:
    """A command's start loads every entry and checks its ``policy.onnx`` without the ``onnx`` package (about 0.7 s
    of a start; ``docs/benchmarks.md``, "A command's start")."""
    script = ("import sys\nfrom gaitlib.library import Library\nlibrary = Library(sys.argv[1])\n"
              "[library.entry(g) for g in library.gaits()]\n"
              "print(sorted(m for m in sys.modules if m.split('.')[0] in ('onnx', 'ml_dtypes')))")
    done = subprocess.run([sys.executable, "-c", script, str(shipped_library_dir())], capture_output=True, text=True,
                          timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


@pytest.mark.parametrize("gait", ["stand", "trot", "pace"])
def test_shipped_entries_carry_the_current_deployment_block(gait: str) -> None:
    folder = shipped_library_dir() / gait
    meta = json.loads((folder / "metadata.json").read_text())
    assert meta["format_version"] == 2 and "deployment" in meta  # format 2 promises the block
    derived = _block(folder, folder / "policy.onnx")
    # numbers as the loader holds them (the reference table, rounded to 1e-6, may round the other way on another
    # processor), names and prose exactly
    assert deployment_difference(meta["deployment"], derived) is None
    assert _words(meta["deployment"]) == _words(derived)


def test_the_block_states_where_training_starts_a_robot_and_the_delay_it_trained_with(trot_entry: Path) -> None:
    """Row 0 of the start state is the environment's reference state initialization at phase 0 (no randomization),
    velocities included; the trained action delay is the entry's."""
    block = json.loads((trot_entry / "metadata.json").read_text())
    deployment = block["deployment"]
    clip = clip_from_description(GaitDescription(**block["description"]))
    cfg = EnvConfig(randomization=RandomizationConfig(enabled=False), random_start_phase=False)
    env = ImitationEnv(make_backend("mujoco", num_worlds=1), [clip], cfg)
    s, start = env.sim_state, deployment["reference"]["start_state"]
    row = {c["name"]: start["rows"][0][c["start"] : c["start"] + c["size"]] for c in start["columns"]}
    np.testing.assert_allclose(row["root_quat"], s.root_quat[0].numpy(), atol=1e-5)
    np.testing.assert_allclose(row["root_lin_vel"], s.root_lin_vel[0].numpy(), atol=1e-5)
    np.testing.assert_allclose(row["root_ang_vel"], s.root_ang_vel[0].numpy(), atol=1e-5)
    np.testing.assert_allclose(row["joint_vel"], s.joint_vel[0].numpy(), atol=1e-5)
    assert deployment["action"]["delay"]["trained_steps"] == [0, 1]


def test_the_loop_follows_a_turning_reference_across_its_cycles(tmp_path) -> None:
    """A turning gait's block gives its turn per cycle, and the loop's observations, the heading error included,
    equal the environment's for 24 control steps (0.8 s): 1.6 cycles of turn_left, across a seam where the reference has
    turned on (a policy whose actions are all 0, so the robot holds the reference's joint targets; only the
    observations are compared)."""
    meta = json.loads((shipped_library_dir() / "trot" / "metadata.json").read_text())
    turn = get_gait("turn_left")
    clip = clip_from_description(turn)
    entry = tmp_path / "turn_left"
    entry.mkdir()
    actor, _ = rsl_rl_models(actor_hidden=(8,), critic_hidden=(8,), observation=obs_fn.ObservationConfig())
    with torch.no_grad():
        for parameter in actor.parameters():
            parameter.zero_()
    export_onnx(actor, entry / "policy.onnx")
    block = deployment_block(clip=clip, action=meta["action"], observation=obs_fn.ObservationConfig(),
                             onnx_path=entry / "policy.onnx", action_delay_steps=(0, 0))
    assert block["reference"]["cycle_yaw"]["value"] == pytest.approx(turn.cycle_yaw)
    (entry / "metadata.json").write_text(json.dumps({"deployment": block}))
    sim = make_backend("mujoco", num_worlds=1)
    cfg = EnvConfig(episode_seconds=100.0, randomization=RandomizationConfig(enabled=False), random_start_phase=False)
    env = ImitationEnv(sim, [clip], cfg)
    try:
        s = env.sim_state
        model = mujoco.MjModel.from_xml_path(str(get_robot("a1").mjcf_path))
        data = mujoco.MjData(model)
        data.qpos[:] = torch.cat([s.root_pos[0], s.root_quat[0], s.joint_pos[0]]).double().numpy()
        data.qvel[:] = torch.cat([s.root_lin_vel[0], s.root_ang_vel[0], s.joint_vel[0]]).double().numpy()
        for step, (obs, action) in enumerate(_load_example().deploy(model, data, entry, 0.8)):
            expected = env.get_observations().policy[0].numpy()
            np.testing.assert_allclose(obs, expected, atol=1e-4, err_msg=f"control step {step}")
            assert not env.step(torch.as_tensor(action, dtype=torch.float32).unsqueeze(0))[2].any()
        assert step + 1 == 24 and env.reference.phase[0].item() > 1.5 and not action.any()
        assert abs(obs[-1]) > 0.1  # the robot turns less than the reference: a heading error both read alike
    finally:
        sim.close()
