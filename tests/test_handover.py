"""Switch-start training: handover states recorded from running gaits, handed over exactly as a switch hands a robot
over, a share of training resets starting from them, and the entry saying how it was trained."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest
import torch
from cli_runner import gaitlib_quick

from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs.handover import HandoverStates, load_states
from gaitlib.errors import GaitlibError
from gaitlib.gaits import clip_from_description, get_gait
from gaitlib.library.policy import per_gait
from gaitlib.sim import make_backend
from gaitlib.training import get_preset
from gaitlib.training.trainer import TrainRequest, train_gait
from gaitlib.transitions.states import StatesConfig, record_states

SMALL = StatesConfig(per_gait=12, num_worlds=4, warmup_s=0.2, spacing_s=0.1, push_max=100.0, backend="mujoco")


@pytest.fixture(scope="module")
def states(tiny_library, tmp_path_factory):
    """Handover states of the tiny library's stand and trot, written and read back."""
    path = tmp_path_factory.mktemp("states") / "states.npz"
    record_states(tiny_library, config=SMALL).save(path)
    return path


def test_recorded_states_cover_each_gait_and_its_cycle_and_read_back(states, tiny_library) -> None:
    loaded, sha = load_states(states)
    assert loaded.gaits == ("stand", "trot") and loaded.identities == tiny_library.identities()
    assert np.bincount(loaded.source).tolist() == [12, 12] and len(sha) == 64
    assert loaded.settings["push_max"] == 100.0 and loaded.settings["warmup_s"] == 0.2
    assert np.ptp(loaded.phase[loaded.source == 1]) > 0.3  # snapshots at random moments, not one phase
    upright = loaded.root_quat
    assert np.allclose(np.linalg.norm(upright, axis=1), 1, atol=1e-5)
    yaw = np.arctan2(2 * (upright[:, 0] * upright[:, 3] + upright[:, 1] * upright[:, 2]),
                     1 - 2 * (upright[:, 2] ** 2 + upright[:, 3] ** 2))
    assert np.abs(yaw).max() < 1e-5  # stored heading-free
    frames = loaded.history
    assert not np.allclose(frames[:, 0], frames[:, 1])  # a real history, not a reset's repeated frame


def test_a_handover_gives_the_policy_what_a_switch_would(tiny_library) -> None:
    clips = [e.clip for e in tiny_library.entries()]
    cfg = tiny_library.shared_policy_settings().env_config(EnvConfig(episode_seconds=100.0))
    policies = [e.policy for e in tiny_library.entries()]
    source = ImitationEnv(make_backend("mujoco", num_worlds=2), clips, cfg, seed=3)
    source.reset_worlds(torch.arange(2), gait=torch.tensor([1, 1]))  # both trot
    with torch.inference_mode():
        for _ in range(8):
            source.step(per_gait(policies, source.gait, source.get_observations()))
    ids, dest, phase = torch.tensor([0, 1]), torch.tensor([0, 0]), torch.tensor([0.25, 0.7])
    handed = {k: v.cpu().numpy() for k, v in source.handover_states(ids).items()}
    source.switch(ids, dest, phase)  # the meta-controller's handover: trot to stand
    expected = source.get_observations().policy

    taker = ImitationEnv(make_backend("mujoco", num_worlds=2), clips, cfg, seed=9)  # other dynamics, other start
    taker.reset_worlds(ids, gait=dest)
    recorded = HandoverStates(gaits=("stand", "trot"), identities={}, settings={}, **handed)
    taker.hand_over(ids, recorded, phase)
    torch.testing.assert_close(taker.get_observations().policy, expected, atol=1e-5, rtol=1e-5)
    assert taker.gait.tolist() == [0, 0]
    torch.testing.assert_close(taker.sim_state.joint_vel, source.sim_state.joint_vel)


def test_the_same_recording_writes_the_same_bytes(states, tiny_library, tmp_path) -> None:
    again = record_states(tiny_library, config=SMALL).save(tmp_path / "again.npz")
    assert again.read_bytes() == states.read_bytes()  # a rerun here reproduces the SHA-256 training records
    assert {member.date_time for member in zipfile.ZipFile(again).infolist()} == {(1980, 1, 1, 0, 0, 0)}  # no clock


def test_a_share_of_resets_starts_from_handover_states(states) -> None:
    loaded, _ = load_states(states)
    trot_only = loaded.select(loaded.rows(exclude="stand"))
    clips = [clip_from_description(get_gait("stand"))]
    sim = make_backend("mujoco", num_worlds=16)
    env = ImitationEnv(sim, clips, EnvConfig(), handover=trot_only, handover_share=0.5)
    history = env._history  # frames differ within a handed-over history, not within a reset's
    handed = (~torch.isclose(history[:, 0], history[:, 1]).all(dim=1)).sum().item()
    assert 2 <= handed <= 14
    with pytest.raises(ValueError, match="handover_share must be in"):
        ImitationEnv(make_backend("mujoco", num_worlds=1), env.clips, EnvConfig(), handover_share=0.5)


def test_switch_start_training_records_how_it_was_trained(states, tmp_path) -> None:
    result = train_gait(
        TrainRequest(
            description=get_gait("stand"), preset=get_preset("tiny"), iterations=2, library=tmp_path / "lib",
            run_dir=tmp_path / "runs", backend="mujoco", eval_episodes=1, eval_seconds=0.3, states=states,
            switch_start=0.5,
        )
    )
    record = json.loads((result.entry / "metadata.json").read_text())["training"]["switch_start"]
    assert record["share"] == 0.5 and record["from_gaits"] == ["trot"] and record["states_used"] == 12
    assert record["states_sha256"] == load_states(states)[1]
    plain = train_gait(
        TrainRequest(
            description=get_gait("trot"), preset=get_preset("tiny"), iterations=1, library=tmp_path / "lib",
            run_dir=tmp_path / "runs-trot", backend="mujoco", eval_episodes=1, eval_seconds=0.3,
        )
    )
    assert json.loads((plain.entry / "metadata.json").read_text())["training"]["switch_start"] is None


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--switch-start", "0.3"], "--switch-start needs --states FILE"),
        (["--switch-start", "1.5"], "--switch-start"),
    ],
)
def test_bad_switch_start_requests_are_one_line(tmp_path, args, message) -> None:
    result = gaitlib_quick("train", "stand", "--preset", "tiny", "--library", str(tmp_path / "lib"), *args)
    assert result.returncode == 2 and message in result.stderr and result.stderr.count("\n") == 1
    assert not (tmp_path / "lib").exists()


def test_states_of_the_trained_gait_alone_are_refused(tiny_library, tmp_path) -> None:
    path = tmp_path / "stand.npz"
    record_states(tiny_library, gaits=["stand", "trot"], config=SMALL).save(path)
    loaded, _ = load_states(path)
    loaded.select(loaded.rows(exclude="trot")).save(path)  # stand's states only
    with pytest.raises(GaitlibError, match="holds no state of a gait other than stand"):
        train_gait(
            TrainRequest(
                description=get_gait("stand"), preset=get_preset("tiny"), iterations=1, library=tmp_path / "lib",
                run_dir=tmp_path / "runs", backend="mujoco", states=path, switch_start=0.5,
            )
        )
    path.write_bytes(b"not a states file")
    with pytest.raises(GaitlibError, match="is not a readable handover-states file"):
        load_states(path)


def test_the_commands_record_states_and_train_from_them(tiny_library, tmp_path) -> None:
    out = tmp_path / "states.npz"
    recorded = gaitlib_quick("states", "--per-gait", "4", "--worlds", "4", "--backend", "mujoco", "--library",
                             str(tiny_library.root), "--out", str(out))
    assert recorded.returncode == 0, recorded.stderr
    assert f"{out}: 8 handover states of stand, trot" in recorded.stderr
    trained = gaitlib_quick("train", "stand", "--preset", "tiny", "--iterations", "1", "--eval-episodes", "1",
                            "--eval-seconds", "0.5", "--states", str(out), "--library", str(tmp_path / "lib"),
                            "--run-dir", str(tmp_path / "r"), "--backend", "mujoco")
    assert trained.returncode == 0, trained.stderr
    meta = json.loads((tmp_path / "lib" / "stand" / "metadata.json").read_text())
    assert meta["training"]["switch_start"]["share"] == 0.4  # the default with --states
