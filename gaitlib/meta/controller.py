"""The meta-controller (paper Algorithm 1): every control step (30 Hz) the active policy of each world acts; a
world with a queued policy asks the strategy whether to switch now and at which destination phase, and switches
when it says so, or when the request has waited ``deadline_s`` (forced, at the strategy's best candidate).
A world its guard caught into a catch skill (a gait of ``catchers``) holds it past the guard's horizon until it is
calm (:func:`gaitlib.envs.catch.is_calm`), at most :data:`~gaitlib.envs.catch.CALM_WAIT_S` after the catch, then
returns to the requested gait through the normal switch.

Works on any :class:`~gaitlib.envs.ImitationEnv` (any backend, any number of worlds) whose gaits are the library
policies given, in the same order.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import torch

from gaitlib.envs import ImitationEnv
from gaitlib.envs.catch import CALM_WAIT_S, is_calm
from gaitlib.envs.observations import ObservationBatch
from gaitlib.library.policy import GaitPolicy, per_gait
from gaitlib.meta.guard import CatchEvent, Guard
from gaitlib.strategies import Strategy, SwitchQuery, phase_grid

__all__ = ["DEADLINE_S", "MetaController", "MetaStep", "SwitchDetail", "SwitchEvent"]

DEADLINE_S = 2.0
"""A request not acted on within this time is forced, s."""


@dataclass(frozen=True)
class SwitchEvent:
    """One switch made by the meta-controller."""

    world: int
    step: int
    """Controller step at which the switch happened (counted from the controller's creation)."""
    source: int
    dest: int
    phase: float
    """Destination phase switched to, cycles."""
    score: float
    """The strategy's score of that phase (NaN for ``random``)."""
    forced: bool
    """True when the deadline, not the strategy, made the switch."""
    wait_s: float
    """Time from the request to the switch, s."""


@dataclass(frozen=True)
class SwitchDetail:
    """The k switches of one control step, as tensors, seen right after they were made (before the policies act)."""

    world: torch.Tensor
    """(k,) worlds."""
    source: torch.Tensor
    """(k,) gait switched from."""
    dest: torch.Tensor
    """(k,) gait switched to."""
    phase_source: torch.Tensor
    """(k,) source reference phase at the switch, cycles."""
    phase_dest: torch.Tensor
    """(k,) destination phase switched to, cycles."""
    latent: torch.Tensor
    """(k, L) the source actor's last hidden layer psi_m on the observation before the switch."""
    observation: ObservationBatch
    """(k,) rows of the environment's observations before the switch."""


@dataclass(frozen=True)
class MetaStep:
    """What one controller step did."""

    actions: torch.Tensor
    """(N, 12) actions applied, each from its world's active policy (after this step's switches)."""
    fell: torch.Tensor
    """(N,) bool: the world terminated (the environment has reset it; its request is dropped)."""
    events: list[SwitchEvent]
    """Switches made at this step."""
    waiting: torch.Tensor
    """(N,) bool: worlds that had a queued policy at this step (before switching)."""
    best_score: torch.Tensor
    """(N,) the strategy's best candidate score of waiting worlds this step (NaN elsewhere)."""
    best_phase: torch.Tensor
    """(N,) the best candidate destination phase of waiting worlds this step (NaN elsewhere)."""
    touch: torch.Tensor
    """(N,) bool: a non-foot body (a leg's, or the trunk) was on the ground at the end of this step, before any
    reset: a fall by the ``contact`` definition, a touch ridden through by the ``trunk`` one."""
    catches: list[CatchEvent] = field(default_factory=list)
    """The guard's catches at this step (made before the policies acted)."""


class MetaController:
    """An active and a queued policy per world, switched by a strategy (paper Algorithm 1)."""

    def __init__(
        self,
        env: ImitationEnv,
        policies: list[GaitPolicy],
        strategy: Strategy,
        *,
        typical_value: torch.Tensor | None = None,
        deadline_s: float = DEADLINE_S,
        candidates: int | None = None,
        guard: Guard | None = None,
        catchers: tuple[int, ...] = (),
    ) -> None:
        """``policies[g]`` drives ``env``'s gait g. ``typical_value`` (G,) divides destination critic values for
        strategies that need values (required by them). ``guard``: catch worlds about to fall
        (:mod:`gaitlib.meta.guard`); ``None``: unguarded. ``catchers``: the gaits that are catch skills (a world
        caught into one holds it until calm)."""
        if len(policies) != len(env.clips):
            raise ValueError(f"{len(policies)} policies for an environment of {len(env.clips)} gaits")
        if strategy.needs_value and typical_value is None:
            raise ValueError(f"strategy '{strategy.name}' needs the gaits' typical values")
        self.env = env
        self.policies = policies
        self.strategy = strategy
        self.deadline_steps = max(0, round(deadline_s / env.dt))
        self.candidates = phase_grid(candidates, env.device) if candidates else phase_grid(device=env.device)
        self.typical_value = None if typical_value is None else torch.as_tensor(typical_value, device=env.device)
        n = env.num_envs
        self.queued = torch.full((n,), -1, dtype=torch.long, device=env.device)
        """(N,) the queued gait of each world, -1 for none."""
        self.waited = torch.zeros(n, dtype=torch.long, device=env.device)
        """(N,) control steps each queued request has waited."""
        self.guard = guard
        self.requested = torch.full((n,), -1, dtype=torch.long, device=env.device)
        """(N,) the gait a caught world returns to, -1 where none is pending."""
        self.hold = torch.zeros(n, dtype=torch.long, device=env.device)
        """(N,) control steps a caught world still holds the gait it was caught into."""
        self.settle = torch.zeros(n, dtype=torch.long, device=env.device)
        """(N,) control steps the guard still leaves a world alone after a switch the strategy chose (not a forced
        one): the score that chose it counted the horizon after it, as a catch's offer does."""
        self._hold_steps = round(guard.horizon_s / env.dt) if guard is not None else 0
        self.catchers = torch.zeros(len(env.clips), dtype=torch.bool, device=env.device)
        self.catchers[list(catchers)] = True
        self.calm_wait = torch.zeros(n, dtype=torch.long, device=env.device)
        """(N,) control steps a world caught into a catch skill may still wait to be calm once its hold is over."""
        self._calm_wait_steps = round(CALM_WAIT_S / env.dt)
        self.stay = torch.full((n,), float("nan"), device=env.device)
        """(N,) the survival estimate the guard read at the last step (NaN unguarded)."""
        self._pending: dict[int, CatchEvent] = {}  # world -> its last catch, until the requested gait runs again
        self.steps = 0
        self.on_switch: Callable[[SwitchDetail], None] | None = None
        """Called with each step's switches right after they are made (before the policies act)."""

    @property
    def active(self) -> torch.Tensor:
        """(N,) the gait each world's active policy drives."""
        return self.env.gait

    def request(self, world_ids: torch.Tensor, gait: torch.Tensor | int) -> None:
        """Queue ``gait`` for worlds ``world_ids`` (replacing any queued one); the wait starts now."""
        world_ids = torch.as_tensor(world_ids, device=self.env.device).reshape(-1)
        self.queued[world_ids] = torch.as_tensor(gait, device=self.env.device)
        self.waited[world_ids] = 0
        self.requested[world_ids] = -1  # the new request is what a caught world now returns to
        for world in world_ids.tolist():
            self._pending.pop(world, None)

    def cancel(self, world_ids: torch.Tensor) -> None:
        """Drop the queued requests of ``world_ids``."""
        self.queued[world_ids] = -1

    def step(self) -> MetaStep:
        """Decide the switches of waiting worlds, act with every world's active policy, step the environment."""
        env = self.env
        n = env.num_envs
        best_score = torch.full((n,), float("nan"), device=env.device)
        best_phase = torch.full((n,), float("nan"), device=env.device)
        events: list[SwitchEvent] = []
        catches = self._guard(events) if self.guard is not None else []
        waiting = (self.queued >= 0) & (self.queued != env.gait)
        for world in ((self.queued >= 0) & ~waiting).nonzero().squeeze(1).tolist():  # already met (a catch into it)
            gait = int(env.gait[world])
            events.append(SwitchEvent(world=world, step=self.steps, source=gait, dest=gait,
                                      phase=float(env.phase[world]), score=float("nan"), forced=False,
                                      wait_s=float(self.waited[world]) * env.dt))
        self.queued[(self.queued >= 0) & ~waiting] = -1
        waiting &= self.hold <= 0  # a caught world holds its new gait first
        ids = waiting.nonzero().squeeze(1)
        if len(ids):
            decision, query, before = self._decide(ids)
            best_score[ids], best_phase[ids] = decision.score, decision.phase
            forced = self.waited[ids] >= self.deadline_steps
            go = decision.switch | forced
            if go.any():
                chosen = ids[go]
                env.switch(chosen, self.queued[chosen], decision.phase[go])
                self.settle[ids[decision.switch]] = self._hold_steps + 1  # counted down at this step's end too
                if self.on_switch is not None:
                    self.on_switch(
                        SwitchDetail(
                            world=chosen, source=query.source[go], dest=query.dest[go],
                            phase_source=query.phase_source[go], phase_dest=decision.phase[go],
                            latent=query.latent[go], observation=before[go],
                        )
                    )
                for i, world in zip(go.nonzero().squeeze(1).tolist(), chosen.tolist(), strict=True):
                    events.append(
                        SwitchEvent(
                            world=world,
                            step=self.steps,
                            source=int(query.source[i]),
                            dest=int(query.dest[i]),
                            phase=float(decision.phase[i]),
                            score=float(decision.score[i]),
                            forced=bool(forced[i] & ~decision.switch[i]),
                            wait_s=float(self.waited[world]) * env.dt,
                        )
                    )
                self.queued[chosen] = -1
        actions = per_gait(self.policies, env.gait, env.get_observations())
        _, _, dones, extras = env.step(actions)
        fell = dones & ~extras["time_outs"]
        self.queued[dones] = -1
        self.waited[self.queued >= 0] += 1
        self.steps += 1
        if self.guard is not None:
            self._return(dones)
        return MetaStep(actions, fell, events, waiting, best_score, best_phase, extras["touch"].to(fell.device),
                        catches)

    def _guard(self, events: list[SwitchEvent]) -> list[CatchEvent]:
        """Catch every world the guard fires on (:meth:`Guard.fires`), at once (not one that still holds the gait
        of its last catch; one within the horizon after a switch its strategy chose only below the floor: the score
        of that switch already counted the horizon after it); a catch into the queued gait is that request's switch
        (an event of ``events``)."""
        env = self.env
        ids = torch.arange(env.num_envs, device=env.device)
        reading = self.guard.read(env, self.policies, ids, self.candidates)
        fire = self.guard.fires(reading, quiet=self.settle > 0) & (self.hold <= 0)  # the horizon after a switch
        self.stay = reading.stay
        if not fire.any():
            return []
        chosen = fire.nonzero().squeeze(1)
        best, dest = reading.best()
        dest, phase, source = dest[chosen], reading.phase[chosen, dest[chosen]], env.gait[chosen].clone()
        phase_source = env.phase[chosen].clone()
        obs = env.get_observations()[chosen]
        requested = torch.where(self.queued[chosen] >= 0, self.queued[chosen], self.requested[chosen])
        requested = torch.where(requested >= 0, requested, source)
        env.switch(chosen, dest, phase)
        met = requested == dest
        if met.any() and self.on_switch is not None:
            self.on_switch(SwitchDetail(world=chosen[met], source=source[met], dest=dest[met],
                                        phase_source=phase_source[met],
                                        phase_dest=phase[met], latent=reading.latent[chosen][met],
                                        observation=obs[met]))
        catches = []
        for i, world in enumerate(chosen.tolist()):
            catch = CatchEvent(world=world, step=self.steps, source=int(source[i]), dest=int(dest[i]),
                               phase=float(phase[i]), stay=float(reading.stay[world]), offer=float(best[world]),
                               requested=int(requested[i]))
            catches.append(catch)
            if met[i]:
                catch.back_step = self.steps
                if int(self.queued[world]) >= 0:  # the request's switch, made by the guard
                    events.append(SwitchEvent(world=world, step=self.steps, source=catch.source, dest=catch.dest,
                                              phase=catch.phase, score=catch.offer, forced=False,
                                              wait_s=float(self.waited[world]) * env.dt))
                self.queued[world], self.requested[world] = -1, -1
                self._pending.pop(world, None)
            else:
                self.requested[world], self._pending[world] = catch.requested, catch
                self.queued[world] = -1
                self.hold[world] = self._hold_steps
                if bool(self.catchers[catch.dest]):
                    self.calm_wait[world] = self._calm_wait_steps - self._hold_steps
        return catches

    def _return(self, dones: torch.Tensor) -> None:
        """Count down the holds; request the gait a caught world returns to once its hold is over; note when it
        runs again. A world that ended its episode forgets its catch."""
        env = self.env
        self.hold = (self.hold - 1).clamp(min=0)
        self.settle = (self.settle - 1).clamp(min=0)
        self.hold[dones], self.settle[dones], self.calm_wait[dones] = 0, 0, 0
        waiting = (self.hold == 0) & (self.calm_wait > 0)
        if waiting.any():  # held one more step where the catch skill has not calmed the robot yet
            calm = is_calm(env.sim_state).to(waiting.device)
            self.calm_wait[waiting & calm] = 0
            self.calm_wait[waiting & ~calm] -= 1
            self.hold[waiting & ~calm] = 1
        self.requested[dones] = -1
        for world in dones.nonzero().squeeze(1).tolist():
            self._pending.pop(world, None)
        for world, catch in list(self._pending.items()):
            if int(env.gait[world]) == catch.requested:
                catch.back_step = self.steps
                del self._pending[world]
                self.requested[world] = -1
            elif int(self.hold[world]) == 0 and int(self.queued[world]) < 0:
                self.queued[world], self.waited[world] = catch.requested, 0

    def _decide(self, ids: torch.Tensor):
        env = self.env
        obs = env.get_observations()[ids]
        source, dest = env.gait[ids], self.queued[ids]
        query = SwitchQuery(
            source=source,
            dest=dest,
            phase_source=env.phase[ids],
            latent=per_gait(self.policies, source, obs, method="latent"),
            candidates=self.candidates,
            steps_left=(self.deadline_steps - self.waited[ids]).clamp(min=0),
            phase_step=env.dt * env.reference.rate[source],
        )
        if self.strategy.needs_value:
            c = len(self.candidates)
            preview = env.preview_switch(ids, dest, self.candidates)
            values = per_gait(self.policies, dest.repeat_interleave(c), preview, method="value")
            values = values.reshape(len(ids), c)
            query.dest_value = values / self.typical_value[dest].unsqueeze(1)
        return self.strategy.decide(query), query, obs
