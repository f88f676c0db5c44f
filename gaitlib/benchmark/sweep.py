"""The disturbance sweep (paper Fig. 4, top): every strategy performs every ordered pair under pushes of fixed
magnitude, 0 to 500 N, and the success rate of each (strategy, pair, magnitude) cell is counted.

One transition, per world, all worlds at once (a group = one strategy at one magnitude, its pairs interleaved):

1. reset with the source gait m of the least-served pair (reference state initialization, Table 1 randomization);
2. the meta-controller runs m for ``warmup_s`` plus a uniform extra time in [0, ``source_extra_s``]; for the last
   ``push_lead_s`` of it, pushes of the group's magnitude (random horizontal direction, ``push_duration_s``, a
   quiet time in ``push_interval_s`` before each) hit the trunk (a fall before the request is a source fall: the
   world starts again at 1 with the same pair, nothing is counted);
3. the switch to n is requested; the strategy switches when it says so, or the request is forced after
   ``deadline_s``; the pushes go on until ``deadline_s`` after the request, whatever the strategy does (the last
   one runs out), so every strategy meets the same disturbance window and differs only in when and to which
   phase it switches;
4. success if the robot does not fall from the request until ``horizon_s`` after the switch (which always covers
   the whole disturbance window).

With a :class:`~gaitlib.benchmark.gap.DeploymentGap` the same sweep runs on another A1 model, with a fixed action
delay or scaled motor torque (paper Fig. 4, bottom: the real robot; ``--magnitudes 0``).

Each group is a unit of work (its own seed, a fresh simulator), run here or on a Ray worker (:class:`GroupWorker`);
results are written to ``OUT/results.json`` (atomically, by this process alone, in group order) after each group;
a rerun with the same settings skips the finished groups, so an interrupted sweep loses at most the groups under
way.
"""

from __future__ import annotations

import itertools
import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch

from gaitlib.atomic import release_lock, stale_temporaries, take_lock, write_json
from gaitlib.benchmark.gap import DeploymentGap
from gaitlib.benchmark.results import group_key, open_results
from gaitlib.cluster import ClusterConfig, WorkerSpec, run_ordered
from gaitlib.defaults import COMPARED
from gaitlib.envs import EnvConfig
from gaitlib.envs.randomization import DISTURBANCE_INTERVAL_S, DISTURBANCE_LEAD_S, PushConfig
from gaitlib.errors import GaitlibError
from gaitlib.meta import DEADLINE_S, SwitchingSetup
from gaitlib.robots import RobotSpec
from gaitlib.sim import make_backend
from gaitlib.transitions import SUCCESS_HORIZON_S

__all__ = [
    "MAGNITUDE_RESOLUTION_N",
    "CellCounts",
    "GroupTask",
    "GroupWorker",
    "SweepConfig",
    "default_magnitudes",
    "run_sweep",
]

_EPISODE_SECONDS = 1e6  # no time-outs: worlds are reset after each transition
MAGNITUDE_RESOLUTION_N = 0.001
"""Push magnitudes that round to the same multiple of this, N, are one cell (one key, one seed)."""


def default_magnitudes() -> tuple[float, ...]:
    """0, 50, ..., 500 N (the paper's sweep)."""
    return tuple(float(m) for m in range(0, 501, 50))


@dataclass(frozen=True, kw_only=True)
class SweepConfig:
    """What the sweep runs (checked when built: one-line errors). Everything but ``backend`` and ``device`` must match
    to resume: the worlds' count decides which world draws which random numbers, so it changes the results."""

    strategies: tuple[str, ...] = COMPARED
    """Strategy names (:func:`gaitlib.strategies.strategy_names`)."""
    magnitudes: tuple[float, ...] = default_magnitudes()
    """Push magnitudes, N."""
    samples: int = 100
    """Transitions per (strategy, pair, magnitude) cell."""
    pairs: tuple[tuple[str, str], ...] | None = None
    """Ordered (source, destination) pairs; ``None``: every ordered pair of the library's gaits."""
    num_worlds: int = 256
    """Parallel worlds."""
    warmup_s: float = 1.0
    """Shortest source run after a reset before the request, s."""
    source_extra_s: float = 1.0
    """Further source run, uniform in [0, this], s (spreads the source phase at the request)."""
    horizon_s: float = SUCCESS_HORIZON_S
    """Time after the switch without a fall that makes a success, s (the collection's label horizon)."""
    deadline_s: float = DEADLINE_S
    """A request not acted on within this time is forced, s."""
    push_duration_s: tuple[float, float] = (0.1, 0.3)
    """Duration of each push, s (paper: 0.1-0.3 s)."""
    push_interval_s: tuple[float, float] = DISTURBANCE_INTERVAL_S
    """Quiet time before each push, s."""
    push_lead_s: float = DISTURBANCE_LEAD_S
    """Pushes begin this long before the request (shorter than ``warmup_s``) and end ``deadline_s`` after it, s."""
    gap: DeploymentGap = field(default_factory=DeploymentGap)
    """Another A1 model, a fixed action delay, a motor strength (default: none; it needs the ``mujoco``
    backend)."""
    backend: str = "auto"
    """Simulation backend (``auto`` is ``mujoco`` under a gap that needs it)."""
    device: str | None = None
    """Torch device of the backend (``None``: its default)."""
    seed: int = 0
    """Base seed; each magnitude derives its own from it (the same for every strategy)."""

    def __post_init__(self) -> None:
        if self.samples < 1 or self.num_worlds < 1:
            raise GaitlibError("samples and worlds must be positive")
        if not self.strategies or not self.magnitudes:
            raise GaitlibError("give at least one strategy and one magnitude")
        if not all(math.isfinite(m) and m >= 0 for m in self.magnitudes):
            raise GaitlibError("push magnitudes must be finite and not negative")
        if len(set(self.strategies)) != len(self.strategies):
            raise GaitlibError(f"a strategy is given twice in {', '.join(self.strategies)}; give each once")
        keys = [group_key("", m) for m in self.magnitudes]
        for i, key in enumerate(keys):
            if key in keys[:i]:
                raise GaitlibError(
                    f"push magnitudes {self.magnitudes[keys.index(key)]!r} N and {self.magnitudes[i]!r} N are one "
                    f"cell (magnitudes are resolved to {MAGNITUDE_RESOLUTION_N:g} N); give each once"
                )
        if not 0 <= self.push_lead_s < self.warmup_s:
            raise GaitlibError("the push lead must lie in [0, warm-up time)")
        if self.horizon_s < self.deadline_s:
            raise GaitlibError(
                "the horizon must be at least the deadline, so that outcomes cover the disturbance window"
            )
        self.backend_name()  # newton under a gap that needs mujoco: one line now

    def backend_name(self) -> str:
        """The backend the groups run on (``auto`` resolved)."""
        return self.gap.backend_name(self.backend)

    def settings(self) -> dict:
        """The settings a resumed sweep must repeat (the gap's entries only where it differs from none)."""
        fixed = asdict(self)
        for name in ("backend", "device", "gap"):
            fixed.pop(name)
        return json.loads(json.dumps(fixed | self.gap.settings()))


@dataclass
class CellCounts:
    """Outcomes of one (strategy, pair, magnitude) cell."""

    samples: int = 0
    successes: int = 0
    forced: int = 0
    """Switches made by the deadline rather than the strategy."""
    wait_s: float = 0.0
    """Total time from request to switch over the transitions that switched, s."""
    switched: int = 0
    """Transitions that reached the switch (the others fell while waiting)."""
    source_falls: int = 0
    """Source runs that fell before the request (redone, not counted in ``samples``)."""


def run_sweep(
    out: Path,
    setup: SwitchingSetup,
    config: SweepConfig,
    *,
    progress: Callable[[str, int, int], None] | None = None,
    cluster: ClusterConfig | None = None,
) -> dict:
    """Run (or resume) the sweep into ``out``; returns the results dict (as written to ``results.json``).

    Groups run one after the other in this process, or with ``cluster`` on Ray workers (:mod:`gaitlib.cluster`);
    either way this process alone writes ``results.json``, in group order, and the results are the same.
    ``progress(group, done, total)`` is called as transitions finish (``done`` over the whole sweep; with Ray, as
    groups finish).
    """
    cfg = config
    out = Path(out)
    pairs = _pairs(cfg, setup)
    settings = cfg.settings() | {"pairs": [list(p) for p in pairs]}
    identities = setup.resources.library.identities(setup.gaits)
    open_results(out, settings, identities)  # refuse other settings before anything is created
    lock = out / "results.json.lock"
    fd = take_lock(lock, writing=str(out / "results.json"), error=GaitlibError)  # one writer per --out
    try:
        for leftover in stale_temporaries(out / "results.json"):  # of a killed run (the lock says none runs)
            leftover.unlink(missing_ok=True)
        return _sweep(out, setup, cfg, pairs, open_results(out, settings, identities), identities, progress, cluster)
    finally:
        release_lock(lock, fd)


def _sweep(out: Path, setup: SwitchingSetup, cfg: SweepConfig, pairs: list, results: dict, identities: dict,
           progress, cluster: ClusterConfig | None) -> dict:
    """The groups of ``results`` not yet done, run and written one after the other (under the writer lock)."""
    groups = list(itertools.product(cfg.strategies, cfg.magnitudes))
    per_group = cfg.samples * len(pairs)
    total = per_group * len(groups)
    todo = [GroupTask(s, m) for s, m in groups if group_key(s, m) not in results["groups"]]
    done = total - per_group * len(todo)
    worker = {"library": str(setup.resources.library.root), "identities": identities, "pairs": pairs, "config": cfg}
    if cluster is None:  # in this process: progress within each group too
        worker |= {"setup": setup, "progress": lambda key, n: progress and progress(key, done + n, total)}
    else:
        cluster = cluster.for_backend(cfg.backend_name(), cfg.device)
    ordered = run_ordered(todo, spec=WorkerSpec(GroupWorker, worker), cluster=cluster)
    try:
        for task, (cells, elapsed) in ordered:
            key = group_key(task.strategy, task.magnitude)
            done += per_group
            results["groups"][key] = {
                "strategy": task.strategy,
                "magnitude_n": task.magnitude,
                "backend": cfg.backend_name(),
                "elapsed_s": round(elapsed, 2),
                "cells": {f"{m}-{n}": asdict(c) for (m, n), c in cells.items()},
            }
            write_json(out / "results.json", results, indent=1, checksum=True)
            if progress is not None and cluster is not None:
                progress(key, done, total)
    finally:
        ordered.close()
    return results


@dataclass(frozen=True)
class GroupTask:
    """One group of the sweep: a strategy at a push magnitude (all pairs)."""

    strategy: str
    magnitude: float
    """Push magnitude, N."""


class GroupWorker:
    """Loads the library's switching setup (and the gap's robot) once; called with a :class:`GroupTask`, it runs that
    group on a fresh simulator and returns its cells and its wall-clock time, s. Its results are a pure function of
    the task, the settings and the library (the group's seed derives from the sweep's seed and the magnitude). Built
    with keyword arguments only, so that Ray can build it in an actor."""

    def __init__(self, *, library: str, identities: dict, pairs: list, config: SweepConfig, setup=None,
                 progress: Callable[[str, int], None] | None = None) -> None:
        from gaitlib.meta import load_switching

        self._setup = setup if setup is not None else load_switching(library)
        if self._setup.resources.library.identities(self._setup.gaits) != identities:
            raise GaitlibError(f"the library at {library} holds other policies than the sweep's (identities)")
        self._pairs, self._cfg, self._progress = [tuple(p) for p in pairs], config, progress
        self._robot = config.gap.robot_spec()

    def __call__(self, task: GroupTask) -> tuple[dict[tuple[str, str], CellCounts], float]:
        start, key = time.perf_counter(), group_key(task.strategy, task.magnitude)

        def report(finished: int) -> None:
            if self._progress is not None:
                self._progress(key, finished)

        cells = _run_group(self._setup, self._robot, task, self._pairs, self._cfg, report)
        return cells, time.perf_counter() - start


def _pairs(cfg: SweepConfig, setup: SwitchingSetup) -> list[tuple[str, str]]:
    if cfg.pairs is None:
        return list(itertools.permutations(setup.gaits, 2))
    for m, n in cfg.pairs:
        setup.gait_index(m), setup.gait_index(n)
        if m == n:
            raise GaitlibError(f"pair {m}-{n}: source and destination must differ")
    return list(dict.fromkeys(cfg.pairs))


def _run_group(
    setup: SwitchingSetup,
    robot: RobotSpec,
    task: GroupTask,
    pairs: Sequence[tuple[str, str]],
    cfg: SweepConfig,
    report: Callable[[int], None],
) -> dict[tuple[str, str], CellCounts]:
    """All transitions of one strategy at one push magnitude, on ``robot``."""
    # Every strategy meets the same random draws at a magnitude (common random numbers: differences between
    # strategies are not blurred by different worlds), and each magnitude its own.
    magnitude = task.magnitude
    seed = int(np.random.SeedSequence([cfg.seed, round(magnitude * 1000)]).generate_state(1)[0])
    sim = make_backend(cfg.backend_name(), num_worlds=cfg.num_worlds, robot=robot, device=cfg.device)
    try:
        pushes = PushConfig(
            max_force=magnitude, fixed_force=True, duration=cfg.push_duration_s, interval=cfg.push_interval_s
        )
        env = cfg.gap.make_env(setup, sim, EnvConfig(episode_seconds=_EPISODE_SECONDS, pushes=pushes), seed=seed)
        controller = setup.controller(env, task.strategy, deadline_s=cfg.deadline_s, seed=seed)
        return _Group(env, controller, pairs, setup, cfg, seed, report).run()
    finally:
        sim.close()


class _Group:
    """Per-world transition state machines (stage: 0 source run, 1 waiting for the switch, 2 after it)."""

    SOURCE, WAITING, AFTER, IDLE = 0, 1, 2, 3

    def __init__(self, env, controller, pairs, setup, cfg: SweepConfig, seed: int, report) -> None:
        self.env, self.ctl, self.cfg, self.report = env, controller, cfg, report
        dev, n = env.device, env.num_envs
        self.pairs = list(pairs)
        self.source = torch.tensor([setup.gait_index(m) for m, _ in pairs], device=dev)
        self.dest = torch.tensor([setup.gait_index(d) for _, d in pairs], device=dev)
        self.cells = {pair: CellCounts() for pair in pairs}
        self.started = [0] * len(pairs)  # transitions begun (finished or under way) per pair
        self.finished = 0
        self.gen = torch.Generator().manual_seed(seed)
        self.pair = torch.zeros(n, dtype=torch.long, device=dev)
        self.stage = torch.full((n,), self.IDLE, dtype=torch.long, device=dev)
        self.steps_left = torch.zeros(n, dtype=torch.long, device=dev)
        self.warmup = round(cfg.warmup_s / env.dt)
        self.extra = round(cfg.source_extra_s / env.dt)
        self.horizon = max(1, round(cfg.horizon_s / env.dt))
        self.lead = round(cfg.push_lead_s / env.dt)
        self.push_steps = self.lead + round(cfg.deadline_s / env.dt)
        self.push_left = torch.zeros(n, dtype=torch.long, device=dev)  # control steps of pushes left per world
        self._begin(torch.arange(n, device=dev))

    def run(self) -> dict[tuple[str, str], CellCounts]:
        while bool((self.stage != self.IDLE).any()):
            self.step()
        return self.cells

    def step(self) -> None:
        result = self.ctl.step()
        self.steps_left -= 1
        self.push_left -= 1
        for event in result.events:
            w = event.world
            if int(self.stage[w]) != self.WAITING:
                continue
            cell = self.cells[self.pairs[int(self.pair[w])]]
            cell.switched += 1
            cell.forced += int(event.forced)
            cell.wait_s += event.wait_s
            self.stage[w] = self.AFTER
            self.steps_left[w] = self.horizon
        fell = result.fell
        source_fell = fell & (self.stage == self.SOURCE)
        for w in source_fell.nonzero().squeeze(1).tolist():
            self.cells[self.pairs[int(self.pair[w])]].source_falls += 1
        failed = fell & ((self.stage == self.WAITING) | (self.stage == self.AFTER))
        succeeded = ~fell & (self.stage == self.AFTER) & (self.steps_left <= 0)
        due = ~fell & (self.stage == self.SOURCE) & (self.steps_left <= 0)
        pushed = ~fell & (self.stage == self.SOURCE) & (self.steps_left == self.lead)
        calmed = ~fell & (self.stage != self.SOURCE) & (self.push_left == 0)
        for mask, ok in ((failed, False), (succeeded, True)):
            for w in mask.nonzero().squeeze(1).tolist():
                cell = self.cells[self.pairs[int(self.pair[w])]]
                cell.samples += 1
                cell.successes += int(ok)
                self.finished += 1
            if mask.any():
                self.report(self.finished)
        if source_fell.any():
            self._start_source(source_fell.nonzero().squeeze(1))
        ended = failed | succeeded
        if ended.any():
            ids = ended.nonzero().squeeze(1)
            self.ctl.cancel(ids)
            self._begin(ids)
        if pushed.any():
            self.env.enable_pushes(pushed.nonzero().squeeze(1), True)
            self.push_left[pushed] = self.push_steps
        if calmed.any():
            self.env.enable_pushes(calmed.nonzero().squeeze(1), False)
        if due.any():
            ids = due.nonzero().squeeze(1)
            self.ctl.request(ids, self.dest[self.pair[ids]])
            self.stage[ids] = self.WAITING

    def _begin(self, ids: torch.Tensor) -> None:
        """Start worlds ``ids`` on the least-started pair that still needs transitions, or leave them idle."""
        starting = []
        for w in ids.tolist():
            open_pairs = [i for i, s in enumerate(self.started) if s < self.cfg.samples]
            if not open_pairs:
                self.stage[w] = self.IDLE
                self.env.enable_pushes(torch.tensor([w], device=self.env.device), False)
                continue
            chosen = min(open_pairs, key=lambda i: self.started[i])
            self.started[chosen] += 1
            self.pair[w] = chosen
            starting.append(w)
        if starting:
            self._start_source(torch.tensor(starting, dtype=torch.long, device=self.env.device))

    def _start_source(self, ids: torch.Tensor) -> None:
        self.env.enable_pushes(ids, False)
        self.env.reset_worlds(ids, gait=self.source[self.pair[ids]])
        self.stage[ids] = self.SOURCE
        self.push_left[ids] = -1  # armed again ``lead`` steps before the request
        extra = torch.randint(self.extra + 1, (len(ids),), generator=self.gen).to(self.env.device)
        self.steps_left[ids] = self.warmup + extra
