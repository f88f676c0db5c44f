"""Reference clips in the motion_imitation text format (Peng et al. 2020): JSON with frames of root and joint poses.

A file holds ``LoopMode`` (``"Wrap"``: the clip repeats, its last frame being its first pose; ``"Clamp"``: it
plays once), ``FrameDuration`` (s) and ``Frames``, each frame 19 numbers: root position x, y, z (m, world frame),
root orientation quaternion x, y, z, w (trunk to world), and the 12 joint angles (rad) in the A1 joint order
FR, FL, RR, RL x (hip abduction, thigh, calf). With ``"EnableCycleOffsetPosition": true`` a wrapping clip's trunk
advances per cycle by the horizontal displacement from its first to its last frame (otherwise it returns to its
start each cycle, as in motion_imitation); with ``"EnableCycleOffsetRotation": true`` it also turns per cycle by
its heading change from first to last frame (:attr:`~gaitlib.gaits.ReferenceClip.cycle_yaw`), about the vertical
through its first frame's trunk (motion_imitation turns about the world origin: the same for a clip that starts
there).
Velocities are finite differences, foot positions come from the A1's forward kinematics, and foot contacts are
estimated from foot heights.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from gaitlib.errors import GaitError
from gaitlib.gaits.clip import ReferenceClip
from gaitlib.robots.a1.constants import NUM_JOINTS
from gaitlib.rotations import yaw_of

__all__ = ["load_motion_file", "save_motion_file"]

_FRAME_SIZE = 3 + 4 + NUM_JOINTS
_LOOP_MODES = {"Wrap": True, "Clamp": False}


def load_motion_file(path: str | Path, *, contact_tolerance: float = 0.01) -> ReferenceClip:
    """Read a motion_imitation clip of the A1.

    Args:
        path: the JSON text file.
        contact_tolerance: a foot counts as on the ground when its centre is within this height, m, of the lowest
            foot centre anywhere in the clip.

    Raises:
        GaitError: the file is unreadable, not JSON, or lacks or malforms a field; the message names the file and
            the problem on one line.
    """
    path = Path(path)

    def fail(problem: str) -> GaitError:
        return GaitError(f"{path}: {problem}")

    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise fail(f"cannot read motion file: {error}") from error
    loop, duration, table, displacement, turn = _parse(data, fail)
    clip = ReferenceClip.from_frames(
        name=path.stem,
        frame_duration=duration,
        loop=loop,
        root_pos=table[:, :3],
        root_quat=table[:, [6, 3, 4, 5]],  # stored x, y, z, w
        joint_pos=table[:, 7:],
        contact=np.zeros((len(table), 4), dtype=bool),
        cycle_displacement=displacement,
        cycle_yaw=turn,
    )
    heights = clip.foot_pos_world[..., 2]
    return dataclasses.replace(clip, contact=heights <= heights.min() + contact_tolerance)



def _parse(data: object, fail: Callable[[str], GaitError]) -> tuple[bool, float, np.ndarray, np.ndarray, float]:
    """Check a motion file's JSON; return whether it loops, its frame duration (s), its (K, 19) frame table, its
    per-cycle trunk displacement (3,), m, and its per-cycle turn, rad."""
    if not isinstance(data, dict):
        raise fail("a motion file must hold a JSON object with LoopMode, FrameDuration and Frames")
    missing = [key for key in ("LoopMode", "FrameDuration", "Frames") if key not in data]
    if missing:
        raise fail(f"missing key(s) {', '.join(missing)}")
    if data["LoopMode"] not in _LOOP_MODES:
        raise fail(f'LoopMode must be "Wrap" or "Clamp", got {data["LoopMode"]!r}')
    loop = _LOOP_MODES[data["LoopMode"]]
    duration = data["FrameDuration"]
    if (
        isinstance(duration, bool)
        or not isinstance(duration, (int, float))
        or not math.isfinite(duration)
        or duration <= 0.0
    ):
        raise fail(f"FrameDuration must be a positive number of seconds, got {duration!r}")
    frames = data["Frames"]
    least = 3 if loop else 2
    if not isinstance(frames, list) or len(frames) < least:
        raise fail(f"Frames must be a list of at least {least} frames for LoopMode {data['LoopMode']}")
    for index, frame in enumerate(frames):
        if (
            not isinstance(frame, list)
            or len(frame) != _FRAME_SIZE
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in frame)
        ):
            raise fail(f"frame {index} must be {_FRAME_SIZE} finite numbers (root xyz, quaternion xyzw, 12 joints)")
    table = np.asarray(frames, dtype=np.float64)
    if (np.linalg.norm(table[:, 3:7], axis=1) < 1e-6).any():
        raise fail("a frame has a zero root quaternion")
    offset = data.get("EnableCycleOffsetPosition", False)
    if not isinstance(offset, bool):
        raise fail(f"EnableCycleOffsetPosition must be true or false, got {offset!r}")
    displacement = table[-1, :3] - table[0, :3] if offset else np.zeros(3)
    displacement[2] = 0.0
    rotation = data.get("EnableCycleOffsetRotation", False)
    if not isinstance(rotation, bool):
        raise fail(f"EnableCycleOffsetRotation must be true or false, got {rotation!r}")
    turn = 0.0
    if rotation and loop:  # the trunk's heading change over the clip, (-pi, pi)
        heading = yaw_of(table[[0, -1]][:, [6, 3, 4, 5]])
        turn = float((heading[1] - heading[0] + np.pi) % (2.0 * np.pi) - np.pi)
        if not abs(turn) < np.pi:
            raise fail("EnableCycleOffsetRotation: the clip turns half a turn (pi rad) per cycle; a clip turns less")
    return loop, float(duration), table, displacement, turn


def save_motion_file(clip: ReferenceClip, path: str | Path) -> None:
    """Write ``clip``'s frames in the motion_imitation format (velocities and contacts are not stored)."""
    quat_xyzw = clip.root_quat[:, [1, 2, 3, 0]]
    frames = np.concatenate([clip.root_pos, quat_xyzw, clip.joint_pos], axis=1)
    data = {
        "LoopMode": "Wrap" if clip.loop else "Clamp",
        "FrameDuration": clip.frame_duration,
        "EnableCycleOffsetPosition": bool(clip.loop and np.any(clip.cycle_displacement != 0.0)),
        "EnableCycleOffsetRotation": bool(clip.loop and clip.cycle_yaw != 0.0),
        "Frames": frames.tolist(),
    }
    Path(path).write_text(json.dumps(data), encoding="utf-8")
