"""``gaitlib throughput sim`` end to end, through the console entry point."""

from __future__ import annotations

import json
import re

import pytest
from cli_runner import gaitlib, gaitlib_quick

EXPECTED_KEYS = {"backend", "worlds", "control_hz", "substeps", "env_steps_per_s", "raw_steps_per_s", "ratio"}



def test_throughput_sim_prints_one_json_object() -> None:
    result = gaitlib("throughput", "sim", "--backend", "mujoco", "--worlds", "8", "--seconds", "0.4", "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report.keys() >= EXPECTED_KEYS
    assert report["backend"] == "mujoco" and report["worlds"] == 8 and report["substeps"] == 8
    assert report["env_steps_per_s"] > 0 and report["raw_steps_per_s"] > 0
    assert report["ratio"] == report["env_steps_per_s"] / report["raw_steps_per_s"]


def test_unknown_backend_is_one_error_line() -> None:
    result = gaitlib_quick("throughput", "sim", "--backend", "bullet", "--worlds", "2")
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        "gaitlib: error: unknown backend 'bullet' (known: auto, mujoco, newton)"
    ]


def test_zero_worlds_is_one_error_line() -> None:
    result = gaitlib_quick("throughput", "sim", "--worlds", "0")
    assert result.returncode == 2
    assert result.stderr.strip() == "gaitlib: error: --worlds must be a whole number in [1, 65536], got 0"


def test_help_lists_only_working_commands() -> None:
    result = gaitlib_quick("--help")
    assert result.returncode == 0
    panel = result.stdout.split("Commands")[1]
    listed = set(re.findall(r"^│ ([a-z][\w-]*) ", panel, flags=re.MULTILINE))
    assert listed == {
        "benchmark", "throughput", "collect", "drive", "eval", "fit", "gaits", "library", "map", "mirror", "routes",
        "run", "states", "survival", "train",
    }


@pytest.mark.newton
def test_throughput_sim_newton_stdout_is_only_the_json_object() -> None:
    result = gaitlib("throughput", "sim", "--backend", "newton", "--worlds", "2", "--seconds", "0.3", "--json")
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["backend"] == "newton"
