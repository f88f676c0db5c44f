"""Collect transition samples: library policies switched at random moments and phases, outcome after a horizon.

Every world loops through the same cycle, all worlds at once (per-world state machines held as tensors):

1. reset (reference state initialization, fresh Table 1 randomization) with the source gait m of an ordered pair
   (m, n): the allowed pair with the fewest samples so far (those in the file and in progress included; ties
   broken at random), so every pair gets the same number of samples whatever its cycle length;
2. run m's policy for ``warmup_s`` plus a uniform extra time in [0, ``source_extra_s``]; a fall here is counted as
   a source fall and the world starts again at 1 with the same pair (so that the pairs of the samples stay
   uniform however often a source falls);
3. record psi_m, phi_m, the explicit state and m's critic value, switch to n at a uniform phi_n (the reference
   re-anchored where the robot stands) and record n's critic value on the new observation;
4. run n's policy for ``horizon_s``: alpha = 0 at the first termination, 1 if none.
5. after a fall, back to 1. After a success the world goes on without a reset (``chain``): n, which has just run
   for ``horizon_s``, becomes the next source, of the least-sampled pair starting from n, unless that pair is
   more than one batch of worlds ahead of the least-sampled pair overall (then back to 1); the next switch comes
   after a uniform time in [0, ``source_extra_s``]. This is how a robot runs on the meta-controller (one gait
   after another) and it saves the warm-up of most samples.

At every step each world is driven by the policy of the gait it currently imitates. Episodes are made far longer
than any cycle, so time-outs never cut a sample. With ``push_max`` > 0 random pushes (random horizontal direction,
0.1-0.3 s, magnitude uniform in [0, ``push_max``], a quiet time in ``push_interval_s`` between them) hit the robot
while the source runs; from the switch on no new push starts (one under way runs out), so the outcome is decided
by the state the switch finds, which is what the transition-net sees. Each sample records the largest push
magnitude of its source run.

Samples are written in batches through :mod:`gaitlib.transitions.schema`; rerunning with the same output file
resumes (new random numbers, the count continues, nothing written is lost or repeated), and Ctrl-C writes the
finished samples still in memory before it propagates.
"""

from __future__ import annotations

import dataclasses
import itertools
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import torch

from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs import observations as obs_fn
from gaitlib.envs.randomization import DISTURBANCE_INTERVAL_S, PushConfig, RandomizationConfig
from gaitlib.errors import GaitlibError
from gaitlib.sim import make_backend, resolve_backend_name
from gaitlib.training.library import LibraryEntry, load_entry
from gaitlib.training.policy import GaitPolicy
from gaitlib.transitions import schema
from gaitlib.transitions.explicit import EXPLICIT_DIM, explicit_state

__all__ = ["CollectConfig", "CollectProgress", "CollectResult", "collect"]

_EPISODE_SECONDS = 1e6
"""Episode length given to the environment, s: no time-out ever ends a cycle (worlds are reset after each)."""
_PUSH_COLUMNS = slice(obs_fn.PRIVILEGED_DIM - 3, obs_fn.PRIVILEGED_DIM)
"""Where the applied push force sits in the privileged observation (its last 3 values, in units of 100 N)."""
_PUSH_UNIT = 100.0


@dataclass(frozen=True, kw_only=True)
class CollectConfig:
    """How samples are drawn and written. Everything but ``samples``, ``num_worlds``, ``batch_size``, ``device`` and
    ``time_limit_s`` is stored in the file's settings, and a resumed collection must repeat it."""

    samples: int
    """Samples the file holds when collection ends (a resumed run continues up to this count)."""
    num_worlds: int = 64
    """Parallel worlds."""
    horizon_s: float = 2.0
    """Time after the switch within which no termination means success, s."""
    warmup_s: float = 1.0
    """Shortest time the source policy runs after a reset before it may be switched, s."""
    source_extra_s: float = 1.0
    """After the warm-up (or a chained success) the source runs a further time drawn uniformly from [0, this], s."""
    chain: bool = True
    """After a successful switch the destination becomes the next source without a reset (see the module doc)."""
    push_max: float = 0.0
    """Largest random push magnitude, N (uniform in [0, push_max]); 0 disables pushes."""
    push_interval_s: tuple[float, float] = DISTURBANCE_INTERVAL_S
    """Quiet time between pushes while the source runs, s (uniform in this range)."""
    pairs: tuple[tuple[str, str], ...] | None = None
    """Ordered (source, destination) gait pairs to sample, uniformly; ``None``: every ordered pair of ``gaits``."""
    backend: str = "auto"
    """Simulation backend."""
    device: str | None = None
    """Torch device of the backend (``None``: its default)."""
    seed: int = 0
    """Base seed; each run of a resumed file derives its own streams from it and the file's next chunk index."""
    batch_size: int = 256
    """Finished samples gathered before a write (one chunk) and a progress report."""
    time_limit_s: float | None = None
    """Stop after the first write past this much wall-clock time, s (``None``: run until ``samples``); a rerun
    resumes."""


@dataclass(frozen=True)
class CollectProgress:
    """What the progress display shows after each written chunk."""

    samples: int
    """Samples in the file."""
    target: int
    """Samples the file will hold when done."""
    samples_per_s: float
    """Throughput of this run, samples per wall-clock second."""
    elapsed_s: float
    """Wall-clock time of this run, s."""
    pair_counts: dict[tuple[str, str], tuple[int, int]]
    """(successes, samples) per ordered pair, over the whole file."""
    source_falls: int
    """Cycles of this run discarded because the source policy fell before the switch."""
    steps_per_sample: float
    """Control steps (summed over worlds) this run took per sample written."""

    @property
    def success_rates(self) -> dict[tuple[str, str], float]:
        """Fraction of successful switches per ordered pair that has samples."""
        return {pair: ok / n for pair, (ok, n) in self.pair_counts.items() if n}


@dataclass(frozen=True)
class CollectResult:
    """A finished (or already complete) collection."""

    path: Path
    samples: int
    """Samples in the file."""
    written: int
    """Samples written by this run."""
    elapsed_s: float
    """Wall-clock time of this run, s."""
    samples_per_s: float
    pair_counts: dict[tuple[str, str], tuple[int, int]]
    """(successes, samples) per ordered pair, over the whole file."""
    source_falls: int
    steps_per_sample: float
    """Control steps (summed over worlds) this run took per sample written."""
    note: str | None
    """What opening the file repaired (rows of an interrupted append), else ``None``."""


def collect(
    output: Path,
    *,
    library: Path,
    gaits: Sequence[str],
    config: CollectConfig,
    progress: Callable[[CollectProgress], None] | None = None,
) -> CollectResult:
    """Collect transition samples of the library policies of ``gaits`` into ``output`` until it holds
    ``config.samples`` (creating it, or resuming it when it exists).

    Raises :class:`~gaitlib.errors.GaitlibError` subclasses with one-line messages: bad settings, missing or
    inconsistent library entries, an ``output`` that is not a matching transition file.
    """
    cfg = config
    output = Path(output)
    gaits = list(gaits)
    pairs = _check(cfg, gaits)
    entries = [load_entry(Path(library), name) for name in gaits]
    latent_dim, action = _common_policy_shape(entries)
    backend_name = resolve_backend_name(cfg.backend)
    pushes = PushConfig(max_force=cfg.push_max, interval=cfg.push_interval_s)
    settings = {
        "horizon_s": cfg.horizon_s,
        "warmup_s": cfg.warmup_s,
        "source_extra_s": cfg.source_extra_s,
        "push_max_n": cfg.push_max,
        "push_duration_s": list(pushes.duration),
        "push_interval_s": list(pushes.interval),
        "pushes_during": "source run only (none starts after the switch); push_force: largest of the source run",
        "pairs": [list(p) for p in pairs],
        "pair_choice": "least-sampled ordered pair at each reset, ties at random; phase_dest uniform in [0, 1)",
        "chain": cfg.chain,
        "backend": backend_name,
        "seed": cfg.seed,
        "randomization": dataclasses.asdict(RandomizationConfig()),
        "action": action,
    }
    header = schema.TransitionHeader(
        gaits=tuple(gaits), identities=tuple(e.identity for e in entries), latent_dim=latent_dim, settings=settings
    )
    if not output.exists():
        schema.create(output, gaits=gaits, identities=list(header.identities), latent_dim=latent_dim, settings=settings)
    target = schema.open_for_append(output, expect=header)
    sim = None
    try:
        f, count = target.file, target.count
        counts = _pair_counts(f, count, len(gaits))
        if count >= cfg.samples:
            return CollectResult(output, count, 0, 0.0, 0.0, _named(counts, gaits), 0, 0.0, target.note)
        chunk = int(f["chunk"][count - 1]) + 1 if count else 0
        env_seed, draw_seed = (int(s) for s in np.random.SeedSequence([cfg.seed, chunk]).generate_state(2))
        sim = make_backend(backend_name, num_worlds=cfg.num_worlds, device=cfg.device)
        env_cfg = EnvConfig(
            episode_seconds=_EPISODE_SECONDS, action_scale=action["scale"], action_clip=action["clip"], pushes=pushes
        )
        env = ImitationEnv(sim, [e.clip for e in entries], env_cfg, seed=env_seed)
        schema.record_session(
            f,
            {
                "first_chunk": chunk,
                "samples_at_start": count,
                "env_seed": env_seed,
                "draw_seed": draw_seed,
                "num_worlds": cfg.num_worlds,
                "control_dt_s": env.dt,
                "torch": torch.__version__,
                "started": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            },
        )
        run = _Run(
            env,
            [e.policy.to(env.device) for e in entries],
            pairs=[(gaits.index(m), gaits.index(n)) for m, n in pairs],
            counts=counts[..., 1],
            cfg=cfg,
            latent_dim=latent_dim,
            seed=draw_seed,
        )
        start = time.perf_counter()
        written = 0

        def write() -> None:
            nonlocal count, chunk, written
            batch = run.take(limit=cfg.samples - count)
            if batch is None:
                return
            batch.chunk[:] = chunk
            np.add.at(counts, (batch.source, batch.dest, 0), batch.success)
            np.add.at(counts, (batch.source, batch.dest, 1), 1)
            count = schema.append(f, batch)
            chunk += 1
            written += len(batch)

        try:
            with torch.inference_mode():
                while count < cfg.samples:
                    run.step()
                    if run.pending >= min(cfg.batch_size, cfg.samples - count):
                        write()
                        if progress is not None:
                            elapsed = time.perf_counter() - start
                            progress(
                                CollectProgress(
                                    samples=count,
                                    target=cfg.samples,
                                    samples_per_s=written / elapsed,
                                    elapsed_s=elapsed,
                                    pair_counts=_named(counts, gaits),
                                    source_falls=run.source_falls,
                                    steps_per_sample=run.world_steps / max(written, 1),
                                )
                            )
                        if cfg.time_limit_s is not None and time.perf_counter() - start >= cfg.time_limit_s:
                            break
        except KeyboardInterrupt:
            write()  # finished samples still in memory
            raise
        elapsed = time.perf_counter() - start
        return CollectResult(
            output,
            count,
            written,
            elapsed,
            written / elapsed,
            _named(counts, gaits),
            run.source_falls,
            run.world_steps / max(written, 1),
            target.note,
        )
    finally:
        target.close()
        if sim is not None:
            sim.close()


class _Run:
    """The vectorized per-world cycle: reset with a source gait, run, switch, run the horizon, label."""

    def __init__(
        self,
        env: ImitationEnv,
        policies: list[GaitPolicy],
        *,
        pairs: list[tuple[int, int]],
        counts: np.ndarray,
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
        self._load = torch.tensor([int(counts[m, d]) for m, d in pairs])  # samples per pair, written or under way
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
        self.pending = 0
        """Finished samples not yet taken."""
        self._restart(torch.arange(n, device=dev), new_pair=True)

    def step(self) -> None:
        """Advance every world one control step and move its state machine on."""
        env = self.env
        obs, _, dones, extras = env.step(self._per_gait(env.gait, "act", env.get_observations()))
        fell = dones & ~extras["time_outs"]
        self._steps_left -= 1
        push = obs["privileged"][:, _PUSH_COLUMNS].norm(dim=1) * _PUSH_UNIT
        self._max_push = torch.where(self._in_horizon, self._max_push, torch.maximum(self._max_push, push))
        finished = self._in_horizon & (fell | (self._steps_left <= 0))
        source_fell = ~self._in_horizon & fell
        due = ~self._in_horizon & ~fell & (self._steps_left <= 0)
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

    def take(self, *, limit: int) -> schema.TransitionBatch | None:
        """The finished samples in order (at most ``limit``; the rest are dropped), ``chunk`` left at 0; ``None``
        if there are none."""
        done, self._done, self.pending = self._done, [], 0
        return schema.TransitionBatch.concatenate(done).select(slice(0, limit)) if done else None

    def _per_gait(self, gait: torch.Tensor, method: str, obs) -> torch.Tensor:
        """``policy.method(obs rows)`` of each row's gait (one call per gait present)."""
        out = None
        for g, policy in enumerate(self.policies):
            rows = (gait == g).nonzero().squeeze(1)
            if len(rows) == 0:
                continue
            values = getattr(policy, method)(obs[rows])
            if out is None:
                out = torch.empty((len(gait), *values.shape[1:]), dtype=values.dtype, device=values.device)
            out[rows] = values
        assert out is not None
        return out

    def _restart(self, ids: torch.Tensor, *, new_pair: bool) -> None:
        k = len(ids)
        if new_pair:
            self._pair[ids] = self._least_sampled(k).to(self._dev)
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
        keys = torch.where(candidates, self._load.unsqueeze(0).float(), torch.inf)
        keys = keys + 0.5 * torch.rand(keys.shape, generator=self._gen)
        best_key, best = keys.min(dim=1)
        ok = best_key <= float(self._load.min() + self.env.num_envs)
        chosen = torch.zeros(self.env.num_envs, dtype=torch.bool)
        chosen[ids.cpu()[ok]] = True
        ids, best = ids[ok.to(ids.device)], best[ok]
        self._pair[ids] = best.to(self._dev)
        self._load += torch.bincount(best, minlength=len(self._load))
        self.env.enable_pushes(ids, True)
        self._max_push[ids] = 0.0
        self._in_horizon[ids] = False
        self._steps_left[ids] = torch.randint(self._extra + 1, (len(ids),), generator=self._gen).to(self._dev)
        return chosen.to(self._dev)

    def _least_sampled(self, k: int) -> torch.Tensor:
        """(k,) pairs for k new cycles, filling up the least-sampled pairs first (ties at random)."""
        levels = self._load.unsqueeze(1) + torch.arange(k).unsqueeze(0)  # (P, k): load after 1..k more cycles
        keys = levels + 0.5 * torch.rand(levels.shape, generator=self._gen)
        chosen = torch.topk(keys.flatten(), k, largest=False).indices // k
        self._load += torch.bincount(chosen, minlength=len(self._load))
        return chosen[torch.randperm(k, generator=self._gen)]

    def _switch(self, ids: torch.Tensor) -> None:
        env = self.env
        before = env.get_observations()[ids]
        source = env.gait[ids]
        self._source[ids] = source
        self._latent[ids] = self._per_gait(source, "latent", before)
        self._value_source[ids] = self._per_gait(source, "value", before)
        self._explicit[ids] = explicit_state(before["policy"])
        self._phase_source[ids] = env.phase[ids]
        self._switch_time[ids] = env.episode_length_buf[ids].float() * env.dt
        dest = self._pair_dest[self._pair[ids]]
        phase = torch.rand(len(ids), generator=self._gen).to(self._dev)
        env.switch(ids, dest, phase)
        env.enable_pushes(ids, False)
        self._phase_dest[ids] = phase
        self._value_dest[ids] = self._per_gait(dest, "value", env.get_observations()[ids])
        self._in_horizon[ids] = True
        self._steps_left[ids] = self._horizon

    def _finish(self, ids: torch.Tensor, alive: torch.Tensor) -> None:
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
            )
        )
        self.pending += len(ids)


def _check(cfg: CollectConfig, gaits: list[str]) -> list[tuple[str, str]]:
    """Validate the request; returns the ordered pairs to sample."""
    if len(gaits) < 2 or len(set(gaits)) != len(gaits):
        raise GaitlibError(f"need at least two distinct gaits to collect transitions, got {gaits}")
    if cfg.samples < 1 or cfg.num_worlds < 1 or cfg.batch_size < 1:
        raise GaitlibError("samples, num_worlds and batch_size must be positive")
    if cfg.horizon_s <= 0 or cfg.warmup_s < 0 or cfg.source_extra_s < 0 or cfg.push_max < 0:
        raise GaitlibError("horizon must be positive; warm-up, extra source time and push_max not negative")
    if cfg.pairs is None:
        return list(itertools.permutations(gaits, 2))
    pairs = [tuple(p) for p in cfg.pairs]
    for m, n in pairs:
        if m not in gaits or n not in gaits or m == n:
            raise GaitlibError(f"pair {m}->{n}: both gaits must be among {gaits} and differ")
    return list(dict.fromkeys(pairs))


def _common_policy_shape(entries: list[LibraryEntry]) -> tuple[int, dict]:
    """The latent size and action settings all ``entries`` share (they drive one environment, one file)."""
    latent = {e.name: e.policy.latent_dim for e in entries}
    if len(set(latent.values())) != 1:
        raise GaitlibError(f"library policies have different latent sizes {latent}; retrain them alike")
    actions = {e.name: (e.action_scale, float(e.metadata["action"]["clip"])) for e in entries}
    if len(set(actions.values())) != 1:
        raise GaitlibError(f"library policies use different action scales/clips {actions}; retrain them alike")
    scale, clip = next(iter(actions.values()))
    return next(iter(latent.values())), {"type": entries[0].metadata["action"]["type"], "scale": scale, "clip": clip}


def _pair_counts(f, count: int, num_gaits: int) -> np.ndarray:
    """(G, G, 2) successes and samples per ordered pair among the first ``count`` rows of ``f``."""
    counts = np.zeros((num_gaits, num_gaits, 2), dtype=np.int64)
    if count:
        source, dest = f["source"][:count], f["dest"][:count]
        np.add.at(counts, (source, dest, 0), f["success"][:count])
        np.add.at(counts, (source, dest, 1), 1)
    return counts


def _named(counts: np.ndarray, gaits: list[str]) -> dict[tuple[str, str], tuple[int, int]]:
    return {
        (m, n): (int(counts[i, j, 0]), int(counts[i, j, 1]))
        for (i, m), (j, n) in itertools.product(enumerate(gaits), repeat=2)
        if counts[i, j, 1]
    }
