"""What ``gaitlib drive`` is asked to do: a timeline of velocity commands (or waypoints made into one), and the
library skill nearest each command.

A command is a planar velocity in the trunk's heading frame: forward speed (m/s, negative backward), lateral speed
(m/s, positive to the left) and yaw rate (rad/s, positive counter-clockwise), legged_gym's ``lin_vel_x``,
``lin_vel_y`` and ``ang_vel_yaw``. Its distance to a skill, a gait description's own three numbers, is Euclidean
over (forward, lateral, yaw rate x :data:`TURN_RADIUS_M`): the yaw rate becomes the speed it asks of the feet.
"""

from __future__ import annotations

import csv
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gaitlib.errors import GaitlibError
from gaitlib.gaits.description import GaitDescription
from gaitlib.robots.a1.constants import HIP_OFFSETS, THIGH_OFFSET_Y

__all__ = [
    "COMMAND_HEADER",
    "RANGE_BOUND",
    "TURN_RADIUS_M",
    "WAYPOINT_HEADER",
    "Commands",
    "Skill",
    "distance",
    "nearest_skills",
    "read_commands",
    "read_waypoints",
    "skills_of",
    "waypoint_commands",
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
MAX_SECONDS = 600.0
"""The longest drive, s (as ``gaitlib run``'s times)."""


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
            inside = (t > start) & (t <= stop)
            poses[inside] = [_advance(pose, forward, lateral, yaw_rate, s - start) for s in t[inside]]
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
    """The skills of gaits described by ``descriptions``, in their order."""
    return [Skill(d.name, (d.forward_speed, d.lateral_speed, d.yaw_rate)) for d in descriptions]


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
            f"the command at {commands.time_s[i]:g} s (forward {forward:g} m/s, lateral {lateral:g} m/s, yaw rate "
            f"{yaw_rate:g} rad/s) is beyond every skill of the library: the nearest, {skills[chosen[i]].name}, is "
            f"{nearest[i]:.3f} m/s away, more than {RANGE_BOUND:g}"
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
        raise GaitlibError(f"{path}: the first command is at {times[0]:g} s; the drive starts with it at 0 s")
    back = np.flatnonzero(np.diff(times) <= 0)
    if len(back):
        k = int(back[0]) + 1
        raise GaitlibError(f"{path}: times must increase, but row {k + 1} ({times[k]:g} s) does not come after "
                           f"row {k} ({times[k - 1]:g} s)")
    if times[-1] > MAX_SECONDS:
        raise GaitlibError(f"{path}: the drive ends at {times[-1]:g} s, longer than {MAX_SECONDS:g} s")
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
    if np.abs(points).max() > 1000.0:
        raise GaitlibError(f"{path}: a waypoint lies more than 1000 m from the start")
    return points


def waypoint_commands(points: np.ndarray, skills: Sequence[Skill]) -> Commands:
    """The command timeline that drives from ``points[0]`` (facing +x) through each later point, open loop: at
    each point turn in place toward the next with the fastest skill that turns in place that way (the other way
    round if the library turns only the other way), then go straight to it with the slowest skill that goes straight
    ahead. One line if the library has no such skill."""
    ahead = [s for s in skills if s.velocity[0] > STRAIGHT and max(abs(s.velocity[1]), abs(s.velocity[2])) <= STRAIGHT]
    turners = [s for s in skills if abs(s.velocity[2]) > STRAIGHT and max(map(abs, s.velocity[:2])) <= STRAIGHT]
    if not ahead:
        raise GaitlibError("waypoints need a skill that goes straight ahead; the library holds none")
    forward = min(ahead, key=lambda s: s.velocity[0]).velocity
    times, velocities, heading = [0.0], [], 0.0
    for k, (start, end) in enumerate(itertools.pairwise(points)):
        step = end - start
        turn = math.remainder(math.atan2(step[1], step[0]) - heading, 2 * math.pi)
        if abs(turn) > math.radians(1.0):
            spin = _turner(turners, turn, point=k + 1)
            angle = turn if math.copysign(1.0, turn) == math.copysign(1.0, spin[2]) else turn - math.copysign(
                2 * math.pi, turn)
            times.append(times[-1] + angle / spin[2])
            velocities.append(spin)
        heading += turn
        times.append(times[-1] + float(np.linalg.norm(step)) / forward[0])
        velocities.append(forward)
    if times[-1] > MAX_SECONDS:
        raise GaitlibError(f"the waypoints take {times[-1]:.0f} s to drive, longer than {MAX_SECONDS:g} s")
    return Commands(time_s=np.array(times), velocity=np.array(velocities, dtype=float))


def _turner(turners: list[Skill], turn: float, *, point: int) -> tuple[float, float, float]:
    if not turners:
        raise GaitlibError(f"the waypoints turn {math.degrees(turn):.0f} degrees at waypoint {point}; the library "
                           "holds no skill that turns in place")
    same_way = [s for s in turners if s.velocity[2] * turn > 0]
    return max(same_way or turners, key=lambda s: abs(s.velocity[2])).velocity


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
    try:
        with open(path, newline="") as file:
            reader = csv.reader(file)
            lines = [(reader.line_num, row) for row in reader if any(cell.strip() for cell in row)]
    except (OSError, UnicodeDecodeError) as error:
        raise GaitlibError(f"{path}: cannot be read as {what} ({error.__class__.__name__})") from None
    except csv.Error as error:
        raise GaitlibError(f"{path}: not a CSV file ({error})") from None
    if not lines:
        raise GaitlibError(f"{path} is empty; {what} has the header {','.join(header)} and its rows")
    found = tuple(cell.strip() for cell in lines[0][1])
    if found != header:
        raise GaitlibError(f"{path}: the header is '{','.join(found)}'; {what} needs '{','.join(header)}'")
    rows = []
    for number, row in lines[1:]:
        if len(row) != len(header):
            raise GaitlibError(f"{path}: line {number} has {len(row)} fields, not {len(header)}")
        try:
            values = [float(cell) for cell in row]
        except ValueError:
            raise GaitlibError(f"{path}: line {number} is not numbers: '{','.join(row)}'") from None
        if not all(math.isfinite(v) for v in values):
            raise GaitlibError(f"{path}: line {number} holds a value that is not finite: '{','.join(row)}'")
        rows.append(values)
    return np.array(rows, dtype=float).reshape(-1, len(header))
