"""Imitation reward terms against hand-computed values."""

from __future__ import annotations

import math

import pytest
import torch

from gaitlib.envs import rewards as r
from gaitlib.envs.reference import ReferenceFrame
from gaitlib.sim import SimState


def state(n: int = 1, **values: torch.Tensor) -> SimState:
    """A robot at rest at the origin, upright, facing +x, with ``values`` replacing readings."""
    quat = torch.zeros(n, 4)
    quat[:, 0] = 1.0
    fields = {
        "root_pos": torch.zeros(n, 3),
        "root_quat": quat,
        "root_lin_vel": torch.zeros(n, 3),
        "root_ang_vel": torch.zeros(n, 3),
        "joint_pos": torch.zeros(n, 12),
        "joint_vel": torch.zeros(n, 12),
        "foot_contact": torch.zeros(n, 4, dtype=torch.bool),
        "foot_pos": torch.zeros(n, 4, 3),
        "body_contact": torch.zeros(n, dtype=torch.bool),
        "trunk_contact": torch.zeros(n, dtype=torch.bool),
    }
    return SimState(**(fields | values))


def reference(n: int = 1, **values: torch.Tensor) -> ReferenceFrame:
    """A reference that :func:`state` matches exactly, with ``values`` replacing quantities."""
    s = state(n)
    fields = {
        "root_pos": s.root_pos,
        "root_quat": s.root_quat,
        "root_lin_vel": s.root_lin_vel,
        "root_ang_vel": s.root_ang_vel,
        "heading_lin_vel": torch.zeros(n, 3),
        "joint_pos": s.joint_pos,
        "joint_vel": s.joint_vel,
        "foot_pos_heading": torch.zeros(n, 4, 3),
        "contact": s.foot_contact,
    }
    return ReferenceFrame(**(fields | values))


def term(name: str) -> r.RewardTerm:
    return next(t for t in r.IMITATION_REWARD if t.name == name)


def value(name: str, s: SimState, ref: ReferenceFrame) -> list[float]:
    return r.reward(r.IMITATION_REWARD, s, ref)[1][name].tolist()


def test_pose_reward() -> None:
    ref = torch.zeros(2, 12)
    ref[1, 0], ref[1, 5] = 0.1, -0.2  # squared error 0.01 + 0.04 = 0.05
    assert term("pose").scale == 5.0
    assert value("pose", state(2), reference(2, joint_pos=ref)) == pytest.approx([1.0, math.exp(-5 * 0.05)])


def test_joint_velocity_reward() -> None:
    out = value("joint_velocity", state(joint_vel=torch.full((1, 12), 1.0)), reference())
    assert out == pytest.approx([math.exp(-0.1 * 12)])


def test_end_effector_reward_weights_height_three_times_in_the_heading_frame() -> None:
    feet = torch.tensor([[[0.18, -0.13, -0.27], [0.18, 0.13, -0.27], [-0.18, -0.13, -0.27], [-0.18, 0.13, -0.27]]])
    ref = feet.clone()
    ref[0, 0, 0] += 0.01  # dx^2 = 1e-4
    ref[0, 2, 2] += 0.01  # 3 dz^2 = 3e-4
    expected = [math.exp(-40 * 4e-4)]
    assert value("end_effector", state(foot_pos=feet), reference(foot_pos_heading=ref)) == pytest.approx(expected)
    # The same robot moved and turned 90 degrees left: its feet, seen from its own heading, are unchanged.
    root = torch.tensor([[1.0, 2.0, 0.0]])
    turned = state(
        root_pos=root,
        root_quat=torch.tensor([[math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)]]),
        foot_pos=root.unsqueeze(1) + torch.stack([-feet[..., 1], feet[..., 0], feet[..., 2]], dim=-1),
    )
    assert value("end_effector", turned, reference(foot_pos_heading=ref)) == pytest.approx(expected, rel=1e-4)


def test_root_pose_reward() -> None:
    angle = 0.2  # about x
    s = state(root_pos=torch.tensor([[0.0, 0.0, 0.25]]))
    quat = torch.tensor([[math.cos(angle / 2), math.sin(angle / 2), 0.0, 0.0]])
    ref = reference(root_pos=torch.tensor([[0.1, 0.0, 0.26]]), root_quat=quat)
    assert value("root_pose", s, ref) == pytest.approx([math.exp(-20 * (0.01 + 0.0001 + 0.5 * 0.04))], rel=1e-5)


def test_root_velocity_reward() -> None:
    s = state(root_lin_vel=torch.tensor([[0.5, 0.0, 0.0]]), root_ang_vel=torch.tensor([[0.0, 0.0, 1.0]]))
    ref = reference(root_lin_vel=torch.tensor([[0.3, 0.0, 0.0]]))
    assert value("root_velocity", s, ref) == pytest.approx([math.exp(-2 * (0.04 + 0.1))])


def test_reward_is_the_weighted_sum_and_the_paper_weights_sum_to_one() -> None:
    weights = {t.name: t.weight for t in r.IMITATION_REWARD}
    assert weights == {
        "pose": 0.5,
        "joint_velocity": 0.05,
        "end_effector": 0.2,
        "root_pose": 0.15,
        "root_velocity": 0.1,
    }
    assert sum(weights.values()) == pytest.approx(1.0)
    s = state(joint_vel=torch.full((1, 12), 1.0))
    total, values = r.reward(r.IMITATION_REWARD, s, reference())
    assert total.item() == pytest.approx(sum(weights[name] * v.item() for name, v in values.items()))
    assert total.item() == pytest.approx(1.0 - 0.05 * (1.0 - math.exp(-0.1 * 12)))
