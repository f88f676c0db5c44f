"""The guard: every control step, whether or not a switch is requested, each world's chance of staying up if it keeps
its gait (the survival estimate, :mod:`gaitlib.strategies.survival`) is compared with what switching now offers (the
calibrated transition-net at each other gait's best destination phase,
:meth:`~gaitlib.strategies.lookahead.LookaheadStrategy.offers`; where the estimate holds a catch table,
:attr:`SurvivalEstimate.catch_into`, at the table's gait alone for the running gait and the direction the trunk's
acceleration says it is pushed toward, and where the table has none it is never caught); where the best offer beats
staying by more than the margin, or where the estimate reads below its floor (:attr:`SurvivalEstimate.floor`), the
world switches there at once (a *catch*), without waiting for a better phase. Within the horizon after a switch its
strategy chose, only the floor catches: that switch's score already counted the horizon after it.
The guard acts from the earliest moment of an episode its estimate saw a state of
(:attr:`SurvivalEstimate.armed_from_s`, the recording's first; before it the robot settles from its start, states
the estimate never learnt). After a catch the world holds the gait it was caught into for the estimate's horizon (it
is not caught again meanwhile: the net's offer already counted the time after that switch), then returns to the
requested gait through the normal switch (the controller's strategy), which is when it is safe by that strategy's
measure."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from gaitlib.library.policy import GaitPolicy, per_gait
from gaitlib.strategies.lookahead import LookaheadStrategy
from gaitlib.strategies.survival import SurvivalEstimate, check_guard, shove_sector, survival_features
from gaitlib.transitions.explicit import explicit_state

__all__ = ["CatchEvent", "Guard", "GuardReading", "catch_summary"]


@dataclass
class CatchEvent:
    """One catch of the guard."""

    world: int
    step: int
    """Controller step at which the catch switched (counted from the controller's creation)."""
    source: int
    """Gait caught from."""
    dest: int
    """Gait caught into."""
    phase: float
    """Destination phase switched to, cycles."""
    stay: float
    """The survival estimate of keeping ``source`` at the catch."""
    offer: float
    """The calibrated net's success probability of the switch made."""
    requested: int
    """The gait requested at the catch (the world returns to it)."""
    back_step: int | None = None
    """Controller step at which the requested gait ran again (``None``: not yet, or never)."""


@dataclass(frozen=True)
class GuardReading:
    """What the guard read of k worlds this step."""

    stay: torch.Tensor
    """(k,) survival estimate of keeping the gait."""
    offer: torch.Tensor
    """(k, G) calibrated success of switching now to each gait at its best phase (NaN on the own gait)."""
    phase: torch.Tensor
    """(k, G) that phase, cycles."""
    latent: torch.Tensor
    """(k, L) the actors' latents psi_m."""
    armed: torch.Tensor
    """(k,) bool: the episode has run at least the estimate's :attr:`~SurvivalEstimate.armed_from_s`."""

    def best(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(k,) the best offer and (k,) its gait."""
        return self.offer.nan_to_num(float("-inf")).max(dim=1)


class Guard:
    """Catches worlds whose gait is about to fail into the gait the net says saves them (module doc)."""

    def __init__(self, estimate: SurvivalEstimate, scorer: LookaheadStrategy, *, margin: float | None = None) -> None:
        """``margin``: the margin used instead of the one chosen with ``estimate``."""
        check_guard(margin=margin)
        self.estimate = estimate
        self.scorer = scorer
        self.margin = estimate.margin if margin is None else margin
        """A switch is taken where it offers more than staying by more than this."""
        self._catch_into = estimate.catch_into  # built once: the guard reads it every control step

    @property
    def horizon_s(self) -> float:
        """How far ahead the estimate looks, s; a caught world holds its new gait this long before it returns."""
        return self.estimate.horizon_s

    def read(self, env, policies: list[GaitPolicy], ids: torch.Tensor, candidates: torch.Tensor) -> GuardReading:
        """What the guard sees of worlds ``ids`` of ``env`` now."""
        obs = env.get_observations()[ids]
        gait, phase = env.gait[ids], env.phase[ids]
        latent = per_gait(policies, gait, obs, method="latent")
        needs = self.estimate.inputs
        value = per_gait(policies, gait, obs, method="value").reshape(-1) if "value" in needs else phase
        explicit = explicit_state(obs.policy) if "explicit" in needs else None
        imu = env.trunk_acceleration[ids] if "imu" in needs else None
        features = survival_features(needs, len(env.clips), gait=gait, latent=latent, phase=phase, value=value,
                                     explicit=explicit, imu=imu)
        stay = self.estimate.probability(features, gait).to(env.device)
        offer, best_phase = self.scorer.offers(gait, latent, phase, candidates, len(env.clips))
        if (table := self._catch_into) is not None:  # only the table's gait is offered (none: -1)
            if table.device != offer.device:
                self._catch_into = table = table.to(offer.device)
            sector = shove_sector(env.trunk_acceleration[ids]).to(offer.device)
            into = table[gait.to(offer.device), sector]
            other = torch.arange(offer.shape[1], device=offer.device) != into.unsqueeze(1)
            offer = offer.masked_fill(other, float("nan"))
        armed = env.episode_length_buf[ids] * env.dt >= self.estimate.armed_from_s - 1e-6
        return GuardReading(stay, offer.to(env.device), best_phase.to(env.device), latent, armed)

    def fires(self, reading: GuardReading, *, quiet: torch.Tensor | None = None) -> torch.Tensor:
        """(k,) bool: armed, an offer to switch to, and the best offer beats staying by more than the margin (not
        where ``quiet`` (k,) bool: within the horizon after a chosen switch) or staying reads below the floor."""
        best, _ = reading.best()
        beats = best - reading.stay > self.margin
        if quiet is not None:
            beats &= ~quiet
        low = reading.stay < self.estimate.floor
        return (beats | low) & (best > float("-inf")) & reading.armed


def catch_summary(catches: list[CatchEvent], gaits: tuple[str, ...], dt: float) -> dict:
    """Many worlds' catches in short: how many, per "from-to", and the time until the requested gait ran again
    (median over the catches it did, s)."""
    pairs: dict[str, int] = {}
    for c in catches:
        pair = f"{gaits[c.source]}-{gaits[c.dest]}"
        pairs[pair] = pairs.get(pair, 0) + 1
    back = sorted((c.back_step - c.step) * dt for c in catches if c.back_step is not None)
    return {"catches": len(catches), "by_pair": pairs, "back_after_s_median": back[len(back) // 2] if back else None}
