"""Gaits of the A1: descriptions (a few numbers per gait, shipped as TOML files), leg kinematics, and reference
clips built from a description through the leg inverse kinematics or loaded from motion_imitation files.

Typical use::

    from gaitlib.gaits import clip_from_description, get_gait

    clip = clip_from_description(get_gait("trot"))
    frame = clip.frame(phase)  # phase: (N,) tensor of cycles -> ClipFrame of (N, ...) tensors
"""

from __future__ import annotations

from gaitlib.gaits.clip import ClipFrame, ReferenceClip
from gaitlib.gaits.description import GaitDescription, load_gait_file
from gaitlib.gaits.kinematics import (
    forward_kinematics,
    inverse_kinematics,
    leg_forward_kinematics,
    leg_inverse_kinematics,
)
from gaitlib.gaits.motion_file import load_motion_file, save_motion_file
from gaitlib.gaits.registry import gait_names, get_gait, register_gait
from gaitlib.gaits.synthesis import clip_from_description, contact_schedule, foot_trajectory, trunk_height, trunk_sway

__all__ = [
    "ClipFrame",
    "GaitDescription",
    "ReferenceClip",
    "clip_from_description",
    "contact_schedule",
    "foot_trajectory",
    "forward_kinematics",
    "gait_names",
    "get_gait",
    "inverse_kinematics",
    "leg_forward_kinematics",
    "leg_inverse_kinematics",
    "load_gait_file",
    "load_motion_file",
    "register_gait",
    "save_motion_file",
    "trunk_height",
    "trunk_sway",
]
