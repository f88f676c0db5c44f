"""Parity: the newton (mujoco_warp) and mujoco (MuJoCo C) backends step the same physics."""

from __future__ import annotations

import pytest

from gaitlib.sim.parity import PARITY_LIMITS, parity_run

pytestmark = pytest.mark.newton


@pytest.mark.parametrize("airborne", [False, True], ids=["ground", "falling-pushed"])
def test_backends_stay_close_over_one_second_of_stepping(airborne: bool) -> None:
    result = parity_run(airborne=airborne, newton_device="cpu")
    assert result.moved > 0.3  # the motion is real
    assert not result.diverged and result.contact_mismatches == 0
    for name, limit in PARITY_LIMITS.items():
        assert result.worst[name] < limit, (name, result.worst)
