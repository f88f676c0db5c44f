"""Collect transition samples: library policies switched at random moments and phases, outcome after a horizon.

A collection is a sequence of independent **chunks** (:mod:`gaitlib.collection.chunks`): each a fresh environment
of ``num_worlds`` worlds seeded from ``SeedSequence([seed, chunk index])`` and a quota of samples per ordered pair
(equal within one, the extra samples rotating over the pairs from chunk to chunk), so a chunk's samples are a pure
function of (seed, chunk index, quota, settings, library) and chunks run here or on Ray workers
(:mod:`gaitlib.cluster`) with the same result.

Each sample is one switch trial of :mod:`gaitlib.meta.trials`, the protocol the benchmark judges by, made by the
``random`` strategy (switch at once, at a uniform destination phase phi_n), with the collection's protocol
(:meth:`TrialProtocol.collection <gaitlib.meta.TrialProtocol.collection>`):

1. reset (reference state initialization, fresh Table 1 randomization) with the source gait m of an ordered pair
   (m, n): the open pair (quota not all begun) begun least so far (ties broken at random), so every pair gets its
   quota whatever its cycle length;
2. run m's policy for ``warmup_s`` plus a uniform extra time in [0, ``source_extra_s``]; a fall here is counted as
   a source fall and the world starts again at 1 with the same pair (so that the pairs of the samples stay
   uniform however often a source falls);
3. at the switch, record psi_m, phi_m, the explicit state and m's critic value, switch to n at a uniform phi_n (the
   reference re-anchored where the robot stands) and record n's critic value on the new observation;
4. alpha = 0 at a fall within ``horizon_s`` after the end of the switch's control step, 1 if none: the benchmark's
   verdict on the same trial;
5. after a fall, back to 1. After a success the world goes on without a reset (``chain``): n becomes the next
   source, of the least-begun open pair starting from n, unless that pair is more than one batch of worlds ahead
   of the least-begun open pair (then back to 1); the next switch comes after a uniform time in
   [0, ``source_extra_s``]. This is how a robot runs on the meta-controller (one gait after another) and it saves
   the warm-up of most samples.
6. once every quota is begun, free worlds run spare trials of the pairs not yet filled; the first samples of a
   pair to finish are kept, and the chunk ends when every quota is filled.

Episodes are made far longer than any trial, so time-outs never cut a sample. With ``push_max`` > 0 random pushes
(random horizontal direction, 0.1-0.3 s, magnitude uniform in [0, ``push_max``], a quiet time in
``push_interval_s`` between them) hit the robot while the source runs; from the switch on no new push starts (one
under way runs out), so the outcome is decided by the state the switch finds, which is what the transition-net
sees. Each sample records the largest push magnitude of its source run.

This process alone commits the chunks, in chunk order, through :mod:`gaitlib.transitions.writer` (one writer per
file; a kill or Ctrl-C loses the chunks under way, never a committed one); rerunning with the same output file
resumes at the next chunk (the count continues, nothing written is lost or repeated). Nothing is created before
the request is checked.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import torch

from gaitlib.cluster import ClusterConfig, WorkerSpec, run_ordered
from gaitlib.collection.chunks import ChunkTask, ChunkWorker
from gaitlib.envs import EnvConfig
from gaitlib.envs import observations as obs_fn
from gaitlib.errors import GaitlibError
from gaitlib.library.store import Library, LibraryError, PolicySettings
from gaitlib.meta import TrialProtocol
from gaitlib.sim import resolve_backend_name
from gaitlib.transitions import schema
from gaitlib.transitions.writer import open_writer

__all__ = ["CollectConfig", "CollectProgress", "CollectResult", "collect"]


@dataclass(frozen=True, kw_only=True)
class CollectConfig:
    """How samples are drawn and written. Everything but ``samples``, ``num_worlds``, ``chunk``, ``device`` and
    ``time_limit_s`` is stored in the file's settings, and a resumed collection must repeat it. The protocol is
    checked when it is built, the rest when :func:`collect` starts (one-line errors, before any work)."""

    samples: int
    """Samples the file holds when collection ends (a resumed run continues up to this count)."""
    num_worlds: int = 64
    """Parallel worlds."""
    protocol: TrialProtocol = field(default_factory=TrialProtocol.collection)
    """The switch trial: warm-up, extra source time, horizon, push window and timing, chaining."""
    push_max: float = 0.0
    """Largest random push magnitude, N (uniform in [0, push_max]); 0 disables pushes."""
    pairs: tuple[tuple[str, str], ...] | None = None
    """Ordered (source, destination) gait pairs to sample, uniformly; ``None``: every ordered pair of ``gaits``."""
    backend: str = "auto"
    """Simulation backend."""
    device: str | None = None
    """Torch device of the backend (``None``: its default)."""
    seed: int = 0
    """Base seed; each run of a resumed file derives its own streams from it and the file's next chunk index."""
    chunk: int | None = None
    """Samples per chunk (``None``: 16 per world): the unit of work (a fresh environment of ``num_worlds`` worlds,
    every world reset, seeded from ``seed`` and the chunk index), of a commit and of a progress report. Larger
    chunks waste less to the first warm-ups and the idle worlds at the end of each (about 5% at 16 per world); a
    kill or a dead worker loses the chunks under way."""
    time_limit_s: float | None = None
    """Stop after the first write past this much wall-clock time, s (``None``: run until ``samples``); a rerun
    resumes."""

    @property
    def chunk_samples(self) -> int:
        """Samples per chunk (:attr:`chunk`, else 16 per world)."""
        return self.chunk if self.chunk is not None else 16 * self.num_worlds


@dataclass(frozen=True)
class CollectProgress:
    """What the progress display shows after each written chunk."""

    samples: int
    """Samples in the file."""
    target: int
    """Samples the file will hold when done."""
    samples_per_s: float
    """Throughput of this run, samples per wall-clock second (those finished in the chunk under way included)."""
    elapsed_s: float
    """Wall-clock time of this run, s."""
    pair_counts: dict[tuple[str, str], tuple[int, int]]
    """(successes, samples) per ordered pair, over the whole file."""
    source_falls: int
    """Cycles of this run discarded because the source policy fell before the switch."""
    steps_per_sample: float
    """Control steps (summed over worlds) this run took per sample written."""
    under_way: int = 0
    """Samples finished in the chunk under way, not yet in the file (chunks collected in this process; a chunk on
    a Ray worker shows when it is committed). 0: the report of a commit; more: a report from inside a chunk."""

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
    cluster: ClusterConfig | None = None,
) -> CollectResult:
    """Collect transition samples of the library policies of ``gaits`` (``None``: every entry; always stored in the
    library's canonical order) into ``output`` until it holds ``config.samples`` (creating it, or resuming it when
    it exists). Chunks run in this process, or on Ray workers with ``cluster``; either way this process alone
    writes the file, chunk after chunk in order, so the file is the same whoever ran the chunks.

    Raises :class:`~gaitlib.errors.GaitlibError` subclasses with one-line messages: bad settings, missing or
    inconsistent library entries, an ``output`` that is not a matching transition file.
    """
    cfg, output = config, Path(output)
    if not library.root.is_dir():
        raise LibraryError(f"no library at {library.root}")
    names = library.order(gaits)
    pairs = _check(cfg, names)
    shared = library.shared_policy_settings(names)
    header = _header(library, names, pairs, cfg, shared)
    with open_writer(output, header=header) as target:
        counts = _pair_counts(target.committed, len(names))
        if target.count >= cfg.samples:
            return CollectResult(output, target.count, 0, 0.0, 0.0, _named(counts, names), 0, 0.0, target.note)
        tasks = _plan(target.count, target.next_chunk, cfg, len(pairs))
        target.record_session(
            {
                "first_chunk": target.next_chunk,
                "samples_at_start": target.count,
                "chunk_seeds": f"numpy.random.SeedSequence([{cfg.seed}, chunk]).generate_state(4): env, source "
                "times, pair choice, destination phase",
                "chunk_samples": cfg.chunk_samples,
                "num_worlds": cfg.num_worlds,
                "ray": cluster is not None,
                "torch": torch.__version__,
                "started": datetime.now(UTC).isoformat(timespec="seconds"),
            },
        )
        if cluster is not None:
            cluster = cluster.for_backend(header.settings["backend"], cfg.device)
        worker = {
            "library": str(library.root), "header": header, "protocol": cfg.protocol, "push_max": cfg.push_max,
            "num_worlds": cfg.num_worlds, "seed": cfg.seed, "device": cfg.device,
        }
        return _write_until_done(output, target, tasks, worker, counts, names, cfg, cluster, progress)


def _header(
    library: Library, gaits: tuple[str, ...], pairs: list[tuple[str, str]], cfg: CollectConfig, shared: PolicySettings
) -> schema.TransitionHeader:
    """What the file records of the policies and settings (a resumed run must repeat them)."""
    p = cfg.protocol
    settings = {
        "horizon_s": p.horizon_s,
        "horizon_from": "the end of the switch's control step (the benchmark's verdict)",
        "warmup_s": p.warmup_s,
        "source_extra_s": p.source_extra_s,
        "push_max_n": cfg.push_max,
        "push_duration_s": list(p.push_duration_s),
        "push_interval_s": list(p.push_interval_s),
        "pushes_during": "source run only (none starts after the switch); push_force: largest of the source run"
        if p.push_window == "source"
        else f"from {p.push_lead_s:g} s before the request to {p.deadline_s:g} s after it; push_force: largest of "
        "the source run",
        "pairs": [list(p) for p in pairs],
        "pair_choice": "per chunk a quota per ordered pair (equal within one, the extra rotating over chunks); "
        "least-begun open pair at each reset, ties at random; phase_dest uniform in [0, 1)",
        "chain": p.chain,
        "backend": resolve_backend_name(cfg.backend),
        "seed": cfg.seed,
        "randomization": dataclasses.asdict(shared.env_config(EnvConfig()).randomization),
        "action": shared.action,
        "observation": obs_fn.layout(shared.observation),
    }
    identities = tuple(library.identities(gaits).values())
    return schema.TransitionHeader(gaits=gaits, identities=identities, latent_dim=shared.latent_dim, settings=settings)


def _plan(count: int, next_chunk: int, cfg: CollectConfig, num_pairs: int) -> Iterator[ChunkTask]:
    """The chunks that take the file from ``count`` samples to ``cfg.samples``, made as they are asked for (a run
    with a time limit may ask for few of very many): chunk ``next_chunk`` on, each of
    :meth:`CollectConfig.chunk_samples` samples (the last one fewer), each pair's quota the same within one, the
    extra samples rotating over the pairs from chunk to chunk (so pairs stay within one of each other per chunk)."""
    size = cfg.chunk_samples
    for chunk in itertools.count(next_chunk):
        n = min(size, cfg.samples - count)
        if n <= 0:
            return
        base, extra = divmod(n, num_pairs)
        first = (chunk * extra) % num_pairs
        quota = [base + int((p - first) % num_pairs < extra) for p in range(num_pairs)]
        yield ChunkTask(chunk, tuple(quota))
        count += n


def _write_until_done(output, target, tasks, worker: dict, counts, gaits, cfg: CollectConfig, cluster, progress):
    """Collect the chunks (here or on Ray workers), commit each in chunk order as it comes, report progress (inside
    a chunk too, where it runs here); Ctrl-C stops after the chunk being committed (the chunks under way are
    lost)."""
    count, written, falls, steps, start = target.count, 0, 0, 0, time.perf_counter()

    def report(under_way: int = 0) -> CollectProgress:
        elapsed = time.perf_counter() - start
        return CollectProgress(
            samples=count,
            target=cfg.samples,
            samples_per_s=(written + under_way) / elapsed,
            elapsed_s=elapsed,
            pair_counts=_named(counts, gaits),
            source_falls=falls,
            steps_per_sample=steps / max(written, 1),
            under_way=under_way,
        )

    if cluster is None and progress is not None:
        worker = worker | {"report": lambda under_way: progress(report(under_way))}
    results = run_ordered(tasks, spec=WorkerSpec(ChunkWorker, worker), cluster=cluster)
    try:
        for _, chunk in results:
            batch = chunk.batch
            np.add.at(counts, (batch.source, batch.dest, 0), batch.success)
            np.add.at(counts, (batch.source, batch.dest, 1), 1)
            count = target.append(batch)
            written, falls, steps = written + len(batch), falls + chunk.source_falls, steps + chunk.world_steps
            if progress is not None:
                progress(report())
            if cfg.time_limit_s is not None and time.perf_counter() - start >= cfg.time_limit_s:
                break
    finally:
        results.close()
    done = report()
    return CollectResult(
        output, count, written, done.elapsed_s, done.samples_per_s, done.pair_counts, falls,
        done.steps_per_sample, target.note,
    )


def _check(cfg: CollectConfig, gaits: tuple[str, ...]) -> list[tuple[str, str]]:
    """Validate the request; returns the ordered pairs to sample."""
    if len(gaits) < 2 or len(set(gaits)) != len(gaits):
        raise GaitlibError(f"need at least two distinct gaits to collect transitions, got {gaits}")
    if cfg.samples < 1 or cfg.num_worlds < 1 or cfg.chunk_samples < 1:
        raise GaitlibError("samples, num_worlds and chunk must be positive")
    if not (math.isfinite(cfg.push_max) and cfg.push_max >= 0):
        raise GaitlibError("push_max must be finite and not negative")
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
