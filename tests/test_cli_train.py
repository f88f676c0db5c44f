"""``gaitlib train`` and ``gaitlib eval`` end to end through the console entry point."""

from __future__ import annotations

import json
import subprocess
import sys

from cli_runner import gaitlib


def test_train_then_eval_json(tmp_path) -> None:
    library, runs = str(tmp_path / "library"), str(tmp_path / "runs")
    trained = gaitlib(
        "train", "stand", "--iterations", "1", "--eval-episodes", "2", "--library", library, "--run-dir", runs
    )
    assert trained.returncode == 0, trained.stderr
    assert "wrote" in trained.stderr and "fall rate" in trained.stderr
    evaluated = gaitlib("eval", "stand", "--library", library, "--episodes", "3", "--seconds", "0.5", "--json")
    assert evaluated.returncode == 0, evaluated.stderr
    report = json.loads(evaluated.stdout)
    assert report["gait"] == "stand" and report["episodes"] == 3
    assert 0.0 <= report["fall_rate"] <= 1.0 and report["joint_rmse"] >= 0.0


def test_unknown_gait_is_one_error_line(tmp_path) -> None:
    result = gaitlib("train", "moonwalk", "--library", str(tmp_path))
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        "gaitlib: error: unknown gait 'moonwalk' (known: bound, pace, pronk, stand, trot, walk)"
    ]


def test_eval_of_a_missing_entry_is_one_error_line(tmp_path) -> None:
    result = gaitlib("eval", "pace", "--library", str(tmp_path))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gaitlib: error: no library entry for gait 'pace'")


def test_unknown_preset_is_one_error_line(tmp_path) -> None:
    result = gaitlib("train", "stand", "--preset", "gpu-cluster", "--library", str(tmp_path))
    assert result.returncode == 2
    assert result.stderr.strip() == "gaitlib: error: unknown preset 'gpu-cluster' (known: cpu, paper, tiny)"


def test_ctrl_c_saves_a_checkpoint_and_resume_continues(tmp_path) -> None:
    import signal
    import time

    import torch

    library, runs = tmp_path / "library", tmp_path / "runs"
    args = ["train", "stand", "--iterations", "1000", "--checkpoint-every", "1", "--eval-episodes", "2",
            "--library", str(library), "--run-dir", str(runs)]
    process = subprocess.Popen(
        [sys.executable, "-c", "from gaitlib.cli import main; main()", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    latest = runs / "checkpoints" / "latest.pt"
    deadline = time.monotonic() + 300
    while not latest.exists() and time.monotonic() < deadline:
        time.sleep(0.5)
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=300)
    assert process.returncode == 130
    assert stderr.strip().splitlines()[-1].startswith("gaitlib: interrupted; finished work is saved")
    saved = torch.load(latest, weights_only=False)
    assert saved["iteration"] >= 1 and not (library / "stand").exists()
    resumed = gaitlib("train", "stand", "--iterations", str(saved["iteration"] + 1), "--resume",
                      "--eval-episodes", "2", "--library", str(library), "--run-dir", str(runs))
    assert resumed.returncode == 0, resumed.stderr
    assert f"after {saved['iteration'] + 1} iterations" in resumed.stderr
