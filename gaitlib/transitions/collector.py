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

Samples are committed in batches through :mod:`gaitlib.transitions.writer` (one writer per file; a kill loses at
most the batch being written); rerunning with the same output file resumes (new random numbers, the count
continues, nothing written is lost or repeated), and Ctrl-C writes the finished samples still in memory before it
propagates. Nothing is created before the request is checked.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import torch

from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs import observations as obs_fn
from gaitlib.envs.randomization import DISTURBANCE_INTERVAL_S, PushConfig
from gaitlib.errors import GaitlibError
from gaitlib.sim import make_backend, resolve_backend_name
from gaitlib.training.library import Library, PolicySettings
from gaitlib.transitions import schema
from gaitlib.transitions.cycle import SwitchCycles
from gaitlib.transitions.writer import open_writer

__all__ = ["CollectConfig", "CollectProgress", "CollectResult", "collect"]

_EPISODE_SECONDS = 1e6
"""Episode length given to the environment, s: no time-out ever ends a cycle (worlds are reset after each)."""


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
    """What opening the file removed (leftovers of an interrupted run), else ``None``."""


def collect(
    output: Path,
    *,
    library: Library,
    gaits: Sequence[str] | None = None,
    config: CollectConfig,
    progress: Callable[[CollectProgress], None] | None = None,
) -> CollectResult:
    """Collect transition samples of the library policies of ``gaits`` (``None``: every entry; always stored in the
    library's canonical order) into ``output`` until it holds ``config.samples`` (creating it, or resuming it when
    it exists).

    Raises :class:`~gaitlib.errors.GaitlibError` subclasses with one-line messages: bad settings, missing or
    inconsistent library entries, an ``output`` that is not a matching transition file.
    """
    cfg, output = config, Path(output)
    names = library.order(gaits)
    pairs = _check(cfg, names)
    shared = library.shared_policy_settings(names)
    header = _header(library, names, pairs, cfg, shared)
    with open_writer(output, header=header) as target:
        counts = _pair_counts(target.committed, len(names))
        if target.count >= cfg.samples:
            return CollectResult(output, target.count, 0, 0.0, 0.0, _named(counts, names), 0, 0.0, target.note)
        sim = make_backend(header.settings["backend"], num_worlds=cfg.num_worlds, device=cfg.device)
        try:
            run = _start_run(target, sim, library.entries(names), shared, header, pairs, counts, cfg)
            return _write_until_done(output, target, run, counts, names, cfg, progress)
        finally:
            sim.close()


def _header(
    library: Library, gaits: tuple[str, ...], pairs: list[tuple[str, str]], cfg: CollectConfig, shared: PolicySettings
) -> schema.TransitionHeader:
    """What the file records of the policies and settings (a resumed run must repeat them)."""
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
        "backend": resolve_backend_name(cfg.backend),
        "seed": cfg.seed,
        "randomization": dataclasses.asdict(shared.env_config(EnvConfig()).randomization),
        "action": shared.action,
        "observation": obs_fn.layout(shared.observation),
    }
    identities = tuple(library.identities(gaits).values())
    return schema.TransitionHeader(gaits=gaits, identities=identities, latent_dim=shared.latent_dim, settings=settings)


def _start_run(target, sim, entries, shared, header, pairs, counts, cfg: CollectConfig) -> SwitchCycles:
    """The environment and the per-world cycles of this run, with random streams derived from the seed and the
    file's next chunk index (so a resumed run draws new numbers); the run is recorded in the file's sessions."""
    count, chunk = target.count, target.next_chunk
    env_seed, draw_seed = (int(s) for s in np.random.SeedSequence([cfg.seed, chunk]).generate_state(2))
    env_cfg = shared.env_config(
        EnvConfig(
            episode_seconds=_EPISODE_SECONDS,
            pushes=PushConfig(max_force=cfg.push_max, interval=cfg.push_interval_s),
        )
    )
    env = ImitationEnv(sim, [e.clip for e in entries], env_cfg, seed=env_seed)
    target.record_session(
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
    gaits = list(header.gaits)
    return SwitchCycles(
        env,
        [e.policy.to(env.device) for e in entries],
        pairs=[(gaits.index(m), gaits.index(n)) for m, n in pairs],
        counts=counts[..., 1],
        cfg=cfg,
        latent_dim=header.latent_dim,
        seed=draw_seed,
        first_chunk=chunk,
    )


def _write_until_done(output, target, run: SwitchCycles, counts, gaits, cfg: CollectConfig, progress):
    """Step the cycles, append a chunk whenever a batch of samples is finished, report progress; Ctrl-C writes the
    finished samples still in memory before it propagates."""
    count, written, start = target.count, 0, time.perf_counter()

    def write() -> None:
        nonlocal count, written
        batch = run.take(limit=cfg.samples - count)
        if batch is None:
            return
        np.add.at(counts, (batch.source, batch.dest, 0), batch.success)
        np.add.at(counts, (batch.source, batch.dest, 1), 1)
        count = target.append(batch)
        written += len(batch)

    def report() -> CollectProgress:
        elapsed = time.perf_counter() - start
        return CollectProgress(
            samples=count,
            target=cfg.samples,
            samples_per_s=written / elapsed,
            elapsed_s=elapsed,
            pair_counts=_named(counts, gaits),
            source_falls=run.source_falls,
            steps_per_sample=run.world_steps / max(written, 1),
        )

    try:
        with torch.inference_mode():
            while count < cfg.samples:
                run.step()
                if run.pending >= min(cfg.batch_size, cfg.samples - count):
                    write()
                    if progress is not None:
                        progress(report())
                    if cfg.time_limit_s is not None and time.perf_counter() - start >= cfg.time_limit_s:
                        break
    except KeyboardInterrupt:
        write()  # finished samples still in memory
        raise
    done = report()
    return CollectResult(
        output, count, written, done.elapsed_s, done.samples_per_s, done.pair_counts, run.source_falls,
        done.steps_per_sample, target.note,
    )


def _check(cfg: CollectConfig, gaits: tuple[str, ...]) -> list[tuple[str, str]]:
    """Validate the request; returns the ordered pairs to sample."""
    if len(gaits) < 2 or len(set(gaits)) != len(gaits):
        raise GaitlibError(f"need at least two distinct gaits to collect transitions, got {gaits}")
    if cfg.samples < 1 or cfg.num_worlds < 1 or cfg.batch_size < 1:
        raise GaitlibError("samples, num_worlds and batch_size must be positive")
    times = (cfg.horizon_s, cfg.warmup_s, cfg.source_extra_s, cfg.push_max, *cfg.push_interval_s)
    if not all(math.isfinite(t) for t in times):
        raise GaitlibError("horizon, warm-up, extra source time, push_max and push interval must be finite")
    if cfg.horizon_s <= 0 or cfg.warmup_s < 0 or cfg.source_extra_s < 0 or cfg.push_max < 0:
        raise GaitlibError("horizon must be positive; warm-up, extra source time and push_max not negative")
    if cfg.pairs is None:
        return list(itertools.permutations(gaits, 2))
    pairs = [tuple(p) for p in cfg.pairs]
    if not pairs:
        raise GaitlibError("no gait pairs to sample")
    for m, n in pairs:
        if m not in gaits or n not in gaits or m == n:
            raise GaitlibError(f"pair {m}->{n}: both gaits must be among {gaits} and differ")
    return list(dict.fromkeys(pairs))


def _pair_counts(committed: dict[str, np.ndarray], num_gaits: int) -> np.ndarray:
    """(G, G, 2) successes and samples per ordered pair of the ``committed`` samples."""
    counts = np.zeros((num_gaits, num_gaits, 2), dtype=np.int64)
    source, dest = committed["source"], committed["dest"]
    np.add.at(counts, (source, dest, 0), committed["success"])
    np.add.at(counts, (source, dest, 1), 1)
    return counts


def _named(counts: np.ndarray, gaits: list[str]) -> dict[tuple[str, str], tuple[int, int]]:
    return {
        (m, n): (int(counts[i, j, 0]), int(counts[i, j, 1]))
        for (i, m), (j, n) in itertools.product(enumerate(gaits), repeat=2)
        if counts[i, j, 1]
    }
