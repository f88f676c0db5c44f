"""benchmarks/gpu_check.py runs end to end: at tiny sizes on the CPU, every measurement is a line of real figures (in
this process, which has imported Newton already: a fresh interpreter would spend seconds on it again); without CUDA
at its real sizes, the script prints every measurement as an error line on stdout and the check goes on."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from benchmarks import gpu_check

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "gpu_check.py"


def run_check(*args: str) -> tuple[int, list[dict[str, object]]]:
    done = subprocess.run(
        [sys.executable, str(SCRIPT), *args],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
        cwd=SCRIPT.parents[1],
    )
    lines = [json.loads(line) for line in done.stdout.splitlines()]  # nothing but JSON lines on stdout
    return done.returncode, lines


def test_tiny_check_measures_everything_on_the_cpu() -> None:
    lines = list(gpu_check.check(gpu_check.TINY))
    assert [line["measure"] for line in lines] == ["sim", "parity", "train", "collect"]
    assert not [line for line in lines if "error" in line]
    assert not [line for line in lines if gpu_check.has_failed(line)]  # the script's exit status: 0
    assert all(line["device"] == "cpu" and line["seconds"] > 0 for line in lines)
    sims, parity, train, collect = lines[:1], lines[1], lines[2], lines[3]

    assert [line["worlds"] for line in sims] == [8]
    for line in sims:
        assert line["backend"] == "newton" and line["substeps"] == 8
        assert line["env_steps_per_s"] > 0 and line["raw_eager_steps_per_s"] > 0
        assert line["raw_steps_per_s"] == max(line["raw_eager_steps_per_s"], line["raw_graph_steps_per_s"])
        assert line["ratio"] == pytest.approx(line["env_steps_per_s"] / line["raw_steps_per_s"], rel=0.01, abs=1e-3)

    assert parity["passed"] is True and parity["failed_cases"] == []
    assert 0 < parity["max_root_pos_diff_m"] < 2e-3 and parity["foot_contact_mismatches"] == 0

    assert train["backend"] == "mujoco" and train["preset"] == "tiny" and train["worlds"] == 4
    assert train["iterations"] >= 1
    assert train["samples"] == train["iterations"] * 4 * 8  # tiny preset: 4 worlds x 8 steps per iteration
    assert train["samples_per_s"] > 0

    assert collect["worlds"] == 8 and collect["backend"] == "mujoco"
    assert collect["samples_per_s"] > 0 and collect["steps_per_sample"] > 0


@pytest.mark.skipif(
    torch.cuda.is_available(),
    reason="a CUDA GPU is here: the real-size check would run for minutes instead of reporting that CUDA is missing "
    "(run benchmarks/gpu_check.py itself)",
)
def test_real_size_check_without_cuda_reports_each_measurement_as_an_error() -> None:
    returncode, lines = run_check()
    assert [line["measure"] for line in lines] == ["sim", "sim", "parity", "train", "collect"]
    assert [line["worlds"] for line in lines] == [1024, 4096, 2, None, 4096]  # training's worlds come from its preset
    assert all(
        line["error"] == "RuntimeError: CUDA is not available here; on the CPU run with --tiny" for line in lines
    )
    assert returncode == 1
