"""Unit-quaternion arithmetic, written once for numpy arrays and torch tensors (the lowest layer: robots, sim,
gaits and envs all take their rotations from here).

Quaternions are ``(w, x, y, z)`` in the last dimension and rotate trunk-frame vectors into the world frame, as in
:mod:`gaitlib.sim.contract` (Hamilton convention, as in MuJoCo's ``mju_mulQuat``). Every function broadcasts over
leading dimensions and returns the array type it is given; torch is imported only when a tensor is passed.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

__all__ = [
    "quat_angle_between",
    "quat_conjugate",
    "quat_from_yaw",
    "quat_multiply",
    "quat_rotate",
    "quat_rotate_inverse",
    "quat_to_rotation_vector",
    "yaw_of",
]

Array = TypeVar("Array")
"""A ``numpy.ndarray`` or a ``torch.Tensor``."""


@dataclass(frozen=True)
class _Ops:
    """The few operations whose names differ between numpy and torch."""

    stack: Callable
    """``stack(parts, axis)``."""
    cat: Callable
    """``cat(parts, axis)``."""
    cross: Callable
    """Cross product over the last dimension, broadcasting."""
    atan2: Callable
    acos: Callable
    sin: Callable
    cos: Callable
    zeros_like: Callable
    at_most: Callable
    """``at_most(x, bound)``: elementwise min with a scalar."""


_NUMPY = _Ops(
    stack=np.stack,
    cat=np.concatenate,
    cross=np.cross,
    atan2=np.arctan2,
    acos=np.arccos,
    sin=np.sin,
    cos=np.cos,
    zeros_like=np.zeros_like,
    at_most=np.minimum,
)


@functools.cache
def _torch_ops() -> _Ops:
    import torch

    return _Ops(
        stack=torch.stack,
        cat=torch.cat,
        cross=torch.linalg.cross,
        atan2=torch.atan2,
        acos=torch.acos,
        sin=torch.sin,
        cos=torch.cos,
        zeros_like=torch.zeros_like,
        at_most=lambda x, bound: x.clamp(max=bound),
    )


def _ops(x: object) -> _Ops:
    return _NUMPY if isinstance(x, np.ndarray | np.generic) else _torch_ops()


def quat_multiply(a: Array, b: Array) -> Array:
    """Hamilton product ``a ⊗ b`` of (..., 4) quaternions (rotation ``b`` first, then ``a``)."""
    aw, ax, ay, az = (a[..., i] for i in range(4))
    bw, bx, by, bz = (b[..., i] for i in range(4))
    return _ops(a).stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        -1,
    )


def quat_conjugate(q: Array) -> Array:
    """Conjugate of (..., 4) quaternions: the inverse rotation of a unit quaternion."""
    return _ops(q).cat([q[..., :1], -q[..., 1:]], -1)


def quat_rotate(q: Array, v: Array) -> Array:
    """Rotate (..., 3) vectors ``v`` by (..., 4) unit quaternions ``q`` (trunk to world)."""
    cross = _ops(q).cross
    w, u = q[..., :1], q[..., 1:]
    t = 2.0 * cross(u, v)
    return v + w * t + cross(u, t)


def quat_rotate_inverse(q: Array, v: Array) -> Array:
    """Rotate (..., 3) vectors ``v`` by the inverse of (..., 4) unit quaternions ``q`` (world to trunk)."""
    return quat_rotate(quat_conjugate(q), v)


def yaw_of(q: Array) -> Array:
    """Heading angle (...) in rad of (..., 4) unit quaternions: rotation about world z of the trunk's x axis."""
    w, x, y, z = (q[..., i] for i in range(4))
    return _ops(q).atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def quat_from_yaw(yaw: Array) -> Array:
    """Unit quaternions (..., 4) of rotations by ``yaw`` (...) rad about world z."""
    ops = _ops(yaw)
    half = 0.5 * yaw
    zero = ops.zeros_like(half)
    return ops.stack([ops.cos(half), zero, zero, ops.sin(half)], -1)


def quat_angle_between(a: Array, b: Array) -> Array:
    """Rotation angle (...) in rad, in [0, pi], of the relative rotation between unit quaternions ``a`` and ``b``."""
    ops = _ops(a)
    return 2.0 * ops.acos(ops.at_most(abs((a * b).sum(-1)), 1.0))


def quat_to_rotation_vector(q: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) (axis times angle in [0, pi], rad) of (..., 4) unit quaternions (numpy only: the
    reference clips' finite differences)."""
    q = np.where(q[..., :1] < 0.0, -q, q)  # the shorter of the two equivalent rotations
    sin_half = np.linalg.norm(q[..., 1:], axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(sin_half, q[..., :1])
    # angle / sin(angle / 2) tends to 2 as the rotation vanishes.
    scale = np.where(sin_half > 1e-12, angle / np.maximum(sin_half, 1e-12), 2.0)
    return q[..., 1:] * scale
