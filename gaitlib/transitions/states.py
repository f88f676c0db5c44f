"""Recording handover states (:mod:`gaitlib.envs.handover`) of a library's gaits as they really run: each gait's
policy drives its worlds under paper Table 1 randomization (and random pushes, if asked), and after a warm-up each
world is snapshot at random moments, about every :attr:`StatesConfig.spacing_s`, so that the states cover every
phase of the cycle; a world that falls starts afresh (its next snapshot after a new warm-up)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import torch

from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs.handover import ARRAYS, HandoverStates
from gaitlib.envs.randomization import DISTURBANCE_INTERVAL_S, PushConfig
from gaitlib.errors import GaitlibError
from gaitlib.library.policy import per_gait
from gaitlib.library.store import Library
from gaitlib.sim import make_backend, resolve_backend_name

__all__ = ["StatesConfig", "record_states"]


@dataclass(frozen=True, kw_only=True)
class StatesConfig:
    """How handover states are recorded."""

    per_gait: int = 20_000
    """States of each gait."""
    push_max: float = 0.0
    """Largest random push while the gaits run, N (0: none; direction random, 0.1-0.3 s every 1-3 s)."""
    num_worlds: int = 256
    """Parallel worlds (the gaits spread over them)."""
    warmup_s: float = 1.0
    """Time a world runs after a reset before its first snapshot, s (the transition collection's warm-up)."""
    spacing_s: float = 0.5
    """Mean time between two snapshots of one world, s (each control step snapshots with probability dt /
    spacing_s, so snapshots fall at every phase)."""
    backend: str = "auto"
    seed: int = 0


def record_states(
    library: Library,
    *,
    gaits: Sequence[str] | None = None,
    config: StatesConfig,
    progress: Callable[[int, int], None] | None = None,
) -> HandoverStates:
    """Record ``config.per_gait`` handover states of each of ``gaits`` (``None``: every entry) of ``library``;
    ``progress(done, total)`` after each control step that recorded some."""
    cfg = config
    names = library.order(gaits)
    if cfg.per_gait < 1 or cfg.num_worlds < 1 or not (cfg.spacing_s > 0 and cfg.warmup_s >= 0 and cfg.push_max >= 0):
        raise GaitlibError("states need per_gait and worlds >= 1, a positive spacing, no negative warm-up or push")
    entries, shared = library.entries(names), library.shared_policy_settings(names)
    pushes = PushConfig(max_force=cfg.push_max, interval=DISTURBANCE_INTERVAL_S)
    env_cfg = shared.env_config(EnvConfig(episode_seconds=1e6, pushes=pushes))
    backend = resolve_backend_name(cfg.backend)
    sim = make_backend(backend, num_worlds=cfg.num_worlds)
    gen = torch.Generator().manual_seed(cfg.seed)
    try:
        env = ImitationEnv(sim, [e.clip for e in entries], env_cfg, seed=cfg.seed)
        dev, n, g = env.device, env.num_envs, len(names)
        env.reset_worlds(torch.arange(n, device=dev), gait=torch.arange(n, device=dev) % g)
        policies = [e.policy.to(dev) for e in entries]
        warmup, chance = round(cfg.warmup_s / env.dt), env.dt / cfg.spacing_s
        counts, parts = np.zeros(g, dtype=np.int64), []
        with torch.inference_mode():
            while counts.min() < cfg.per_gait:
                env.step(per_gait(policies, env.gait, env.get_observations()))
                due = (env.episode_length_buf >= warmup) & (torch.rand(n, generator=gen) < chance).to(dev)
                open_gait = torch.as_tensor(counts < cfg.per_gait, device=dev)[env.gait]
                ids = (due & open_gait).nonzero().squeeze(1)
                if len(ids):
                    rows = {k: v.cpu().numpy() for k, v in env.handover_states(ids).items()}
                    rows["source"] = rows["source"].astype(np.int64)
                    keep = _quota(rows["source"], counts, cfg.per_gait)
                    parts.append({k: v[keep] for k, v in rows.items()})
                    if progress is not None:
                        progress(int(counts.sum()), g * cfg.per_gait)
                full = torch.as_tensor(counts >= cfg.per_gait, device=dev)[env.gait]
                if full.any() and (counts < cfg.per_gait).any():  # worlds of a finished gait run an open one
                    moved = full.nonzero().squeeze(1)
                    open_ids = torch.as_tensor(np.flatnonzero(counts < cfg.per_gait), device=dev)
                    env.reset_worlds(moved, gait=open_ids[torch.arange(len(moved), device=dev) % len(open_ids)])
    finally:
        sim.close()
    settings = dataclasses.asdict(cfg) | {
        "backend": backend,
        "push_interval_s": list(pushes.interval),
        "randomization": dataclasses.asdict(env_cfg.randomization),
        "recorded": "the state after a control step of the gait's own policy, its history as that policy read it",
    }
    arrays = {name: np.concatenate([p[name] for p in parts]) for name in ARRAYS}
    order = np.argsort(arrays["source"], kind="stable")
    return HandoverStates(
        gaits=names,
        identities=library.identities(names),
        settings=settings,
        **{name: values[order] for name, values in arrays.items()},
    )


def _quota(source: np.ndarray, counts: np.ndarray, per_gait: int) -> np.ndarray:
    """Indices of the new states ``source`` (gait per state) that fit under each gait's quota; ``counts`` is updated."""
    keep = []
    for row, gait in enumerate(source):
        if counts[gait] < per_gait:
            counts[gait] += 1
            keep.append(row)
    return np.asarray(keep, dtype=np.int64)
