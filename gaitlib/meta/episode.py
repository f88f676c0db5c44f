"""One robot, requested switches recorded step by step for the plots and the video: a sequence of gaits, each
requested a hold after the switch before (``gaitlib run``), or gaits asked for step by step by a pilot
(``gaitlib drive``: a command timeline, or a closed loop to waypoints)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import pairwise
from typing import Protocol

import numpy as np
import torch

from gaitlib.defaults import DEFAULT_FALLS, DEFAULT_STRATEGY, MAX_RUN_SECONDS, Falls
from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs.randomization import DISTURBANCE_LEAD_S
from gaitlib.envs.terminations import TerminationConfig
from gaitlib.errors import GaitlibError
from gaitlib.meta.controller import DEADLINE_S, MetaController, MetaStep, SwitchEvent
from gaitlib.meta.guard import CatchEvent, Guard
from gaitlib.meta.setup import SwitchingSetup
from gaitlib.meta.trials import SwitchTrials, TrialOutcome, TrialProtocol, TrialSchedule
from gaitlib.rotations import yaw_of
from gaitlib.sim import make_backend

__all__ = ["Pilot", "RunTrace", "check_run_length", "drive_episode", "run_episode"]


@dataclass
class RunTrace:
    """A recorded run: per control step arrays (T = steps run), the requests and the switches."""

    gaits: tuple[str, ...]
    source: str
    dests: tuple[str, ...]
    """The gaits requested, in order."""
    strategy: str
    thresholds: tuple[float | None, ...]
    """The strategy's threshold for each requested switch's pair (``None`` for ``random``)."""
    dt: float
    """Control period, s."""
    push_n: float
    """Push magnitude, N (0: none): pushes hit from ``DISTURBANCE_LEAD_S`` before each request until the deadline."""
    falls: Falls = DEFAULT_FALLS
    """What a fall was."""
    time_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """(T,) time at the end of each step, s."""
    active: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    """(T,) active gait index during each step."""
    score: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """(T,) the strategy's best candidate score while a request waited (NaN otherwise)."""
    best_phase: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """(T,) the best candidate destination phase while a request waited, cycles (NaN otherwise)."""
    root_height: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """(T,) trunk height, m."""
    push: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """(T,) magnitude of the push on the trunk during each step, N."""
    foot_contact: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), dtype=bool))
    """(T, feet) foot contacts, in the robot's foot order (the A1's FR, FL, RR, RL)."""
    touch: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    """(T,) a non-foot body (a leg's, or the trunk) on the ground at the end of the step: a touch the robot rode
    through (with the ``trunk`` definition of a fall)."""
    qpos: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    """(T, 7 + joints) generalized positions (trunk position, quaternion w-x-y-z, joints) for rendering."""
    requests_s: list[float] = field(default_factory=list)
    """When each switch was requested, s (one per request made; a fall ends the run before the rest)."""
    switches: list[SwitchEvent] = field(default_factory=list)
    """The switches made, in order."""
    fell_s: float | None = None
    """When the robot fell (the run stops there), s; ``None`` if it stayed up."""
    start_qpos: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """(7 + joints,) generalized positions at the start, before the first step (as :attr:`qpos`)."""
    guarded: bool = False
    """Whether the guard was on (:mod:`gaitlib.meta.guard`)."""
    guard_margin: float | None = None
    """The guard's margin (``None``: unguarded)."""
    stay: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """(T,) the guard's survival estimate of keeping the running gait at each step (NaN unguarded)."""
    catches: list[CatchEvent] = field(default_factory=list)
    """The guard's catches, in order."""

    @property
    def stayed_up(self) -> bool:
        return self.fell_s is None

    @property
    def touches(self) -> int:
        """Unbroken touches of a non-foot body on the ground the robot rode through."""
        return int(np.count_nonzero(np.diff(self.touch.astype(np.int8), prepend=0) == 1))

    @property
    def longest_touch_s(self) -> float:
        """The longest of them, s (0: none)."""
        longest = run = 0
        for touching in self.touch.tolist():
            run = run + 1 if touching else 0
            longest = max(longest, run)
        return longest * self.dt

    def guard_report(self, *, why_off: str | None = None) -> dict:
        """Whether the guard was on (``why_off``: why not), its margin, and each catch: when, from which gait to
        which, what the estimate and the net read, and how long until the requested gait ran again."""
        g = self.gaits
        catches = [
            {"time_s": c.step * self.dt, "from": g[c.source], "to": g[c.dest], "phase": c.phase, "stay": c.stay,
             "offer": c.offer, "requested": g[c.requested],
             "back_after_s": None if c.back_step is None else (c.back_step - c.step) * self.dt}
            for c in self.catches
        ]
        return {"on": self.guarded, "margin": self.guard_margin, "why_off": why_off, "catches": catches}

    @property
    def switches_s(self) -> list[float]:
        """When each switch happened, s."""
        return [event.step * self.dt for event in self.switches]


def check_run_length(*, request_s: float, requests: int, hold_s: float, deadline_s: float = DEADLINE_S) -> None:
    """Refuse a run (:func:`run_episode`) of ``requests`` gaits requested in turn that can last longer than
    :data:`~gaitlib.defaults.MAX_RUN_SECONDS`: its first request at ``request_s``, then for each gait the switch's
    deadline and the hold after it."""
    longest = request_s + requests * (deadline_s + hold_s)
    if longest > MAX_RUN_SECONDS:
        raise GaitlibError(
            f"a run of {requests} request(s) can last {longest:.6g} s (the first request at {request_s:g} s, then for "
            f"each gait the switch's deadline of {deadline_s:g} s and the hold of {hold_s:g} s), longer than the "
            f"longest run, {MAX_RUN_SECONDS:g} s"
        )


def run_episode(
    setup: SwitchingSetup,
    *,
    source: str,
    dests: Sequence[str],
    strategy: str = DEFAULT_STRATEGY,
    request_s: float = 2.0,
    hold_s: float = 4.0,
    push_n: float = 0.0,
    deadline_s: float = DEADLINE_S,
    action_delay: int | None = None,
    backend: str = "auto",
    seed: int = 0,
    falls: Falls = DEFAULT_FALLS,
    guard: Guard | None = None,
) -> RunTrace:
    """Switch trials of :mod:`gaitlib.meta.trials`, chained on one robot: run ``source``, request ``dests[0]`` at
    ``request_s``, let ``strategy`` switch; ``hold_s`` after the end of that switch's control step request the next
    gait of ``dests``, and so on; the run ends ``hold_s`` after the last switch, or at a fall. Pushes of ``push_n``
    (random direction, 0.1-0.3 s, a quiet 0.2-1.0 s before each) hit the robot from ``DISTURBANCE_LEAD_S`` before
    each request until ``deadline_s`` after it (the benchmark's window). ``action_delay``: every action waits
    exactly this many control steps (``None``: the policies' trained random delay). ``falls``: what ends the run as
    a fall (:class:`gaitlib.defaults.Falls`); touches are recorded either way. ``guard``: the guard
    catches the robot where another gait offers clearly more than staying (``None``: unguarded)."""
    dests = (dests,) if isinstance(dests, str) else tuple(dests)
    gaits = [setup.gait_index(g) for g in (source, *dests)]  # unknown names: one line each
    if not dests:
        raise GaitlibError("no gait requested")
    for a, b in pairwise((source, *dests)):
        if a == b:
            raise GaitlibError(f"'{a}' is requested while the robot already runs it")
    lead_s = min(DISTURBANCE_LEAD_S, request_s) if request_s >= 0 else 0.0
    if not request_s >= 0 or not hold_s > lead_s:  # NaN fails too
        raise GaitlibError(
            f"the request time ({request_s:g} s) must not be negative and the hold ({hold_s:g} s) longer than the "
            f"pushes' lead before a request ({lead_s:g} s)"
        )
    pairs = list(pairwise(gaits))
    check_run_length(request_s=request_s, requests=len(pairs), hold_s=hold_s, deadline_s=deadline_s)
    # Each trial's verdict horizon ends where the next request's push lead begins; the last one's lead is run below.
    protocol = TrialProtocol(
        warmup_s=request_s, source_extra_s=0.0, horizon_s=hold_s - lead_s, deadline_s=deadline_s,
        push_lead_s=lead_s, chain=True,
    )
    sim = make_backend(backend, num_worlds=1)
    try:
        pushes = protocol.pushes(push_n, fixed=True)
        seconds = request_s + len(pairs) * (deadline_s + hold_s) + 1.0
        cfg = EnvConfig(episode_seconds=seconds, pushes=pushes, termination=TerminationConfig().counting(falls))
        env = setup.make_env(sim, cfg, seed=seed, action_delay=action_delay)
        ctl = setup.controller(env, strategy, deadline_s=deadline_s, seed=seed, guard=guard)
        threshold = None if strategy == "random" else ctl.strategy.threshold
        trace = RunTrace(
            gaits=setup.gaits,
            source=source,
            dests=dests,
            strategy=strategy,
            thresholds=tuple(_pair_threshold(threshold, pair) for pair in pairs),
            dt=env.dt,
            push_n=push_n,
            falls=falls,
            guarded=guard is not None,
            guard_margin=None if guard is None else guard.margin,
        )
        rows: dict[str, list] = {name: [] for name in _ROWS}
        trials = SwitchTrials(ctl, protocol, _Sequence(pairs), seed=seed)
        trace.start_qpos = _qpos(env)
        tail = round(lead_s / env.dt)
        while trials.running or tail > 0:
            if trials.running:
                result = trials.step()
            else:
                result, tail = ctl.step(), tail - 1
            if not _take(trace, rows, ctl, result):
                break
            if int(ctl.queued[0]) >= 0 and len(trace.requests_s) == len(trace.switches):
                trace.requests_s.append(ctl.steps * env.dt)  # requested at the end of this step
        _fill(trace, rows, legs=sim.robot.num_feet, qpos_size=7 + sim.robot.num_joints)
        return trace
    finally:
        sim.close()


class Pilot(Protocol):
    """What steers a drive (:func:`drive_episode`): a command timeline, or a closed loop to waypoints."""

    def start(self) -> str:
        """The gait to start in."""

    def steer(self, step: int, dt: float, pose: np.ndarray, running: str) -> str | None:
        """The gait to run at control step ``step`` (``dt`` s each), given the trunk's pose before it (x m, y m,
        heading rad, in the world) and the gait that runs; ``None`` ends the drive. Called once more after the last
        step, with the end pose (its answer unused)."""


def drive_episode(
    setup: SwitchingSetup,
    *,
    pilot: Pilot,
    end_s: float,
    strategy: str = DEFAULT_STRATEGY,
    deadline_s: float = DEADLINE_S,
    action_delay: int | None = None,
    backend: str = "auto",
    seed: int = 0,
    falls: Falls = DEFAULT_FALLS,
    guard: Guard | None = None,
) -> RunTrace:
    """One robot driven by ``pilot``: it starts in the pilot's first gait (reference state initialization at a
    random phase, fresh Table 1 randomization); at every control step the pilot is asked for its gait from the
    trunk's pose, and a gait that differs from the one it asked for before is requested from the meta-controller,
    which ``strategy`` switches as in :func:`run_episode` (the active gait asked for again cancels a request still
    waiting, and a caught robot's return). The run ends when the pilot says so, at ``end_s``, or at a fall. No
    pushes. ``action_delay``, ``seed``, ``falls`` and ``guard``: as :func:`run_episode`'s."""
    sim = make_backend(backend, num_worlds=1)
    try:
        cfg = EnvConfig(episode_seconds=end_s + 1.0, termination=TerminationConfig().counting(falls))
        env = setup.make_env(sim, cfg, seed=seed, action_delay=action_delay)
        steps = round(end_s / env.dt)
        if steps < 1:
            raise GaitlibError(f"a drive of {end_s:g} s is shorter than half a control step ({env.dt:.4g} s): there "
                               "is nothing to drive")
        ctl = setup.controller(env, strategy, deadline_s=deadline_s, seed=seed, guard=guard)
        wanted = setup.gait_index(pilot.start())
        env.reset_worlds(torch.zeros(1, dtype=torch.long, device=env.device),
                         gait=torch.full((1,), wanted, dtype=torch.long, device=env.device))
        trace = RunTrace(gaits=setup.gaits, source=setup.gaits[wanted], dests=(), strategy=strategy,
                         thresholds=(), dt=env.dt, push_n=0.0, falls=falls, guarded=guard is not None,
                         guard_margin=None if guard is None else guard.margin)
        trace.start_qpos = _qpos(env)
        rows: dict[str, list] = {name: [] for name in _ROWS}
        world = torch.zeros(1, dtype=torch.long, device=env.device)
        for step in range(steps + 1):
            name = pilot.steer(step, env.dt, _pose(env), setup.gaits[int(env.gait[0])])
            if name is None or step == steps:
                break
            gait = setup.gait_index(name)
            if gait != wanted:
                wanted = gait
                ctl.request(world, wanted)  # what a caught robot returns to from now
                if wanted == int(env.gait[0]):
                    ctl.cancel(world)  # already met
                else:
                    trace.requests_s.append(step * env.dt)
                    trace.dests += (setup.gaits[wanted],)
            if not _take(trace, rows, ctl, ctl.step()):
                break
        _fill(trace, rows, legs=sim.robot.num_feet, qpos_size=7 + sim.robot.num_joints)
        return trace
    finally:
        sim.close()


def _take(trace: RunTrace, rows: dict[str, list], ctl: MetaController, result: MetaStep) -> bool:
    """Take the single world's controller step ``result`` into ``trace`` and ``rows``; False at a fall (the run
    stops there)."""
    env = ctl.env
    trace.switches += result.events
    trace.catches += result.catches
    if bool(result.fell[0]):
        trace.fell_s = ctl.steps * env.dt
        return False
    _record(rows, env, result, time_s=ctl.steps * env.dt, active=int(env.gait[0]),  # switched before acting
            stay=float(ctl.stay[0]))
    return True


class _Sequence(TrialSchedule):
    """The trials of one robot, one pair after the other, chained; a fall ends them (the robot is down)."""

    def __init__(self, pairs: list[tuple[int, int]]) -> None:
        self.pairs = pairs
        self._next = 0

    def begin(self, k: int) -> torch.Tensor:
        pairs = torch.full((k,), -1, dtype=torch.long)
        if self._next == 0:
            pairs[0], self._next = 0, 1
        return pairs

    def chain(self, worlds: torch.Tensor, gaits: torch.Tensor) -> torch.Tensor:
        pairs = torch.full((len(gaits),), -1, dtype=torch.long)
        if self._next < len(self.pairs):
            pairs[0], self._next = self._next, self._next + 1
        return pairs

    def source_fell(self, worlds: torch.Tensor, pairs: torch.Tensor) -> torch.Tensor:
        return torch.zeros(len(pairs), dtype=torch.bool)  # the robot is down: no new trial begins

    def finished(self, outcome: TrialOutcome) -> None:
        pass  # the trace is the outcome

    @property
    def done(self) -> bool:
        return False  # the engine stops when no trial runs: after the last hold, or at a fall


def _pair_threshold(threshold: float | dict | None, pair: tuple[int, int]) -> float | None:
    """A strategy's threshold for ``pair`` (source, dest): its own one, or its single one."""
    return threshold.get(pair) if isinstance(threshold, dict) else threshold


_ROWS = ("time_s", "active", "score", "best_phase", "root_height", "push", "foot_contact", "touch", "qpos", "stay")
"""The per-step fields of :class:`RunTrace`."""


def _record(rows: dict[str, list], env: ImitationEnv, result: MetaStep, *, time_s: float, active: int,
            stay: float) -> None:
    """Append one control step of the single world to ``rows``."""
    s = env.sim_state
    rows["stay"].append(stay)
    rows["time_s"].append(time_s)
    rows["active"].append(active)
    rows["score"].append(float(result.best_score[0]))
    rows["best_phase"].append(float(result.best_phase[0]))
    rows["root_height"].append(float(s.root_pos[0, 2]))
    rows["push"].append(float(env.push_force[0].norm()))
    rows["foot_contact"].append(s.foot_contact[0].cpu().numpy().astype(bool))
    rows["touch"].append(bool(result.touch[0]))
    rows["qpos"].append(_qpos(env))


def _pose(env: ImitationEnv) -> np.ndarray:
    """The single world's trunk pose now: x (m), y (m) and heading (rad), what a robot's state estimator gives."""
    s = env.sim_state
    return np.array([float(s.root_pos[0, 0]), float(s.root_pos[0, 1]), float(yaw_of(s.root_quat[0]))])


def _qpos(env: ImitationEnv) -> np.ndarray:
    """The single world's generalized positions now: trunk position, quaternion w-x-y-z, joints."""
    s = env.sim_state
    return torch.cat([s.root_pos[0], s.root_quat[0], s.joint_pos[0]]).cpu().numpy()


def _fill(trace: RunTrace, rows: dict[str, list], *, legs: int, qpos_size: int) -> None:
    """Give ``trace`` the recorded steps as arrays."""
    for name, values in rows.items():
        setattr(trace, name, np.asarray(values))
    trace.active = trace.active.astype(np.int64)
    trace.touch = trace.touch.astype(bool)
    trace.foot_contact = trace.foot_contact.astype(bool).reshape(-1, legs)
    trace.qpos = trace.qpos.reshape(-1, qpos_size)
