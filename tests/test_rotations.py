"""gaitlib.rotations: one implementation for numpy and torch, checked against MuJoCo's own quaternion routines."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
import torch

from gaitlib import rotations as r


def unit_quats(k: int, seed: int = 0) -> np.ndarray:
    q = np.random.default_rng(seed).normal(size=(k, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def test_product_and_rotation_match_mujoco() -> None:
    a, b = unit_quats(8, 1), unit_quats(8, 2)
    v = np.random.default_rng(3).normal(size=(8, 3))
    for i in range(8):
        product = np.zeros(4)
        mujoco.mju_mulQuat(product, a[i], b[i])
        np.testing.assert_allclose(r.quat_multiply(a[i], b[i]), product, atol=1e-12)
        rotated = np.zeros(3)
        mujoco.mju_rotVecQuat(rotated, v[i], a[i])
        np.testing.assert_allclose(r.quat_rotate(a[i], v[i]), rotated, atol=1e-12)
        np.testing.assert_allclose(r.quat_rotate_inverse(a[i], rotated), v[i], atol=1e-12)


@pytest.mark.parametrize("name", ["quat_multiply", "quat_rotate", "quat_rotate_inverse", "quat_angle_between"])
def test_numpy_and_torch_agree(name: str) -> None:
    a, b = unit_quats(16, 4), unit_quats(16, 5)
    second = b if name in ("quat_multiply", "quat_angle_between") else b[:, :3]
    out_np = getattr(r, name)(a, second)
    out_torch = getattr(r, name)(torch.from_numpy(a), torch.from_numpy(second))
    assert isinstance(out_np, np.ndarray) and isinstance(out_torch, torch.Tensor)
    np.testing.assert_allclose(out_torch.numpy(), out_np, atol=1e-12)


def test_yaw_round_trip_and_angle_between() -> None:
    yaw = np.linspace(-3.0, 3.0, 7)
    for values in (yaw, torch.from_numpy(yaw)):
        q = r.quat_from_yaw(values)
        np.testing.assert_allclose(np.asarray(r.yaw_of(q)), yaw, atol=1e-12)
        angle = r.quat_angle_between(q, r.quat_from_yaw(values * 0.0))
        np.testing.assert_allclose(np.asarray(angle), np.abs(yaw), atol=1e-6)
    # A pitch leaves the heading alone; a rotation vector is axis times angle.
    pitch = np.array([math.cos(0.2), 0.0, math.sin(0.2), 0.0])
    assert r.yaw_of(pitch) == pytest.approx(0.0)
    np.testing.assert_allclose(r.quat_to_rotation_vector(pitch), [0.0, 0.4, 0.0], atol=1e-12)
    np.testing.assert_allclose(r.quat_to_rotation_vector(-pitch), [0.0, 0.4, 0.0], atol=1e-12)


def test_broadcasting_over_feet() -> None:
    q = torch.from_numpy(unit_quats(3, 6)).float()
    feet = torch.randn(3, 4, 3)
    per_foot = torch.stack([r.quat_rotate(q, feet[:, f]) for f in range(4)], dim=1)
    torch.testing.assert_close(r.quat_rotate(q.unsqueeze(1), feet), per_foot)
