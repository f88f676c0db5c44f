"""One robot, one requested switch: what ``gaitlib run`` does, recorded step by step for the plot and the video."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from gaitlib.defaults import DEFAULT_STRATEGY
from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs.randomization import DISTURBANCE_LEAD_S
from gaitlib.errors import GaitlibError
from gaitlib.meta.controller import DEADLINE_S, MetaStep, SwitchEvent
from gaitlib.meta.setup import SwitchingSetup
from gaitlib.meta.trials import SwitchTrials, TrialOutcome, TrialProtocol, TrialSchedule
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
    foot_contact: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), dtype=bool))
    """(T, feet) foot contacts, in the robot's foot order (the A1's FR, FL, RR, RL)."""
    qpos: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    """(T, 7 + joints) generalized positions (trunk position, quaternion w-x-y-z, joints) for rendering."""
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
    """One switch trial of :mod:`gaitlib.meta.trials` on one robot: run ``source``, request ``dest`` at
    ``request_s``, let ``strategy`` switch; pushes of ``push_n`` (random direction, 0.1-0.3 s, a quiet 0.2-1.0 s
    before each) hit it from ``DISTURBANCE_LEAD_S`` before the request until ``deadline_s`` after it (the
    benchmark's window). ``action_delay``: every action waits exactly this many control steps (``None``: the
    policies' trained random delay). Stops ``seconds - request_s`` after the switch's control step, or at a fall."""
    m, n = setup.gait_index(source), setup.gait_index(dest)
    if m == n:
        raise GaitlibError(f"--from and --to are both '{source}'")
    if not 0 <= request_s < seconds:
        raise GaitlibError(f"the request ({request_s:g} s) must come within the run ({seconds:g} s)")
    protocol = TrialProtocol(
        warmup_s=request_s, source_extra_s=0.0, horizon_s=seconds - request_s, deadline_s=deadline_s,
        push_lead_s=min(DISTURBANCE_LEAD_S, request_s),
    )
    sim = make_backend(backend, num_worlds=1)
    try:
        pushes = protocol.pushes(push_n, fixed=True)
        env = setup.make_env(
            sim, EnvConfig(episode_seconds=seconds + deadline_s + 1.0, pushes=pushes), seed=seed,
            action_delay=action_delay,
        )
        ctl = setup.controller(env, strategy, deadline_s=deadline_s, seed=seed)
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
        trial = _OneTrial((m, n))
        trials = SwitchTrials(ctl, protocol, trial, seed=seed)
        while trials.running:
            result = trials.step()
            if result.events:
                trace.switch = result.events[0]
            if bool(result.fell[0]):
                trace.fell_s = ctl.steps * env.dt
                break
            _record(rows, env, result, time_s=ctl.steps * env.dt, active=int(env.gait[0]))  # switched before acting
        _fill(trace, rows, legs=sim.robot.num_feet, qpos_size=7 + sim.robot.num_joints)
        return trace
    finally:
        sim.close()


class _OneTrial(TrialSchedule):
    """One trial of one pair; a source fall ends it (the robot is down)."""

    def __init__(self, pair: tuple[int, int]) -> None:
        self.pairs = [pair]
        self._begun = False

    def begin(self, k: int) -> torch.Tensor:
        pairs = torch.full((k,), -1, dtype=torch.long)
        pairs[0] = -1 if self._begun else 0
        self._begun = True
        return pairs

    def source_fell(self, pairs: torch.Tensor) -> bool:
        return False

    def finished(self, outcome: TrialOutcome) -> None:
        pass  # the trace is the outcome


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


def _fill(trace: RunTrace, rows: dict[str, list], *, legs: int, qpos_size: int) -> None:
    """Give ``trace`` the recorded steps as arrays."""
    for name, values in rows.items():
        setattr(trace, name, np.asarray(values))
    trace.active = trace.active.astype(np.int64)
    trace.foot_contact = trace.foot_contact.astype(bool).reshape(-1, legs)
    trace.qpos = trace.qpos.reshape(-1, qpos_size)
