"""One robot, one requested switch: what ``gaitlib run`` does, recorded step by step for the plot and the video."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from gaitlib.defaults import DEFAULT_STRATEGY
from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs.randomization import DISTURBANCE_INTERVAL_S, DISTURBANCE_LEAD_S, PushConfig
from gaitlib.errors import GaitlibError
from gaitlib.meta.controller import DEADLINE_S, MetaStep, SwitchEvent
from gaitlib.meta.setup import SwitchingSetup
from gaitlib.sim import make_backend

__all__ = ["RunTrace", "run_episode"]


@dataclass
class RunTrace:
    """A recorded run: per control step arrays (T = steps run) and the switch."""

    gaits: tuple[str, ...]
    source: str
    dest: str
    strategy: str
    threshold: float | None
    """The strategy's threshold for this pair (``None`` for ``random``)."""
    dt: float
    """Control period, s."""
    request_s: float
    """When the switch was requested, s."""
    push_n: float
    """Push magnitude, N (0: none): pushes hit from ``DISTURBANCE_LEAD_S`` before the request until the deadline."""
    time_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """(T,) time at the end of each step, s."""
    active: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    """(T,) active gait index during each step."""
    score: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """(T,) the strategy's best candidate score while the request waited (NaN otherwise)."""
    best_phase: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """(T,) the best candidate destination phase while the request waited, cycles (NaN otherwise)."""
    root_height: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """(T,) trunk height, m."""
    push: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """(T,) magnitude of the push on the trunk during each step, N."""
    foot_contact: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), dtype=bool))
    """(T, 4) foot contacts (FR, FL, RR, RL)."""
    qpos: np.ndarray = field(default_factory=lambda: np.zeros((0, 19)))
    """(T, 19) generalized positions (trunk position, quaternion w-x-y-z, 12 joints) for rendering."""
    switch: SwitchEvent | None = None
    """The switch, if one happened."""
    fell_s: float | None = None
    """When the robot fell (the run stops there), s; ``None`` if it stayed up."""

    @property
    def stayed_up(self) -> bool:
        return self.fell_s is None

    @property
    def switch_s(self) -> float | None:
        """When the switch happened, s."""
        return None if self.switch is None else self.switch.step * self.dt


def run_episode(
    setup: SwitchingSetup,
    *,
    source: str,
    dest: str,
    strategy: str = DEFAULT_STRATEGY,
    request_s: float = 2.0,
    push_n: float = 0.0,
    seconds: float = 6.0,
    deadline_s: float = DEADLINE_S,
    action_delay: int | None = None,
    backend: str = "auto",
    seed: int = 0,
) -> RunTrace:
    """Run one robot on ``source``, request ``dest`` at ``request_s``, let ``strategy`` switch; pushes of ``push_n``
    (random direction, 0.1-0.3 s, a quiet 0.2-1.0 s before each) hit it from ``DISTURBANCE_LEAD_S`` before the
    request until ``deadline_s`` after it (the benchmark's window). ``action_delay``: every action waits exactly
    this many control steps (``None``: the policies' trained random delay). Stops at ``seconds`` or at a fall."""
    m, n = setup.gait_index(source), setup.gait_index(dest)
    if m == n:
        raise GaitlibError(f"--from and --to are both '{source}'")
    sim = make_backend(backend, num_worlds=1)
    try:
        pushes = PushConfig(max_force=push_n, fixed_force=True, interval=DISTURBANCE_INTERVAL_S)
        env = setup.make_env(
            sim, EnvConfig(episode_seconds=seconds + 1.0, pushes=pushes), seed=seed, action_delay=action_delay
        )
        ctl = setup.controller(env, strategy, deadline_s=deadline_s, seed=seed)
        world = torch.zeros(1, dtype=torch.long, device=env.device)
        env.reset_worlds(world, gait=torch.tensor([m], device=env.device))
        env.enable_pushes(world, False)
        trace = RunTrace(
            gaits=setup.gaits,
            source=source,
            dest=dest,
            strategy=strategy,
            threshold=None if strategy == "random" else _pair_threshold(ctl.strategy.threshold, (m, n)),
            dt=env.dt,
            request_s=request_s,
            push_n=push_n,
        )
        rows: dict[str, list] = {name: [] for name in _ROWS}
        request_step = round(request_s / env.dt)
        push_start = max(0, request_step - round(DISTURBANCE_LEAD_S / env.dt))
        push_end = request_step + round(deadline_s / env.dt)
        for step in range(round(seconds / env.dt)):
            if step == push_start:
                env.enable_pushes(world, push_n > 0)
            if step == push_end:
                env.enable_pushes(world, False)
            if step == request_step:
                ctl.request(world, n)
            active = int(env.gait[0])
            result = ctl.step()
            if result.events:
                trace.switch = result.events[0]
            if bool(result.fell[0]):
                trace.fell_s = (step + 1) * env.dt
                break
            _record(rows, env, result, time_s=(step + 1) * env.dt, active=n if result.events else active)
        _fill(trace, rows)
        return trace
    finally:
        sim.close()


def _pair_threshold(threshold: float | dict | None, pair: tuple[int, int]) -> float | None:
    """A strategy's threshold for ``pair`` (source, dest): its own one, or its single one."""
    return threshold.get(pair) if isinstance(threshold, dict) else threshold


_ROWS = ("time_s", "active", "score", "best_phase", "root_height", "push", "foot_contact", "qpos")
"""The per-step fields of :class:`RunTrace`."""


def _record(rows: dict[str, list], env: ImitationEnv, result: MetaStep, *, time_s: float, active: int) -> None:
    """Append one control step of the single world to ``rows``."""
    s = env.sim_state
    rows["time_s"].append(time_s)
    rows["active"].append(active)
    rows["score"].append(float(result.best_score[0]))
    rows["best_phase"].append(float(result.best_phase[0]))
    rows["root_height"].append(float(s.root_pos[0, 2]))
    rows["push"].append(float(env.push_force[0].norm()))
    rows["foot_contact"].append(s.foot_contact[0].cpu().numpy().astype(bool))
    rows["qpos"].append(torch.cat([s.root_pos[0], s.root_quat[0], s.joint_pos[0]]).cpu().numpy())


def _fill(trace: RunTrace, rows: dict[str, list]) -> None:
    """Give ``trace`` the recorded steps as arrays."""
    for name, values in rows.items():
        setattr(trace, name, np.asarray(values))
    trace.active = trace.active.astype(np.int64)
    trace.foot_contact = trace.foot_contact.astype(bool).reshape(-1, 4)
    trace.qpos = trace.qpos.reshape(len(rows["qpos"]), -1)
