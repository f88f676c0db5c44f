"""``gaitlib train`` and ``gaitlib eval`` end to end through the console entry point."""

from __future__ import annotations

import json
import math
import subprocess
import sys

from cli_runner import gaitlib, gaitlib_quick


def test_train_then_eval_json(tmp_path) -> None:
    library, runs = tmp_path / "library", str(tmp_path / "runs")
    trained = gaitlib_quick(  # in this process: the training runs in a fresh one in the Ctrl-C test below
        "train", "stand", "--preset", "tiny", "--iterations", "2", "--seed", "3", "--eval-episodes", "2",
        "--eval-seconds", "2", "--library", str(library), "--run-dir", runs,
    )
    assert trained.returncode == 0, trained.stderr
    assert "after 2 iterations, 64 samples" in trained.stderr and "falls 0.000 (trunk), touches" in trained.stderr
    assert "gaitlib: reference check of stand: 0.0 deg of roll and 0.0 deg of pitch" in trained.stderr
    meta = json.loads((library / "stand" / "metadata.json").read_text())
    assert meta["training"]["preset"]["name"] == "tiny" and meta["training"]["iterations"] == 2
    assert [row[0] for row in meta["training"]["curve"]["rows"]] == [1, 2]
    # The training evaluation (2 episodes x 2 s, seed + 1) is reproduced exactly by the saved policy in a new
    # process: the entry holds the trained weights and normalizer, and evaluation depends on its seed alone.
    evaluated = gaitlib("eval", "stand", "--library", str(library), "--episodes", "2", "--seconds", "2", "--seed", "4",
                        "--json")
    assert evaluated.returncode == 0, evaluated.stderr
    report = json.loads(evaluated.stdout)
    assert report == {"gait": "stand"} | meta["evaluation"]
    assert report["episodes"] == 2 and report["seconds"] == 2.0 and math.isfinite(report["joint_rmse"])


def test_unknown_gait_is_one_error_line(tmp_path) -> None:
    result = gaitlib_quick("train", "moonwalk", "--library", str(tmp_path))
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        "gaitlib: error: unknown gait 'moonwalk' (known: bound, catch, pace, pace_slow, pronk, sidestep_left, "
        "sidestep_right, stand, trot, trot_back, trot_in_place, trot_left, trot_right, trot_slow, turn_left, "
        "turn_right, walk)"
    ]


def test_eval_of_a_missing_entry_is_one_error_line(tmp_path) -> None:
    result = gaitlib_quick("eval", "pace", "--library", str(tmp_path))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gaitlib: error: no library entry for gait 'pace'")


def test_unknown_preset_is_one_error_line(tmp_path) -> None:
    result = gaitlib_quick("train", "stand", "--preset", "gpu-cluster", "--library", str(tmp_path))
    assert result.returncode == 2
    assert result.stderr.strip() == "gaitlib: error: unknown preset 'gpu-cluster' (known: cpu, paper, tiny)"


def test_ctrl_c_saves_a_checkpoint_and_resume_continues(tmp_path) -> None:
    import signal
    import time

    import torch

    library, runs = tmp_path / "library", tmp_path / "runs"
    args = ["train", "stand", "--preset", "tiny", "--iterations", "100000", "--checkpoint-every", "1",
            "--eval-episodes", "2", "--eval-seconds", "0.5", "--library", str(library), "--run-dir", str(runs)]
    process = subprocess.Popen(
        [sys.executable, "-c", "from gaitlib.cli import main; main()", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # Ctrl-C's default action, even where this suite runs as a background job (which inherits SIGINT ignored,
        # and so would let the training run on)
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
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
    done = saved["iter"]
    assert done >= 1 and saved["infos"]["samples"] == done * 32 and not (library / "stand").exists()
    resumed = gaitlib_quick("train", "stand", "--preset", "tiny", "--iterations", str(done + 1), "--resume",
                            "--eval-episodes", "2", "--eval-seconds", "0.5", "--library", str(library), "--run-dir",
                            str(runs))
    assert resumed.returncode == 0, resumed.stderr
    assert f"after {done + 1} iterations, {(done + 1) * 32:,} samples" in resumed.stderr
