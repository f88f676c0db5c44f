"""The catch task's reward: stay up and come to a calm stance, without a reference motion (the ``catch`` task of a
gait description, :data:`gaitlib.gaits.description.TASKS`).

A catch policy is handed a robot a few control steps into a shove (or running unshoved) by whichever gait ran, as
the meta-controller's guard hands it over, and is rewarded for what a recovery controller wants, not for following a
clip: the trunk upright, its horizontal velocity and its angular rates brought to zero, the feet back under the hips
(the nominal stance of its clip, stand's), smooth actions and small torques, and no fall.

The terms are small pure functions of one control step (:class:`CatchStep`), declared once with their weights in
:data:`CATCH_REWARD`; each weight's source is beside it. The weights are rates per second and the reward of a step
is ``dt * sum(weight * value)``, legged_gym's convention (``_prepare_reward_function`` multiplies every scale by
``dt``; github.com/leggedrobotics/legged_gym), which ABS's recovery configuration (He et al., RSS 2024,
arXiv:2401.17583, ``go1_rec_config.py``: alive +5, velocity tracking +10, orientation -20, termination -100) is
written in: a fall then costs ``dt * 100`` besides the alive reward it forgoes.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import torch

from gaitlib.envs.reference import ReferenceFrame
from gaitlib.envs.rewards import end_effector_error
from gaitlib.rotations import quat_rotate_inverse
from gaitlib.sim import SimState

__all__ = [
    "CALM_RATE_RAD_S",
    "CALM_SPEED_M_S",
    "CALM_TILT_DEG",
    "CALM_WAIT_S",
    "CATCH_EPISODE_S",
    "CATCH_REWARD",
    "CatchStep",
    "CatchTerm",
    "action_rate",
    "alive",
    "calm_rates",
    "catch_reward",
    "fell",
    "is_calm",
    "pd_torque",
    "stance",
    "still",
    "tilt",
    "torque",
]

CATCH_EPISODE_S = 2.5
"""A catch episode's length, s: ABS trains its recovery policy on 2 s episodes; half a second more lets a robot
caught late in a 30 N s shove finish its steps and stand still before the time-out."""
CALM_TILT_DEG = 10.0
"""A calm trunk leans less than this from upright, deg: a third of the 30 deg of roll and pitch ABS's recovery
episodes start from (``go1_rec_config.py``)."""
CALM_SPEED_M_S = 0.5
"""A calm trunk moves horizontally slower than this, m/s: sqrt of the :func:`still` kernel's sigma (0.25 (m/s)^2)
in :data:`CATCH_REWARD`, where the reward has fallen to 1/e of standing still."""
CALM_RATE_RAD_S = 1.0
"""A calm trunk rolls, pitches and turns slower than this, rad/s: sqrt of the :func:`calm_rates` kernel's sigma
(1 (rad/s)^2) in :data:`CATCH_REWARD`, its 1/e point."""
CALM_WAIT_S = CATCH_EPISODE_S
"""Longest a robot caught into a catch skill waits to be calm before it is handed back, s: the catch skill's training
episode (what it learnt to do after a catch is done by then)."""


@dataclass(frozen=True, kw_only=True)
class CatchStep:
    """What one control step of N worlds gives the catch terms."""

    state: SimState
    """The robot after the step."""
    ref: ReferenceFrame
    """The stance the task comes to (its clip's frame now: level trunk, feet under the hips)."""
    action: torch.Tensor
    """(N, J) the action of this step (after clipping), action units."""
    last_action: torch.Tensor
    """(N, J) the action of the step before (the source policy's, just after a hand-over), action units."""
    torque: torch.Tensor
    """(N, J) the joint torques the PD servos command at the end of the step, N m."""
    terminated: torch.Tensor
    """(N,) bool: the step ended the episode in a fall (not a time-out)."""


@dataclass(frozen=True)
class CatchTerm:
    """One catch reward term: ``weight * value`` per second."""

    name: str
    """Logged as ``/reward/<name>``."""
    value: Callable[[CatchStep], torch.Tensor]
    """(N,) the term's value of each world: a kernel in [0, 1] or a non-negative cost."""
    weight: float
    """Reward per second per unit of the value (negative: a cost)."""


def alive(step: CatchStep) -> torch.Tensor:
    """1 for every world (the episode's end is the fall; what staying up is worth)."""
    return torch.ones_like(step.terminated, dtype=torch.float32)


def tilt(step: CatchStep) -> torch.Tensor:
    """|g_xy|^2, the horizontal part of gravity's direction in the trunk frame: 0 upright, sin^2 of the tilt
    (1 at 90 deg); legged_gym's ``_reward_orientation``."""
    return _leaning(step.state).square().sum(-1)


def _leaning(state: SimState) -> torch.Tensor:
    """(N, 2) the horizontal part of gravity's direction in the trunk frame: its norm is the sine of the tilt."""
    down = torch.zeros_like(state.root_lin_vel)
    down[:, 2] = -1.0
    return quat_rotate_inverse(state.root_quat, down)[:, :2]


def still(step: CatchStep, *, sigma: float) -> torch.Tensor:
    """exp(-|v_xy|^2 / sigma) of the trunk's horizontal velocity (m/s, sigma in (m/s)^2): 1 at rest; legged_gym's
    ``_reward_tracking_lin_vel`` with a zero command."""
    return torch.exp(-step.state.root_lin_vel[:, :2].square().sum(-1) / sigma)


def calm_rates(step: CatchStep, *, sigma: float) -> torch.Tensor:
    """exp(-|w|^2 / sigma) of the trunk's angular velocity (rad/s, trunk frame, sigma in (rad/s)^2): 1 when it
    neither rolls, pitches nor turns."""
    return torch.exp(-step.state.root_ang_vel.square().sum(-1) / sigma)


def stance(step: CatchStep, *, scale: float) -> torch.Tensor:
    """exp(-scale * e) of the feet's distance from the stance's, e = sum_feet |p - p_stance|^2 (m^2, ``scale`` in
    1/m^2), the feet relative to the trunk in the robot's heading frame: 1 with every foot under its hip at the
    stance's height (the trunk's height comes with it)."""
    return torch.exp(-scale * end_effector_error(step.state, step.ref, height_weight=1.0))


def action_rate(step: CatchStep) -> torch.Tensor:
    """sum_j (a_t - a_{t-1})^2, action units squared; legged_gym's ``_reward_action_rate``."""
    return (step.action - step.last_action).square().sum(-1)


def torque(step: CatchStep) -> torch.Tensor:
    """sum_j tau^2, (N m)^2; legged_gym's ``_reward_torques``."""
    return step.torque.square().sum(-1)


def fell(step: CatchStep) -> torch.Tensor:
    """1 on the step that ends the episode in a fall, else 0 (a time-out is no fall)."""
    return step.terminated.float()


CATCH_REWARD: tuple[CatchTerm, ...] = (
    CatchTerm("alive", alive, 5.0),  # ABS recovery: alive +5
    CatchTerm("tilt", tilt, -20.0),  # ABS recovery: orientation -20 (legged_gym's orientation term)
    # ABS recovery: velocity tracking +10, legged_gym's exp kernel, tracking_sigma 0.25 (m/s)^2; the command is rest
    CatchTerm("still", partial(still, sigma=0.25), 10.0),
    # choice: half the velocity term, legged_gym's ratio of its angular to its linear tracking (0.5 to 1.0); sigma
    # 1 (rad/s)^2, as a shoved trunk turns at a few rad/s and a calm one at a few tenths
    CatchTerm("calm_rates", partial(calm_rates, sigma=1.0), 5.0),
    # choice: below the velocity and rate terms, so that a step that catches a shove costs less than sliding on; the
    # scale is the imitation reward's end-effector term's (Peng et al. 2020: 40 per m^2), 5 cm off at each foot: 0.67
    CatchTerm("stance", partial(stance, scale=40.0), 3.0),
    CatchTerm("action_rate", action_rate, -0.01),  # legged_gym's A1: action_rate -0.01 (the same action scale 0.25)
    CatchTerm("torque", torque, -0.0002),  # legged_gym's A1: torques -0.0002
    CatchTerm("termination", fell, -100.0),  # ABS recovery: termination -100
)
"""The catch reward's terms and weights (per second; the module doc)."""


def pd_torque(targets: torch.Tensor, joint_pos: torch.Tensor, joint_vel: torch.Tensor, kp: torch.Tensor,
              kd: torch.Tensor, *, limit: float) -> torch.Tensor:
    """(N, J) the PD law's torque, N m: ``clip(kp (q* - q) - kd qd, -limit, limit)`` with the targets q* (N, J) rad,
    joint angles q (N, J) rad and velocities qd (N, J) rad/s, and each world's gains ``kp`` (N,) N m/rad and ``kd``
    (N,) N m s/rad (what the servos command at that instant; :class:`gaitlib.robots.RobotSpec`)."""
    raw = kp.unsqueeze(1) * (targets - joint_pos) - kd.unsqueeze(1) * joint_vel
    return raw.clamp(-limit, limit)


def catch_reward(
    terms: tuple[CatchTerm, ...], step: CatchStep, *, dt: float
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """The reward of one control step of ``dt`` s (N,), ``dt * sum(weight * value)``, and each term's value (N,), by
    name."""
    values = {t.name: t.value(step) for t in terms}
    return dt * sum(t.weight * values[t.name] for t in terms), values


def is_calm(state: SimState) -> torch.Tensor:
    """(N,) bool: the trunk is calm, the moment a catch hands the robot back (:class:`~gaitlib.meta.MetaController`):
    tilted less than :data:`CALM_TILT_DEG`, moving horizontally slower than :data:`CALM_SPEED_M_S` and turning slower
    than :data:`CALM_RATE_RAD_S`. A robot reads the tilt and the rates from its IMU and the speed from its state
    estimator."""
    return ((_leaning(state).norm(dim=-1) < math.sin(math.radians(CALM_TILT_DEG))) &
            (state.root_lin_vel[:, :2].norm(dim=-1) < CALM_SPEED_M_S) &
            (state.root_ang_vel.norm(dim=-1) < CALM_RATE_RAD_S))
