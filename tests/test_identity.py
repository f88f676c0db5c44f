"""A run's identity is the content of everything it reads: a resumed training run with another gait description,
states file or recipe is refused naming what differs, before any simulation; a checkpoint that cannot be resumed
gives advice that agrees with the refusal of a fresh run in its folder."""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import pytest
import torch
from cli_runner import gaitlib_quick

from gaitlib.errors import GaitlibError
from gaitlib.gaits import get_gait
from gaitlib.training import get_preset
from gaitlib.training.recipe import Recipe
from gaitlib.training.trainer import TrainRequest, train_gait
from gaitlib.transitions.states import StatesConfig, record_states

SMALL = StatesConfig(per_gait=4, num_worlds=2, warmup_s=0.2, spacing_s=0.1, backend="mujoco")


def request(tmp_path, **kw) -> TrainRequest:
    base = {
        "description": get_gait("stand"), "preset": get_preset("tiny"), "iterations": 1,
        "library": tmp_path / "library", "run_dir": tmp_path / "runs" / "stand", "backend": "mujoco",
        "checkpoint_every": 1, "eval_episodes": 1, "eval_seconds": 0.3,
    }
    return TrainRequest(**(base | kw))


@pytest.fixture(scope="module")
def states_files(tiny_library, tmp_path_factory):
    """Two handover-states files of the tiny library, recorded with different seeds: the same gaits, other states."""
    folder = tmp_path_factory.mktemp("states")
    paths = folder / "a.npz", folder / "b.npz"
    for seed, path in enumerate(paths):
        record_states(tiny_library, config=dataclasses.replace(SMALL, seed=seed)).save(path)
    assert paths[0].read_bytes() != paths[1].read_bytes()
    return paths


@pytest.fixture(scope="module")
def started(tmp_path_factory, states_files):
    """A run of one iteration with the first states file: its folder holds ``latest.pt``."""
    tmp_path = tmp_path_factory.mktemp("started")
    train_gait(request(tmp_path, states=states_files[0], switch_start=0.4))
    return tmp_path


def _resume(started, tmp_path, **kw):
    """Resume a copy of the started run (each test its own, so that none changes another's) with ``kw`` changed."""
    shutil.copytree(started / "runs", tmp_path / "runs")
    return train_gait(request(tmp_path, iterations=2, resume=True, library=started / "library", **kw))


def test_resume_with_another_gait_description_names_the_field(started, states_files, tmp_path) -> None:
    taller = dataclasses.replace(get_gait("stand"), body_height=0.30)
    with pytest.raises(GaitlibError) as refused:
        _resume(started, tmp_path, description=taller, states=states_files[0], switch_start=0.4)
    message = str(refused.value)
    assert "--gait-file: body_height 0.26 then, 0.3 now" in message and "\n" not in message
    assert not (tmp_path / "runs" / "stand" / "events").exists()
    assert sorted(p.name for p in (tmp_path / "runs" / "stand" / "checkpoints").iterdir()) == ["latest.pt",
                                                                                                "model_1.pt"]


def test_resume_with_another_states_file_is_refused(started, states_files, tmp_path) -> None:
    with pytest.raises(GaitlibError, match=r"--states: the file's content differs \(SHA-256 [0-9a-f]{12} then, "):
        _resume(started, tmp_path, states=states_files[1], switch_start=0.4)


def test_resume_with_the_same_content_under_another_name_continues(started, states_files, tmp_path) -> None:
    copy = tmp_path / "renamed.npz"
    shutil.copyfile(states_files[0], copy)
    result = _resume(started, tmp_path / "run", states=copy, switch_start=0.4)
    assert result.iterations == 2


def test_resume_with_another_recipe_names_the_option(started, states_files, tmp_path) -> None:
    with pytest.raises(GaitlibError, match=r"of another training run: --gamma: gamma 0.99 then, 0.95 now; "):
        _resume(started, tmp_path, states=states_files[0], switch_start=0.4, recipe=Recipe(gamma=0.95))


def test_resume_on_other_worlds_is_refused_and_a_record_from_before_worlds_were_recorded_continues(
    started, states_files, tmp_path
) -> None:
    tiny = get_preset("tiny")
    with pytest.raises(GaitlibError, match=r"of another training run: --worlds: worlds 4 then, 8 now; "):
        _resume(started, tmp_path, states=states_files[0], switch_start=0.4,
                preset=dataclasses.replace(tiny, num_envs=8))
    old = tmp_path / "old"
    shutil.copytree(started / "runs", old / "runs")
    latest = old / "runs" / "stand" / "checkpoints" / "latest.pt"
    saved = torch.load(latest, weights_only=True)
    del saved["infos"]["worlds"]  # as a checkpoint from before --worlds: every run had its preset's worlds
    torch.save(saved, latest)
    result = train_gait(request(old, iterations=2, resume=True, library=started / "library", states=states_files[0],
                                switch_start=0.4))
    assert result.iterations == 2


def test_a_checkpoint_without_content_identity_is_refused(started, states_files, tmp_path) -> None:
    shutil.copytree(started / "runs", tmp_path / "runs")
    latest = tmp_path / "runs" / "stand" / "checkpoints" / "latest.pt"
    saved = torch.load(latest, weights_only=True)
    for key in ("description", "states_sha256"):  # as a checkpoint from before they were recorded
        del saved["infos"][key]
    torch.save(saved, latest)
    with pytest.raises(GaitlibError, match="records no content of its gait description or states file"):
        train_gait(request(tmp_path, iterations=2, resume=True, library=started / "library",
                           states=states_files[0], switch_start=0.4))


def test_advice_for_a_truncated_checkpoint_does_not_contradict_itself(started, tmp_path) -> None:
    shutil.copytree(started / "runs", tmp_path / "runs")
    latest = tmp_path / "runs" / "stand" / "checkpoints" / "latest.pt"
    latest.write_bytes(latest.read_bytes()[:100])
    args = ["train", "stand", "--preset", "tiny", "--iterations", "2", "--library", str(tmp_path / "lib"),
            "--run-dir", str(tmp_path / "runs" / "stand"), "--backend", "mujoco"]
    afresh, resumed = gaitlib_quick(*args), gaitlib_quick(*args, "--resume")
    advice = f"give this run its own --run-dir, or remove {latest} to start over in its folder"
    for refused in (afresh, resumed):
        assert refused.returncode == 2 and refused.stderr.count("\n") == 1, refused.stderr
        assert "is unreadable" in refused.stderr and advice in refused.stderr
        assert "--resume" not in refused.stderr and "afresh" not in refused.stderr
    assert not (tmp_path / "lib").exists()


def test_the_command_line_refuses_a_changed_gait_file_in_one_line(started, states_files, tmp_path) -> None:
    from gaitlib import gaits

    shutil.copytree(started / "runs", tmp_path / "runs")
    shipped = (Path(gaits.__file__).parent / "descriptions" / "stand.toml").read_text()
    taller = tmp_path / "stand.toml"
    taller.write_text(shipped.replace("body_height = 0.26", "body_height = 0.30"))
    assert taller.read_text() != shipped
    refused = gaitlib_quick("train", "stand", "--preset", "tiny", "--iterations", "2", "--resume", "--gait-file",
                            str(taller), "--states", str(states_files[0]), "--switch-start", "0.4", "--library",
                            str(started / "library"), "--run-dir", str(tmp_path / "runs" / "stand"), "--backend",
                            "mujoco")
    assert refused.returncode == 2 and refused.stderr.count("\n") == 1, refused.stderr
    assert "--gait-file: body_height 0.26 then, 0.3 now" in refused.stderr
