"""``gaitlib eval`` on a gait that sidesteps, turns or goes backward: its lateral speed, yaw rate and heading
against the reference's, on the real simulator; a gait that goes straight ahead records none of them."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from gaitlib.envs import EnvConfig
from gaitlib.evaluation import evaluate_policy
from gaitlib.gaits import clip_from_description, get_gait
from gaitlib.library import Library

SHIPPED = Path(__file__).resolve().parents[1] / "library"


def _evaluate(clip, seconds: float = 1.0):
    """The shipped stand's policy (it neither turns nor sidesteps) on ``clip``, two episodes."""
    lib = Library(SHIPPED)
    return evaluate_policy(lib.entry("stand").policy, clip, env_cfg=lib.shared_policy_settings(["stand"]).env_config(
        EnvConfig()), episodes=2, seconds=seconds, backend="mujoco", seed=0)


def test_a_turning_gait_is_measured_against_its_turning_reference() -> None:
    result = _evaluate(clip_from_description(get_gait("turn_left")))
    s = result.steering
    assert s is not None and set(result.as_dict()["steering"]) == {
        "lateral_speed", "reference_lateral_speed", "lateral_speed_error", "yaw_rate", "reference_yaw_rate",
        "yaw_rate_error", "median_heading_error_deg"}
    assert s.reference_yaw_rate == pytest.approx(1.0, rel=0.02)  # the description's 1 rad/s
    assert s.yaw_rate_error == pytest.approx(abs(s.yaw_rate - s.reference_yaw_rate) / s.reference_yaw_rate)
    assert abs(s.reference_lateral_speed) < 0.01 and s.lateral_speed_error == pytest.approx(abs(s.lateral_speed))
    if result.fall_rate == 0:  # both up for 1 s: the heading falls behind the reference's by the turns' difference
        lag = math.degrees(abs(s.reference_yaw_rate - s.yaw_rate) * result.mean_episode_seconds)
        assert s.median_heading_error_deg == pytest.approx(lag, abs=10.0) and s.median_heading_error_deg > 20


def test_a_sidestep_is_measured_sideways() -> None:
    s = _evaluate(clip_from_description(get_gait("sidestep_left")), seconds=0.5).steering
    assert s is not None and s.reference_lateral_speed == pytest.approx(0.3, rel=0.05)
    assert abs(s.reference_yaw_rate) < 1e-3 and s.yaw_rate_error == pytest.approx(abs(s.yaw_rate))
    assert s.lateral_speed_error == pytest.approx(abs(s.lateral_speed - s.reference_lateral_speed) / 0.3, rel=0.06)


def test_a_backward_trot_is_measured_for_the_drift_its_bar_allows() -> None:
    s = _evaluate(clip_from_description(get_gait("trot_back")), seconds=0.3).steering
    assert s is not None and abs(s.reference_lateral_speed) < 1e-3 and abs(s.reference_yaw_rate) < 1e-3
    assert s.lateral_speed_error == pytest.approx(abs(s.lateral_speed))
    assert s.yaw_rate_error == pytest.approx(abs(s.yaw_rate))


def test_a_gait_that_goes_straight_ahead_records_no_steering_figures() -> None:
    result = _evaluate(Library(SHIPPED).entry("trot").clip, seconds=0.3)
    assert result.steering is None and "steering" not in result.as_dict()
