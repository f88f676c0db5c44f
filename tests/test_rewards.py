"""Imitation reward terms against hand-computed values."""

from __future__ import annotations

import math

import pytest
import torch

from gaitlib.envs import rewards as r
from gaitlib.envs.rewards import RewardConfig


def test_pose_reward() -> None:
    q = torch.zeros(2, 12)
    ref = torch.zeros(2, 12)
    ref[1, 0], ref[1, 5] = 0.1, -0.2  # squared error 0.01 + 0.04 = 0.05
    out = r.pose_reward(q, ref, scale=5.0)
    assert out.tolist() == pytest.approx([1.0, math.exp(-5 * 0.05)])


def test_joint_velocity_reward() -> None:
    out = r.joint_velocity_reward(torch.full((1, 12), 1.0), torch.zeros(1, 12), scale=0.1)
    assert out.item() == pytest.approx(math.exp(-0.1 * 12))


def test_end_effector_reward_weights_height_three_times() -> None:
    feet = torch.zeros(1, 4, 3)
    ref = torch.zeros(1, 4, 3)
    ref[0, 0, 0] = 0.01  # dx^2 = 1e-4
    ref[0, 2, 2] = 0.01  # 3 dz^2 = 3e-4
    out = r.end_effector_reward(feet, ref, scale=40.0, height_weight=3.0)
    assert out.item() == pytest.approx(math.exp(-40 * 4e-4))


def test_root_pose_reward() -> None:
    out = r.root_pose_reward(
        torch.tensor([[0.0, 0.0, 0.25]]),
        torch.tensor([[0.1, 0.0, 0.26]]),
        torch.tensor([0.2]),
        scale=20.0,
        rotation_weight=0.5,
    )
    assert out.item() == pytest.approx(math.exp(-20 * (0.01 + 0.0001 + 0.5 * 0.04)))


def test_root_velocity_reward() -> None:
    out = r.root_velocity_reward(
        torch.tensor([[0.5, 0.0, 0.0]]),
        torch.tensor([[0.3, 0.0, 0.0]]),
        torch.tensor([[0.0, 0.0, 1.0]]),
        torch.zeros(1, 3),
        scale=2.0,
        angular_weight=0.1,
    )
    assert out.item() == pytest.approx(math.exp(-2 * (0.04 + 0.1)))


def test_paper_weights_sum_to_one() -> None:
    weights = RewardConfig().terms()
    assert weights == {
        "pose": 0.5,
        "joint_velocity": 0.05,
        "end_effector": 0.2,
        "root_pose": 0.15,
        "root_velocity": 0.1,
    }
    assert sum(weights.values()) == pytest.approx(1.0)
