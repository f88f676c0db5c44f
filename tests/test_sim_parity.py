"""Parity: the newton (mujoco_warp) and mujoco (MuJoCo C) backends step the same physics."""

from __future__ import annotations

import math

import pytest
import torch

from gaitlib.robots import get_robot
from gaitlib.robots.a1 import constants as a1
from gaitlib.sim import make_backend, standing_state

pytestmark = pytest.mark.newton

ROBOT = get_robot("a1")


def stepping_targets(t: float, n: int) -> torch.Tensor:
    """A stepping-like motion: thighs and calves oscillate at 1.5 Hz; world 1 also swings its hips."""
    targets = torch.tensor(a1.DEFAULT_JOINT_POS).repeat(n, 1)
    targets[:, 1::3] += 0.3 * math.sin(2 * math.pi * 1.5 * t)
    targets[:, 2::3] += 0.4 * math.sin(2 * math.pi * 1.5 * t + 0.7)
    targets[1, 0::3] += 0.2 * math.sin(2 * math.pi * 1.0 * t)
    return targets


@pytest.mark.parametrize("airborne", [False, True], ids=["ground", "falling-pushed"])
def test_backends_stay_close_over_one_second_of_stepping(airborne: bool) -> None:
    n = 2
    backends = [make_backend(name, num_worlds=n, device="cpu") for name in ("mujoco", "newton")]
    start = standing_state(ROBOT, n)
    if airborne:
        start.root_pos[:, 2] = 1.0
    for backend in backends:
        backend.reset(torch.arange(n), start)
        if airborne:
            backend.set_trunk_force(torch.tensor([0]), torch.tensor([[0.0, 50.0, 0.0]]))
    worst = {"root_pos": 0.0, "root_quat": 0.0, "joint_pos": 0.0, "foot_pos": 0.0}
    moved = 0.0
    for k in range(30):  # 1 s at 30 Hz
        targets = stepping_targets(k / 30, n)
        states = []
        for backend in backends:
            backend.set_pd_targets(targets)
            assert not backend.step().any()
            states.append(backend.state())
        c, w = states
        for name in worst:
            worst[name] = max(worst[name], (getattr(c, name) - getattr(w, name)).abs().max().item())
        moved = max(moved, (c.joint_pos - start.joint_pos).abs().max().item())
        if not airborne and k >= 2:
            assert torch.equal(c.foot_contact, w.foot_contact)
    assert moved > 0.3  # the motion is real
    assert worst["root_pos"] < 2e-3 and worst["root_quat"] < 5e-3
    assert worst["joint_pos"] < 1e-2 and worst["foot_pos"] < 2e-3
    for backend in backends:
        backend.close()
