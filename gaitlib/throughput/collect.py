"""Collection throughput: transition samples per second against what the environment step allows, measured in the
same run.

The reference is a plain policy rollout of the same library policies in the same environment (same worlds, gaits
spread over them, pushes as in the collection): its control steps per second, divided by the control steps the
collection spends per sample (warm-ups, source runs, horizons and the cycles lost to source falls, counted by the
collector itself), is the sample rate the environment step allows. The reference is timed before and after the
collection and averaged, so a drift of machine speed hits both sides alike.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import torch

from gaitlib.collection import CollectConfig, collect
from gaitlib.envs import EnvConfig
from gaitlib.envs.randomization import DISTURBANCE_INTERVAL_S, PushConfig
from gaitlib.library import Library
from gaitlib.library.policy import per_gait
from gaitlib.meta import load_switching
from gaitlib.sim import make_backend

__all__ = ["CollectThroughput", "measure_collect_throughput"]


@dataclass(frozen=True)
class CollectThroughput:
    """Samples per second of ``gaitlib collect`` and of what the environment step allows."""

    worlds: int
    seconds: float
    """Wall-clock time given to each measurement, s."""
    push_max: float
    """Largest push of the collection, N."""
    env_steps_per_s: float
    """Reference: control steps per second (all worlds) of a plain policy rollout."""
    samples_per_s: float
    """Samples per second the collector wrote."""
    steps_per_sample: float
    """Control steps (all worlds) the collector spent per sample."""
    allowed_samples_per_s: float
    """env_steps_per_s / steps_per_sample."""
    ratio: float
    """samples_per_s / allowed_samples_per_s (goal: >= 0.8)."""

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def measure_collect_throughput(
    library: Library, *, worlds: int, seconds: float, push_max: float, chunk: int | None = None, backend: str = "mujoco"
) -> CollectThroughput:
    """Time the reference rollout, a collection, and the reference again, ``seconds`` each (the collection runs
    whole chunks of ``chunk`` samples, by default collect's 16 per world, so it may take longer: about 70 s at 256
    worlds on a 2-core CPU)."""
    setup = load_switching(library)
    reference = [_rollout_steps_per_s(setup, worlds, seconds, push_max, backend)]
    with tempfile.TemporaryDirectory() as scratch:
        config = CollectConfig(  # default chunks (their fresh warm-ups count): it stops after the first past seconds
            samples=10**9,
            num_worlds=worlds,
            push_max=push_max,
            backend=backend,
            chunk=chunk,
            time_limit_s=seconds,
        )
        result = collect(Path(scratch) / "throughput.h5", library=library, config=config)
    reference.append(_rollout_steps_per_s(setup, worlds, seconds, push_max, backend))
    env_rate = sum(reference) / len(reference)
    allowed = env_rate / result.steps_per_sample
    return CollectThroughput(
        worlds=worlds,
        seconds=seconds,
        push_max=push_max,
        env_steps_per_s=env_rate,
        samples_per_s=result.samples_per_s,
        steps_per_sample=result.steps_per_sample,
        allowed_samples_per_s=allowed,
        ratio=result.samples_per_s / allowed,
    )


def _rollout_steps_per_s(setup, worlds: int, seconds: float, push_max: float, backend: str) -> float:
    sim = make_backend(backend, num_worlds=worlds)
    try:
        cfg = EnvConfig(episode_seconds=1e6, pushes=PushConfig(max_force=push_max, interval=DISTURBANCE_INTERVAL_S))
        env = setup.make_env(sim, cfg, seed=0)
        gaits = torch.arange(worlds, device=env.device) % len(setup.gaits)
        env.reset_worlds(torch.arange(worlds, device=env.device), gait=gaits)
        policies = [e.policy.to(env.device) for e in setup.entries]
        steps = 0
        with torch.inference_mode():
            start = time.perf_counter()
            while time.perf_counter() - start < seconds:
                env.step(per_gait(policies, gaits, env.get_observations()))
                steps += 1
            elapsed = time.perf_counter() - start
        return steps * worlds / elapsed
    finally:
        sim.close()
