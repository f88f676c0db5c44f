"""The collector's unit of work, a *chunk*: a fresh environment of ``num_worlds`` worlds seeded from the seed and
the chunk index, and a fixed quota of samples per ordered pair, run through the per-world cycle (reset with a
source gait, run it, switch, run the horizon, label the outcome; see :mod:`gaitlib.transitions.collector` for the
protocol) until every quota is filled. A chunk's samples are a pure function of (seed, chunk index, quota,
settings, library), whoever runs it: :class:`ChunkWorker` runs chunks in this process or in a Ray actor."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch

from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs.randomization import PushConfig
from gaitlib.errors import GaitlibError
from gaitlib.training.policy import GaitPolicy, per_gait
from gaitlib.transitions import schema
from gaitlib.transitions.explicit import EXPLICIT_DIM, explicit_state

if TYPE_CHECKING:
    from gaitlib.transitions.collector import CollectConfig

__all__ = ["ChunkResult", "ChunkTask", "ChunkWorker", "SwitchCycles", "chunk_seeds"]

EPISODE_SECONDS = 1e6
"""Episode length given to the environment, s: no time-out ever ends a cycle (worlds are reset after each)."""
REPORT_EVERY_S = 1.0
"""Wall-clock time between a chunk's reports of its finished samples, s."""


def chunk_seeds(seed: int, chunk: int) -> tuple[int, int]:
    """(environment seed, draw seed) of chunk ``chunk``: ``numpy.random.SeedSequence([seed, chunk])``."""
    env_seed, draw_seed = (int(s) for s in np.random.SeedSequence([seed, chunk]).generate_state(2))
    return env_seed, draw_seed


@dataclass(frozen=True)
class ChunkTask:
    """One chunk to collect."""

    chunk: int
    """Chunk index (the file's ``chunk`` column; seeds derive from it)."""
    quota: tuple[int, ...]
    """Samples of each ordered pair (in the order of the file's pairs setting)."""


@dataclass(frozen=True)
class ChunkResult:
    """A collected chunk."""

    batch: schema.TransitionBatch
    """Its samples in the order they finished, ``chunk`` set."""
    source_falls: int
    """Cycles discarded because the source fell before the switch."""
    world_steps: int
    """Control steps taken, summed over worlds (idle worlds at the end included)."""


class ChunkWorker:
    """Loads a library's policies once and owns one simulator; called with a :class:`ChunkTask`, it collects that
    chunk (a fresh environment on the same simulator, every world reset). Build it with keyword arguments only, so
    that Ray can build it in an actor.

    ``report``: called with the samples the chunk under way has finished so far (when there are more than at the
    last call), about every :data:`REPORT_EVERY_S` (a worker in this process only: it is how the progress display
    moves inside a chunk)."""

    def __init__(
        self,
        *,
        library: str | Path,
        header: schema.TransitionHeader,
        config: CollectConfig,
        report: Callable[[int], None] | None = None,
    ) -> None:
        from gaitlib.sim import make_backend
        from gaitlib.training.library import Library

        lib, gaits = Library(library), header.gaits
        if tuple(lib.identities(gaits).values()) != header.identities:
            raise GaitlibError(f"the library at {lib.root} holds other policies than the file records (identities)")
        entries, shared = lib.entries(gaits), lib.shared_policy_settings(gaits)
        self._cfg, self._header = config, header
        self._pairs = [(gaits.index(m), gaits.index(n)) for m, n in header.settings["pairs"]]
        self._clips = [e.clip for e in entries]
        pushes = PushConfig(max_force=config.push_max, interval=config.push_interval_s)
        self._env_cfg = shared.env_config(EnvConfig(episode_seconds=EPISODE_SECONDS, pushes=pushes))
        self._sim = make_backend(header.settings["backend"], num_worlds=config.num_worlds, device=config.device)
        self._policies = [e.policy.to(self._sim.device) for e in entries]
        self._report = report

    def __call__(self, task: ChunkTask) -> ChunkResult:
        env_seed, draw_seed = chunk_seeds(self._cfg.seed, task.chunk)
        env = ImitationEnv(self._sim, self._clips, self._env_cfg, seed=env_seed)
        cycles = SwitchCycles(
            env, self._policies, pairs=self._pairs, quota=np.asarray(task.quota), cfg=self._cfg,
            latent_dim=self._header.latent_dim, seed=draw_seed,
        )
        last, reported = time.perf_counter(), 0
        with torch.inference_mode():
            while not cycles.done:
                cycles.step()
                if self._report is not None and time.perf_counter() - last >= REPORT_EVERY_S:
                    last = time.perf_counter()
                    if 0 < cycles.finished != reported:  # news only: a report always has samples under way
                        reported = cycles.finished
                        self._report(reported)
        batch = cycles.take()
        batch.chunk[:] = task.chunk
        return ChunkResult(batch, cycles.source_falls, cycles.world_steps)

    def close(self) -> None:
        """Release the simulator."""
        self._sim.close()


class SwitchCycles:
    """The vectorized per-world cycle of one chunk: reset with a source gait, run, switch, run the horizon, label;
    a world whose pair quotas are all begun goes idle (it keeps stepping, unpushed, and counts for nothing)."""

    def __init__(
        self,
        env: ImitationEnv,
        policies: list[GaitPolicy],
        *,
        pairs: list[tuple[int, int]],
        quota: np.ndarray,
        cfg: CollectConfig,
        latent_dim: int,
        seed: int,
    ) -> None:
        self.env = env
        self.policies = policies
        self.source_falls = 0
        self.world_steps = 0
        """Control steps taken over all worlds."""
        dev, n = env.device, env.num_envs
        self._chain = cfg.chain
        self._dev = dev
        self._gen = torch.Generator().manual_seed(seed)
        self._pair_source = torch.tensor([m for m, _ in pairs], device=dev)
        self._pair_dest = torch.tensor([d for _, d in pairs], device=dev)
        self._warmup = round(cfg.warmup_s / env.dt)
        self._extra = round(cfg.source_extra_s / env.dt)
        self._horizon = max(1, round(cfg.horizon_s / env.dt))
        self._pair = torch.zeros(n, dtype=torch.long, device=dev)  # index into the pairs of each world's cycle
        self._quota = torch.as_tensor(quota, dtype=torch.long)  # (P,) samples of each pair in this chunk
        self._load = torch.zeros(len(pairs), dtype=torch.long)  # cycles begun per pair (finished or under way)
        self._filled = torch.zeros(len(pairs), dtype=torch.long)  # samples kept per pair
        self._active = torch.zeros(n, dtype=torch.bool, device=dev)  # worlds in a cycle (the others are idle)
        self._in_horizon = torch.zeros(n, dtype=torch.bool, device=dev)
        self._steps_left = torch.zeros(n, dtype=torch.long, device=dev)  # in the current stage, control steps
        # What is known of each world's sample at the switch, and the largest push since.
        self._source = torch.zeros(n, dtype=torch.long, device=dev)
        self._latent = torch.zeros(n, latent_dim, device=dev)
        self._explicit = torch.zeros(n, EXPLICIT_DIM, device=dev)
        self._phase_source = torch.zeros(n, device=dev)
        self._phase_dest = torch.zeros(n, device=dev)
        self._value_source = torch.zeros(n, device=dev)
        self._value_dest = torch.zeros(n, device=dev)
        self._switch_time = torch.zeros(n, device=dev)
        self._max_push = torch.zeros(n, device=dev)
        self._done: list[schema.TransitionBatch] = []
        self._restart(torch.arange(n, device=dev), new_pair=True)

    def step(self) -> None:
        """Advance every world one control step and move its state machine on."""
        env = self.env
        _, _, dones, extras = env.step(per_gait(self.policies, env.gait, env.get_observations()))
        fell = dones & ~extras["time_outs"] & self._active
        self._steps_left -= 1
        push = env.push_force.norm(dim=1)
        self._max_push = torch.where(self._in_horizon, self._max_push, torch.maximum(self._max_push, push))
        finished = self._active & self._in_horizon & (fell | (self._steps_left <= 0))
        source_fell = ~self._in_horizon & fell
        due = self._active & ~self._in_horizon & ~fell & (self._steps_left <= 0)
        self.world_steps += env.num_envs
        if finished.any():
            self._finish(finished.nonzero().squeeze(1), ~fell)
        self.source_falls += int(source_fell.sum())
        chained = finished & ~fell & self._chain
        if chained.any():
            chained = self._continue(chained.nonzero().squeeze(1))
        restart = finished & ~chained
        if restart.any():
            self._restart(restart.nonzero().squeeze(1), new_pair=True)
        if source_fell.any():
            self._restart(source_fell.nonzero().squeeze(1), new_pair=False)
        if due.any():
            self._switch(due.nonzero().squeeze(1))

    @property
    def finished(self) -> int:
        """Samples kept so far."""
        return int(self._filled.sum())

    @property
    def done(self) -> bool:
        """Every quota is filled."""
        return bool((self._filled >= self._quota).all())

    def take(self) -> schema.TransitionBatch:
        """The finished samples in the order they finished (``chunk`` 0: the caller sets it)."""
        done, self._done = self._done, []
        return schema.TransitionBatch.concatenate(done)

    def _restart(self, ids: torch.Tensor, *, new_pair: bool) -> None:
        if new_pair:
            chosen = self._least_sampled(len(ids)).to(self._dev)
            idle = ids[chosen < 0]
            self._active[idle] = False
            self._in_horizon[idle] = False
            self.env.enable_pushes(idle, False)
            ids = ids[chosen >= 0]
            self._pair[ids] = chosen[chosen >= 0]
            self._active[ids] = True
        k = len(ids)
        if k == 0:
            return
        self.env.reset_worlds(ids, gait=self._pair_source[self._pair[ids]])
        self.env.enable_pushes(ids, True)
        self._max_push[ids] = 0.0
        self._in_horizon[ids] = False
        extra = torch.randint(self._extra + 1, (k,), generator=self._gen).to(self._dev)
        self._steps_left[ids] = self._warmup + extra

    def _continue(self, ids: torch.Tensor) -> torch.Tensor:
        """Chain worlds ``ids`` (just through a successful switch) into a new cycle from the gait they now run, where
        that keeps the pairs balanced; returns the (N,) mask of the worlds chained."""
        gait = self.env.gait[ids].cpu()
        candidates = self._pair_source.cpu().unsqueeze(0) == gait.unsqueeze(1)  # (k, P)
        candidates &= (self._load < self._quota).unsqueeze(0)
        keys = torch.where(candidates, self._load.unsqueeze(0).float(), torch.inf)
        keys = keys + 0.5 * torch.rand(keys.shape, generator=self._gen)
        best_key, best = keys.min(dim=1)
        # One world at a time, in order: the pair must still be open, and not more than a batch of worlds ahead.
        ok = torch.zeros(len(ids), dtype=torch.bool)
        for row, pair in enumerate(best.tolist()):
            open_pairs = self._load < self._quota
            if math.isfinite(best_key[row]) and open_pairs[pair]:
                ok[row] = bool(self._load[pair] <= self._load[open_pairs].min() + self.env.num_envs)
                self._load[pair] += int(ok[row])
        chosen = torch.zeros(self.env.num_envs, dtype=torch.bool)
        chosen[ids.cpu()[ok]] = True
        ids, best = ids[ok.to(ids.device)], best[ok]
        self._pair[ids] = best.to(self._dev)
        self._active[ids] = True
        self.env.enable_pushes(ids, True)
        self._max_push[ids] = 0.0
        self._in_horizon[ids] = False
        self._steps_left[ids] = torch.randint(self._extra + 1, (len(ids),), generator=self._gen).to(self._dev)
        return chosen.to(self._dev)

    def _least_sampled(self, k: int) -> torch.Tensor:
        """(k,) pairs for k new cycles, filling up the least-begun open pairs first (ties at random). Once every
        quota is begun, the worlds left over run spare cycles of the pairs not yet filled (the least-begun first;
        the first samples to finish are kept), so that the chunk's last samples do not wait on a few worlds; -1
        (idle) once every pair is filled."""
        levels = self._load.unsqueeze(1) + torch.arange(k).unsqueeze(0)  # (P, k): load after 1..k more cycles
        keys = levels + 0.5 * torch.rand(levels.shape, generator=self._gen)
        room = int((self._quota - self._load).clamp(min=0).sum())
        unfilled = self._filled < self._quota
        open_keys = torch.where(levels < self._quota.unsqueeze(1), keys, torch.inf)
        spare_keys = torch.where(unfilled.unsqueeze(1), keys, torch.inf)
        count = min(k, room) if room else (k if bool(unfilled.any()) else 0)
        chosen = torch.topk((open_keys if room else spare_keys).flatten(), count, largest=False).indices // k
        self._load += torch.bincount(chosen, minlength=len(self._load))
        chosen = torch.cat([chosen, torch.full((k - len(chosen),), -1, dtype=torch.long)])
        return chosen[torch.randperm(k, generator=self._gen)]

    def _switch(self, ids: torch.Tensor) -> None:
        env = self.env
        before = env.get_observations()[ids]
        source = env.gait[ids]
        self._source[ids] = source
        self._latent[ids] = per_gait(self.policies, source, before, method="latent")
        self._value_source[ids] = per_gait(self.policies, source, before, method="value")
        self._explicit[ids] = explicit_state(before["policy"])
        self._phase_source[ids] = env.phase[ids]
        self._switch_time[ids] = env.episode_length_buf[ids].float() * env.dt
        dest = self._pair_dest[self._pair[ids]]
        phase = torch.rand(len(ids), generator=self._gen).to(self._dev)
        env.switch(ids, dest, phase)
        env.enable_pushes(ids, False)
        self._phase_dest[ids] = phase
        self._value_dest[ids] = per_gait(self.policies, dest, env.get_observations()[ids], method="value")
        self._in_horizon[ids] = True
        self._steps_left[ids] = self._horizon

    def _finish(self, ids: torch.Tensor, alive: torch.Tensor) -> None:
        """Keep the samples of worlds ``ids`` whose pair is not yet filled (in world order)."""
        self._active[ids] = False  # until _restart or _continue picks a new cycle
        keep = []
        for row, pair in enumerate(self._pair[ids].tolist()):
            if self._filled[pair] < self._quota[pair]:
                self._filled[pair] += 1
                keep.append(row)
        ids = ids[torch.tensor(keep, dtype=torch.long, device=ids.device)]

        def rows(t: torch.Tensor) -> np.ndarray:
            return t[ids].cpu().numpy()

        self._done.append(
            schema.TransitionBatch(
                source=rows(self._source),
                dest=rows(self._pair_dest[self._pair]),
                latent=rows(self._latent),
                phase_source=rows(self._phase_source),
                phase_dest=rows(self._phase_dest),
                explicit=rows(self._explicit),
                value_source=rows(self._value_source),
                value_dest=rows(self._value_dest),
                push_force=rows(self._max_push),
                success=rows(alive),
                switch_time=rows(self._switch_time),
                world=ids.cpu().numpy(),
                chunk=np.zeros(len(ids)),
                fall_after=np.where(rows(alive), np.inf, rows(self._horizon - self._steps_left) * self.env.dt),
            )
        )

