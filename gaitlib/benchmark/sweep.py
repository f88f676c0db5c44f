"""The disturbance sweep (paper Fig. 4, top): every strategy performs every ordered pair under pushes of fixed
magnitude, 0 to 500 N, and the success rate of each (strategy, pair, magnitude) cell is counted.

One group = one strategy at one magnitude, its pairs interleaved, all worlds at once: each transition is a switch
trial of :mod:`gaitlib.meta.trials` with the ``request`` push window (pushes of the group's magnitude from
``push_lead_s`` before the request until ``deadline_s`` after it, whatever the strategy does, so every strategy
meets the same disturbance and differs only in when and to which phase it switches); each new trial takes the
least-served pair; a source that falls before the request starts again with the same pair, uncounted.

With a :class:`~gaitlib.benchmark.gap.DeploymentGap` the same sweep runs on another A1 model, with a fixed action
delay or scaled motor torque (paper Fig. 4, bottom: the real robot; ``--magnitudes 0``).

Each group is a unit of work (its own seed, a fresh simulator), run here or on a Ray worker (:class:`GroupWorker`);
results are written to ``OUT/results.json`` (atomically, by this process alone, in group order) after each group;
a rerun with the same settings skips the finished groups, so an interrupted sweep loses at most the groups under
way.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch

from gaitlib.atomic import file_sha256, release_lock, stale_temporaries, take_lock, write_json
from gaitlib.benchmark.gap import DeploymentGap
from gaitlib.benchmark.results import group_key, open_results
from gaitlib.cluster import ClusterConfig, WorkerSpec, run_ordered
from gaitlib.defaults import COMPARED, DEFAULT_FALLS, Falls
from gaitlib.envs import EnvConfig
from gaitlib.envs.terminations import TerminationConfig
from gaitlib.errors import GaitlibError
from gaitlib.library.store import Library
from gaitlib.meta import SwitchEvent, SwitchingSetup, SwitchTrials, TrialOutcome, TrialProtocol, TrialSchedule
from gaitlib.meta.guard import catch_summary
from gaitlib.robots import RobotSpec
from gaitlib.sim import make_backend

__all__ = [
    "MAGNITUDE_RESOLUTION_N",
    "CellCounts",
    "CellSchedule",
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
    protocol: TrialProtocol = field(default_factory=TrialProtocol)
    """The switch trial: times, deadline, horizon and push window (the ``request`` window, no chaining)."""
    gap: DeploymentGap = field(default_factory=DeploymentGap)
    """Another A1 model, a fixed action delay, a motor strength (default: none; it needs the ``mujoco``
    backend)."""
    backend: str = "auto"
    """Simulation backend (``auto`` is ``mujoco`` under a gap that needs it)."""
    device: str | None = None
    """Torch device of the backend (``None``: its default)."""
    seed: int = 0
    """Base seed; each magnitude derives its own from it (the same for every strategy)."""
    falls: Falls = DEFAULT_FALLS
    """What ends a transition as a fall (:class:`gaitlib.defaults.Falls`): ``trunk``, the trunk too low,
    turned away or on the ground, a leg's touch ridden through (the field's: legged_gym's and Isaac Lab's A1);
    ``contact``, any non-foot body on the ground too (gaitlib's strict definition). Touches are counted beside
    either way."""
    guard: bool = False
    """Run every transition with the guard on (:mod:`gaitlib.meta.guard`; off by default, so that the strategies'
    figures stay comparable with the paper's)."""
    guard_margin: float | None = None
    """The guard's margin (``None``: the one chosen with the library's survival estimate)."""
    routes: dict[str, tuple[str, ...]] = field(default_factory=dict)
    """``"m-n"`` -> the gaits (m, ..., n) a transition of that pair switches through, each switch with the group's
    strategy, one after the other on the same robot (:mod:`gaitlib.strategies.routes`); the other pairs switch
    directly."""

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
        p = self.protocol
        if p.push_window != "request" or p.chain:
            raise GaitlibError("the benchmark's trials push around the request and are not chained")
        if p.push_lead_s >= p.warmup_s:
            raise GaitlibError("the push lead must lie in [0, warm-up time)")
        if p.horizon_s < p.deadline_s:
            raise GaitlibError(
                "the horizon must be at least the deadline, so that outcomes cover the disturbance window"
            )
        for pair, path in self.routes.items():
            if len(path) < 2 or f"{path[0]}-{path[-1]}" != pair or any(a == b for a, b in itertools.pairwise(path)):
                raise GaitlibError(f"the route {' -> '.join(path)} does not lead from one gait to another as {pair}")
        self.backend_name()  # newton under a gap that needs mujoco: one line now

    def backend_name(self) -> str:
        """The backend the groups run on (``auto`` resolved)."""
        return self.gap.backend_name(self.backend)

    def settings(self) -> dict:
        """The settings a resumed sweep must repeat (the gap's entries only where it differs from none)."""
        fixed = asdict(self)
        defaults = (() if self.routes else ("routes",)) + (() if self.guard else ("guard", "guard_margin"))
        for name in ("backend", "device", "gap", "protocol", *defaults):  # defaults: sweeps from before they existed
            fixed.pop(name)
        protocol = asdict(self.protocol)
        for name in ("push_window", "chain"):  # always the request window, never chained
            protocol.pop(name)
        return json.loads(json.dumps(fixed | protocol | self.gap.settings()))


@dataclass
class CellCounts:
    """Outcomes of one (strategy, pair, magnitude) cell."""

    samples: int = 0
    """Transitions counted (a routed one once, whatever its legs)."""
    successes: int = 0
    forced: int = 0
    """Switches made by the deadline rather than the strategy."""
    wait_s: float = 0.0
    """Total time from request to switch over the switches made, s."""
    switched: int = 0
    """Switches made (the other requests fell while waiting; a routed transition makes one a leg it reaches)."""
    source_falls: int = 0
    """Source runs that fell before a transition's first request (redone, not counted in ``samples``)."""
    touched: int = 0
    """Transitions in which a non-foot body touched the ground from a request to its verdict (a fall by the
    ``contact`` definition, ridden through or not by the ``trunk`` one)."""
    longest_touch_s: float = 0.0
    """The longest unbroken touch over the cell's transitions, s."""


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
    # Everything that decides the numbers: a resume with any of it changed is refused (open_results names it).
    settings = cfg.settings() | {"pairs": [list(p) for p in pairs],
                                 "switching": setup.resources.library.switching_identity()}
    if cfg.guard:  # the estimate decides the numbers too; a library without one is refused in one line
        setup.guard(margin=cfg.guard_margin)
        settings["survival"] = file_sha256(setup.resources.library.switching_dir / Library.SURVIVAL)
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
        for task, (cells, elapsed, guard) in ordered:
            key = group_key(task.strategy, task.magnitude)
            done += per_group
            results["groups"][key] = {
                "strategy": task.strategy,
                "magnitude_n": task.magnitude,
                "backend": cfg.backend_name(),
                "elapsed_s": round(elapsed, 2),
                "cells": {f"{m}-{n}": asdict(c) for (m, n), c in cells.items()},
            } | ({"guard": guard} if cfg.guard else {})
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

        if setup is None:
            setup = load_switching(library)
            if config.pairs is not None and not (config.guard or config.routes):
                setup = setup.serving(config.pairs)  # as the command served them (gaitlib benchmark --pairs)
        self._setup = setup
        if self._setup.resources.library.identities(self._setup.gaits) != identities:
            raise GaitlibError(f"the library at {library} holds other policies than the sweep's (identities)")
        self._pairs, self._cfg, self._progress = [tuple(p) for p in pairs], config, progress
        self._robot = config.gap.robot_spec()

    def __call__(self, task: GroupTask) -> tuple[dict[tuple[str, str], CellCounts], float, dict]:
        start, key = time.perf_counter(), group_key(task.strategy, task.magnitude)

        def report(finished: int) -> None:
            if self._progress is not None:
                self._progress(key, finished)

        cells, guard = _run_group(self._setup, self._robot, task, self._pairs, self._cfg, report)
        return cells, time.perf_counter() - start, guard


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
) -> tuple[dict[tuple[str, str], CellCounts], dict]:
    """All transitions of one strategy at one push magnitude, on ``robot``, and the guard's catches among them
    (:func:`~gaitlib.meta.guard.catch_summary`)."""
    # Every strategy meets the same random draws at a magnitude (common random numbers: differences between
    # strategies are not blurred by different worlds), and each magnitude its own.
    magnitude = task.magnitude
    seed = int(np.random.SeedSequence([cfg.seed, round(magnitude * 1000)]).generate_state(1)[0])
    sim = make_backend(cfg.backend_name(), num_worlds=cfg.num_worlds, robot=robot, device=cfg.device)
    try:
        pushes = cfg.protocol.pushes(magnitude, fixed=True)
        termination = TerminationConfig().counting(cfg.falls)
        env_cfg = EnvConfig(episode_seconds=_EPISODE_SECONDS, pushes=pushes, termination=termination)
        env = cfg.gap.make_env(setup, sim, env_cfg, seed=seed)
        guard = setup.guard(margin=cfg.guard_margin) if cfg.guard else None
        controller = setup.controller(env, task.strategy, deadline_s=cfg.protocol.deadline_s, seed=seed, guard=guard)
        routes = [cfg.routes.get(f"{m}-{n}", (m, n)) for m, n in pairs]
        legs = [[(setup.gait_index(a), setup.gait_index(b)) for a, b in itertools.pairwise(r)] for r in routes]
        cells = CellSchedule(legs, pairs, cfg.samples, report)
        protocol = dataclasses.replace(cfg.protocol, chain=bool(cfg.routes))  # a route's legs on one robot
        trials, catches = SwitchTrials(controller, protocol, cells, seed=seed), []
        while trials.running:
            catches += trials.step().catches
        return cells.cells, catch_summary(catches, setup.gaits, env.dt)
    finally:
        sim.close()


class CellSchedule(TrialSchedule):
    """The sweep's schedule: ``samples`` transitions of each pair, each new one of the least-started pair; counts
    outcomes per cell. A pair's transition is its route: one switch, or several chained on the same robot
    (``routes[i]``, the legs of pair i as gait indices); it succeeds when every leg does, and a fall anywhere, between
    legs included, fails it. The engine's pairs (:attr:`pairs`) are the legs of every route, in order."""

    def __init__(self, routes: list[list[tuple[int, int]]], names: Sequence[tuple[str, str]], samples: int,
                 report: Callable[[int], None]) -> None:
        self.names, self.samples, self.report = list(names), samples, report
        self.pairs = [leg for legs in routes for leg in legs]
        self._cell = [i for i, legs in enumerate(routes) for _ in legs]  # leg -> its pair
        self._first = list(itertools.accumulate((len(legs) for legs in routes[:-1]), initial=0))
        self._next = [i + 1 if i + 1 < len(self.pairs) and self._cell[i + 1] == c else -1
                      for i, c in enumerate(self._cell)]
        self.cells = {pair: CellCounts() for pair in self.names}
        self.started = [0] * len(routes)  # transitions begun (finished or under way) per pair
        self.ended = 0
        self._going_on: dict[int, int] = {}  # world -> the leg it goes on with, after a leg that stayed up
        self._touches: dict[int, float] = {}  # world -> its routed transition's longest touch so far, s (-1: none)

    def _counts(self, leg: int) -> CellCounts:
        return self.cells[self.names[self._cell[leg]]]

    def begin(self, k: int) -> torch.Tensor:
        chosen = []
        for _ in range(k):
            open_pairs = [i for i, s in enumerate(self.started) if s < self.samples]
            if not open_pairs:
                chosen.append(-1)
                continue
            pair = min(open_pairs, key=lambda i: self.started[i])
            self.started[pair] += 1
            chosen.append(self._first[pair])
        return torch.tensor(chosen, dtype=torch.long)

    def switched(self, pair: int, event: SwitchEvent) -> None:
        cell = self._counts(pair)
        cell.switched += 1
        cell.forced += int(event.forced)
        cell.wait_s += event.wait_s

    def source_fell(self, worlds: torch.Tensor, pairs: torch.Tensor) -> torch.Tensor:
        again = [leg == self._first[self._cell[leg]] for leg in pairs.tolist()]
        for world, leg, first in zip(worlds.tolist(), pairs.tolist(), again, strict=True):
            if first:  # before the transition's first request: run it again, uncounted
                self._counts(leg).source_falls += 1
            else:  # in the gait between two legs: the transition failed
                self._count(leg, False, self._touches.pop(world, -1.0))
        if not all(again):
            self.report(self.ended)
        return torch.tensor(again, dtype=torch.bool)

    def finished(self, outcome: TrialOutcome) -> None:
        touch = torch.where(outcome.touched, outcome.longest_touch_s, -1.0).tolist()
        for world, leg, ok, longest in zip(outcome.world.tolist(), outcome.pair.tolist(), outcome.success.tolist(),
                                           touch, strict=True):
            longest = max(longest, self._touches.pop(world, -1.0))
            if ok and self._next[leg] >= 0:
                self._going_on[world] = self._next[leg]
                self._touches[world] = longest
            else:
                self._count(leg, ok, longest)
        self.report(self.ended)

    def chain(self, worlds: torch.Tensor, gaits: torch.Tensor) -> torch.Tensor:
        return torch.tensor([self._going_on.pop(w, -1) for w in worlds.tolist()], dtype=torch.long)

    def _count(self, leg: int, success: bool, longest_touch_s: float) -> None:
        """Count a transition of ``leg``'s pair; ``longest_touch_s`` < 0: it touched nothing."""
        cell = self._counts(leg)
        cell.samples += 1
        cell.successes += int(success)
        cell.touched += int(longest_touch_s >= 0)
        cell.longest_touch_s = max(cell.longest_touch_s, longest_touch_s)
        self.ended += 1

