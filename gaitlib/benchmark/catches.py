"""Where the guard catches to: the catch table, chosen by rollouts on training draws.

The transition-net scores switches from the states it was fitted on; two control steps into a shove, the running
gait's latent has barely felt it, so the gait the net offers most is no better a catch than staying
(``benchmarks/guard_oracle.py``). The catch table instead names, for each running gait, the gait to catch into: each
gait of the library is shoved once (a :class:`~gaitlib.evaluation.SinglePush` of ``impulse`` N s on ``episodes``
worlds) and every world switched at once, ``delay`` control steps after its shove starts, into each other gait
(or each of the candidates given, :attr:`CatchTableConfig.into`: a library's catch skill alone, say) at its best
destination phase (the calibrated net's, as the guard switches), kept to the episode's end. The worlds are
sorted by the sector of :data:`~gaitlib.evaluation.SECTORS` their trunk's acceleration points to at the catch
(:func:`~gaitlib.strategies.survival.shove_sector`, what the guard reads then); in each sector, the gait whose
catches fell least is the table's, if they fell less than staying did and the sector read at least
:data:`~gaitlib.defaults.MIN_CATCH_WORLDS` worlds (else that sector has no catch: the guard leaves the gait alone
when shoved that way). The draws are the caller's ``seed`` (training seeds: never an
evaluation's).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import torch

from gaitlib.benchmark.guarded_push import guarded_push_rollout, shove_episode
from gaitlib.defaults import DEFAULT_FALLS, MIN_CATCH_WORLDS, Falls
from gaitlib.errors import GaitlibError
from gaitlib.evaluation import SECTORS, SinglePush, sector_of
from gaitlib.meta.guard import Guard, GuardReading
from gaitlib.meta.setup import SwitchingSetup
from gaitlib.strategies.survival import shove_sector

__all__ = ["CatchTableConfig", "TimedCatch", "fit_catch_table", "timed_catch_falls"]

_NEVER_S = 1e6
"""A hold no episode outlasts, s: a timed catch keeps its gait."""


class TimedCatch(Guard):
    """A guard that catches every world exactly ``delay`` control steps after its shove starts (the shove ``shove``
    describes: :class:`SinglePush`'s arguments), into gait ``dest`` or, with ``dest`` ``None``, into the gait the
    reading offers most; it never returns. It keeps, per world, the sector its trunk's acceleration pointed to at the
    catch (:attr:`sector`) and the sector it was shoved toward (:attr:`shoved`)."""

    def __init__(self, guard: Guard, *, delay: int, dest: int | None, shove: dict) -> None:
        estimate = guard.estimate  # a fixed destination is offered whatever catch table the estimate holds
        if dest is not None:
            estimate = dataclasses.replace(estimate, info={k: v for k, v in estimate.info.items() if k != "catches"})
        super().__init__(estimate, guard.scorer, margin=guard.margin)
        self.delay, self.dest, self.shove = delay, dest, shove
        self._start: torch.Tensor | None = None
        self._env = None
        self.sector: torch.Tensor | None = None
        """(N,) index into SECTORS read from each world's acceleration at its catch (-1: not reached)."""
        self.shoved: torch.Tensor | None = None
        """(N,) index into SECTORS of each world's shove, relative to its heading."""

    @property
    def horizon_s(self) -> float:
        return _NEVER_S

    def read(self, env, policies, ids, candidates) -> GuardReading:
        if self._env is not env:  # the rollout's own draws (SinglePush is drawn from its seed alone)
            push = SinglePush(env, **self.shove)
            self._env, self._start, self.shoved = env, push.start, sector_of(push.angle).cpu()
            self.sector = torch.full((env.num_envs,), -1, dtype=torch.long)
        due = (env.episode_length_buf[ids] == self._start[ids] + self.delay).cpu()
        self.sector[ids.cpu()[due]] = shove_sector(env.trunk_acceleration[ids][due.to(env.device)]).cpu()
        reading = super().read(env, policies, ids, candidates)
        if self.dest is not None:
            keep = torch.zeros_like(reading.offer, dtype=torch.bool)
            keep[:, self.dest] = True
            reading = GuardReading(reading.stay, reading.offer.masked_fill(~keep, float("nan")), reading.phase,
                                   reading.latent, reading.armed)
        return reading

    def fires(self, reading: GuardReading, *, quiet: torch.Tensor | None = None) -> torch.Tensor:
        best, _ = reading.best()
        return (self._env.episode_length_buf == self._start + self.delay) & torch.isfinite(best)


@dataclass(frozen=True, kw_only=True)
class CatchTableConfig:
    """How the catch table is measured (module doc)."""

    impulse_ns: float = 18.0
    """The shove, N s (18 N s fells 15-41% of the shipped gaits' episodes: enough falls to rank the catches)."""
    episodes: int = 256
    """Worlds per running gait and catch gait."""
    delay_steps: int = 2
    """Control steps from the shove's start to the catch."""
    seed: int = 1000
    backend: str = "mujoco"
    falls: Falls = DEFAULT_FALLS
    into: tuple[str, ...] | None = None
    """The gaits a catch may go to (``None``: every gait); a running gait with none but itself among them is never
    caught (no rollout is run for it)."""

    def __post_init__(self) -> None:
        if self.episodes < MIN_CATCH_WORLDS * len(SECTORS):
            raise GaitlibError(f"{self.episodes} episodes give fewer than {MIN_CATCH_WORLDS} worlds per direction of "
                               f"shove to choose a catch on: give at least {MIN_CATCH_WORLDS * len(SECTORS)}")


def timed_catch_falls(setup: SwitchingSetup, guard: Guard, gait: int, dest: int | None, *, impulse_ns: float,
                      episodes: int, delay_steps: int, seed: int, backend: str,
                      falls: Falls = DEFAULT_FALLS) -> tuple[torch.Tensor, TimedCatch | None]:
    """((episodes,) bool: the worlds of ``gait`` that fell, shoved once with ``impulse_ns`` N s and caught
    ``delay_steps`` control steps after into ``dest``; the catching guard, which kept each world's sectors) (``dest``
    ``-1``: not caught, staying, and no guard; ``None``: into the gait ``guard`` offers most)."""
    duration_s = 0.1
    cfg, cycle_s = shove_episode(setup, gait, duration_s=duration_s, falls=falls)
    shove = {"impulse": impulse_ns, "duration_s": duration_s, "cycle_s": cycle_s, "seed": seed}
    catching = None if dest == -1 else TimedCatch(guard, delay=delay_steps, dest=dest, shove=shove)
    run = guarded_push_rollout(setup, gait, catching, cfg, impulse=impulse_ns, episodes=episodes,
                               duration_s=duration_s, cycle_s=cycle_s, backend=backend, seed=seed)
    return run.tally.fell.cpu().bool(), catching


def fit_catch_table(setup: SwitchingSetup, guard: Guard, config: CatchTableConfig, *, progress=None) -> dict:
    """The catch table of ``setup``'s gaits (module doc): JSON-ready, with every rollout's falls per sector."""
    gaits = setup.gaits
    into = [setup.gait_index(name) for name in config.into] if config.into is not None else range(len(gaits))
    dests = {g: [d for d in into if d != g] for g in range(len(gaits))}
    falls: dict[str, dict[str, dict[str, int]]] = {}
    worlds: dict[str, dict[str, int]] = {}
    agreement: dict[str, float] = {}
    done, total = 0, sum(len(d) + 1 for d in dests.values() if d)
    for g, name in enumerate(gaits):
        if not dests[g]:
            continue
        fell = {}
        for d in [-1, *dests[g]]:
            fell["stay" if d == -1 else gaits[d]], catching = timed_catch_falls(
                setup, guard, g, d, impulse_ns=config.impulse_ns, episodes=config.episodes,
                delay_steps=config.delay_steps, seed=config.seed + g, backend=config.backend, falls=config.falls)
            if catching is not None:  # every catch rollout reads the same sectors (one shove draw, one state)
                sector, shoved = catching.sector, catching.shoved
            done += 1
            if progress is not None:
                progress(done, total)
        falls[name] = {s: {option: int(f[sector == k].sum()) for option, f in fell.items()}
                       for k, s in enumerate(SECTORS)}
        worlds[name] = {s: int((sector == k).sum()) for k, s in enumerate(SECTORS)}
        agreement[name] = float((sector == shoved).float().mean())
    catch_into = {}
    for name, by_sector in falls.items():
        row = {}
        for s, counts in by_sector.items():
            best = min((d for d in counts if d != "stay"), key=lambda d: (counts[d], d))
            if counts[best] < counts["stay"] and worlds[name][s] >= MIN_CATCH_WORLDS:  # never chosen on a handful
                row[s] = best
        if row:
            catch_into[name] = row
    return {
        "catch_into": catch_into, "falls": falls, "worlds": worlds, "sector_agreement": agreement,
        "episodes": config.episodes, "min_worlds": MIN_CATCH_WORLDS,
        "impulse_ns": config.impulse_ns, "delay_steps": config.delay_steps,
        "seed": config.seed, "falls_definition": Falls(config.falls).value,
        "into": None if config.into is None else list(config.into),
    }
