"""``gaitlib run`` and ``gaitlib benchmark`` end to end on a tiny library (the README's main job on the shipped library:
test_user_library.py, in a fresh clone, and test_packaging.py, from the installed wheel)."""

from __future__ import annotations

import functools
import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from cli_runner import gaitlib, gaitlib_quick


def _strict(text: str) -> dict:
    """``text`` parsed as JSON that has no NaN or Infinity (RFC 8259; Python's reader would take them)."""

    def refuse(constant: str):
        raise ValueError(f"{constant} is not JSON")

    return json.loads(text, parse_constant=refuse)


def test_run_writes_its_plot_and_reports_the_switch(switching_library, tmp_path) -> None:
    plot = tmp_path / "run.png"
    result = gaitlib_quick(
        "run", "--from", "trot", "--to", "stand", "--strategy", "tmt", "--request-at", "0.5", "--hold", "1.0",
        "--plot", str(plot), "--library", str(switching_library), "--backend", "mujoco", "--json",
    )
    assert result.returncode == 0, result.stderr
    report = _strict(result.stdout)
    assert report["from"] == "trot" and report["to"] == ["stand"] and report["strategy"] == "tmt"
    assert report["requests_s"] == [pytest.approx(0.5)] and len(report["switches"]) <= 1
    assert all(s["switch_s"] >= 0.5 - 1e-9 and (s["from"], s["to"]) == ("trot", "stand") for s in report["switches"])
    assert isinstance(report["stayed_up"], bool)
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_run_prints_random_s_switch_without_a_score(switching_library, tmp_path) -> None:
    result = gaitlib_quick(
        "run", "--from", "trot", "--to", "stand", "--strategy", "random", "--request-at", "0.2", "--hold", "0.3",
        "--plot", str(tmp_path / "run.png"), "--library", str(switching_library), "--backend", "mujoco",
    )
    assert result.returncode == 0, result.stderr
    assert "switched at 0.20 s after waiting 0.00 s (random: no score, φn = " in result.stdout


@functools.cache
def _video_support() -> str | None:
    """Why a video cannot be rendered here (found independently of gaitlib), or ``None`` if it can."""
    if importlib.util.find_spec("imageio") is None:
        return "imageio"
    probe = (
        "import mujoco; m = mujoco.MjModel.from_xml_string('<mujoco><worldbody><geom size=\\'1\\'/></worldbody>"
        "</mujoco>'); mujoco.Renderer(m, 32, 32)"
    )
    for platform in ("egl", "osmesa"):
        env = os.environ | {"MUJOCO_GL": platform}
        if subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True).returncode == 0:
            return None
    return "OpenGL"


MISSING = {
    "imageio": "imageio is not installed (pip install 'gaitlib[video]')",
    "OpenGL": "no headless OpenGL (EGL or OSMesa) on this machine",
}
"""What :func:`_video_support` finds missing, in words."""


def _run_with_a_video(library: Path, tmp_path: Path) -> tuple[subprocess.CompletedProcess[str], Path]:
    video = tmp_path / "run.mp4"
    result = gaitlib(
        "run", "--strategy", "random", "--request-at", "0.2", "--hold", "0.3", "--plot", str(tmp_path / "p.png"),
        "--video", str(video), "--library", str(library), "--backend", "mujoco",
    )
    return result, video


def test_run_with_a_video_renders_it(switching_library, tmp_path) -> None:
    missing = _video_support()
    if missing is not None:
        pytest.skip(f"{MISSING[missing]}: gaitlib run --video is not rendered here, only its refusal is tested")
    import imageio

    result, video = _run_with_a_video(switching_library, tmp_path)
    assert result.returncode == 0, result.stderr
    reader = imageio.get_reader(video)
    # Requested at 0.2 s (6 steps), switched in the 7th, held 0.3 s (9 steps) after it: 16 frames at 30 Hz.
    assert reader.count_frames() == 16 and reader.get_data(0).shape == (480, 640, 3)


def test_run_with_a_video_it_cannot_render_says_in_one_line_why_not(switching_library, tmp_path) -> None:
    missing = _video_support()
    if missing is None:
        pytest.skip("imageio and headless OpenGL are both here: the refusal of gaitlib run --video without them is "
                    "not run")
    result, video = _run_with_a_video(switching_library, tmp_path)
    lines = result.stderr.strip().splitlines()
    why = "pip install 'gaitlib[video]'" if missing == "imageio" else "no headless OpenGL"
    assert result.returncode == 2 and len(lines) == 1 and why in lines[0], result.stderr
    assert not video.exists() and not list(tmp_path.glob(".run.mp4*"))


def test_unknown_gait_or_strategy_is_one_error_line(switching_library) -> None:
    for args, message in (
        (("--to", "gallop"), "unknown gait 'gallop'"),
        (("--strategy", "oracle"), "unknown strategy 'oracle'"),
        (("--to", "stand,"), "--to takes gait names separated by commas, got 'stand,'"),
        (("--to", "stand,stand"), "'stand' is requested while the robot already runs it"),
    ):
        result = gaitlib_quick("run", *args, "--library", str(switching_library))
        lines = result.stderr.strip().splitlines()
        assert result.returncode == 2 and len(lines) == 1 and message in lines[0], result.stderr


def test_benchmark_writes_csv_json_and_plot_and_prints_success(switching_library, tmp_path) -> None:
    out = tmp_path / "bench"
    args = [
        "benchmark", "--strategies", "random,tmt-value,net-lookahead", "--magnitudes", "0:100:100", "--samples", "2",
        "--pairs", "stand-trot", "--worlds", "4", "--out", str(out), "--library", str(switching_library),
        "--backend", "mujoco",
    ]
    result = gaitlib_quick(*args, "--json")
    assert result.returncode == 0, result.stderr
    success = _strict(result.stdout)["success"]
    assert set(success) == {"random", "tmt-value", "net-lookahead"}
    assert set(success["random"]) == {"stand-trot"} and set(success["random"]["stand-trot"]) == {"0", "100"}
    assert all(0.0 <= v <= 1.0 for v in success["tmt-value"]["stand-trot"].values())
    assert {p.name for p in out.iterdir()} >= {"results.json", "results.csv", "success.png", "matrix.png"}
    again = gaitlib_quick(*args)  # everything is done: it only reports
    assert again.returncode == 0 and "mean success over push magnitudes" in again.stdout
    row = next(line for line in again.stdout.splitlines() if "stand-trot" in line and "│" in line)
    assert len([cell for cell in row.split("│") if cell.strip()]) == 4, again.stdout  # the pair, three strategies
    margin = next(line for line in again.stdout.splitlines() if line.startswith("net-lookahead on stand-trot: vs"))
    assert "vs random" in margin and margin.endswith("percentage points (95%)"), again.stdout


def test_benchmark_rejects_a_bad_magnitude_range(switching_library) -> None:
    result = gaitlib_quick("benchmark", "--magnitudes", "0:500", "--library", str(switching_library))
    assert result.returncode == 2 and "--magnitudes" in result.stderr.strip().splitlines()[0]


def test_throughput_collect_reports_a_ratio_against_the_environment_step(switching_library) -> None:
    result = gaitlib_quick(
        "throughput", "collect", "--worlds", "4", "--seconds", "1", "--chunk", "4", "--library", str(switching_library),
        "--json",
    )
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["env_steps_per_s"] > 0 and report["samples_per_s"] > 0 and report["steps_per_sample"] > 1
    expected = report["samples_per_s"] * report["steps_per_sample"] / report["env_steps_per_s"]
    assert report["ratio"] == pytest.approx(expected)
