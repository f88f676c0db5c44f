"""``gaitlib train`` under ``torchrun``: two CPU ranks (gloo) train one gait through rsl-rl's multi-GPU path."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import torch
from cli_runner import gaitlib_quick

from gaitlib.library import Library

TRAIN = ("train", "stand", "--preset", "tiny", "--backend", "mujoco", "--seed", "5", "--eval-episodes", "2",
         "--eval-seconds", "0.5")


def _torchrun(tmp_path, *args: str) -> subprocess.CompletedProcess[str]:
    """``torchrun --nproc-per-node 2 gaitlib ARGS`` on the CPU (no GPU is seen)."""
    command = [
        sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc-per-node", "2",
        "-m", "gaitlib.cli", *args,
    ]
    env = os.environ | {"CUDA_VISIBLE_DEVICES": "", "OMP_NUM_THREADS": "1"}
    return subprocess.run(command, capture_output=True, text=True, timeout=300, env=env, cwd=tmp_path)


def test_two_ranks_train_one_policy_stop_together_and_rank_0_writes_it(tmp_path) -> None:
    # A time limit that ends the run after its first iteration: rank 0 decides when time is up and tells the other,
    # so neither waits for an update the other has left.
    two = _torchrun(tmp_path, *TRAIN, "--iterations", "50", "--minutes", "0.0001", "--library", "two",
                    "--run-dir", "runs/two")
    assert two.returncode == 0, two.stderr[-3000:]
    assert two.stderr.count("wrote ") == 1  # rank 0 alone reports
    meta = json.loads((tmp_path / "two" / "stand" / "metadata.json").read_text())
    assert meta["training"]["iterations"] == 1
    # The ranks ended with the same weights (gradients averaged at every update), each from its own 4 worlds.
    assert meta["training"]["distributed"] == {"world_size": 2, "parameters_in_sync": True}
    assert meta["training"]["samples"] == 2 * 4 * 8 * 1  # ranks x worlds x steps x iterations
    assert sorted(p.name for p in (tmp_path / "runs" / "two" / "checkpoints").iterdir()) == ["latest.pt"]

    one = gaitlib_quick(*TRAIN, "--iterations", "1", "--library", str(tmp_path / "one"), "--run-dir",
                        str(tmp_path / "r1"))
    assert one.returncode == 0, one.stderr[-3000:]
    single = Library(tmp_path / "one").entry("stand").policy.actor.state_dict()
    pair = Library(tmp_path / "two").entry("stand").policy.actor.state_dict()
    # The same seed alone learns something else: rank 1's samples took part in the update.
    assert any(not torch.equal(single[k], pair[k]) for k in single if k.startswith("mlp"))
