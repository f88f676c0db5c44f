"""``gaitlib drive``: a command timeline made into requests of the nearest skills, or waypoints steered to closed
loop (:mod:`gaitlib.meta.steering`), run on one robot through the meta-controller
(:func:`~gaitlib.meta.episode.drive_episode`), and measured.

A command drive is measured against its commanded path, the commands integrated from the robot's start pose
(straight lines and circular arcs). A command's achieved velocity is the robot's mean over the time the command was
in force (until a fall): its trunk's horizontal displacement per step, in its heading frame at that step, and its
heading change per second; the velocity error is the achieved minus the commanded, and its time-weighted root mean
square over the drive, per component and by the drive's distance (:func:`gaitlib.meta.commands.distance`). A
waypoint drive's commands are the skills it asked for, each from when it asked; it is measured by each waypoint's
arrival and closest approach, and the distance from the end to the last waypoint.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np

from gaitlib.defaults import DEFAULT_FALLS, DEFAULT_STRATEGY, Falls
from gaitlib.meta.commands import Commands, distance, nearest_skills, skills_of
from gaitlib.meta.episode import RunTrace, drive_episode
from gaitlib.meta.guard import Guard
from gaitlib.meta.setup import SwitchingSetup
from gaitlib.meta.steering import (
    REACH_M,
    TURN_ENTER,
    TURN_EXIT,
    Steering,
    WaypointPilot,
    check_waypoints,
)
from gaitlib.rotations import yaw_of

__all__ = ["DriveResult", "WaypointOutcome", "drive", "drive_waypoints", "step_velocity"]


@dataclass(frozen=True)
class WaypointOutcome:
    """How a waypoint drive went, waypoint by waypoint (the first, where the robot starts, left out)."""

    points: np.ndarray
    """(P, 2) the waypoints as given, m."""
    world: np.ndarray
    """(P, 2) the same in the world frame of :attr:`DriveResult.pose`, m."""
    reached_s: list[float | None]
    """(P - 1) when each later waypoint was reached (within :data:`~gaitlib.meta.steering.REACH_M`), s; ``None``:
    not reached."""
    closest_m: list[float | None]
    """(P - 1) each later waypoint's closest approach while it was aimed at, m; ``None``: never aimed at (the drive
    ended before)."""
    time_limit_s: float
    """The drive's time limit (:func:`~gaitlib.meta.steering.time_limit_s`), s."""
    steering: Steering

    @property
    def reached_all(self) -> bool:
        return all(t is not None for t in self.reached_s)

    def report(self) -> dict:
        """The JSON-ready keys of a waypoint drive: each later waypoint (its number in the file, counted from 1, and
        its x, y as given), whether and when it was reached and its closest approach; whether all were; the time
        limit; the steering's skills and constants."""
        rows = [{"index": k + 2, "x": x, "y": y, "reached": t is not None, "reached_s": t, "closest_m": closest}
                for k, ((x, y), t, closest) in enumerate(
                    zip(self.points[1:].tolist(), self.reached_s, self.closest_m, strict=True))]
        steering = self.steering
        return {
            "waypoints": rows,
            "reached_all": self.reached_all,
            "time_limit_s": self.time_limit_s,
            "steering": {"reach_m": REACH_M, "turn_enter_deg": math.degrees(TURN_ENTER),
                         "turn_exit_deg": math.degrees(TURN_EXIT), "ahead": steering.ahead.name,
                         "in_place": [s.name for s in steering.in_place], "arcs": [s.name for s in steering.arcs]},
        }


@dataclass(frozen=True)
class DriveResult:
    """A drive: its commands, the skill each requested, the run and the measurements."""

    commands: Commands
    """The commands, or for a waypoint drive the skills it asked for, each as its velocity from when it asked."""
    skills: list[str]
    """The skill requested for each command, the nearest."""
    skill_distance: np.ndarray
    """(K,) each command's distance to its skill, m/s."""
    trace: RunTrace
    pose: np.ndarray
    """(T + 1, 4) the robot's time (s), x (m), y (m) and heading (rad, unwrapped) at the start and after each
    step."""
    commanded: np.ndarray
    """(N, 2) what the drive was asked to follow in the world frame, m: the commanded path every control step to the
    drive's end, or the waypoints (straight legs between them)."""
    achieved: np.ndarray
    """(K, 3) each command's achieved forward speed (m/s), lateral speed (m/s) and yaw rate (rad/s); NaN for a
    command the robot did not live to run."""
    waypoints: WaypointOutcome | None = None
    """A waypoint drive's outcome (``None``: a command drive)."""

    @property
    def error(self) -> np.ndarray:
        """(K, 3) achieved minus commanded velocity."""
        return self.achieved - self.commands.velocity

    def rms_error(self) -> dict[str, float | None]:
        """The velocity error's root mean square over the commands run, weighted by their time run: forward,
        lateral (m/s), yaw rate (rad/s) and by the drive's distance (m/s); ``None`` if no command ran."""
        ran = ~np.isnan(self.achieved[:, 0])
        if not ran.any():
            return dict.fromkeys(("forward", "lateral", "yaw_rate", "distance"))
        weight = np.minimum(np.diff(self.commands.time_s), self.pose[-1, 0] - self.commands.time_s[:-1])[ran]
        weight = weight / weight.sum()
        error = self.error[ran]
        rms = np.sqrt(weight @ error**2)
        gap = distance(self.achieved[ran], self.commands.velocity[ran])
        return {"forward": float(rms[0]), "lateral": float(rms[1]), "yaw_rate": float(rms[2]),
                "distance": float(np.sqrt(weight @ gap**2))}

    @property
    def path_length_m(self) -> float:
        """Length of the commanded path (of the legs between the waypoints), m."""
        return float(np.linalg.norm(np.diff(self.commanded, axis=0), axis=1).sum())

    @property
    def end_error_m(self) -> float:
        """Distance from the robot's last position to the commanded path's end (the last waypoint), m."""
        return float(np.linalg.norm(self.pose[-1, 1:3] - self.commanded[-1]))


def drive(
    setup: SwitchingSetup,
    commands: Commands,
    *,
    strategy: str = DEFAULT_STRATEGY,
    action_delay: int | None = None,
    backend: str = "auto",
    seed: int = 0,
    falls: Falls = DEFAULT_FALLS,
    guard: Guard | None = None,
) -> DriveResult:
    """Drive one robot by ``commands`` with ``setup``'s library, open loop: each command requests its nearest skill
    (:func:`~gaitlib.meta.commands.nearest_skills`, which refuses a command beyond the library's range before any
    work), switched by ``strategy`` (guarded by ``guard`` when given); then measure the run."""
    names, gaps = nearest_skills(commands, skills_of([e.description for e in setup.entries]))
    trace = drive_episode(setup, pilot=_Timeline(commands.time_s[:-1].tolist(), names), end_s=commands.end_s,
                          strategy=strategy, action_delay=action_delay, backend=backend, seed=seed, falls=falls,
                          guard=guard)
    pose = _pose(trace)
    planned = commands.path(trace.dt)
    cos, sin = np.cos(pose[0, 3]), np.sin(pose[0, 3])
    commanded = pose[0, 1:3] + planned[:, :2] @ np.array([[cos, sin], [-sin, cos]])
    return DriveResult(commands=commands, skills=names, skill_distance=gaps, trace=trace, pose=pose,
                       commanded=commanded, achieved=_achieved(pose, commands))


def drive_waypoints(
    setup: SwitchingSetup,
    points: np.ndarray,
    *,
    strategy: str = DEFAULT_STRATEGY,
    action_delay: int | None = None,
    backend: str = "auto",
    seed: int = 0,
    falls: Falls = DEFAULT_FALLS,
    guard: Guard | None = None,
) -> DriveResult:
    """Drive one robot from ``points[0]`` (P, 2, m; where it starts, facing +x) through each later point, closed
    loop: every control step :class:`~gaitlib.meta.steering.WaypointPilot` aims again from the trunk's measured pose
    and asks for a skill, switched by ``strategy`` (guarded by ``guard`` when given). The drive ends once the last
    waypoint is reached, at a fall, or at its time limit (:func:`~gaitlib.meta.steering.time_limit_s`).
    :func:`~gaitlib.meta.steering.check_waypoints` refuses what cannot be driven in one line, before any work."""
    skills = skills_of([e.description for e in setup.entries])
    steering, limit = check_waypoints(points, skills)
    pilot = WaypointPilot(steering=steering, points=np.asarray(points, dtype=float))
    trace = drive_episode(setup, pilot=pilot, end_s=limit, strategy=strategy, action_delay=action_delay,
                          backend=backend, seed=seed, falls=falls, guard=guard)
    pose = _pose(trace)
    end_s = round(limit / trace.dt) * trace.dt if None in pilot.reached_s else len(trace.time_s) * trace.dt
    asked = [(t, name) for t, name in pilot.requests if t < end_s - 1e-9]
    velocity = {s.name: s.velocity for s in skills}
    commands = Commands(time_s=np.array([t for t, _ in asked] + [end_s]),
                        velocity=np.array([velocity[name] for _, name in asked], dtype=float))
    outcome = WaypointOutcome(points=pilot.points, world=pilot.world(pilot.points), reached_s=pilot.reached_s,
                              closest_m=pilot.closest_m, time_limit_s=limit, steering=steering)
    return DriveResult(commands=commands, skills=[name for _, name in asked], skill_distance=np.zeros(len(asked)),
                       trace=trace, pose=pose, commanded=outcome.world, achieved=_achieved(pose, commands),
                       waypoints=outcome)


class _Timeline:
    """The pilot of a command drive: each command's skill from the control step its time rounds to (a later
    command at the same step replaces it), whatever the pose."""

    def __init__(self, times: list[float], names: list[str]) -> None:
        self.times, self.names = times, names
        self._due: list[int] = []

    def start(self) -> str:
        return self.names[0]

    def steer(self, step: int, dt: float, pose: np.ndarray, running: str) -> str:
        if not self._due:
            self._due = [round(t / dt) for t in self.times]
        return self.names[bisect.bisect_right(self._due, step) - 1]


def _pose(trace: RunTrace) -> np.ndarray:
    """(T + 1, 4) the robot's time, x, y and unwrapped heading at the start and after each step of ``trace``."""
    qpos = np.vstack([trace.start_qpos[None], trace.qpos.reshape(-1, len(trace.start_qpos))])
    heading = np.unwrap(yaw_of(qpos[:, 3:7].astype(np.float64)))
    return np.column_stack([np.arange(len(qpos)) * trace.dt, qpos[:, 0], qpos[:, 1], heading])


def step_velocity(pose: np.ndarray) -> np.ndarray:
    """(T, 3) the robot's velocity over each step of ``pose`` (T + 1 rows of time, x, y, heading): its trunk's
    horizontal displacement in its heading frame at the step's middle, forward and lateral (m/s), and its heading
    change (rad/s), per step's duration."""
    if len(pose) < 2:
        return np.zeros((0, 3))
    dt = pose[1, 0] - pose[0, 0]
    step = np.diff(pose[:, 1:3], axis=0)
    mid = 0.5 * (pose[1:, 3] + pose[:-1, 3])
    cos, sin = np.cos(mid), np.sin(mid)
    return np.column_stack([cos * step[:, 0] + sin * step[:, 1], -sin * step[:, 0] + cos * step[:, 1],
                            np.diff(pose[:, 3])]) / dt


def _achieved(pose: np.ndarray, commands: Commands) -> np.ndarray:
    """(K, 3) each command's mean velocity over the steps it was in force and run (NaN: none)."""
    velocity, ends = step_velocity(pose), pose[1:, 0]
    achieved = np.full((len(commands.velocity), 3), np.nan)
    for i in range(len(commands.velocity)):
        inside = (ends > commands.time_s[i] + 1e-9) & (ends <= commands.time_s[i + 1] + 1e-9)
        if inside.any():
            achieved[i] = velocity[inside].mean(axis=0)
    return achieved
