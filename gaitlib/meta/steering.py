"""How ``gaitlib drive --waypoints`` steers, closed loop: every control step it aims again from the trunk's measured
pose, and requests one of the library's skills through the meta-controller.

The pose is the trunk's x, y (m) and heading (rad) from the simulator, standing for what a robot's state estimator
gives. The rule, in the waypoints' frame (the first waypoint is where the robot starts, facing +x):

1. **Reach.** A waypoint counts as reached once the trunk is within :data:`REACH_M` of it; the next one is aimed at
   from the same step on. Each new waypoint starts unaligned.
2. **Aim.** The bearing error is the waypoint's direction from the trunk minus its heading, wrapped to [-pi, pi].
   With hysteresis: an unaligned robot turns until the error is below :data:`TURN_EXIT`; an aligned one goes ahead
   until the error is above :data:`TURN_ENTER` and its heading line misses the reach circle (near the waypoint a
   large error still passes within :data:`REACH_M`: going on reaches it without a turn). So the meta-controller is
   asked for a new skill only when the error crosses one of two thresholds far apart, not every step.
3. **Go** with the slowest skill that goes straight ahead (:class:`Steering`).
4. **Turn** with, in this order: the fastest skill turning in place the needed way; the tightest arc turning that
   way (a skill going ahead while it turns) whose turning circle does not hold the waypoint (from inside the circle
   an arc circles it for ever); the fastest skill turning in place the other way, the long way round; an arc the
   other way whose circle does not hold the waypoint; else straight ahead, until the waypoint leaves the circles.
   A turn keeps its skill until aligned, unless that skill is an arc whose circle comes to hold the waypoint.
5. **Wait.** A skill requested is asked for until it runs: while the meta-controller waits for its moment to switch
   (at most its deadline, 2 s) or the guard holds a catch, the rule only counts arrivals. Deciding again meanwhile
   would judge the old skill's motion: a turn in place overshooting during the wait for the straight skill would be
   asked to go on turning, cancel that request, and circle again.
6. **Lead.** A turn ends early by the angle it turns while its switch to the straight skill waits: its yaw rate
   times the mean wait of that switch so far in the drive (0 s before the first), so that the straight skill starts
   aligned even where the strategy waits most of its deadline.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from gaitlib.defaults import MAX_RUN_SECONDS
from gaitlib.errors import GaitlibError
from gaitlib.meta.commands import STRAIGHT, Skill
from gaitlib.meta.controller import DEADLINE_S

__all__ = [
    "REACH_M",
    "TIME_FACTOR",
    "TURN_ENTER",
    "TURN_EXIT",
    "Aim",
    "Steering",
    "WaypointPilot",
    "bearing_error",
    "check_waypoints",
    "holds",
    "next_aim",
    "steering_of",
    "time_limit_s",
    "turning",
    "turning_skill",
]

REACH_M = 0.2
"""A waypoint is reached once the trunk is within this of it, m: the goal is 0.25 m, and a step of the fastest
skill (1.45 m/s at 30 Hz) is under 0.05 m, so an arrival counted here is within the goal."""
TURN_ENTER = math.radians(30.0)
"""An aligned robot starts turning when the bearing error exceeds this (and its heading line misses the reach
circle), rad: a robot going ahead to pass a waypoint a distance d > :data:`REACH_M` aside turns at 2 d from it."""
TURN_EXIT = math.radians(5.0)
"""A turning robot counts as aligned, and goes ahead, once the bearing error is below this, rad: from 2 m away a
5 degree error passes the waypoint 0.17 m aside, within :data:`REACH_M`; the gap to :data:`TURN_ENTER` takes the
turn's overshoot while the switch to the straight skill is made."""
TIME_FACTOR = 2.0
"""The drive's time limit gives each leg this many times its length at the straight skill's speed (besides a full
turn and two switch deadlines per waypoint, :func:`time_limit_s`)."""


@dataclass(frozen=True)
class Steering:
    """The skills a waypoint drive uses, picked from the library by their commanded velocities."""

    ahead: Skill
    """The slowest skill that goes straight ahead (forward speed above 0.05 m/s, lateral speed and yaw rate at most
    0.05): a drive to points asks for accuracy before speed."""
    in_place: tuple[Skill, ...]
    """The skills that turn in place (yaw rate above 0.05 rad/s, forward and lateral speed at most 0.05 m/s)."""
    arcs: tuple[Skill, ...]
    """The skills that turn while going ahead (forward speed above 0.05 m/s, yaw rate above 0.05 rad/s, lateral
    speed at most 0.05 m/s), on a circle of radius forward speed over yaw rate."""

    @property
    def slowest_turn(self) -> float:
        """The smallest yaw rate of the turning skills, rad/s."""
        return min(abs(s.velocity[2]) for s in (*self.in_place, *self.arcs))


def steering_of(skills: Sequence[Skill]) -> Steering:
    """The :class:`Steering` of a library of ``skills``; one line if it holds no skill to go straight ahead or none
    that turns (a closed loop must be able to correct its heading)."""
    ahead = [s for s in skills if s.velocity[0] > STRAIGHT and max(abs(s.velocity[1]), abs(s.velocity[2])) <= STRAIGHT]
    if not ahead:
        raise GaitlibError("waypoints need a skill that goes straight ahead; the library holds none")
    in_place = tuple(s for s in skills if abs(s.velocity[2]) > STRAIGHT and max(map(abs, s.velocity[:2])) <= STRAIGHT)
    arcs = tuple(s for s in skills
                 if s.velocity[0] > STRAIGHT and abs(s.velocity[2]) > STRAIGHT and abs(s.velocity[1]) <= STRAIGHT)
    if not in_place and not arcs:
        raise GaitlibError("waypoints need a skill that turns, in place or going ahead, to aim at them again as the "
                           "robot drifts; the library holds none")
    return Steering(ahead=min(ahead, key=lambda s: s.velocity[0]), in_place=in_place, arcs=arcs)


def bearing_error(pose: np.ndarray, target: np.ndarray) -> float:
    """The direction of ``target`` (x, y, m) seen from ``pose`` (x m, y m, heading rad) minus the heading, rad,
    wrapped to [-pi, pi] (positive: the target lies to the left)."""
    return math.remainder(math.atan2(target[1] - pose[1], target[0] - pose[0]) - pose[2], 2 * math.pi)


def turning(was_turning: bool, error: float, distance: float, *, lead: float = 0.0) -> bool:
    """Whether the robot turns at this step, given whether it turned at the last one, the bearing ``error`` (rad)
    and the ``distance`` to the waypoint (m): the hysteresis of :data:`TURN_EXIT` and :data:`TURN_ENTER`, where a
    robot going ahead keeps going while its heading line passes within :data:`REACH_M` of the waypoint. ``lead``
    (rad, signed as the turn's yaw rate): the angle the turn is expected to cover while the switch that ends it
    waits; a turn ends once the angle still to turn its way is at most ``|lead|`` plus :data:`TURN_EXIT` (or it has
    just passed the waypoint's bearing by less than :data:`TURN_EXIT`)."""
    if was_turning:
        if lead == 0.0:
            return abs(error) >= TURN_EXIT
        to_go = (error * math.copysign(1.0, lead)) % (2 * math.pi)  # the turn's way round to the bearing
        return TURN_EXIT + abs(lead) < to_go < 2 * math.pi - TURN_EXIT
    passes = abs(error) < math.pi / 2 and distance * math.sin(abs(error)) <= REACH_M
    return abs(error) > TURN_ENTER and not passes


def holds(arc: Skill, pose: np.ndarray, target: np.ndarray, *, margin: float = 0.0) -> bool:
    """Whether the turning circle of ``arc`` (radius forward speed over yaw rate, centred beside ``pose`` on the
    side it turns to), widened by ``margin`` (m), holds ``target``: the arc never faces a point inside it."""
    forward, _, yaw_rate = arc.velocity
    radius = forward / abs(yaw_rate)
    side = math.copysign(1.0, yaw_rate)
    centre = np.array([pose[0] - side * radius * math.sin(pose[2]), pose[1] + side * radius * math.cos(pose[2])])
    return float(np.linalg.norm(np.asarray(target[:2]) - centre)) < radius + margin


def turning_skill(steering: Steering, pose: np.ndarray, target: np.ndarray) -> Skill:
    """The skill that turns ``pose`` toward ``target`` by the rule's order (module docstring, 4.); an arc is taken
    only with the target :data:`REACH_M` outside its circle, so that one taken at the circle's edge is not given up
    at the next step."""
    way = math.copysign(1.0, bearing_error(pose, target))
    for sign in (way, -way):
        spins = [s for s in steering.in_place if s.velocity[2] * sign > 0]
        if spins:
            return max(spins, key=lambda s: abs(s.velocity[2]))
        arcs = [s for s in steering.arcs if s.velocity[2] * sign > 0 and not holds(s, pose, target, margin=REACH_M)]
        if arcs:
            return min(arcs, key=lambda s: s.velocity[0] / abs(s.velocity[2]))
    return steering.ahead


@dataclass(frozen=True)
class Aim:
    """Where a waypoint drive stands: the waypoint aimed at, whether it turns, and the skill it requests."""

    target: int
    """The index of the waypoint aimed at (1 at the start; the number of waypoints once all are reached)."""
    turning: bool
    skill: Skill


def next_aim(steering: Steering, points: np.ndarray, aim: Aim | None, pose: np.ndarray, *,
             waiting: bool = False, wait_s: float = 0.0) -> Aim:
    """The rule for one control step: from ``aim`` (``None`` at the start) and the measured ``pose`` (x m, y m,
    heading rad, in the frame of ``points``), the waypoint aimed at now, whether to turn and the skill to request.
    The skill stays as it is once every waypoint is reached, and while ``waiting``: the skill requested does not run
    yet (the meta-controller waits for its moment, at most its deadline, or the guard holds a catch). ``wait_s``:
    how long the switch from the running turn to the straight skill is expected to wait, s (its lead,
    :func:`turning`)."""
    target, was_turning, skill = (1, True, steering.ahead) if aim is None else (aim.target, aim.turning, aim.skill)
    while target < len(points) and math.dist(pose[:2], points[target]) <= REACH_M:
        target, was_turning = target + 1, True  # a new waypoint starts unaligned
    if target == len(points) or waiting:
        return Aim(target, was_turning, skill)
    goal = points[target]
    lead = skill.velocity[2] * wait_s if was_turning else 0.0
    turn = turning(was_turning, bearing_error(pose, goal), math.dist(pose[:2], goal), lead=lead)
    if not turn:
        return Aim(target, False, steering.ahead)
    kept = was_turning and aim is not None and aim.target == target and skill != steering.ahead
    if kept and not (skill in steering.arcs and holds(skill, pose, goal)):
        return Aim(target, True, skill)
    return Aim(target, True, turning_skill(steering, pose, goal))


def time_limit_s(points: np.ndarray, steering: Steering) -> float:
    """The longest a drive through ``points`` may take, s: each leg :data:`TIME_FACTOR` times its length at the
    straight skill's speed, and at each waypoint a full turn at the slowest turning skill's yaw rate and two switch
    deadlines (to the turn and back)."""
    legs = np.linalg.norm(np.diff(points, axis=0), axis=1)
    return float(TIME_FACTOR * legs.sum() / steering.ahead.velocity[0]
                 + len(legs) * (2 * math.pi / steering.slowest_turn + 2 * DEADLINE_S))


def check_waypoints(points: np.ndarray, skills: Sequence[Skill]) -> tuple[Steering, float]:
    """The steering (:func:`steering_of`) and the time limit (:func:`time_limit_s`, s) of a drive through
    ``points`` with ``skills``; one line, before any work, if every waypoint lies within :data:`REACH_M` of the
    start (all are reached before the first step), if the library cannot steer, or if the time limit is longer than
    the longest run."""
    if np.linalg.norm(points - points[0], axis=1).max() <= REACH_M:
        raise GaitlibError(f"every waypoint lies within {REACH_M:g} m of the first, where the robot starts: all are "
                           "reached before the first step, there is nothing to drive")
    steering = steering_of(skills)
    limit = time_limit_s(points, steering)
    if limit > MAX_RUN_SECONDS:
        length = float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())
        raise GaitlibError(f"the waypoints' time limit is {limit:.4g} s ({length:.4g} m of legs at "
                           f"{steering.ahead.velocity[0]:g} m/s, turns and switches), longer than the longest run, "
                           f"{MAX_RUN_SECONDS:g} s")
    return steering, limit


@dataclass
class WaypointPilot:
    """A waypoint drive's pilot for :func:`~gaitlib.meta.episode.drive_episode`: :func:`next_aim` every step, from
    the measured pose taken into the waypoints' frame (the start pose is the first waypoint, facing +x), with each
    waypoint's arrival and closest approach, and the waits of the switches it asked for (a turn's lead is the mean
    wait of its switches to the straight skill so far, 0 s before the first)."""

    steering: Steering
    points: np.ndarray
    """(P, 2) the waypoints, m, the first where the robot starts."""
    origin: np.ndarray | None = None
    """The start pose in the world (x m, y m, heading rad), taken at the first step."""
    aim: Aim | None = None
    reached_s: list[float | None] = field(default_factory=list)
    """When each later waypoint was reached, s (``None``: not reached)."""
    closest_m: list[float | None] = field(default_factory=list)
    """Each later waypoint's closest approach while it was aimed at, m (``None``: never aimed at)."""
    requests: list[tuple[float, str]] = field(default_factory=list)
    """(time s, skill) each time the skill asked for changed."""
    waits: dict[tuple[str, str], list[float]] = field(default_factory=dict)
    """(from, to) skill: the waits of the switches asked for, from the request to the switch, s."""
    asked: tuple[float, str] | None = None
    """When the skill asked for and not yet running was asked for (s), and the skill that ran then."""

    def __post_init__(self) -> None:
        self.reached_s = [None] * (len(self.points) - 1)
        self.closest_m = [None] * (len(self.points) - 1)

    def start(self) -> str:
        """The skill to start in: the rule at the start pose."""
        name = self._steer(0.0, np.array([*self.points[0], 0.0]))
        self.requests.append((0.0, name))
        return name

    def steer(self, step: int, dt: float, pose: np.ndarray, running: str) -> str | None:
        """The skill to run at control step ``step`` (``dt`` s each) from the world ``pose`` (x, y, heading) before
        it, ``running`` the skill that runs; ``None`` once every waypoint is reached (the drive ends)."""
        if self.origin is None:
            self.origin = np.array(pose, dtype=float)
        time_s, asked = step * dt, self.aim.skill.name
        if self.asked is not None and running == asked:  # switched at the last step's start
            self.waits.setdefault((self.asked[1], asked), []).append(max(0.0, time_s - dt - self.asked[0]))
            self.asked = None
        seen = self.waits.get((asked, self.steering.ahead.name))
        name = self._steer(time_s, self.local(pose), waiting=running != asked,
                           wait_s=float(np.mean(seen)) if seen else 0.0)
        if name is not None and name != asked:
            self.requests.append((time_s, name))
            self.asked = (time_s, running)
        return name

    def local(self, pose: np.ndarray) -> np.ndarray:
        """World ``pose`` rows (..., 3) in the waypoints' frame."""
        pose = np.asarray(pose, dtype=float)
        x, y, heading = self.origin
        cos, sin = math.cos(heading), math.sin(heading)
        dx, dy = pose[..., 0] - x, pose[..., 1] - y
        return np.stack([self.points[0, 0] + cos * dx + sin * dy, self.points[0, 1] - sin * dx + cos * dy,
                         pose[..., 2] - heading], axis=-1)

    def world(self, points: np.ndarray) -> np.ndarray:
        """(..., 2) ``points`` of the waypoints' frame in the world."""
        x, y, heading = self.origin
        cos, sin = math.cos(heading), math.sin(heading)
        d = np.asarray(points, dtype=float) - self.points[0]
        return np.stack([x + cos * d[..., 0] - sin * d[..., 1], y + sin * d[..., 0] + cos * d[..., 1]], axis=-1)

    def _steer(self, time_s: float, pose: np.ndarray, *, waiting: bool = False, wait_s: float = 0.0) -> str | None:
        """:func:`next_aim` at ``pose`` (the waypoints' frame), the arrivals and closest approaches taken."""
        first = 1 if self.aim is None else self.aim.target
        self.aim = aim = next_aim(self.steering, self.points, self.aim, pose, waiting=waiting, wait_s=wait_s)
        for k in range(first, min(aim.target + 1, len(self.points))):  # aimed at during this step
            gap = math.dist(pose[:2], self.points[k])
            seen = self.closest_m[k - 1]
            self.closest_m[k - 1] = gap if seen is None else min(seen, gap)
            if k < aim.target:
                self.reached_s[k - 1] = time_s
        return None if aim.target == len(self.points) else aim.skill.name
