"""Parity: the newton (mujoco_warp) and mujoco (MuJoCo C) backends step the same physics."""

from __future__ import annotations

import pytest
import torch

from gaitlib.sim.parity import PARITY_LIMITS, parity_run

pytestmark = pytest.mark.newton

DEVICES = [
    "cpu",
    pytest.param(
        "cuda:0",
        marks=pytest.mark.skipif(
            not torch.cuda.is_available(), reason="no CUDA GPU on this machine: the newton backend's parity on the "
            "GPU is not run (only on the CPU)"
        ),
    ),
]
"""Where the newton backend runs: the CPU everywhere, the GPU where there is one."""


@pytest.mark.parametrize("airborne", [False, True], ids=["ground", "falling-pushed"])
@pytest.mark.parametrize("device", DEVICES)
def test_backends_stay_close_over_one_second_of_stepping(device: str, airborne: bool) -> None:
    result = parity_run(airborne=airborne, newton_device=device)
    assert result.moved > 0.3  # the motion is real
    assert not result.diverged and result.contact_mismatches == 0
    for name, limit in PARITY_LIMITS.items():
        assert result.worst[name] < limit, (name, result.worst)
