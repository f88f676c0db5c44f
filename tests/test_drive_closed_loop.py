"""``gaitlib drive --waypoints``, closed loop: the steering rule as pure functions on synthetic poses (bearing,
hysteresis, a turn's lead, the turning skill's order, reach, waiting), the pilot re-aiming from a perturbed pose,
the time limit and the refusals, and on the real simulator a waypoint the open-loop plan misses, reached."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from cli_runner import gaitlib_quick

from gaitlib.errors import GaitlibError
from gaitlib.meta.commands import Commands, Skill
from gaitlib.meta.steering import (
    REACH_M,
    TURN_ENTER,
    TURN_EXIT,
    Aim,
    Steering,
    WaypointPilot,
    bearing_error,
    check_waypoints,
    holds,
    next_aim,
    steering_of,
    time_limit_s,
    turning,
    turning_skill,
)

ROOT = Path(__file__).resolve().parents[1]
PRONK, STAND = Skill("pronk", (0.5, 0.0, 0.0)), Skill("stand", (0.0, 0.0, 0.0))
TURN_LEFT, TURN_RIGHT = Skill("turn_left", (0.0, 0.0, 1.0)), Skill("turn_right", (0.0, 0.0, -1.0))
ARC_LEFT, ARC_RIGHT = Skill("trot_left", (0.5, 0.0, 0.5)), Skill("trot_right", (0.5, 0.0, -0.5))
TROT, SIDESTEP = Skill("trot", (1.45, 0.0, 0.0)), Skill("sidestep_left", (0.0, 0.3, 0.0))
STEER13 = steering_of([STAND, TROT, PRONK, SIDESTEP, ARC_LEFT, ARC_RIGHT, TURN_LEFT])  # its one turner turns left


# ------------------------------------------------------------------------------------------------- the rule
def test_the_skills_a_library_steers_with() -> None:
    assert (STEER13.ahead, STEER13.in_place, STEER13.arcs) == (PRONK, (TURN_LEFT,), (ARC_LEFT, ARC_RIGHT))
    with pytest.raises(GaitlibError, match="waypoints need a skill that goes straight ahead; the library holds none"):
        steering_of([STAND, TURN_LEFT, SIDESTEP])
    with pytest.raises(GaitlibError, match="need a skill that turns, in place or going ahead"):
        steering_of([STAND, TROT, PRONK, SIDESTEP])


def test_bearing_error_and_the_hysteresis() -> None:
    assert bearing_error(np.array([0.0, 0.0, 0.0]), np.array([1.0, 1.0])) == pytest.approx(math.pi / 4)
    assert bearing_error(np.array([1.0, 1.0, math.pi]), np.array([1.0, 0.0])) == pytest.approx(math.pi / 2)
    assert bearing_error(np.array([0.0, 0.0, 3.0]), np.array([-1.0, -0.1])) == pytest.approx(
        math.atan2(-0.1, -1.0) - 3.0 + 2 * math.pi)  # wrapped
    far = 2.0
    # going ahead: a robot keeps going up to TURN_ENTER, turning one up to TURN_EXIT: no switch at every step
    assert not turning(False, TURN_ENTER - 0.01, far) and turning(False, -TURN_ENTER - 0.01, far)
    assert turning(True, TURN_EXIT + 0.01, far) and not turning(True, -(TURN_EXIT - 0.01), far)
    # near the waypoint a large error still passes it within the reach radius: go on rather than turn
    near = 0.9 * REACH_M / math.sin(math.radians(40))
    assert not turning(False, math.radians(40), near) and turning(False, math.radians(40), 1.2 * near / 0.9)
    assert turning(False, math.radians(100), 0.25)  # behind the robot: going on would not pass it


def test_a_turn_ends_early_by_the_angle_its_wait_turns() -> None:
    lead = 1.0 * 0.5  # a turn at 1 rad/s whose switch to the straight skill waited 0.5 s the last times
    assert turning(True, 0.6, 2.0, lead=lead) and not turning(True, 0.5, 2.0, lead=lead)
    assert not turning(True, -0.05, 2.0, lead=lead)  # just past the bearing: aligned
    assert turning(True, -0.6, 2.0, lead=lead)  # the long way round for a left turner: 5.7 rad to go
    assert not turning(True, -0.5, 2.0, lead=-lead) and turning(True, 0.6, 2.0, lead=-lead)  # a right turn


def test_the_turning_skill_by_the_rule_s_order() -> None:
    pose = np.zeros(3)
    left, right_far, right_near = np.array([0.0, 1.0]), np.array([0.5, -3.0]), np.array([0.3, -0.7])
    assert turning_skill(STEER13, pose, left) == TURN_LEFT  # in place, the needed way
    assert holds(ARC_RIGHT, pose, right_near) and not holds(ARC_RIGHT, pose, right_far, margin=REACH_M)
    assert turning_skill(STEER13, pose, right_far) == ARC_RIGHT  # no right turner in place: the arc that way
    assert turning_skill(STEER13, pose, right_near) == TURN_LEFT  # inside its circle: left, the long way round
    both = Steering(ahead=PRONK, in_place=(TURN_LEFT, TURN_RIGHT), arcs=(ARC_LEFT, ARC_RIGHT))
    assert turning_skill(both, pose, right_near) == TURN_RIGHT
    arcs_only = Steering(ahead=PRONK, in_place=(), arcs=(ARC_LEFT, ARC_RIGHT))
    assert turning_skill(arcs_only, pose, right_near) == ARC_LEFT  # the other arc, whose circle does not hold it
    assert turning_skill(Steering(ahead=PRONK, in_place=(), arcs=(ARC_RIGHT,)), pose, right_near) == PRONK


def test_reach_waiting_and_a_new_waypoint_starting_unaligned() -> None:
    points = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 0.1], [2.0, 2.0]])
    aim = next_aim(STEER13, points, None, np.array([0.0, 0.0, 0.0]))
    assert aim == Aim(target=1, turning=False, skill=PRONK)
    aim = next_aim(STEER13, points, aim, np.array([1.0, 0.0, math.radians(20)]))
    assert aim == Aim(1, False, PRONK)  # 20 degrees off: within the hysteresis, it goes on
    aim = next_aim(STEER13, points, aim, np.array([1.85, 0.0, 0.0]))  # within REACH_M of the next two at once
    assert aim == Aim(3, True, TURN_LEFT)  # a new waypoint starts unaligned: a 90 degree turn to the left
    held = next_aim(STEER13, points, aim, np.array([1.9, 0.0, math.pi / 2]), waiting=True)
    assert held == Aim(3, True, TURN_LEFT)  # aligned, but the turn is not running yet: nothing is decided
    assert next_aim(STEER13, points, aim, np.array([1.9, 0.0, math.pi / 2])) == Aim(3, False, PRONK)
    done = next_aim(STEER13, points, aim, np.array([2.0, 1.9, math.pi / 2]))
    assert done.target == len(points)


def test_the_pilot_aims_again_from_a_perturbed_pose() -> None:
    points = np.array([[1.0, 1.0], [5.0, 1.0], [5.0, 3.0]])
    pilot = WaypointPilot(steering=STEER13, points=points)
    assert pilot.start() == "pronk"
    start = np.array([5.0, -2.0, math.pi / 2])  # the world pose the simulator starts the robot in
    assert pilot.steer(0, 0.1, start, "pronk") == "pronk"
    assert pilot.local(start) == pytest.approx([1.0, 1.0, 0.0]) and pilot.world(points[1]) == pytest.approx([5, 2])
    assert pilot.steer(1, 0.1, [5.0, -1.0, math.pi / 2], "pronk") == "pronk"  # on its way: 3 m from waypoint 2
    drifted = [4.5, -1.0, math.pi / 2 + 0.6]  # shoved 0.5 m to its left and turned 34 degrees further left
    assert pilot.steer(2, 0.1, drifted, "pronk") == "trot_right"  # the waypoint is to the right, far from the arc
    assert pilot.steer(3, 0.1, drifted, "pronk") == "trot_right"  # asked until the switch is made
    assert pilot.steer(4, 0.1, [4.5, -0.6, math.pi / 2 + 0.3], "trot_right") == "trot_right"  # turning
    assert pilot.steer(5, 0.1, [4.5, -0.5, math.atan2(2.5, 0.5)], "trot_right") == "pronk"  # aligned again
    assert pilot.waits == {("pronk", "trot_right"): [pytest.approx(0.1)]}  # asked at 0.2 s, switched at 0.3 s
    assert pilot.steer(6, 0.1, [4.9, 1.9, math.pi / 2], "pronk") == "turn_left"  # reached: turn to waypoint 3
    assert pilot.reached_s == [pytest.approx(0.6), None] and pilot.closest_m[0] == pytest.approx(math.hypot(0.1, 0.1))
    assert pilot.steer(7, 0.1, [3.05, 2.05, math.pi], "turn_left") is None  # the last one: the drive ends
    assert pilot.reached_s == pytest.approx([0.6, 0.7])
    assert [name for _, name in pilot.requests] == ["pronk", "trot_right", "pronk", "turn_left"]


def test_the_time_limit_and_what_cannot_be_driven() -> None:
    square = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0], [0.0, 0.0]])
    legs = 4 * (2 * 2.0 / 0.5 + 2 * math.pi / 0.5 + 2 * 2.0)  # twice each leg at 0.5 m/s, a turn at 0.5 rad/s
    assert time_limit_s(square, STEER13) == pytest.approx(legs)
    assert check_waypoints(square, [STAND, PRONK, TURN_LEFT])[1] == pytest.approx(4 * (8 + 2 * math.pi + 4))
    with pytest.raises(GaitlibError, match=r"every waypoint lies within 0\.2 m of the first"):
        check_waypoints(np.array([[0.0, 0.0], [0.1, 0.1], [-0.1, 0.0]]), [PRONK, TURN_LEFT])
    with pytest.raises(GaitlibError, match=r"the waypoints' time limit is 4010 s \(1000 m of legs at 0\.5 m/s"):
        check_waypoints(np.array([[0.0, 0.0], [1000.0, 0.0]]), [PRONK, TURN_LEFT])


# ------------------------------------------------------------------------------------------ on the simulator
@pytest.fixture(scope="module")
def steering_library(tmp_path_factory) -> Path:
    """A library of two shipped entries: the pronk (straight ahead, 0.5 m/s) and library-steer's turn_left."""
    root = tmp_path_factory.mktemp("steer") / "library"
    root.mkdir()
    shutil.copytree(ROOT / "library" / "pronk", root / "pronk")
    shutil.copytree(ROOT / "library-steer" / "turn_left", root / "turn_left")
    return root


def test_a_waypoint_the_open_loop_plan_misses_is_reached_closed_loop(steering_library, tmp_path) -> None:
    from gaitlib.meta import load_switching
    from gaitlib.meta.drive import drive, drive_waypoints

    setup = load_switching(steering_library)
    points = np.array([[0.0, 0.0], [1.5, 0.0]])
    options = {"strategy": "random", "backend": "mujoco", "seed": 0}
    plan = Commands(time_s=np.array([0.0, 3.0]), velocity=np.array([[0.5, 0.0, 0.0]]))  # 1.5 m at 0.5 m/s
    open_loop = drive(setup, plan, **options)
    assert open_loop.trace.stayed_up and open_loop.end_error_m > REACH_M + 0.05  # the pronk is slower than 0.5 m/s
    closed = drive_waypoints(setup, points, **options)
    outcome = closed.waypoints
    assert closed.trace.stayed_up and outcome.reached_all and outcome.closest_m[0] <= REACH_M
    assert closed.end_error_m == pytest.approx(outcome.closest_m[0])  # it ends where it reaches the last one
    assert closed.pose[-1, 0] == pytest.approx(outcome.reached_s[0]) and closed.pose[-1, 0] > 3.0
    assert closed.commands.time_s[-1] == pytest.approx(closed.pose[-1, 0]) and closed.skills[0] == "pronk"


def test_a_waypoint_drive_s_report_and_plot(steering_library, tmp_path) -> None:
    waypoints = tmp_path / "w.csv"
    waypoints.write_text("x,y\n0,0\n0.6,0\n0.6,0.6\n")
    plot = tmp_path / "drive.png"
    result = gaitlib_quick("drive", "--waypoints", str(waypoints), "--library", str(steering_library), "--strategy",
                           "random", "--no-guard", "--backend", "mujoco", "--plot", str(plot), "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["steering"] == {"reach_m": REACH_M, "turn_enter_deg": pytest.approx(30.0),
                                  "turn_exit_deg": pytest.approx(5.0), "ahead": "pronk",
                                  "in_place": ["turn_left"], "arcs": []}
    rows = report["waypoints"]
    assert [(r["index"], r["x"], r["y"]) for r in rows] == [(2, 0.6, 0.0), (3, 0.6, 0.6)]
    for row in rows:
        assert row["reached"] == (row["reached_s"] is not None) and row["closest_m"] is not None
        assert not row["reached"] or row["closest_m"] <= REACH_M
    assert report["reached_all"] == all(r["reached"] for r in rows) and report["time_limit_s"] > 0
    assert report["path_length_m"] == pytest.approx(1.2)
    assert report["end_error_m"] == pytest.approx(math.dist(report["end_reached"], report["end_commanded"]))
    if report["stayed_up"] and report["reached_all"]:
        assert "turn_left" in report["requested"] and report["end_error_m"] <= REACH_M
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_seeds_benchmark_records_each_seed(steering_library, tmp_path, monkeypatch) -> None:
    import datetime
    import sys

    from benchmarks import drive_seeds

    waypoints = tmp_path / "w.csv"
    waypoints.write_text("x,y\n0,0\n0.5,0\n")
    out = tmp_path / "seeds.json"
    monkeypatch.setattr(sys, "argv", ["drive_seeds.py", "--library", str(steering_library), "--waypoints",
                                      str(waypoints), "--seeds", "2", "--first-seed", "5", "--strategy", "random",
                                      "--no-guard", "--out", str(out)])
    drive_seeds.main()
    stored = json.loads(out.read_text())  # evidence, as the results pages read it (benchmarks/results/drive.py)
    assert set(stored) == {"command", "made", "result"} and stored["made"] == datetime.date.today().isoformat()
    assert stored["command"].startswith("python -m benchmarks.drive_seeds --library ")  # this process's arguments
    assert stored["command"].endswith(f"--no-guard --out {out}")
    record = stored["result"]
    assert record["strategy"] == "random" and record["guard"] is False
    assert record["guard_why_off"] == "unguarded (--no-guard)" and record["switching_checksum"] is None  # no models
    assert [row["seed"] for row in record["runs"]] == [5, 6]
    for row in record["runs"]:
        assert row["within_goal_all"] == (row["closest_m"][0] <= drive_seeds.GOAL_M)
        assert row["reached_all"] == (row["reached_s"][0] is not None) and row["wall_s"] > 0
    summary = record["summary"]
    assert summary["seeds"] == 2 and summary["stayed_up"] == sum(row["stayed_up"] for row in record["runs"])
    assert summary["goal_met"] == (summary["stayed_up"] == 2 and summary["within_goal_all"] == 2)
