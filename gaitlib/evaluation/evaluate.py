"""Evaluate a gait policy: N worlds, one episode each, under paper Table 1 randomization (pushes optional)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import torch

from gaitlib.defaults import DEFAULT_FALLS, Falls
from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs.randomization import PushConfig
from gaitlib.evaluation.rollout import FallRecord, rollout
from gaitlib.gaits import ReferenceClip
from gaitlib.library.policy import GaitPolicy
from gaitlib.rotations import quat_from_yaw, quat_rotate_inverse, yaw_of
from gaitlib.sim import make_backend

__all__ = ["EvalResult", "SteeringFigures", "evaluate_policy", "steers"]

_ZERO = 1e-6
"""A reference figure at most this (m/s, rad/s) is zero: its error is absolute, not relative."""


@dataclass(frozen=True, kw_only=True)
class SteeringFigures:
    """How a policy follows a reference that sidesteps or turns: its lateral speed and yaw rate against the
    reference's, and its heading against the reference's heading (which turns with a yaw rate). Each error is
    relative to the reference's figure, or absolute (m/s, rad/s) where that is zero, as ``speed_error``."""

    lateral_speed: float
    """Mean lateral speed in the robot's heading frame over alive steps, m/s, positive to the left."""
    reference_lateral_speed: float
    """The reference's, m/s."""
    lateral_speed_error: float
    """|lateral_speed - reference_lateral_speed| / |reference_lateral_speed| (m/s where that is 0)."""
    yaw_rate: float
    """Mean yaw rate over alive steps (the heading's change per control step over its duration), rad/s,
    positive counter-clockwise."""
    reference_yaw_rate: float
    """The reference's, rad/s."""
    yaw_rate_error: float
    """|yaw_rate - reference_yaw_rate| / |reference_yaw_rate| (rad/s where that is 0)."""
    median_heading_error_deg: float
    """Median over episodes of the absolute angle between the robot's heading and the reference's at the end (or at
    the fall), degrees: for a turning gait, the heading change against the turn the reference makes."""

    def as_dict(self) -> dict:
        return {
            "lateral_speed": self.lateral_speed, "reference_lateral_speed": self.reference_lateral_speed,
            "lateral_speed_error": self.lateral_speed_error, "yaw_rate": self.yaw_rate,
            "reference_yaw_rate": self.reference_yaw_rate, "yaw_rate_error": self.yaw_rate_error,
            "median_heading_error_deg": self.median_heading_error_deg,
        }


def steers(clip: ReferenceClip) -> bool:
    """Whether ``clip`` is a steering skill, whose quality bar reads the steering figures: it turns, sidesteps or goes
    backward (a cycle yaw, or a sideways or backward displacement per cycle over 1 micrometre)."""
    shift = clip.cycle_displacement
    return clip.cycle_yaw != 0.0 or abs(float(shift[1])) > _ZERO or float(shift[0]) < -_ZERO


@dataclass(frozen=True, kw_only=True)
class EvalResult(FallRecord):
    """How well a policy imitates its gait: its falls and touches (:class:`FallRecord`; a fall ends an episode
    before ``seconds``: the trunk sank too low, tilted more than 90 degrees or touched the ground, and with
    ``contact`` any non-foot body touched it; turning away is not a fall, see ``heading_loss_rate``), and how it
    follows its reference."""

    seconds: float
    """Episode length asked for, s."""
    heading_loss_rate: float
    """Fraction of episodes in which the robot, still up, turned more than 90 degrees away from its starting
    heading at some moment, 0-1."""
    median_heading_change_deg: float
    """Median over episodes of the absolute heading change from start to end (or to the fall), degrees."""
    joint_rmse: float
    """Root-mean-square joint angle error against the reference over all alive steps, rad."""
    contact_agreement: float
    """Share of feet over all alive steps whose ground contact is the reference's (down when it plans the foot in
    stance, up when in swing), 0-1: a policy that lands out of step with its gait scores low even where its joints
    follow (the first pronk: 0.45)."""
    forward_speed: float
    """Mean forward speed in the robot's heading frame over alive steps, m/s."""
    reference_speed: float
    """The reference's forward speed, m/s."""
    speed_error: float
    """|forward_speed - reference_speed| / reference_speed (absolute error in m/s for a standing gait)."""
    mean_episode_seconds: float
    """Mean time alive per episode, s."""
    push_max: float
    """Largest random push, N (0: no pushes)."""
    action_delay_steps: int | None
    """Control steps every action waited (``None``: the randomized delay of training)."""
    late_steps: int
    """Control steps every action waited beyond that (the trained range shifted; 0: as trained)."""
    steering: SteeringFigures | None = None
    """For a gait that sidesteps or turns (:func:`steers`), its lateral speed, yaw rate and heading against the
    reference's; ``None`` (and not in :meth:`as_dict`) for one that goes straight."""
    falls_by_cause: dict[str, int]
    """Falls that met each termination (``body_contact``: a non-foot body on the ground, with ``contact`` only;
    ``trunk_contact``: the trunk itself on the ground; ``too_low``: the trunk below 0.12 m; ``orientation_lost``:
    tilted past 90 degrees; ``diverged``: the physics), a fall counted under every one it met: a fall by
    ``body_contact`` alone ended with the trunk still above 0.12 m and tilted less than 90 degrees."""

    def as_dict(self) -> dict:
        """The evaluation as ``gaitlib eval --json`` prints it and an entry's metadata records it."""
        return {
            "episodes": self.episodes, "seconds": self.seconds, "fall_rate": self.fall_rate,
            "fall_ci95": self.fall_ci95, "touch_rate": self.touch_rate, "touch_ci95": self.touch_ci95,
            "longest_touch_s": self.longest_touch_s, "heading_loss_rate": self.heading_loss_rate,
            "median_heading_change_deg": self.median_heading_change_deg, "joint_rmse": self.joint_rmse,
            "contact_agreement": self.contact_agreement, "forward_speed": self.forward_speed,
            "reference_speed": self.reference_speed, "speed_error": self.speed_error,
            "mean_episode_seconds": self.mean_episode_seconds, "push_max": self.push_max,
            "action_delay_steps": self.action_delay_steps, "late_steps": self.late_steps, "falls": self.falls.value,
            "falls_by_cause": dict(self.falls_by_cause),
        } | ({} if self.steering is None else {"steering": self.steering.as_dict()})


def evaluate_policy(
    policy: GaitPolicy,
    clip: ReferenceClip,
    *,
    env_cfg: EnvConfig,
    episodes: int,
    seconds: float,
    backend: str = "auto",
    push_max: float = 0.0,
    action_delay_steps: int | None = None,
    late_steps: int = 0,
    falls: Falls = DEFAULT_FALLS,
    seed: int = 0,
) -> EvalResult:
    """Run ``episodes`` worlds for ``seconds`` s each with the deterministic policy and Table 1 randomization.

    ``env_cfg`` holds the policy's action and observation settings; its episode length, pushes and terminations
    are set here. ``action_delay_steps`` fixes the control steps every action waits (``None``: the randomized
    delay of training); ``late_steps`` delays every action that many control steps more (a step late: 1).
    ``falls``: the definition of a fall counted; leg touches are counted beside it either way.
    """
    randomization = env_cfg.randomization
    if action_delay_steps is not None:
        randomization = replace(randomization, action_delay_steps=(action_delay_steps, action_delay_steps))
    low, high = randomization.action_delay_steps
    randomization = replace(randomization, action_delay_steps=(low + late_steps, high + late_steps))
    cfg = replace(
        env_cfg,
        episode_seconds=seconds,
        pushes=PushConfig(max_force=push_max),
        termination=env_cfg.termination.counting(falls, heading=False),
        randomization=randomization,
    )
    sim = make_backend(backend, num_worlds=episodes)
    try:
        env = ImitationEnv(sim, [clip], cfg, seed=seed)
        counted, t = _run_episodes(env, policy)
        total_alive = t["summed_steps"].sum().clamp(min=1)  # the steps whose speeds and errors were summed
        mean_speed = float(t["speed"].sum() / total_alive)
        mean_ref = float(t["ref_speed"].sum() / total_alive)
        return EvalResult(
            **counted.counted(),
            seconds=seconds,
            heading_loss_rate=float(t["turned"].float().mean()),
            median_heading_change_deg=float(torch.rad2deg(t["heading_change"]).median()),
            joint_rmse=float(torch.sqrt(t["sq_error"].sum() / total_alive)),
            contact_agreement=float(t["contact_agree"].sum() / total_alive),
            forward_speed=mean_speed,
            reference_speed=mean_ref,
            speed_error=_error(mean_speed, mean_ref),
            mean_episode_seconds=float((t["alive_steps"].clamp(min=1) * env.dt).mean()),
            push_max=push_max,
            action_delay_steps=action_delay_steps,
            late_steps=late_steps,
            falls_by_cause={name: int(count.sum()) for name, count in t["causes"].items()},
            steering=_steering(t, total_alive, dt=env.dt) if steers(clip) else None,
        )
    finally:
        sim.close()


def _error(measured: float, reference: float) -> float:
    """|measured - reference| relative to |reference|, or absolute where the reference is zero."""
    error = abs(measured - reference)
    return error / abs(reference) if abs(reference) > _ZERO else error


def _steering(t: dict[str, torch.Tensor], total_alive: torch.Tensor, *, dt: float) -> SteeringFigures:
    lateral, ref_lateral = float(t["lateral"].sum() / total_alive), float(t["ref_lateral"].sum() / total_alive)
    turn, ref_turn = float(t["turn"].sum() / total_alive / dt), float(t["ref_turn"].sum() / total_alive / dt)
    return SteeringFigures(
        lateral_speed=lateral, reference_lateral_speed=ref_lateral, lateral_speed_error=_error(lateral, ref_lateral),
        yaw_rate=turn, reference_yaw_rate=ref_turn, yaw_rate_error=_error(turn, ref_turn),
        median_heading_error_deg=float(torch.rad2deg(t["heading_error"]).median()),
    )


def _run_episodes(env: ImitationEnv, policy: GaitPolicy) -> tuple[FallRecord, dict[str, torch.Tensor]]:
    """One episode per world of ``env`` with the deterministic policy (:func:`~gaitlib.evaluation.rollout.rollout`):
    its falls and touches, and per world (N,): the terminations its fall met (``causes``, by name), turned (more
    than 90 degrees from its start while up), alive steps (the episode's length), the steps summed over (those after
    which the world was still up), summed squared joint error, share of feet in the reference's contact state,
    forward and reference speed, and the last absolute heading change while up, rad; and for steering figures the
    lateral and reference lateral speed, the heading's and the reference's change per step (rad), and the last
    absolute angle between the two headings while up, rad."""
    n, dev = env.num_envs, env.device
    t = {"turned": torch.zeros(n, dtype=torch.bool, device=dev), "causes": {}}
    names = ("alive_steps", "summed_steps", "sq_error", "contact_agree", "speed", "ref_speed", "heading_change",
             "lateral", "ref_lateral", "turn", "ref_turn", "heading_error")
    t |= {k: torch.zeros(n, device=dev) for k in names}
    start_yaw = yaw_of(env.sim_state.root_quat)
    last = {"yaw": start_yaw, "ref_yaw": yaw_of(env.reference.frame().root_quat)}

    def follow(extras: dict, fell: torch.Tensor, ended: torch.Tensor, alive: torch.Tensor) -> None:
        s, ref = env.sim_state, env.reference.frame()
        for name, met in extras["fall_causes"].items():
            t["causes"][name] = (t["causes"][name] | (fell & met)) if name in t["causes"] else fell & met
        live = alive.float()
        yaw = yaw_of(s.root_quat)
        change = _wrap(yaw - start_yaw)
        t["heading_change"] = torch.where(alive, change.abs(), t["heading_change"])
        t["turned"] |= alive & (change.abs() > torch.pi / 2)
        t["sq_error"] += live * (s.joint_pos - ref.joint_pos).square().mean(-1)
        t["contact_agree"] += live * (s.foot_contact.bool() == ref.contact).float().mean(-1)
        t["speed"] += live * quat_rotate_inverse(quat_from_yaw(yaw), s.root_lin_vel)[:, 0]
        t["ref_speed"] += live * ref.heading_lin_vel[:, 0]
        t["lateral"] += live * quat_rotate_inverse(quat_from_yaw(yaw), s.root_lin_vel)[:, 1]
        t["ref_lateral"] += live * ref.heading_lin_vel[:, 1]
        ref_yaw = yaw_of(ref.root_quat)
        t["turn"] += live * _wrap(yaw - last["yaw"])
        t["ref_turn"] += live * _wrap(ref_yaw - last["ref_yaw"])
        t["heading_error"] = torch.where(alive, _wrap(yaw - ref_yaw).abs(), t["heading_error"])
        last["yaw"], last["ref_yaw"] = yaw, ref_yaw
        t["summed_steps"] += live
        t["alive_steps"] += live + ended.float()  # the step that ends an episode counts for its length

    counted, _ = rollout(env, policy, steps=env.max_episode_length, after=follow)
    return counted, t


def _wrap(angle: torch.Tensor) -> torch.Tensor:
    """``angle`` wrapped into [-pi, pi), rad."""
    return torch.remainder(angle + torch.pi, 2 * torch.pi) - torch.pi
