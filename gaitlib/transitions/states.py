"""Recording handover states (:mod:`gaitlib.envs.handover`) of a library's gaits as they really run: each gait's
policy drives its worlds under paper Table 1 randomization (and random pushes, if asked), and after a warm-up each
world is snapshot at random moments, about every :attr:`StatesConfig.spacing_s`, so that the states cover every
phase of the cycle; a world that falls starts afresh (its next snapshot after a new warm-up).

With single shoves (:attr:`StatesConfig.shove_max_ns`), the states a catch skill is handed instead (``gaitlib train
catch``, :mod:`gaitlib.envs.catch`): at each such random moment one horizontal shove of
:attr:`StatesConfig.shove_s` hits the trunk, in a uniformly random direction, its impulse uniform in [0,
``shove_max_ns``] (exactly 0, no shove, in a share :attr:`StatesConfig.calm_share`), as ``gaitlib survival record``
and ``eval --impulses`` shove; the world is snapshot a uniform 1-3 control steps into it (the guard's moment), with
the push still under way (:data:`~gaitlib.envs.handover.PUSH_ARRAYS`), then starts afresh."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import torch

from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.envs.handover import ARRAYS, PUSH_ARRAYS, HandoverStates
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
    shove_max_ns: float = 0.0
    """Largest single shove, N s (0: none, snapshots at random moments; the module doc)."""
    shove_s: float = 0.1
    """A single shove's duration, s (``gaitlib survival record``'s)."""
    shove_steps: tuple[int, int] = (1, 3)
    """A shoved world is snapshot this many control steps into its shove, uniform in the range (inclusive): the
    guard catches 1-3 control steps after a shove begins (``gaitlib survival catches --delay``, 2 by default)."""
    calm_share: float = 0.25
    """With shoves, the share of snapshots taken unshoved (the survival recording's share of unshoved episodes)."""
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
    low, high = cfg.shove_steps
    if not (cfg.shove_max_ns >= 0 and cfg.shove_s > 0 and 1 <= low <= high and 0 <= cfg.calm_share <= 1):
        raise GaitlibError("single shoves need an impulse >= 0 N s, a positive duration, 1 <= the first step into it "
                           "<= the last, a calm share in [0, 1]")
    if cfg.shove_max_ns > 0 and cfg.push_max > 0:
        raise GaitlibError("states are recorded under random pushes (--push-max) or single shoves (--shove-max), not "
                           "both")
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
        shoves = _Shoves(cfg, n, env.dt, gen) if cfg.shove_max_ns > 0 else None
        with torch.inference_mode():
            while counts.min() < cfg.per_gait:
                _, _, dones, _ = env.step(per_gait(policies, env.gait, env.get_observations()))
                due = (env.episode_length_buf >= warmup) & (torch.rand(n, generator=gen) < chance).to(dev)
                open_gait = torch.as_tensor(counts < cfg.per_gait, device=dev)[env.gait]
                ids = (due & open_gait).nonzero().squeeze(1) if shoves is None else shoves.step(env, due & open_gait,
                                                                                                 dones)
                if len(ids):
                    rows = env.handover_states(ids) | (env.push_under_way(ids) if shoves is not None else {})
                    rows = {k: v.cpu().numpy() for k, v in rows.items()}
                    if shoves is not None:
                        env.reset_worlds(ids)  # one shove an episode: the next after a fresh warm-up
                    rows["source"] = rows["source"].astype(np.int64)
                    keep = _quota(rows["source"], counts, cfg.per_gait)
                    parts.append({k: v[keep] for k, v in rows.items()})
                    if progress is not None:
                        progress(int(counts.sum()), g * cfg.per_gait)
                full = torch.as_tensor(counts >= cfg.per_gait, device=dev)[env.gait]
                if full.any() and (counts < cfg.per_gait).any():  # worlds of a finished gait run an open one
                    moved = full.nonzero().squeeze(1)
                    if shoves is not None:
                        shoves.steps_in[moved.cpu()] = -1  # a shove under way ends with the reset
                    open_ids = torch.as_tensor(np.flatnonzero(counts < cfg.per_gait), device=dev)
                    env.reset_worlds(moved, gait=open_ids[torch.arange(len(moved), device=dev) % len(open_ids)])
    finally:
        sim.close()
    shove_keys = ("shove_max_ns", "shove_s", "shove_steps", "calm_share")  # recorded with shoves only: a file
    # recorded without them keeps the bytes it had before they existed
    settings = {k: v for k, v in dataclasses.asdict(cfg).items() if shoves or k not in shove_keys} | {
        "backend": backend,
        "push_interval_s": list(pushes.interval),
        "randomization": dataclasses.asdict(env_cfg.randomization),
        "recorded": "the state after a control step of the gait's own policy, its history as that policy read it"
        + (", 1-3 control steps into a single shove, the push under way" if shoves else ""),
    }
    arrays = {name: np.concatenate([p[name] for p in parts]) for name in ARRAYS + (PUSH_ARRAYS if shoves else ())}
    order = np.argsort(arrays["source"], kind="stable")
    return HandoverStates(
        gaits=names,
        identities=library.identities(names),
        settings=settings,
        **{name: values[order] for name, values in arrays.items()},
    )


class _Shoves:
    """The single shoves of a recording (module doc): which world is how many control steps into its shove, and at
    which step into it it is snapshot."""

    def __init__(self, cfg: StatesConfig, num_worlds: int, dt: float, gen: torch.Generator) -> None:
        self.cfg, self.gen = cfg, gen
        self.length = max(1, round(cfg.shove_s / dt))
        """The shove's duration, control steps."""
        self.dt = dt
        self.steps_in = torch.full((num_worlds,), -1, dtype=torch.long)
        """(N,) control steps each world is into its shove (-1: none under way)."""
        self.take = torch.zeros(num_worlds, dtype=torch.long)
        """(N,) the step into its shove at which each shoved world is snapshot."""

    def step(self, env, due: torch.Tensor, dones: torch.Tensor) -> torch.Tensor:
        """After a control step: shove the worlds ``due`` (N,) that are in none, and return the ids of the worlds to
        snapshot now (``dones``: the worlds the step ended, whose shove is over)."""
        self.steps_in[dones.cpu()] = -1
        self.steps_in[self.steps_in >= 0] += 1
        ready = (self.steps_in >= 0) & (self.steps_in == self.take)
        self.steps_in[ready] = -1
        start = (due.cpu() & (self.steps_in < 0) & ~ready).nonzero().squeeze(1)
        if len(start):
            k, cfg = len(start), self.cfg
            impulse = cfg.shove_max_ns * torch.rand(k, generator=self.gen)
            impulse[torch.rand(k, generator=self.gen) < cfg.calm_share] = 0.0
            angle = 2 * torch.pi * torch.rand(k, generator=self.gen)
            force = (impulse / (self.length * self.dt)).unsqueeze(1) * torch.stack(
                [torch.cos(angle), torch.sin(angle), torch.zeros(k)], 1)
            env.shove(start.to(env.device), force, self.length)
            self.steps_in[start] = 0
            low, high = cfg.shove_steps
            self.take[start] = torch.randint(low, high + 1, (k,), generator=self.gen)
        return ready.nonzero().squeeze(1).to(env.device)


def _quota(source: np.ndarray, counts: np.ndarray, per_gait: int) -> np.ndarray:
    """Indices of the new states ``source`` (gait per state) that fit under each gait's quota; ``counts`` is updated."""
    keep = []
    for row, gait in enumerate(source):
        if counts[gait] < per_gait:
            counts[gait] += 1
            keep.append(row)
    return np.asarray(keep, dtype=np.int64)
