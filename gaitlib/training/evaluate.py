"""Evaluate a gait policy: N worlds, one episode each, under paper Table 1 randomization (pushes optional)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import torch

from gaitlib.defaults import DEFAULT_FALLS, Falls
from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs.randomization import PushConfig
from gaitlib.envs.terminations import FallTally
from gaitlib.gaits import ReferenceClip
from gaitlib.library.policy import GaitPolicy
from gaitlib.rotations import quat_from_yaw, quat_rotate_inverse, yaw_of
from gaitlib.sim import make_backend
from gaitlib.stats import wilson_interval

__all__ = ["EvalResult", "evaluate_policy"]


@dataclass(frozen=True)
class EvalResult:
    """How well a policy imitates its gait."""

    episodes: int
    """Episodes run (one per world)."""
    seconds: float
    """Episode length asked for, s."""
    fall_rate: float
    """Fraction of episodes that ended in a fall before ``seconds``, 0-1, by the definition ``falls``: the trunk
    sank too low, tilted more than 90 degrees or touched the ground (and with ``contact``, any non-foot body touched
    it); turning away is not a fall (see ``heading_loss_rate``)."""
    fall_ci95: tuple[float, float]
    """Wilson 95% interval of ``fall_rate``."""
    touch_rate: float
    """Fraction of episodes in which a non-foot body (a leg's thigh or calf, or the trunk) touched the ground while
    the robot was up, 0-1: the touches ridden through are counted here whether or not they were falls."""
    touch_ci95: tuple[float, float]
    """Wilson 95% interval of ``touch_rate``."""
    longest_touch_s: float
    """The longest unbroken touch of a non-foot body over all episodes, s (0: none)."""
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
    falls: Falls
    """The definition of a fall counted: ``trunk`` (the
    field's) or ``contact`` (a non-foot body on the ground is a fall too)."""
    falls_by_cause: dict[str, int]
    """Falls that met each termination (``body_contact``: a non-foot body on the ground, with ``contact`` only;
    ``trunk_contact``: the trunk itself on the ground; ``too_low``: the trunk below 0.12 m; ``orientation_lost``:
    tilted past 90 degrees; ``diverged``: the physics), a fall counted under every one it met: a fall by
    ``body_contact`` alone ended with the trunk still above 0.12 m and tilted less than 90 degrees."""

    def as_dict(self) -> dict:
        return asdict(self)


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
    ``falls``: the definition of a fall counted (``trunk`` or ``contact``,
    :mod:`gaitlib.envs.terminations`); leg touches are counted beside it either way.
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
        t = _run_episodes(env, policy)
        counted = t["alive_steps"].clamp(min=1)
        total_alive = t["summed_steps"].sum().clamp(min=1)  # the steps whose speeds and errors were summed
        mean_speed = float(t["speed"].sum() / total_alive)
        mean_ref = float(t["ref_speed"].sum() / total_alive)
        error = abs(mean_speed - mean_ref)
        n, fell, touched = env.num_envs, int(t["fell"].sum()), int(t["touched"].sum())
        return EvalResult(
            episodes=n,
            seconds=seconds,
            fall_rate=fell / n,
            fall_ci95=wilson_interval(fell, n),
            touch_rate=touched / n,
            touch_ci95=wilson_interval(touched, n),
            longest_touch_s=float(t["longest_touch"].max()) * env.dt,
            heading_loss_rate=float(t["turned"].float().mean()),
            median_heading_change_deg=float(torch.rad2deg(t["heading_change"]).median()),
            joint_rmse=float(torch.sqrt(t["sq_error"].sum() / total_alive)),
            contact_agreement=float(t["contact_agree"].sum() / total_alive),
            forward_speed=mean_speed,
            reference_speed=mean_ref,
            speed_error=error / abs(mean_ref) if abs(mean_ref) > 1e-6 else error,
            mean_episode_seconds=float((counted * env.dt).mean()),
            push_max=push_max,
            action_delay_steps=action_delay_steps,
            late_steps=late_steps,
            falls=falls,
            falls_by_cause={name: int(count.sum()) for name, count in t["causes"].items()},
        )
    finally:
        sim.close()


def _run_episodes(env: ImitationEnv, policy: GaitPolicy) -> dict[str, torch.Tensor]:
    """One episode per world of ``env`` with the deterministic policy; per world (N,): fell, the terminations its
    fall met (``causes``, by name), touched (a non-foot body on the ground while up, or at the fall), the longest
    unbroken touch (control steps), turned (more than 90 degrees from its start while up), alive steps (the episode's
    length), the steps summed over (those after which the world was still up), summed squared joint error, share of
    feet in the reference's contact state, forward and reference speed, and the last absolute heading change while
    up, rad."""
    n, dev = env.num_envs, env.device
    alive = torch.ones(n, dtype=torch.bool, device=dev)
    t = {"turned": torch.zeros(n, dtype=torch.bool, device=dev)}
    tally = FallTally(n, dev)
    names = ("alive_steps", "summed_steps", "sq_error", "contact_agree", "speed", "ref_speed", "heading_change")
    t |= {k: torch.zeros(n, device=dev) for k in names}
    t["causes"] = {}
    start_yaw = yaw_of(env.sim_state.root_quat)
    obs = env.get_observations()
    for _ in range(env.max_episode_length):
        obs, _, dones, extras = env.step(policy.act(obs))
        s, ref = env.sim_state, env.reference.frame()
        # The rows of worlds that just finished hold their reset state: count only those still alive.
        ended = dones & alive
        fell = tally.step(dones, extras, alive)
        for name, met in extras["fall_causes"].items():
            t["causes"][name] = (t["causes"][name] | (fell & met)) if name in t["causes"] else fell & met
        alive &= ~dones
        live = alive.float()
        yaw = yaw_of(s.root_quat)
        change = torch.remainder(yaw - start_yaw + torch.pi, 2 * torch.pi) - torch.pi
        t["heading_change"] = torch.where(alive, change.abs(), t["heading_change"])
        t["turned"] |= alive & (change.abs() > torch.pi / 2)
        t["sq_error"] += live * (s.joint_pos - ref.joint_pos).square().mean(-1)
        t["contact_agree"] += live * (s.foot_contact.bool() == ref.contact).float().mean(-1)
        t["speed"] += live * quat_rotate_inverse(quat_from_yaw(yaw), s.root_lin_vel)[:, 0]
        t["ref_speed"] += live * ref.heading_lin_vel[:, 0]
        t["summed_steps"] += live
        t["alive_steps"] += live + ended.float()  # the step that ends an episode counts for its length
    return t | {"fell": tally.fell, "touched": tally.touched, "longest_touch": tally.longest}
