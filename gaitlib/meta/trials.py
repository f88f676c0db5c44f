"""The switch trial: one protocol, one engine, shared by the collection's labels (``gaitlib collect``), the
benchmark's verdicts (``gaitlib benchmark``) and one traced robot (``gaitlib run``).

A trial, per world, all worlds at once (per-world state machines held as tensors):

1. reset with the source gait m of the pair the schedule picks (reference state initialization, fresh Table 1
   randomization);
2. the meta-controller runs m for ``warmup_s`` plus a uniform extra time in [0, ``source_extra_s``]; a fall here
   is a *source fall*: the schedule decides whether the world starts again at 1 with the same pair or takes
   another;
3. the switch to n is requested; the controller's strategy switches when it says so (``random``: at once, at a
   uniform destination phase), or the request is forced after ``deadline_s``;
4. the verdict: success if the robot does not fall from the request until ``horizon_s`` after the end of the
   control step in which it switched; beside it, whether a non-foot body touched the ground in that window
   (a *touch*: with the ``trunk`` definition of a fall the robot may ride it through) and the longest such touch.
   Run with the ``trunk`` definition, a trial also gives the ``contact`` verdict: no fall and no touch (the two
   runs are the same motion up to the first touch, where the ``contact`` one would have ended).

Pushes come in one of two windows. ``request`` (the benchmark and ``gaitlib run``): from ``push_lead_s`` before
the request until ``deadline_s`` after it, whatever the strategy does (the last push runs out), so that every
strategy meets the same disturbance and differs only in when and to which phase it switches. ``source`` (the
collection): while the source runs, from the reset to the switch (a push under way runs out), so that the outcome
is decided by the state the switch finds, which is what the transition-net sees. The push magnitudes are the
environment's (:class:`~gaitlib.envs.randomization.PushConfig`).

With ``chain`` a world that stayed up goes on without a reset: the gait it now runs is the source of the next
trial the schedule picks for it, switched after a uniform time in [0, ``source_extra_s``] (how a robot runs on the
meta-controller, one gait after another; it saves the warm-up of most trials), after ``push_lead_s`` more with the
``request`` window (the next request's pushes begin that long before it, as for the first).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import torch

from gaitlib.envs.randomization import DISTURBANCE_INTERVAL_S, DISTURBANCE_LEAD_S, PushConfig
from gaitlib.errors import GaitlibError
from gaitlib.meta.controller import DEADLINE_S, MetaController, MetaStep, SwitchDetail, SwitchEvent

__all__ = ["SUCCESS_HORIZON_S", "SwitchTrials", "TrialOutcome", "TrialProtocol", "TrialSchedule"]

SUCCESS_HORIZON_S = 2.5
"""Default time after a switch within which no fall makes a success, s: the collection's label and the
benchmark's verdict alike (``docs/transitions.md``, "The success horizon", says how it was chosen)."""


@dataclass(frozen=True, kw_only=True)
class TrialProtocol:
    """When a trial requests, switches, is pushed and is judged (checked when built: one-line errors). The defaults
    are the benchmark's; :meth:`collection` gives the collection's."""

    warmup_s: float = 1.0
    """Shortest source run after a reset before the request, s."""
    source_extra_s: float = 1.0
    """Further source run, uniform in [0, this], s (spreads the source phase at the request)."""
    horizon_s: float = SUCCESS_HORIZON_S
    """Time after the switch's control step without a fall that makes a success, s."""
    deadline_s: float = DEADLINE_S
    """A request not acted on within this time is forced, s."""
    push_window: Literal["request", "source"] = "request"
    """``request``: pushes from ``push_lead_s`` before the request until ``deadline_s`` after it; ``source``: while
    the source runs, from the reset to the switch."""
    push_lead_s: float = DISTURBANCE_LEAD_S
    """With the ``request`` window, pushes begin this long before the request (at most ``warmup_s``), s."""
    push_duration_s: tuple[float, float] = (0.1, 0.3)
    """Duration of each push, s (paper: 0.1-0.3 s)."""
    push_interval_s: tuple[float, float] = DISTURBANCE_INTERVAL_S
    """Quiet time before each push, s (uniform in this range)."""
    chain: bool = False
    """After a success the world goes on from the gait it now runs, without a reset (see the module doc)."""

    def __post_init__(self) -> None:
        times = (self.warmup_s, self.source_extra_s, self.horizon_s, self.deadline_s, self.push_lead_s,
                 *self.push_duration_s, *self.push_interval_s)
        if not all(math.isfinite(t) for t in times):
            raise GaitlibError("the trial's times (warm-up, extra time, horizon, deadline, pushes) must be finite")
        if self.horizon_s <= 0 or self.warmup_s < 0 or self.source_extra_s < 0 or self.deadline_s < 0:
            raise GaitlibError("the horizon must be positive; warm-up, extra source time and deadline not negative")
        if self.push_window not in ("request", "source"):
            raise GaitlibError(f"push window '{self.push_window}': request or source")
        if self.push_window == "request" and not 0 <= self.push_lead_s <= self.warmup_s:
            raise GaitlibError("the push lead must lie in [0, warm-up time]")

    @classmethod
    def collection(cls, **fields) -> TrialProtocol:
        """The collection's protocol: pushes while the source runs, trials chained (``fields`` override)."""
        return cls(**({"push_window": "source", "chain": True} | fields))

    def pushes(self, magnitude: float, *, fixed: bool) -> PushConfig:
        """The environment's pushes: exactly ``magnitude`` (``fixed``) or uniform in [0, ``magnitude``], N."""
        return PushConfig(max_force=magnitude, fixed_force=fixed, duration=self.push_duration_s,
                          interval=self.push_interval_s)


@dataclass(frozen=True)
class TrialOutcome:
    """The trials that ended at one control step (k of them, in world order)."""

    world: torch.Tensor
    """(k,) worlds."""
    pair: torch.Tensor
    """(k,) index of each trial's pair in the schedule's pairs."""
    success: torch.Tensor
    """(k,) bool: stayed up for the horizon."""
    fall_after_s: torch.Tensor
    """(k,) time from the switch to the fall, s (inf for a success, 0 for a fall before the switch)."""
    max_push: torch.Tensor
    """(k,) largest push magnitude on the trunk from the reset (or the chained start) to the switch, N."""
    touched: torch.Tensor
    """(k,) bool: a non-foot body touched the ground from the request to the verdict."""
    longest_touch_s: torch.Tensor
    """(k,) the longest unbroken touch in that window, s (0: none)."""


class TrialSchedule(ABC):
    """Which pair each trial runs, and what is kept of its outcome (the collection's quotas and samples, the
    benchmark's cells, one traced run)."""

    pairs: list[tuple[int, int]]
    """Ordered (source, destination) gait indices; trials name them by position."""

    @abstractmethod
    def begin(self, k: int) -> torch.Tensor:
        """(k,) the pairs of k new trials (for worlds in order), -1 where a world is to stay idle."""

    @abstractmethod
    def finished(self, outcome: TrialOutcome) -> None:
        """Take the outcomes of trials that ended."""

    def chain(self, worlds: torch.Tensor, gaits: torch.Tensor) -> torch.Tensor:
        """(k,) pairs of trials chained onto ``worlds`` (k, that stayed up) now running ``gaits``, -1 where a world
        is reset instead."""
        return torch.full((len(gaits),), -1, dtype=torch.long)

    def source_fell(self, worlds: torch.Tensor, pairs: torch.Tensor) -> torch.Tensor:
        """The sources of ``worlds``' trials of ``pairs`` fell before the request; (k,) bool: True where that trial
        starts again, False where the world takes a new one (:meth:`begin`)."""
        return torch.ones(len(pairs), dtype=torch.bool)

    def switched(self, pair: int, event: SwitchEvent) -> None:  # noqa: B027 (optional hook)
        """A trial of ``pair`` switched."""

    @property
    def done(self) -> bool:
        """Nothing more is wanted (worlds still in a trial are abandoned)."""
        return False


class SwitchTrials:
    """Runs switch trials on every world of a meta-controller's environment until its schedule is served.

    ``seed`` draws the source run times; ``on_switch`` sees each switch as it is made (before the policies act on
    it: what the collection records of a sample)."""

    SOURCE, WAITING, AFTER, IDLE = 0, 1, 2, 3

    def __init__(
        self,
        controller: MetaController,
        protocol: TrialProtocol,
        schedule: TrialSchedule,
        *,
        seed: int,
        on_switch: Callable[[SwitchDetail], None] | None = None,
    ) -> None:
        self.ctl, self.protocol, self.schedule = controller, protocol, schedule
        self.env = env = controller.env
        self.world_steps = 0
        """Control steps taken, summed over worlds."""
        self._on_switch = on_switch
        controller.on_switch = self._switched
        dev, n = env.device, env.num_envs
        self._source = torch.tensor([m for m, _ in schedule.pairs], device=dev)
        self._dest = torch.tensor([d for _, d in schedule.pairs], device=dev)
        self._gen = torch.Generator().manual_seed(seed)
        self._pair = torch.zeros(n, dtype=torch.long, device=dev)
        self._stage = torch.full((n,), self.IDLE, dtype=torch.long, device=dev)
        self._steps_left = torch.zeros(n, dtype=torch.long, device=dev)
        self._warmup = round(protocol.warmup_s / env.dt)
        self._extra = round(protocol.source_extra_s / env.dt)
        self._horizon = max(1, round(protocol.horizon_s / env.dt))
        self._windowed = protocol.push_window == "request"
        self._lead = round(protocol.push_lead_s / env.dt)
        self._deadline = round(protocol.deadline_s / env.dt)
        self._push_left = torch.zeros(n, dtype=torch.long, device=dev)  # control steps of pushes left per world
        self._max_push = torch.zeros(n, device=dev)
        self._touch_run = torch.zeros(n, dtype=torch.long, device=dev)  # steps of the touch under way (judged)
        self._touch_longest = torch.zeros(n, dtype=torch.long, device=dev)  # longest since the request
        self._begin(torch.arange(n, device=dev))

    @property
    def running(self) -> bool:
        """Some world is in a trial and the schedule wants more."""
        return bool((self._stage != self.IDLE).any()) and not self.schedule.done

    def run(self) -> None:
        """Step until the schedule is served."""
        while self.running:
            self.step()

    def step(self) -> MetaStep:
        """One control step of every world; the trials move on."""
        before = (self._stage == self.SOURCE) | (self._stage == self.WAITING)
        result = self.ctl.step()
        self.world_steps += self.env.num_envs
        self._steps_left -= 1
        self._push_left -= 1
        for event in result.events:
            w = event.world
            if int(self._stage[w]) != self.WAITING:
                continue
            before[w] = False  # its push from now on is not the source run's
            self.schedule.switched(int(self._pair[w]), event)
            self._stage[w] = self.AFTER
            self._steps_left[w] = self._horizon
        push = self.env.push_force.norm(dim=1)
        self._max_push = torch.where(before, torch.maximum(self._max_push, push), self._max_push)
        fell, stage = result.fell, self._stage
        judged = (stage == self.WAITING) | (stage == self.AFTER)
        touch = result.touch & judged
        self._touch_run = torch.where(touch, self._touch_run + 1, 0)
        self._touch_longest = torch.where(judged, torch.maximum(self._touch_longest, self._touch_run), 0)
        source_fell = fell & (stage == self.SOURCE)
        failed = fell & ((stage == self.WAITING) | (stage == self.AFTER))
        succeeded = ~fell & (stage == self.AFTER) & (self._steps_left <= 0)
        due = ~fell & (stage == self.SOURCE) & (self._steps_left <= 0)
        pushed = ~fell & (stage == self.SOURCE) & (self._steps_left == self._lead) & self._windowed
        calmed = ~fell & (stage != self.SOURCE) & (self._push_left == 0) & self._windowed
        ended = failed | succeeded
        if ended.any():
            self._finish(ended.nonzero().squeeze(1), fell)
        if source_fell.any():
            ids = source_fell.nonzero().squeeze(1)
            again = self.schedule.source_fell(ids.cpu(), self._pair[ids].cpu()).to(ids.device)
            if again.any():
                self._start_source(ids[again])
            self._begin(ids[~again])
        if ended.any():
            ids = ended.nonzero().squeeze(1)
            self.ctl.cancel(ids)
            chained = self._chain(ids, ~fell[ids]) if self.protocol.chain else torch.zeros_like(ids, dtype=torch.bool)
            self._begin(ids[~chained])
        if pushed.any():
            self._push_from_now(pushed.nonzero().squeeze(1))
        if calmed.any():
            self.env.enable_pushes(calmed.nonzero().squeeze(1), False)
        if due.any():
            ids = due.nonzero().squeeze(1)
            self.ctl.request(ids, self._dest[self._pair[ids]])
            self._stage[ids] = self.WAITING
        return result

    def _finish(self, ids: torch.Tensor, fell: torch.Tensor) -> None:
        # Steps since the switch: the switch's own step plus the horizon's steps run (a fall while waiting: 0).
        after = torch.where(self._stage[ids] == self.AFTER, self._horizon + 1 - self._steps_left[ids], 0)
        success = ~fell[ids]
        self.schedule.finished(
            TrialOutcome(
                world=ids,
                pair=self._pair[ids],
                success=success,
                fall_after_s=torch.where(success, torch.inf, after.float() * self.env.dt),
                max_push=self._max_push[ids],
                touched=self._touch_longest[ids] > 0,
                longest_touch_s=self._touch_longest[ids].float() * self.env.dt,
            )
        )

    def _chain(self, ids: torch.Tensor, ok: torch.Tensor) -> torch.Tensor:
        """Chain the worlds of ``ids`` that stayed up (``ok``) into the schedule's next trial for them; returns the
        mask of those chained."""
        pairs = torch.full((len(ids),), -1, dtype=torch.long)
        if ok.any():
            pairs[ok.cpu()] = self.schedule.chain(ids[ok].cpu(), self.env.gait[ids[ok]].cpu())
        chosen = (pairs >= 0).to(ids.device)
        ids = ids[chosen]
        self._pair[ids] = pairs[pairs >= 0].to(ids.device)
        self._enter_source(ids, warmup=self._lead if self._windowed else 0)
        if not self._windowed:
            self.env.enable_pushes(ids, True)
        return chosen

    def _begin(self, ids: torch.Tensor) -> None:
        """Start worlds ``ids`` on the pairs the schedule picks, or leave them idle."""
        if len(ids) == 0:
            return
        pairs = self.schedule.begin(len(ids)).to(ids.device)
        self._idle(ids[pairs < 0])
        starting = pairs >= 0
        self._pair[ids[starting]] = pairs[starting]
        if starting.any():
            self._start_source(ids[starting])

    def _idle(self, ids: torch.Tensor) -> None:
        self._stage[ids] = self.IDLE
        self.env.enable_pushes(ids, False)

    def _start_source(self, ids: torch.Tensor) -> None:
        self.env.enable_pushes(ids, False)
        self.env.reset_worlds(ids, gait=self._source[self._pair[ids]])
        if not self._windowed:
            self.env.enable_pushes(ids, True)
        self._enter_source(ids, warmup=self._warmup)

    def _enter_source(self, ids: torch.Tensor, *, warmup: int) -> None:
        self._stage[ids] = self.SOURCE
        self._max_push[ids] = 0.0
        self._push_left[ids] = -1  # armed again ``lead`` steps before the request
        extra = torch.randint(self._extra + 1, (len(ids),), generator=self._gen).to(self.env.device)
        self._steps_left[ids] = warmup + extra
        if self._windowed:
            early = ids[self._steps_left[ids] <= self._lead]  # a request sooner than the lead: pushed from now
            if len(early):
                self._push_from_now(early)

    def _push_from_now(self, ids: torch.Tensor) -> None:
        self.env.enable_pushes(ids, True)
        self._push_left[ids] = self._steps_left[ids] + self._deadline

    def _switched(self, detail: SwitchDetail) -> None:
        if not self._windowed:
            self.env.enable_pushes(detail.world, False)
        if self._on_switch is not None:
            self._on_switch(detail)
