"""A gait's left-right mirror image: its description (:func:`mirror_description`), how far another description's
phase runs from it (:func:`mirror_shift`), and a clip frame reflected (:func:`mirror_frame`), by the A1's symmetry
(:mod:`gaitlib.robots.a1.constants`, ``MIRROR_*``).

The mirror image of a gait moves each leg as its mirror leg did (FR <-> FL, RR <-> RL: the phase offsets swap) and
the trunk the other way sideways and round (``lateral_speed`` and ``yaw_rate`` negated); everything else is its own
mirror. A description is the mirror of another when it is that image with every phase offset moved by one shift
``d``: its clip at phase ``p + d`` is then the mirror of the other's at ``p`` (a trot is its own mirror half a cycle
on, its diagonals trading places).
"""

from __future__ import annotations

import dataclasses

import torch

from gaitlib.gaits.clip import ClipFrame
from gaitlib.gaits.description import GaitDescription
from gaitlib.robots.a1.constants import (
    MIRROR_AXIAL,
    MIRROR_JOINT_SIGNS,
    MIRROR_JOINTS,
    MIRROR_LEGS,
    MIRROR_QUAT,
    MIRROR_VECTOR,
)

__all__ = ["mirror_description", "mirror_frame", "mirror_shift"]

_SAME_PHASE = 1e-9  # cycles: phase offsets this close are one (they are read from decimal text)


def mirror_description(description: GaitDescription, *, name: str) -> GaitDescription:
    """The mirror image of ``description``, called ``name``."""
    offsets = description.phase_offsets
    return dataclasses.replace(
        description,
        name=name,
        phase_offsets=tuple(offsets[m] for m in MIRROR_LEGS),
        lateral_speed=-description.lateral_speed,
        yaw_rate=-description.yaw_rate,
    )


def mirror_shift(source: GaitDescription, target: GaitDescription) -> float | None:
    """The shift ``d`` in [0, 1) cycles by which ``target`` is the mirror image of ``source`` (``target``'s clip at
    phase ``p + d`` is the mirror of ``source``'s at ``p``), ``None`` if it is not its mirror image at any."""
    image = mirror_description(source, name=target.name)
    shift = (target.phase_offsets[0] - image.phase_offsets[0]) % 1.0
    moved = tuple((o + shift) % 1.0 for o in image.phase_offsets)
    for a, b in zip(moved, target.phase_offsets, strict=True):
        if min(abs(a - b), 1.0 - abs(a - b)) > _SAME_PHASE:
            return None
    same = dataclasses.replace(image, phase_offsets=target.phase_offsets) == target
    return (0.0 if shift > 1.0 - _SAME_PHASE else shift) if same else None


def mirror_frame(frame: ClipFrame) -> ClipFrame:
    """The mirror image of clip frames (N robots), reflected in the world's x-z plane: positions, velocities and feet
    with y negated, orientations and trunk-frame angular velocities as reflected rotations, joints and feet from
    their mirror joints and feet."""

    def signs(values: tuple[float, ...], like: torch.Tensor) -> torch.Tensor:
        return torch.tensor(values, dtype=like.dtype, device=like.device)

    joints, legs = list(MIRROR_JOINTS), list(MIRROR_LEGS)
    vector, axial = signs(MIRROR_VECTOR, frame.root_pos), signs(MIRROR_AXIAL, frame.root_ang_vel)
    return ClipFrame(
        root_pos=frame.root_pos * vector,
        root_quat=frame.root_quat * signs(MIRROR_QUAT, frame.root_quat),
        root_lin_vel=frame.root_lin_vel * vector,
        root_ang_vel=frame.root_ang_vel * axial,
        joint_pos=frame.joint_pos[:, joints] * signs(MIRROR_JOINT_SIGNS, frame.joint_pos),
        joint_vel=frame.joint_vel[:, joints] * signs(MIRROR_JOINT_SIGNS, frame.joint_vel),
        foot_pos_local=frame.foot_pos_local[:, legs] * vector,
        foot_pos_world=frame.foot_pos_world[:, legs] * vector,
        contact=frame.contact[:, legs],
    )
