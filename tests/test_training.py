"""Real PPO iterations on a handful of worlds, library entries, checkpoints, ONNX export, load errors."""

from __future__ import annotations

import errno
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from conftest import REPO, rsl_rl_models

from gaitlib.atomic import write_json
from gaitlib.defaults import Falls
from gaitlib.envs.observations import ObservationBatch, ObservationConfig
from gaitlib.gaits import get_gait
from gaitlib.library import Library, LibraryError
from gaitlib.library.policy import GaitPolicy
from gaitlib.training import get_preset
from gaitlib.training.trainer import TrainRequest, train_gait


def request(tmp_path, gait="stand", **kw) -> TrainRequest:
    base = {
        "description": get_gait(gait),
        "preset": get_preset("tiny"),
        "iterations": 2,
        "library": tmp_path / "library",
        "run_dir": tmp_path / "runs" / gait,
        "backend": "mujoco",
        "checkpoint_every": 1,
        "eval_episodes": 2,
        "eval_seconds": 0.5,
    }
    return TrainRequest(**(base | kw))


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """One tiny training run shared by the tests that only read its result."""
    tmp_path = tmp_path_factory.mktemp("train")
    seen = []
    result = train_gait(request(tmp_path), on_iteration=seen.append)
    return tmp_path, result, seen


def test_training_changes_the_policy_and_writes_an_entry(trained) -> None:
    tmp_path, _result, seen = trained
    assert [s.iteration for s in seen] == [1, 2]
    assert seen[-1].samples == 2 * 4 * 8 and seen[-1].samples_per_s > 0
    assert set(seen[-1].reward_terms) == {"pose", "joint_velocity", "end_effector", "root_pose", "root_velocity"}
    entry = Library(tmp_path / "library").entry("stand")
    first = torch.load(tmp_path / "runs" / "stand" / "checkpoints" / "model_1.pt", weights_only=False)
    assert first["iter"] == 1 and first["infos"]["gait"] == "stand" and first["infos"]["samples"] == 32
    final = entry.policy.actor.state_dict()
    assert not torch.equal(first["actor_state_dict"]["mlp.0.weight"], final["mlp.0.weight"])
    meta = entry.metadata
    assert meta["training"]["samples"] == 64 and meta["training"]["preset"]["name"] == "tiny"
    assert [row[0] for row in meta["training"]["curve"]["rows"]] == [1, 2]  # each iteration once
    assert {"fall_rate", "joint_rmse", "forward_speed"} <= set(meta["evaluation"])
    assert meta["action"]["type"] == "residual_to_reference"
    assert entry.policy.latent_dim == 16


def test_latent_and_value_have_documented_shapes(trained) -> None:
    tmp_path, _, _ = trained
    entry = Library(tmp_path / "library").entry("stand")
    obs = ObservationBatch(policy=torch.randn(5, 159), privileged=torch.randn(5, 14))
    action, latent = entry.policy.act_and_latent(obs)
    assert action.shape == (5, 12) and latent.shape == (5, 16) and entry.policy.value(obs).shape == (5,)
    assert torch.allclose(action, entry.policy.act(obs))


@pytest.mark.parametrize("activation", ["elu", "tanh"])
def test_the_loaded_policy_computes_what_rsl_rl_s_model_computes_bit_for_bit(activation) -> None:
    """The library's plain-torch policy on rsl-rl's weights: the same actions, latents and values, bit for bit,
    with non-trivial normalizer statistics."""
    from tensordict import TensorDict

    gen = torch.Generator().manual_seed(3)
    config = ObservationConfig()
    actor, critic = rsl_rl_models(actor_hidden=(24, 16), critic_hidden=(20, 12), activation=activation,
                                  observation=config)
    with torch.no_grad():
        for model in (actor, critic):
            for tensor in model.state_dict().values():
                if tensor.is_floating_point():
                    tensor.copy_(torch.rand(tensor.shape, generator=gen) + 0.1)  # std > 0, means off 0
    actor.eval(), critic.eval()
    policy = GaitPolicy.from_state({"actor": actor.state_dict(), "critic": critic.state_dict()},
                                   actor_hidden=(24, 16), critic_hidden=(20, 12), activation=activation,
                                   num_actions=12, observation=config)
    x, extra = torch.randn(9, 159, generator=gen) * 3, torch.randn(9, 14, generator=gen)
    obs, groups = ObservationBatch(policy=x, privileged=extra), TensorDict({"policy": x, "privileged": extra},
                                                                          batch_size=[9])
    with torch.inference_mode():
        assert torch.equal(policy.act(obs), actor(groups))
        assert torch.equal(policy.latent(obs), torch.nn.Sequential(*list(actor.mlp)[:-1])(actor.get_latent(groups)))
        assert torch.equal(policy.value(obs), critic(groups).squeeze(-1))
    assert policy.latent_dim == 16 and policy.actor_dim == 159
    with pytest.raises(RuntimeError, match="size mismatch"):
        GaitPolicy.from_state({"actor": actor.state_dict(), "critic": critic.state_dict()}, actor_hidden=(24, 8),
                              critic_hidden=(20, 12), activation=activation, num_actions=12, observation=config)
    with pytest.raises(ValueError, match="unknown activation 'softsign' \\(rsl-rl's names: elu, selu, "):
        GaitPolicy.from_state({"actor": actor.state_dict(), "critic": critic.state_dict()}, actor_hidden=(24, 16),
                              critic_hidden=(20, 12), activation="softsign", num_actions=12, observation=config)


def test_a_command_that_runs_policies_imports_neither_rsl_rl_nor_tensordict() -> None:
    """Loading the shipped library and running the meta-controller leaves rsl-rl and TensorDict (and with it
    torch._dynamo) unimported: what every command that does not train pays at its start."""
    code = (
        "import sys\n"
        "from gaitlib.meta import load_switching\n"
        "from gaitlib.sim import make_backend\n"
        "setup = load_switching(None)\n"
        "controller = setup.controller(setup.make_env(make_backend('mujoco', num_worlds=2)), 'net-lookahead')\n"
        "controller.request([0], setup.gait_index('stand'))\n"
        "for _ in range(3): controller.step()\n"
        "print(sorted({m.split('.')[0] for m in sys.modules} & {'rsl_rl', 'tensordict'}),\n"
        "      'torch._dynamo' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["[]", "False"], out.stdout + out.stderr


def test_onnx_export_has_a_batch_axis_and_matches_the_torch_actor(trained) -> None:
    import onnxruntime

    tmp_path, _, _ = trained
    entry = Library(tmp_path / "library").entry("stand")
    onnx_file = tmp_path / "library" / "stand" / "policy.onnx"
    session = onnxruntime.InferenceSession(str(onnx_file), providers=["CPUExecutionProvider"])
    assert [(io.name, io.shape) for io in session.get_inputs()] == [("obs", ["batch", 159])]
    assert [(io.name, io.shape) for io in session.get_outputs()] == [("actions", ["batch", 12])]
    x = torch.randn(7, 159, generator=torch.Generator().manual_seed(0))
    expected = entry.policy.act(ObservationBatch(policy=x, privileged=torch.zeros(7, 14)))
    (got,) = session.run(None, {"obs": x.numpy()})
    np.testing.assert_allclose(got, expected.numpy(), atol=1e-5, rtol=1e-5)


def test_training_one_gait_leaves_other_entries_untouched(tmp_path) -> None:
    first = train_gait(request(tmp_path, iterations=1))
    before = {p.name: p.read_bytes() for p in first.entry.iterdir()}
    train_gait(request(tmp_path, gait="trot", iterations=1))
    assert Library(tmp_path / "library").gaits() == ("stand", "trot")
    assert {p.name: p.read_bytes() for p in first.entry.iterdir()} == before


def test_resume_continues_from_the_checkpoint(tmp_path) -> None:
    def stop_after_first(stats):
        if stats.iteration == 1:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        train_gait(request(tmp_path, iterations=3), on_iteration=stop_after_first)
    saved = torch.load(tmp_path / "runs" / "stand" / "checkpoints" / "latest.pt", weights_only=False)
    assert saved["iter"] == 1 and saved["infos"]["samples"] == 32
    assert not (tmp_path / "library" / "stand").exists()  # nothing half-written
    seen = []
    result = train_gait(request(tmp_path, iterations=3, resume=True), on_iteration=seen.append)
    assert [s.iteration for s in seen] == [2, 3]
    assert result.samples == 3 * 32 and result.iterations == 3
    rows = Library(tmp_path / "library").entry("stand").metadata["training"]["curve"]["rows"]
    assert [row[0] for row in rows] == [1, 2, 3]  # the curve goes on across the resume


def test_resume_refuses_a_checkpoint_of_another_gait(tmp_path) -> None:
    from gaitlib.errors import GaitlibError

    train_gait(request(tmp_path, iterations=1))
    with pytest.raises(GaitlibError, match=r"is of another training run: GAIT: gait 'stand' then, 'trot' now"):
        train_gait(request(tmp_path, gait="trot", iterations=2, resume=True, run_dir=tmp_path / "runs" / "stand"))


def test_a_failed_checkpoint_write_leaves_the_previous_checkpoint(tmp_path, monkeypatch) -> None:
    train_gait(request(tmp_path, iterations=1))
    checkpoints = tmp_path / "runs" / "stand" / "checkpoints"
    before = (checkpoints / "latest.pt").read_bytes()

    write_bytes = Path.write_bytes

    def torn_write(self: Path, data: bytes) -> int:  # writes part of the checkpoint's file, then the disk fills up
        if self.suffix != ".pt":
            return write_bytes(self, data)
        write_bytes(self, data[: len(data) // 2])
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(Path, "write_bytes", torn_write)
    with pytest.raises(OSError, match="No space left"):
        train_gait(request(tmp_path, iterations=2, resume=True))
    assert (checkpoints / "latest.pt").read_bytes() == before
    assert sorted(p.name for p in checkpoints.iterdir()) == ["latest.pt", "model_1.pt"]  # no partial file left


def test_resume_without_checkpoint_is_an_error(tmp_path) -> None:
    from gaitlib.errors import GaitlibError

    with pytest.raises(GaitlibError, match="nothing to resume"):
        train_gait(request(tmp_path, resume=True))


def _copy_entry(trained, tmp_path):
    import shutil

    src = trained[0] / "library" / "stand"
    shutil.copytree(src, tmp_path / "stand")
    return tmp_path


def test_missing_entry_is_a_clear_error(tmp_path) -> None:
    with pytest.raises(LibraryError, match="no library entry for gait 'pace'"):
        Library(tmp_path).entry("pace")


def test_entry_of_another_format_version_is_refused(trained, tmp_path) -> None:
    library = _copy_entry(trained, tmp_path)
    meta_path = library / "stand" / "metadata.json"
    meta = json.loads(meta_path.read_text())
    meta["format_version"] = 99
    write_json(meta_path, meta, checksum=True)
    with pytest.raises(LibraryError, match="format version 99"):
        Library(library).entry("stand")


def test_entry_with_another_observation_layout_is_refused(trained, tmp_path) -> None:
    library = _copy_entry(trained, tmp_path)
    meta_path = library / "stand" / "metadata.json"
    meta = json.loads(meta_path.read_text())
    meta["observation"]["reference_offsets"] = [1, 2, 3, 4]
    write_json(meta_path, meta, checksum=True)
    with pytest.raises(LibraryError, match="another observation layout"):
        Library(library).entry("stand")


def test_damaged_weights_are_refused(trained, tmp_path) -> None:
    library = _copy_entry(trained, tmp_path)
    (library / "stand" / "policy.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(LibraryError, match="damaged"):
        Library(library).entry("stand")


def test_garbage_metadata_is_refused(trained, tmp_path) -> None:
    library = _copy_entry(trained, tmp_path)
    (library / "stand" / "metadata.json").write_text("{not json")
    with pytest.raises(LibraryError, match="unreadable metadata"):
        Library(library).entry("stand")


def test_eval_averages_over_the_steps_it_sums() -> None:
    """The trot's reference runs at a constant 1.45 m/s: over 30 steps the mean is that, not 29/30 of it (the step
    that ends an episode counts for its length, not for the means); and its feet keep to its contact plan."""
    from gaitlib.envs import EnvConfig
    from gaitlib.evaluation import evaluate_policy
    from gaitlib.library import Library
    from gaitlib.library.layout import shipped_library_dir

    library = Library(shipped_library_dir())
    trot = library.entry("trot")
    result = evaluate_policy(
        trot.policy, trot.clip, env_cfg=library.shared_policy_settings(["trot"]).env_config(EnvConfig()),
        episodes=2, seconds=1.0, backend="mujoco", seed=0,
    )
    assert trot.description.forward_speed == 1.45 and result.mean_episode_seconds == pytest.approx(1.0)
    assert result.reference_speed == pytest.approx(1.45, rel=1e-5)
    # Its feet are mostly where the reference plans them (down in stance, up in swing); the stand's all but always.
    stand = library.entry("stand")
    standing = evaluate_policy(
        stand.policy, stand.clip, env_cfg=library.shared_policy_settings(["stand"]).env_config(EnvConfig()),
        episodes=2, seconds=1.0, backend="mujoco", seed=0,
    )
    assert standing.contact_agreement > 0.98 > result.contact_agreement > 0.8


def test_eval_counts_each_fall_under_the_terminations_it_met() -> None:
    from gaitlib.envs import EnvConfig
    from gaitlib.evaluation import evaluate_policy
    from gaitlib.library import Library
    from gaitlib.library.layout import shipped_library_dir

    library = Library(shipped_library_dir())
    trot = library.entry("trot")
    result = evaluate_policy(  # pushes far beyond what the trot rides out: most episodes fall, strictly counted
        trot.policy, trot.clip, env_cfg=library.shared_policy_settings(["trot"]).env_config(EnvConfig()),
        episodes=8, seconds=2.0, backend="mujoco", push_max=1500.0, falls=Falls.CONTACT, seed=0,
    )
    falls = round(result.fall_rate * result.episodes)
    causes = result.falls_by_cause
    assert set(causes) == {"body_contact", "trunk_contact", "too_low", "orientation_lost", "diverged"} and falls > 0
    assert all(0 <= n <= falls for n in causes.values()) and sum(causes.values()) >= falls  # each fall has a cause
    assert causes["body_contact"] > 0 and result.falls == "contact"
    # A strict fall is a touch too: every episode that fell touched the ground with a non-foot body or the trunk fell.
    assert result.touch_rate * 8 >= causes["body_contact"] and result.longest_touch_s > 0
    trunk = evaluate_policy(  # the default, the field's: a leg's touch ridden through, only the trunk ends an episode
        trot.policy, trot.clip, env_cfg=library.shared_policy_settings(["trot"]).env_config(EnvConfig()),
        episodes=8, seconds=2.0, backend="mujoco", push_max=1500.0, seed=0,
    )
    assert trunk.falls_by_cause["body_contact"] == 0 and trunk.falls == "trunk"
    trunk_causes = sum(trunk.falls_by_cause[c] for c in ("trunk_contact", "too_low", "orientation_lost", "diverged"))
    assert trunk_causes >= trunk.fall_rate * 8 and trunk.touch_rate > 0
    low, high = trunk.touch_ci95
    assert low <= trunk.touch_rate <= high and trunk.fall_ci95[0] <= trunk.fall_rate <= trunk.fall_ci95[1]
