"""The collector's unit of work, a *chunk*: a fresh environment of ``num_worlds`` worlds seeded from the seed and
the chunk index, and a fixed quota of samples per ordered pair, each sample a switch trial of
:mod:`gaitlib.meta.trials` made with the ``random`` strategy (see :mod:`gaitlib.collection.collector` for the
protocol), until every quota is filled. A chunk's samples are a pure function of (seed, chunk index, quota,
settings, library), whoever runs it: :class:`ChunkWorker` runs chunks in this process or in a Ray actor."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs.terminations import TerminationConfig
from gaitlib.errors import GaitlibError
from gaitlib.library.policy import per_gait
from gaitlib.meta import MetaController, SwitchDetail, SwitchTrials, TrialOutcome, TrialProtocol, TrialSchedule
from gaitlib.strategies.random_switch import RandomStrategy
from gaitlib.transitions import schema
from gaitlib.transitions.explicit import EXPLICIT_DIM, explicit_state

__all__ = ["ChunkResult", "ChunkSamples", "ChunkTask", "ChunkWorker", "chunk_seeds"]

EPISODE_SECONDS = 1e6
"""Episode length given to the environment, s: no time-out ever ends a trial (worlds are reset after each)."""
REPORT_EVERY_S = 1.0
"""Wall-clock time between a chunk's reports of its finished samples, s."""


def chunk_seeds(seed: int, chunk: int) -> tuple[int, int, int, int]:
    """(environment, source times, pair choice, destination phase) seeds of chunk ``chunk``:
    ``numpy.random.SeedSequence([seed, chunk]).generate_state(4)``."""
    env, times, pairs, phases = (int(s) for s in np.random.SeedSequence([seed, chunk]).generate_state(4))
    return env, times, pairs, phases


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
        protocol: TrialProtocol,
        push_max: float,
        num_worlds: int,
        seed: int,
        device: str | None = None,
        report: Callable[[int], None] | None = None,
    ) -> None:
        from gaitlib.library.store import Library
        from gaitlib.sim import make_backend

        lib, gaits = Library(library), header.gaits
        if tuple(lib.identities(gaits).values()) != header.identities:
            raise GaitlibError(f"the library at {lib.root} holds other policies than the file records (identities)")
        entries, shared = lib.entries(gaits), lib.shared_policy_settings(gaits)
        self._protocol, self._seed, self._header = protocol, seed, header
        self._pairs = [(gaits.index(m), gaits.index(n)) for m, n in header.settings["pairs"]]
        self._clips = [e.clip for e in entries]
        pushes = protocol.pushes(push_max, fixed=False)
        # Falls by the trunk definition end a trial; a touch is recorded beside, which gives the contact outcome too.
        termination = TerminationConfig().counting("trunk")
        self._env_cfg = shared.env_config(
            EnvConfig(episode_seconds=EPISODE_SECONDS, pushes=pushes, termination=termination)
        )
        self._sim = make_backend(header.settings["backend"], num_worlds=num_worlds, device=device)
        self._policies = [e.policy.to(self._sim.device) for e in entries]
        self._report = report

    def __call__(self, task: ChunkTask) -> ChunkResult:
        env_seed, times_seed, pairs_seed, phases_seed = chunk_seeds(self._seed, task.chunk)
        env = ImitationEnv(self._sim, self._clips, self._env_cfg, seed=env_seed)
        controller = MetaController(
            env, self._policies, RandomStrategy(seed=phases_seed), deadline_s=self._protocol.deadline_s
        )
        samples = ChunkSamples(controller, self._pairs, np.asarray(task.quota), self._header.latent_dim, pairs_seed)
        trials = SwitchTrials(controller, self._protocol, samples, seed=times_seed, on_switch=samples.record)
        last, reported = time.perf_counter(), 0
        with torch.inference_mode():
            while trials.running:
                trials.step()
                if self._report is not None and time.perf_counter() - last >= REPORT_EVERY_S:
                    last = time.perf_counter()
                    if 0 < samples.kept != reported:  # news only: a report always has samples under way
                        reported = samples.kept
                        self._report(reported)
        batch = samples.take()
        batch.chunk[:] = task.chunk
        return ChunkResult(batch, samples.source_falls, trials.world_steps)

    def close(self) -> None:
        """Release the simulator."""
        self._sim.close()


class ChunkSamples(TrialSchedule):
    """The schedule of one chunk and the samples it keeps: a quota per pair, new trials on the least-begun open
    pair (ties at random), chained trials where that keeps the pairs balanced; what the ``random`` strategy's
    switch finds is recorded per world (:meth:`record`, the engine's ``on_switch``) and kept with the outcome."""

    def __init__(
        self,
        controller: MetaController,
        pairs: list[tuple[int, int]],
        quota: np.ndarray,
        latent_dim: int,
        seed: int,
    ) -> None:
        self.pairs = pairs
        self.source_falls = 0
        self._ctl, self._env = controller, controller.env
        dev, n = self._env.device, self._env.num_envs
        self._gen = torch.Generator().manual_seed(seed)
        self._pair_source = torch.tensor([m for m, _ in pairs])
        self._quota = torch.as_tensor(quota, dtype=torch.long)  # (P,) samples of each pair in this chunk
        self._load = torch.zeros(len(pairs), dtype=torch.long)  # trials begun per pair (finished or under way)
        self._filled = torch.zeros(len(pairs), dtype=torch.long)  # samples kept per pair
        # What is known of each world's sample at its switch.
        self._latent = torch.zeros(n, latent_dim, device=dev)
        self._explicit = torch.zeros(n, EXPLICIT_DIM, device=dev)
        self._phase_source = torch.zeros(n, device=dev)
        self._phase_dest = torch.zeros(n, device=dev)
        self._value_source = torch.zeros(n, device=dev)
        self._value_dest = torch.zeros(n, device=dev)
        self._switch_time = torch.zeros(n, device=dev)
        self._done: list[schema.TransitionBatch] = []

    @property
    def kept(self) -> int:
        """Samples kept so far."""
        return int(self._filled.sum())

    @property
    def done(self) -> bool:
        """Every quota is filled."""
        return bool((self._filled >= self._quota).all())

    def take(self) -> schema.TransitionBatch:
        """The kept samples in the order they finished (``chunk`` 0: the caller sets it)."""
        done, self._done = self._done, []
        return schema.TransitionBatch.concatenate(done)

    def begin(self, k: int) -> torch.Tensor:
        """(k,) pairs for k new trials, filling up the least-begun open pairs first (ties at random). Once every
        quota is begun, the worlds left over run spare trials of the pairs not yet filled (the least-begun first;
        the first samples to finish are kept), so that the chunk's last samples do not wait on a few worlds; -1
        (idle) once every pair is filled."""
        levels = self._load.unsqueeze(1) + torch.arange(k).unsqueeze(0)  # (P, k): load after 1..k more trials
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

    def chain(self, worlds: torch.Tensor, gaits: torch.Tensor) -> torch.Tensor:
        """(k,) for worlds now running ``gaits``: the least-begun open pair starting from that gait, unless it is
        more than a batch of worlds ahead of the least-begun open pair (-1: reset instead)."""
        candidates = self._pair_source.unsqueeze(0) == gaits.unsqueeze(1)  # (k, P)
        candidates &= (self._load < self._quota).unsqueeze(0)
        keys = torch.where(candidates, self._load.unsqueeze(0).float(), torch.inf)
        keys = keys + 0.5 * torch.rand(keys.shape, generator=self._gen)
        best_key, best = keys.min(dim=1)
        chosen = torch.full((len(gaits),), -1, dtype=torch.long)
        for row, pair in enumerate(best.tolist()):  # one world at a time, in order
            open_pairs = self._load < self._quota
            if not (math.isfinite(best_key[row]) and open_pairs[pair]):
                continue
            if self._load[pair] <= self._load[open_pairs].min() + self._env.num_envs:  # not a batch ahead
                self._load[pair] += 1
                chosen[row] = pair
        return chosen

    def source_fell(self, worlds: torch.Tensor, pairs: torch.Tensor) -> torch.Tensor:
        self.source_falls += len(pairs)
        return torch.ones(len(pairs), dtype=torch.bool)  # the same pair again: the samples' pairs stay uniform

    def record(self, switch: SwitchDetail) -> None:
        """What the switch of worlds ``switch.world`` found (before any policy acts on it)."""
        env, ids, policies = self._env, switch.world, self._ctl.policies
        before = switch.observation
        self._latent[ids] = switch.latent
        self._value_source[ids] = per_gait(policies, switch.source, before, method="value")
        self._explicit[ids] = explicit_state(before.policy)
        self._phase_source[ids] = switch.phase_source
        self._phase_dest[ids] = switch.phase_dest
        self._switch_time[ids] = env.episode_length_buf[ids].float() * env.dt
        self._value_dest[ids] = per_gait(policies, switch.dest, env.get_observations()[ids], method="value")

    def finished(self, outcome: TrialOutcome) -> None:
        """Keep the samples whose pair is not yet filled (in world order)."""
        keep = []
        for row, pair in enumerate(outcome.pair.tolist()):
            if self._filled[pair] < self._quota[pair]:
                self._filled[pair] += 1
                keep.append(row)
        rows = torch.tensor(keep, dtype=torch.long, device=outcome.world.device)
        ids = outcome.world[rows]

        def at(t: torch.Tensor) -> np.ndarray:
            return t[ids].cpu().numpy()

        pairs = np.asarray(self.pairs, dtype=np.int64).reshape(-1, 2)[outcome.pair[rows].cpu().numpy()]
        self._done.append(
            schema.TransitionBatch(
                source=pairs[:, 0],
                dest=pairs[:, 1],
                latent=at(self._latent),
                phase_source=at(self._phase_source),
                phase_dest=at(self._phase_dest),
                explicit=at(self._explicit),
                value_source=at(self._value_source),
                value_dest=at(self._value_dest),
                push_force=outcome.max_push[rows].cpu().numpy(),
                success=outcome.success[rows].cpu().numpy(),
                switch_time=at(self._switch_time),
                world=ids.cpu().numpy(),
                chunk=np.zeros(len(ids)),
                fall_after=outcome.fall_after_s[rows].cpu().numpy(),
                success_contact=(outcome.success[rows] & ~outcome.touched[rows]).cpu().numpy(),
                longest_touch=outcome.longest_touch_s[rows].cpu().numpy(),
            )
        )
