"""The reference check (``gaitlib.gaits.feasibility``, ``gaitlib gaits``): the physics it rests on, and that it
tells the references gaitlib could not follow from those it could."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from cli_runner import gaitlib_quick

from gaitlib.gaits import clip_from_description, get_gait
from gaitlib.gaits.feasibility import TILT_LIMIT_DEG, _nearest_support_point, check_reference, composite_inertia
from gaitlib.robots.a1.constants import TOTAL_MASS

GRAVITY = 9.81


def test_the_model_mass_is_the_constants_and_its_inertia_is_a_body_inertia() -> None:
    mass, inertia = composite_inertia()
    assert mass == pytest.approx(TOTAL_MASS, abs=1e-3)
    np.testing.assert_allclose(inertia, inertia.T, atol=1e-12)
    principal = np.linalg.eigvalsh(inertia)
    assert (principal > 0).all() and principal[0] + principal[1] >= principal[2]  # triangle inequality
    assert inertia[0, 0] < inertia[1, 1]  # a long body rolls more easily than it pitches


def test_the_support_set_is_the_hull_of_the_stance_feet() -> None:
    square = np.array([[1.0, -1.0], [1.0, 1.0], [-1.0, -1.0], [-1.0, 1.0]])  # FR, FL, RR, RL
    points = np.array([[0.2, 0.3], [3.0, 0.0], [0.0, 0.5], [0.0, 0.5], [2.0, 2.0]])
    feet = np.repeat(square[None], len(points), axis=0)
    contact = np.array([
        [True] * 4,                 # inside the square: itself
        [True] * 4,                 # ahead of it: onto the front edge
        [True, False, False, True],  # one diagonal: onto the line through FR and RL
        [False] * 4,                 # flight: itself (nothing to project onto)
        [True, False, False, False],  # one foot: that foot
    ])
    nearest = _nearest_support_point(points, feet, contact)
    np.testing.assert_allclose(nearest, [[0.2, 0.3], [1.0, 0.0], [-0.25, 0.25], [0.0, 0.5], [1.0, -1.0]])


def test_a_straight_pace_cannot_be_followed_and_a_swaying_one_can() -> None:
    swaying = check_reference(clip_from_description(get_gait("pace")))
    straight = check_reference(clip_from_description(dataclasses.replace(get_gait("pace"), trunk_sway=False)))
    assert straight.tilt_deg[0] > 3 * TILT_LIMIT_DEG and not straight.followable
    assert swaying.tilt_deg[0] < TILT_LIMIT_DEG / 2 and swaying.followable
    for check in (straight, swaying):  # side to side only: a pace does not pitch, and it never flies
        assert check.tilt_deg[1] < 1.0 and check.flight_s == 0.0


def test_a_stand_needs_nothing_and_a_pronk_falls_freely_in_flight() -> None:
    stand = check_reference(clip_from_description(get_gait("stand")))
    assert max(stand.tilt_deg) < 0.01 and stand.outside_share == 0.0 and stand.flight_s == 0.0
    # Feet that stay low in flight: the whole-body centre of mass moves as the trunk does.
    pronk_description = dataclasses.replace(get_gait("pronk"), swing_height=0.0, trunk_bounce=False)
    pronk = check_reference(clip_from_description(pronk_description))
    flight = (1.0 - pronk_description.duty_factor) * pronk_description.period
    assert pronk.flight_s == pytest.approx(flight, abs=2 * pronk_description.period / 1024)
    # A level trunk at constant height, in free fall for t, lands where it took off after rising g t^2 / 8.
    assert pronk.flight_drop_m == pytest.approx(GRAVITY * flight**2 / 8, rel=0.01)
    # Feet lifted in flight carry the centre of mass up with them: the pronk's 8 cm swing leaves less to fall.
    level = dataclasses.replace(get_gait("pronk"), trunk_bounce=False)
    lifted = check_reference(clip_from_description(level))
    assert 0.5 * pronk.flight_drop_m < lifted.flight_drop_m < 0.9 * pronk.flight_drop_m
    # A trunk that falls freely in flight leaves little: the shipped pronk's bounce, a quarter of the level one's.
    bouncing = check_reference(clip_from_description(get_gait("pronk")))
    assert bouncing.flight_drop_m < 0.25 * lifted.flight_drop_m


def test_gaits_lists_every_description_and_flags_a_file_it_cannot_follow(tmp_path) -> None:
    table = gaitlib_quick("gaits")
    assert table.returncode == 0, table.stderr
    for name in ("bound", "pace", "pronk", "stand", "trot", "walk"):
        assert f"\n│ {name} " in table.stdout
    straight = tmp_path / "straight.toml"
    straight.write_text(
        'name = "straight"\nduty_factor = 0.55\nstride_frequency = 1.58\nforward_speed = 0.9\nswing_height = 0.06\n'
        "body_height = 0.26\n[phase_offsets]\nFR = 0.0\nFL = 0.5\nRR = 0.0\nRL = 0.5\n"
    )
    shown = gaitlib_quick("gaits", "trot", "--gait-file", str(straight), "--json")
    assert shown.returncode == 0, shown.stderr
    trot, mine = (json.loads(line) for line in shown.stdout.splitlines())
    assert trot["description"]["name"] == "trot" and trot["check"]["followable"]
    assert mine["description"]["name"] == "straight" and not mine["check"]["followable"]
