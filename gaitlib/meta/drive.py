"""``gaitlib drive``: a command timeline made into requests of the nearest skills, run on one robot through the
meta-controller (:func:`~gaitlib.meta.episode.drive_episode`), and measured against the commanded path.

The commanded path is the commands integrated from the robot's start pose (straight lines and circular arcs). A
command's achieved velocity is the robot's mean over the time the command was in force (until a fall): its trunk's
horizontal displacement per step, in its heading frame at that step, and its heading change per second; the
velocity error is the achieved minus the commanded, and its time-weighted root mean square over the drive, per
component and by the drive's distance (:func:`gaitlib.meta.commands.distance`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gaitlib.defaults import DEFAULT_FALLS, DEFAULT_STRATEGY, Falls
from gaitlib.meta.commands import Commands, distance, nearest_skills, skills_of
from gaitlib.meta.episode import RunTrace, drive_episode
from gaitlib.meta.guard import Guard
from gaitlib.meta.setup import SwitchingSetup
from gaitlib.rotations import yaw_of

__all__ = ["DriveResult", "drive", "step_velocity"]


@dataclass(frozen=True)
class DriveResult:
    """A drive: its commands, the skill each requested, the run and the measurements."""

    commands: Commands
    skills: list[str]
    """The skill requested for each command, the nearest."""
    skill_distance: np.ndarray
    """(K,) each command's distance to its skill, m/s."""
    trace: RunTrace
    pose: np.ndarray
    """(T + 1, 4) the robot's time (s), x (m), y (m) and heading (rad, unwrapped) at the start and after each
    step."""
    commanded: np.ndarray
    """(T' + 1, 4) the commanded path on the same clock to the drive's end: time, x, y, heading."""
    achieved: np.ndarray
    """(K, 3) each command's achieved forward speed (m/s), lateral speed (m/s) and yaw rate (rad/s); NaN for a
    command the robot did not live to run."""

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
        """Length of the commanded path, m."""
        return float(np.linalg.norm(np.diff(self.commanded[:, 1:3], axis=0), axis=1).sum())

    @property
    def end_error_m(self) -> float:
        """Distance from the robot's last position to the commanded path's end, m."""
        return float(np.linalg.norm(self.pose[-1, 1:3] - self.commanded[-1, 1:3]))


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
    """Drive one robot by ``commands`` with ``setup``'s library: each command requests its nearest skill
    (:func:`~gaitlib.meta.commands.nearest_skills`, which refuses a command beyond the library's range before any
    work), switched by ``strategy`` (guarded by ``guard`` when given); then measure the run."""
    names, gaps = nearest_skills(commands, skills_of([e.description for e in setup.entries]))
    timeline = list(zip(commands.time_s[:-1].tolist(), names, strict=True))
    trace = drive_episode(setup, timeline=timeline, end_s=commands.end_s, strategy=strategy,
                          action_delay=action_delay, backend=backend, seed=seed, falls=falls, guard=guard)
    qpos = np.vstack([trace.start_qpos[None], trace.qpos.reshape(-1, len(trace.start_qpos))])
    heading = np.unwrap(yaw_of(qpos[:, 3:7].astype(np.float64)))
    pose = np.column_stack([np.arange(len(qpos)) * trace.dt, qpos[:, 0], qpos[:, 1], heading])
    planned = commands.path(trace.dt)
    cos, sin = np.cos(heading[0]), np.sin(heading[0])
    commanded = np.column_stack([
        np.arange(len(planned)) * trace.dt,
        pose[0, 1] + cos * planned[:, 0] - sin * planned[:, 1],
        pose[0, 2] + sin * planned[:, 0] + cos * planned[:, 1],
        heading[0] + planned[:, 2],
    ])
    return DriveResult(commands=commands, skills=names, skill_distance=gaps, trace=trace, pose=pose,
                       commanded=commanded, achieved=_achieved(pose, commands))


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
