"""Unit-quaternion arithmetic for reference clips (numpy, (w, x, y, z), broadcasting over leading dimensions).

A quaternion ``q`` rotates trunk-frame vectors into the world frame, as in :mod:`gaitlib.sim.contract`.
"""

from __future__ import annotations

import numpy as np

__all__ = ["quat_conjugate", "quat_multiply", "quat_rotate", "quat_to_rotation_vector"]


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a ⊗ b`` of (..., 4) quaternions (rotation ``b`` first, then ``a``)."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """Conjugate of (..., 4) quaternions: the inverse rotation of a unit quaternion."""
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate (..., 3) vectors ``v`` by (..., 4) unit quaternions ``q``."""
    w, u = q[..., :1], q[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def quat_to_rotation_vector(q: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) (axis times angle in [0, pi], rad) of (..., 4) unit quaternions."""
    q = np.where(q[..., :1] < 0.0, -q, q)  # the shorter of the two equivalent rotations
    sin_half = np.linalg.norm(q[..., 1:], axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(sin_half, q[..., :1])
    # angle / sin(angle / 2) tends to 2 as the rotation vanishes.
    scale = np.where(sin_half > 1e-12, angle / np.maximum(sin_half, 1e-12), 2.0)
    return q[..., 1:] * scale
