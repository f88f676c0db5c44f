"""What ``gaitlib drive`` is asked to do: a timeline of velocity commands, and the library skill nearest each
command; or waypoints, steered to closed loop (:mod:`gaitlib.meta.steering`).

A command is a planar velocity in the trunk's heading frame: forward speed (m/s, negative backward), lateral speed
(m/s, positive to the left) and yaw rate (rad/s, positive counter-clockwise), legged_gym's ``lin_vel_x``,
``lin_vel_y`` and ``ang_vel_yaw``. Its distance to a skill, a gait description's own three numbers, is Euclidean
over (forward, lateral, yaw rate x :data:`TURN_RADIUS_M`): the yaw rate becomes the speed it asks of the feet.
"""

from __future__ import annotations

import csv
import io
import math
import os
import stat
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gaitlib.defaults import MAX_RUN_SECONDS
from gaitlib.errors import GaitlibError
from gaitlib.gaits.description import GaitDescription
from gaitlib.robots.a1.constants import CONTROL_HZ, HIP_OFFSETS, THIGH_OFFSET_Y
from gaitlib.values import number_text

__all__ = [
    "COMMAND_HEADER",
    "MAX_INPUT_BYTES",
    "MAX_WAYPOINT_M",
    "RANGE_BOUND",
    "STRAIGHT",
    "TURN_RADIUS_M",
    "WAYPOINT_HEADER",
    "Commands",
    "Skill",
    "distance",
    "nearest_skills",
    "read_commands",
    "read_waypoints",
    "skills_of",
]

COMMAND_HEADER = ("time_s", "forward", "lateral", "yaw_rate")
"""The header of a command timeline: s, m/s, m/s, rad/s."""
WAYPOINT_HEADER = ("x", "y")
"""The header of a waypoint list: m, m, in the frame the robot starts in (x ahead, y to its left)."""
TURN_RADIUS_M = math.hypot(HIP_OFFSETS[0][0], abs(HIP_OFFSETS[0][1]) + abs(THIGH_OFFSET_Y[0]))
"""Horizontal distance from the trunk's centre to a foot below its thigh joint, m (0.226 m, from Unitree's A1
URDF figures in :mod:`gaitlib.robots.a1.constants`): turning at yaw rate w moves a foot on the ground at w times
this relative to the trunk, so it puts a yaw rate into the units of a speed."""
RANGE_BOUND = 0.25
"""A command farther than this from every skill of the library is beyond its range and refused, m/s (a choice: a
quarter of legged_gym's forward command bound of 1 m/s; it takes the forward speeds between the shipped gaits, and
refuses a sidestep of 0.3 m/s, a walk backward of 0.5 m/s or a turn in place of 1.5 rad/s to a library that holds
none of them)."""
STRAIGHT = 0.05
"""A skill's lateral speed (m/s) and yaw rate (rad/s) at most this count as none: it goes straight (or turns in
place, for forward and lateral speeds), as the quality bar's tolerance for a zero reference."""
MAX_WAYPOINT_M = 1000.0
"""The farthest a waypoint may lie from the first, where the robot starts, m."""
MAX_INPUT_BYTES = 1 << 20
"""The largest command timeline or waypoint list read, bytes (1 MiB: some 40,000 rows, beyond any drive of
:data:`~gaitlib.defaults.MAX_RUN_SECONDS`); only this much of a larger file is read before it is refused."""
MAX_VALUE = 1e6
"""The largest size of any number of a command timeline or waypoint list (times, speeds, coordinates are refused
far below it): a larger one is refused as it is read, before any arithmetic on it."""


@dataclass(frozen=True)
class Commands:
    """A command timeline: row i is in force from ``time_s[i]`` until ``time_s[i + 1]``; the last time ends it."""

    time_s: np.ndarray
    """(K + 1,) strictly increasing times from 0, s."""
    velocity: np.ndarray
    """(K, 3) forward speed (m/s), lateral speed (m/s) and yaw rate (rad/s) of each command."""

    @property
    def end_s(self) -> float:
        return float(self.time_s[-1])

    def path(self, dt: float) -> np.ndarray:
        """(S + 1, 3) the commanded pose (x m, y m, heading rad) from the start pose (0, 0, 0) every ``dt`` for the
        drive's S = round(end / dt) control steps, the last row the pose at the end: the commands integrated exactly
        (straight lines and circular arcs)."""
        steps = max(1, round(self.end_s / dt))
        t = np.arange(steps + 1) * dt
        poses = np.zeros((steps + 1, 3))
        pose = np.zeros(3)
        for i, (forward, lateral, yaw_rate) in enumerate(self.velocity):
            start, stop = self.time_s[i], self.time_s[i + 1]
            inside = (t > start) & (t <= stop)  # none where the command is shorter than a step: it only moves on
            for row in np.flatnonzero(inside):
                poses[row] = _advance(pose, forward, lateral, yaw_rate, t[row] - start)
            pose = _advance(pose, forward, lateral, yaw_rate, stop - start)
        poses[(t > self.end_s) | (t == t[-1])] = pose
        return poses


@dataclass(frozen=True)
class Skill:
    """A library gait as a velocity: its description's forward speed, lateral speed and yaw rate."""

    name: str
    velocity: tuple[float, float, float]
    """Forward speed (m/s), lateral speed (m/s), yaw rate (rad/s)."""


def skills_of(descriptions: Sequence[GaitDescription]) -> list[Skill]:
    """The skills of gaits described by ``descriptions``, in their order; a catch skill is none (it comes to the stance
    of a robot the guard hands it, at no velocity a command asks for: the stand is the skill of a halt)."""
    return [Skill(d.name, (d.forward_speed, d.lateral_speed, d.yaw_rate)) for d in descriptions if d.task != "catch"]


def distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The drive's distance between (..., 3) velocities, m/s: Euclidean over (forward, lateral, yaw rate x
    :data:`TURN_RADIUS_M`)."""
    scale = np.array([1.0, 1.0, TURN_RADIUS_M])
    return np.linalg.norm((np.asarray(a) - np.asarray(b)) * scale, axis=-1)


def nearest_skills(commands: Commands, skills: Sequence[Skill]) -> tuple[list[str], np.ndarray]:
    """The skill nearest each command (the first in ``skills``' order on a tie) and its distance, m/s; a command
    beyond :data:`RANGE_BOUND` of every skill is refused in one line."""
    table = np.array([s.velocity for s in skills])
    gaps = distance(commands.velocity[:, None, :], table[None, :, :])
    chosen = gaps.argmin(axis=1)
    nearest = gaps[np.arange(len(chosen)), chosen]
    for i in np.flatnonzero(nearest > RANGE_BOUND)[:1]:
        forward, lateral, yaw_rate = commands.velocity[i]
        raise GaitlibError(
            f"the command at {number_text(commands.time_s[i])} s (forward {number_text(forward)} m/s, lateral "
            f"{number_text(lateral)} m/s, yaw rate {number_text(yaw_rate)} rad/s) is beyond every skill of the "
            f"library: the nearest, {skills[chosen[i]].name}, is {nearest[i]:.3f} m/s away, more than {RANGE_BOUND:g}"
        )
    return [skills[k].name for k in chosen], nearest


def read_commands(path: Path) -> Commands:
    """The command timeline in CSV file ``path`` (header ``time_s,forward,lateral,yaw_rate``; the first row at 0 s,
    times strictly increasing, the last row's time ending the drive and its velocity unused); one line for a file
    that breaks a rule."""
    rows = _read(path, COMMAND_HEADER, what="a command timeline")
    if len(rows) < 2:
        raise GaitlibError(f"{path}: a command timeline needs at least two rows, a command and the end of the drive")
    times = rows[:, 0]
    if times[0] != 0.0:
        raise GaitlibError(f"{path}: the first command is at {number_text(times[0])} s; the drive starts with it at "
                           "0 s")
    back = np.flatnonzero(np.diff(times) <= 0)
    if len(back):
        k = int(back[0]) + 1
        raise GaitlibError(f"{path}: times must increase, but row {k + 1} ({number_text(times[k])} s) does not come "
                           f"after row {k} ({number_text(times[k - 1])} s)")
    _check_length(times[-1], f"{path}: the drive ends at {number_text(times[-1])} s")
    return Commands(time_s=times.copy(), velocity=rows[:-1, 1:].copy())


def read_waypoints(path: Path) -> np.ndarray:
    """(P, 2) the waypoints in CSV file ``path`` (header ``x,y``, m; the first is where the robot starts, facing
    +x; at least two, each away from the one before); one line for a file that breaks a rule."""
    points = _read(path, WAYPOINT_HEADER, what="a waypoint list")
    if len(points) < 2:
        raise GaitlibError(f"{path}: a waypoint list needs at least two points (the first is where the robot starts),"
                           f" got {len(points)}")
    same = np.flatnonzero(np.linalg.norm(np.diff(points, axis=0), axis=1) < 1e-3)
    if len(same):
        k = int(same[0]) + 2
        raise GaitlibError(f"{path}: waypoint {k} is where waypoint {k - 1} is (within 1 mm)")
    far = np.linalg.norm(points - points[0], axis=1)
    if far.max() > MAX_WAYPOINT_M:
        k = int(far.argmax())
        raise GaitlibError(f"{path}: waypoint {k + 1} lies {far[k]:.1f} m from the first, where the robot starts; "
                           f"the farthest a drive goes is {MAX_WAYPOINT_M:g} m")
    return points


def _check_length(end_s: float, drive: str) -> None:
    """Refuse a drive ending at ``end_s`` (``drive`` says so, e.g. ``the drive ends at 700 s``) that is longer
    than :data:`~gaitlib.defaults.MAX_RUN_SECONDS` or holds no control step, before any work."""
    if end_s > MAX_RUN_SECONDS:
        raise GaitlibError(f"{drive}, longer than the longest run, {MAX_RUN_SECONDS:g} s")
    if round(end_s / (1.0 / CONTROL_HZ)) < 1:  # the steps a drive runs (gaitlib.meta.episode.drive_episode)
        raise GaitlibError(f"{drive}, less than half a control step (1/{CONTROL_HZ:g} s): there is nothing to drive")


def _advance(pose: np.ndarray, forward: float, lateral: float, yaw_rate: float, seconds: float) -> np.ndarray:
    """``pose`` (x, y, heading) after ``seconds`` at a constant velocity in its heading frame (an arc if it turns)."""
    x, y, heading = pose
    turned = yaw_rate * seconds
    if abs(turned) < 1e-9:
        along, across = forward * seconds, lateral * seconds
    else:  # the body-frame displacement of a constant twist: (sin w t, 1 - cos w t) / w mixes the two speeds
        s, c = math.sin(turned) / yaw_rate, (1.0 - math.cos(turned)) / yaw_rate
        along, across = forward * s - lateral * c, forward * c + lateral * s
    cos, sin = math.cos(heading), math.sin(heading)
    return np.array([x + cos * along - sin * across, y + sin * along + cos * across, heading + turned])


def _read(path: Path, header: tuple[str, ...], *, what: str) -> np.ndarray:
    """The rows of CSV file ``path`` with exactly ``header``, as finite floats; one line otherwise."""
    reader = csv.reader(io.StringIO(_text(path, what), newline=""))
    try:
        lines = [(reader.line_num, row) for row in reader if any(cell.strip() for cell in row)]
    except csv.Error as error:
        raise GaitlibError(f"{path}: not a CSV file ({error})") from None
    if not lines:
        raise GaitlibError(f"{path} is empty; {what} has the header {','.join(header)} and its rows")
    found = tuple(cell.strip() for cell in lines[0][1])
    if found != header:
        raise GaitlibError(f"{path}: the header is '{_shown(','.join(found))}'; {what} needs '{','.join(header)}'")
    rows = []
    for number, row in lines[1:]:
        if len(row) != len(header):
            raise GaitlibError(f"{path}: line {number} has {len(row)} fields, not {len(header)}")
        try:
            values = [float(cell) for cell in row]
        except ValueError:
            raise GaitlibError(f"{path}: line {number} is not numbers: '{_shown(','.join(row))}'") from None
        if not all(math.isfinite(v) for v in values):
            raise GaitlibError(f"{path}: line {number} holds a value that is not finite: '{','.join(row)}'")
        for cell, value in zip(row, values, strict=True):
            if abs(value) > MAX_VALUE:
                raise GaitlibError(f"{path}: line {number} holds {cell.strip()}, larger than any drive takes (at most "
                                   f"{MAX_VALUE:.0f} in size)")
        rows.append(values)
    return np.array(rows, dtype=float).reshape(-1, len(header))


_KINDS = {stat.S_ISDIR: "a folder", stat.S_ISFIFO: "a named pipe", stat.S_ISCHR: "a device", stat.S_ISBLK: "a device",
          stat.S_ISSOCK: "a socket"}


def _text(path: Path, what: str) -> str:
    """The text of ``path``, a regular file of at most :data:`MAX_INPUT_BYTES` in UTF-8 (a byte order mark at its
    start is dropped): a pipe or a device is refused before it is opened, and a larger file after reading one byte
    more than the limit, so that neither can hang the command or fill its memory."""
    try:
        mode = os.stat(path).st_mode
        if not stat.S_ISREG(mode):
            kind = next((name for test, name in _KINDS.items() if test(mode)), "not a regular file")
            raise GaitlibError(f"{path} is {kind}; {what} is read from a regular file")
        with open(path, "rb") as file:
            data = file.read(MAX_INPUT_BYTES + 1)
    except OSError as error:
        raise GaitlibError(f"{path}: cannot be read as {what} ({error.__class__.__name__})") from None
    if len(data) > MAX_INPUT_BYTES:
        raise GaitlibError(f"{path} is larger than {MAX_INPUT_BYTES >> 20} MiB, more than {what} of any drive holds")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise GaitlibError(f"{path}: cannot be read as {what} (UnicodeDecodeError: not UTF-8 text)") from None


def _shown(text: str) -> str:
    """``text`` as a message shows it: characters that print as nothing or look like others (a byte order mark, a
    zero-width space, a control character) written as escapes, ``\\ufeff``."""
    return text if text.isprintable() else "".join(c if c.isprintable() else ascii(c)[1:-1] for c in text)
