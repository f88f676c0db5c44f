"""``gaitlib drive``: a command timeline on the real simulator with the shipped library, the nearest skill, the
switch through the meta-controller, the commanded path, and bad input refused in one line (the closed loop to
waypoints: ``test_drive_closed_loop.py``)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from cli_runner import gaitlib, gaitlib_quick

from gaitlib.meta.commands import Commands

SHIPPED = Path(__file__).resolve().parents[1] / "library"
HEADER = "time_s,forward,lateral,yaw_rate\n"


def _shipped_speeds() -> dict[str, float]:
    """The forward speed of each shipped gait that neither sidesteps nor turns, read from its entry's metadata (the
    steering skills are farther than 0.2 m/s from the commands below)."""
    speeds = {}
    for path in sorted(SHIPPED.glob("*/metadata.json")):
        description = json.loads(path.read_text())["description"]
        straight = description.get("lateral_speed", 0.0) == 0.0 and description.get("yaw_rate", 0.0) == 0.0
        if straight and description.get("task", "imitation") != "catch":  # the catch skill is no commanded skill
            speeds[path.parent.name] = description["forward_speed"]
    return speeds


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_a_timeline_requests_the_nearest_skill_and_switches_through_the_controller(tmp_path) -> None:
    speeds = _shipped_speeds()
    commanded = [0.8, 0.1]  # between the walk and the pace, then near standing
    nearest = [min(speeds, key=lambda g, v=v: (abs(speeds[g] - v), g)) for v in commanded]
    assert nearest == ["walk", "stand"]  # the walk (0.71 m/s) is nearer 0.8 m/s than the pace (0.9 m/s)
    commands = _write(tmp_path / "c.csv", HEADER + "0,0.8,0,0\n0.5,0.1,0,0\n1.5,0,0,0\n")
    plot = tmp_path / "drive.png"
    result = gaitlib("drive", "--commands", str(commands), "--plot", str(plot), "--backend", "mujoco", "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert [row["skill"] for row in report["commands"]] == nearest
    assert [row["skill_distance"] for row in report["commands"]] == pytest.approx(
        [abs(speeds[g] - v) for g, v in zip(nearest, commanded, strict=True)])
    assert report["strategy"] == "net-lookahead" and report["requests_s"] == [pytest.approx(0.5)]
    assert report["requested"] == ["stand"]
    if report["stayed_up"] or report["fell_s"] > 2.5:
        (switch,) = report["switches"]  # through the controller: within its deadline of the request
        assert (switch["from"], switch["to"]) == ("walk", "stand")
        assert 0.5 - 1e-9 <= switch["switch_s"] <= 2.5 and switch["request_s"] == pytest.approx(0.5)
    steps = len(report["path"]) - 1
    assert steps == (45 if report["stayed_up"] else round(report["fell_s"] * 30))
    assert report["path"][0][0] == 0 and report["path"][-1][0] == pytest.approx(steps / 30, abs=1e-3)
    walked = np.array(report["path"])[:16, 1:3]  # the first 0.5 s, in the walk: the robot moves
    assert np.linalg.norm(walked[-1] - walked[0]) > 0.1
    assert report["end_reached"] == pytest.approx(report["path"][-1][1:3], abs=1e-3)
    assert report["path_length_m"] == pytest.approx(0.8 * 0.5 + 0.1 * 1.0, rel=1e-3)
    assert {"stayed_up", "fell_s", "touches", "longest_touch_s", "velocity_error_rms", "end_error_m",
            "falls"} <= set(report)
    guard = report["guard"]  # the shipped library holds a survival estimate: a drive guards by default
    assert guard["on"] is True and guard["why_off"] is None and isinstance(guard["catches"], list)
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_random_switches_at_the_command_time(tmp_path) -> None:
    commands = _write(tmp_path / "c.csv", HEADER + "0,1.4,0,0\n0.4,0,0,0\n0.8,0,0,0\n")
    result = gaitlib_quick("drive", "--commands", str(commands), "--strategy", "random", "--plot",
                           str(tmp_path / "d.png"), "--backend", "mujoco", "--json", "--seed", "3")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert [row["skill"] for row in report["commands"]] == ["trot", "stand"]
    if report["stayed_up"]:
        (switch,) = report["switches"]
        assert (switch["from"], switch["to"]) == ("trot", "stand")
        assert switch["switch_s"] == pytest.approx(0.4) and switch["wait_s"] == 0.0


def test_the_commanded_path_integrates_lines_and_arcs() -> None:
    commands = Commands(time_s=np.array([0.0, 2.0, 2.0 + math.pi, 3.0 + math.pi]),
                        velocity=np.array([[0.5, 0.0, 0.0], [0.5, 0.0, 0.5], [0.0, -0.3, 0.0]]))
    path = commands.path(0.001)
    # 1 m ahead, a quarter circle of 1 m radius to the left, then 0.3 m to the robot's right (now +x)
    assert path[2000] == pytest.approx([1.0, 0.0, 0.0], abs=1e-9)
    assert path[-1] == pytest.approx([2.3, 1.0, math.pi / 2], abs=2e-3)


@pytest.mark.parametrize(
    ("name", "text", "says"),
    [
        ("empty.csv", "", "is empty"),
        ("header.csv", "t,forward,lateral,yaw_rate\n0,1,0,0\n1,0,0,0\n", "the header is 't,forward,lateral,yaw_rate'"),
        ("word.csv", HEADER + "0,fast,0,0\n1,0,0,0\n", "line 2 is not numbers"),
        ("nan.csv", HEADER + "0,1,0,0\n1,nan,0,0\n", "line 3 holds a value that is not finite"),
        ("inf.csv", HEADER + "0,1,0,inf\n1,0,0,0\n", "line 2 holds a value that is not finite"),
        ("short.csv", HEADER + "0,1,0\n1,0,0,0\n", "line 2 has 3 fields"),
        ("order.csv", HEADER + "0,1,0,0\n2,0,0,0\n2,0,0,0\n", "row 3 (2 s) does not come after row 2 (2 s)"),
        ("late.csv", HEADER + "0.5,1,0,0\n1,0,0,0\n", "the drive starts with it at 0 s"),
        ("one.csv", HEADER + "0,1,0,0\n", "at least two rows"),
        ("aside.csv", HEADER + "0,0,0,0\n1,0,0.7,0\n2,0,0,0\n", "beyond every skill of the library: the nearest"),
    ],
)
def test_a_bad_command_timeline_is_one_line_before_any_work(tmp_path, name, text, says) -> None:
    plot = tmp_path / "drive.png"
    result = gaitlib_quick("drive", "--commands", str(_write(tmp_path / name, text)), "--plot", str(plot))
    assert result.returncode == 2 and says in result.stderr, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and not plot.exists()


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("x,y\n1,2\n", "at least two points"),
        ("x,y\n0,0\n0.1,0\n", "every waypoint lies within 0.2 m of the first, where the robot starts"),
        ("x,y\n0,0\n1,0\n1,0\n", "waypoint 3 is where waypoint 2 is"),
    ],
)
def test_bad_waypoints_are_one_line_before_any_work(tmp_path, text, says) -> None:
    plot = tmp_path / "drive.png"
    result = gaitlib_quick("drive", "--waypoints", str(_write(tmp_path / "w.csv", text)), "--plot", str(plot))
    assert result.returncode == 2 and says in result.stderr, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and not plot.exists()


def test_drive_takes_commands_or_waypoints_not_both(tmp_path) -> None:
    commands = _write(tmp_path / "c.csv", HEADER + "0,1.4,0,0\n1,0,0,0\n")
    for args in ((), ("--commands", str(commands), "--waypoints", str(commands))):
        result = gaitlib_quick("drive", *args)
        assert result.returncode == 2 and "one of --commands FILE.csv or --waypoints FILE.csv" in result.stderr


def test_a_drive_s_video_is_rendered_as_a_run_s_or_refused_in_one_line(tmp_path) -> None:
    import importlib.util

    commands = _write(tmp_path / "c.csv", HEADER + "0,1.4,0,0\n0.3,0,0,0\n")
    video = tmp_path / "drive.mp4"
    result = gaitlib_quick("drive", "--commands", str(commands), "--plot", str(tmp_path / "d.png"), "--video",
                           str(video), "--backend", "mujoco", "--json")
    if importlib.util.find_spec("imageio") is None:  # the run's refusal, after the drive, nothing left behind
        lines = result.stderr.strip().splitlines()
        assert result.returncode == 2 and len(lines) == 1 and "pip install 'gaitlib[video]'" in lines[0]
        assert not video.exists() and not list(tmp_path.glob(".drive.mp4*"))
    elif result.returncode == 0:
        import imageio

        assert imageio.get_reader(video).count_frames() == 9  # 0.3 s at 30 Hz
        assert json.loads(result.stdout)["video"] == str(video)
    else:  # imageio without headless OpenGL
        assert result.returncode == 2 and "no headless OpenGL" in result.stderr


def test_a_drive_is_guarded_as_a_run_is(switching_library, tmp_path) -> None:
    from test_guard import _forced

    from gaitlib.library import Library
    from gaitlib.meta import load_switching
    from gaitlib.strategies.survival import save_survival
    from tests.conftest import copy_library

    library = copy_library(Library(switching_library), tmp_path / "library")
    setup = load_switching(library.root)
    (tmp_path / "states.h5").write_bytes(b"forced")
    save_survival(library, _forced(setup, {"trot": 1e-4, "stand": 1 - 1e-6}), data=tmp_path / "states.h5")
    commands = _write(tmp_path / "c.csv", HEADER + "0,1.45,0,0\n0.5,1.45,0,0\n")
    result = gaitlib_quick("drive", "--commands", str(commands), "--library", str(library.root), "--plot",
                           str(tmp_path / "d.png"), "--backend", "mujoco", "--guard-margin", "0", "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert [row["skill"] for row in report["commands"]] == ["trot"]
    guard = report["guard"]
    assert guard["on"] is True and guard["margin"] == 0.0
    first = guard["catches"][0]  # the estimate gives the trot up at once: caught into the stand, to return
    assert (first["from"], first["to"], first["requested"], first["time_s"]) == ("trot", "stand", "trot", 0.0)
