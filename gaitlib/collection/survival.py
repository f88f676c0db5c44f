"""Recording the states the survival estimate (:mod:`gaitlib.strategies.survival`) is fitted on.

Each episode runs one world of a library's gaits (drawn uniformly) for ``settle_s``; a share ``switch_share`` of
them switches before that to another gait (at a uniform moment from 0.3 s on), so that the states of a gait just
switched into are recorded too: at the destination phase the calibrated transition-net scores best, as the
meta-controller switches (``switch_phase="best"``), or at a uniform one (``"uniform"``). Then, at a uniform moment
of the next second, one horizontal shove of ``duration_s`` hits the trunk in a uniformly random direction (relative
to the heading), of an impulse uniform in [0, ``impulse_max_ns``] (exactly 0 in a share ``calm_share`` of the
episodes: what false alarms are counted on), as ``gaitlib eval --impulses`` shoves; the episode runs ``after_s``
more. A fall is any termination before the end by the definition ``falls`` (heading drift is no fall, as in ``eval
--impulses``).

Every control step from ``record_from_s`` on, each world that is up and keeps its gait from then on records: its
gait, phase, actor latent psi_m, critic value, explicit state, trunk acceleration (what an IMU reads,
:attr:`~gaitlib.envs.ImitationEnv.trunk_acceleration`), and what switching now would offer (the calibrated
transition-net's best destination phase for every other gait, :meth:`LookaheadStrategy.offers`), with the time, the
shove's start and impulse, the episode's end and the time of its fall (inf: none).

The file (HDF5) is written atomically after each batch of ``num_worlds`` episodes; asked for more episodes, a file
recorded with the same library and settings resumes (batch b always runs with seed ``seed + b``), so a kill loses at
most the batch under way.
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from gaitlib.atomic import write_bytes
from gaitlib.defaults import DEFAULT_FALLS, Falls
from gaitlib.envs import EnvConfig
from gaitlib.envs.randomization import PushConfig
from gaitlib.envs.terminations import TerminationConfig
from gaitlib.errors import GaitlibError
from gaitlib.library.policy import per_gait
from gaitlib.meta.setup import SwitchingSetup
from gaitlib.rotations import yaw_of
from gaitlib.sim import make_backend
from gaitlib.strategies import get_strategy, phase_grid
from gaitlib.transitions.explicit import explicit_state

__all__ = ["SWITCH_PHASES", "SurvivalRecording", "read_survival_states", "record_survival"]

_FORMAT = "gaitlib.survival_states"
_COLUMNS = ("episode", "gait", "phase", "latent", "value", "explicit", "imu", "offer", "time_s", "shove_s",
            "impulse_ns", "end_s", "fall_s", "switched")
SWITCH_PHASES = ("best", "uniform")
"""How a recorded switch's destination phase is chosen (:attr:`SurvivalRecording.switch_phase`)."""
_ADDED = ("imu",)
"""Columns that files recorded before them lack: such a file is read (an estimate needing them is refused on it),
not resumed."""


@dataclass(frozen=True, kw_only=True)
class SurvivalRecording:
    """How survival states are recorded (module doc)."""

    episodes: int = 1024
    num_worlds: int = 256
    """Episodes run at once (one world each)."""
    impulse_max_ns: float = 30.0
    """Largest shove, N s."""
    calm_share: float = 0.25
    """Share of episodes not shoved."""
    switch_share: float = 0.25
    """Share of episodes that switch gaits before the shove."""
    switch_phase: str = "best"
    """Destination phase of those switches: ``best`` (the calibrated net's, as the meta-controller switches) or
    ``uniform``."""
    duration_s: float = 0.1
    """The shove's duration, s."""
    settle_s: float = 1.0
    """Time before the shove's window (a second) opens, s."""
    after_s: float = 3.0
    """Time the episode runs after that window, s."""
    record_from_s: float = 0.5
    """States are recorded from this time on, s."""
    falls: Falls = DEFAULT_FALLS
    """The definition of a fall the record counts."""
    backend: str = "mujoco"
    seed: int = 0

    def __post_init__(self) -> None:
        shares = (self.calm_share, self.switch_share)
        if self.episodes < 1 or self.num_worlds < 1 or not all(0 <= s <= 1 for s in shares):
            raise GaitlibError("episodes and worlds must be at least 1, the calm and switch shares in [0, 1]")
        if self.switch_phase not in SWITCH_PHASES:
            raise GaitlibError(f"the switches' destination phase must be one of {', '.join(SWITCH_PHASES)}, not "
                               f"'{self.switch_phase}'")
        times = (self.impulse_max_ns, self.duration_s, self.settle_s, self.after_s, self.record_from_s)
        if not all(math.isfinite(t) and t >= 0 for t in times) or self.duration_s <= 0 or self.settle_s < 0.3:
            raise GaitlibError("the shove's impulse and times must be finite and not negative, its duration "
                               "positive, the settling time at least 0.3 s")

    def settings(self) -> dict:
        """What a resumed file must have been recorded with (everything but the number of episodes)."""
        return {k: v for k, v in dataclasses.asdict(self).items() if k != "episodes"}


def record_survival(path: Path, setup: SwitchingSetup, config: SurvivalRecording, *,
                    progress: Callable[[int, int], None] | None = None) -> dict[str, np.ndarray]:
    """Record ``config.episodes`` episodes of ``setup``'s library into ``path`` (resuming a file of the same
    library and settings); returns every recorded state."""
    identities = setup.resources.library.identities(setup.gaits)
    header = {"format": _FORMAT, "gaits": list(setup.gaits), "identities": identities,
              "settings": config.settings()}
    data: dict[str, np.ndarray] = {}
    if Path(path).is_file():
        found, data = _read(Path(path))
        if {k: found.get(k) for k in header} != header:
            raise GaitlibError(f"{path} was recorded with another library or other settings; record into a new file")
        if missing := [c for c in _ADDED if c not in data]:
            raise GaitlibError(f"{path} was recorded before its {', '.join(missing)} column existed; record into a new "
                               "file")
    batches = math.ceil(config.episodes / config.num_worlds)
    done = len(np.unique(data["episode"])) if data else 0
    for b in range(math.ceil(done / config.num_worlds), batches):
        k = min(config.num_worlds, config.episodes - b * config.num_worlds)
        new = _batch(setup, config, k, seed=config.seed + b, first_episode=b * config.num_worlds)
        header["dt"] = float(new.pop("dt"))
        data = {c: np.concatenate([data[c], new[c]]) if data else new[c] for c in _COLUMNS}
        _write(Path(path), header, data)
        if progress is not None:
            progress(min(config.episodes, (b + 1) * config.num_worlds), config.episodes)
    return data


def read_survival_states(path: Path) -> tuple[dict, dict[str, np.ndarray]]:
    """(header, columns) of a recorded file; one line if it is not one."""
    return _read(Path(path))


def _batch(setup: SwitchingSetup, config: SurvivalRecording, k: int, *, seed: int, first_episode: int) -> dict:
    g = len(setup.gaits)
    seconds = config.settle_s + 1.0 + config.duration_s + config.after_s
    sim = make_backend(config.backend, num_worlds=k)
    try:
        cfg = EnvConfig(episode_seconds=seconds, pushes=PushConfig(max_force=0.0),
                        termination=TerminationConfig().counting(config.falls, heading=False))
        env = setup.make_env(sim, cfg, seed=seed)
        dev, dt = env.device, env.dt
        gen = torch.Generator().manual_seed(seed)
        env.reset_worlds(torch.arange(k, device=dev), gait=torch.randint(g, (k,), generator=gen).to(dev))
        policies = [e.policy.to(dev) for e in setup.entries]
        scorer = get_strategy("net-lookahead", setup.resources)
        candidates = phase_grid(device=dev)
        switching = torch.rand(k, generator=gen) < config.switch_share
        settle = round(config.settle_s / dt)
        switch_at = torch.where(switching, torch.randint(round(0.3 / dt), settle + 1, (k,), generator=gen), -1)
        switch_to = (env.gait.cpu() + torch.randint(1, g, (k,), generator=gen)) % g
        switch_phase = torch.rand(k, generator=gen)
        start = settle + torch.randint(round(1.0 / dt), (k,), generator=gen)
        length = max(1, round(config.duration_s / dt))
        impulse = torch.rand(k, generator=gen) * config.impulse_max_ns
        impulse[torch.rand(k, generator=gen) < config.calm_share] = 0.0
        angle = 2 * math.pi * torch.rand(k, generator=gen)
        alive = torch.ones(k, dtype=torch.bool, device=dev)
        fall_step = torch.full((k,), -1, dtype=torch.long)
        rows: list[dict] = []
        first = round(config.record_from_s / dt)
        with torch.inference_mode():
            for step in range(env.max_episode_length):
                now = (switch_at == step).to(dev) & alive
                if now.any():
                    ids = now.nonzero().squeeze(1)
                    dest, phase = switch_to.to(dev)[ids], switch_phase.to(dev)[ids]
                    if config.switch_phase == "best":
                        gait = env.gait[ids]
                        latent = per_gait(policies, gait, env.get_observations()[ids], method="latent")
                        _, best = scorer.offers(gait, latent, env.phase[ids], candidates, g)
                        phase = best.to(dev)[torch.arange(len(ids), device=dev), dest]
                    env.switch(ids, dest, phase)
                begins, ends = (start == step).to(dev) & alive, (start + length == step).to(dev) & alive
                if begins.any():
                    ids = begins.nonzero().squeeze(1)
                    heading = yaw_of(env.sim_state.root_quat[ids]) + angle.to(dev)[ids]
                    force = (impulse.to(dev)[ids] / (length * dt)).unsqueeze(1)
                    push = torch.stack([torch.cos(heading), torch.sin(heading), torch.zeros_like(heading)], 1)
                    env.backend.set_trunk_force(ids, force * push)
                if ends.any():
                    ids = ends.nonzero().squeeze(1)
                    env.backend.set_trunk_force(ids, torch.zeros(len(ids), 3, device=dev))
                obs = env.get_observations()
                kept = alive & (step > switch_at).to(dev)  # keeps its gait from now on
                if step >= first and kept.any():
                    ids = kept.nonzero().squeeze(1)
                    rows.append(_states(env, policies, scorer, candidates, ids, obs[ids], step))
                _, _, dones, extras = env.step(per_gait(policies, env.gait, obs))
                fell = (dones & ~extras["time_outs"] & alive).cpu()
                fall_step[fell] = step + 1
                alive &= ~dones
    finally:
        sim.close()
    out = {c: np.concatenate([r[c] for r in rows]) for c in rows[0]}
    world = out.pop("world")
    out["episode"] = world + first_episode
    out["shove_s"] = (start.numpy() * dt)[world]
    out["impulse_ns"] = impulse.numpy()[world]
    out["end_s"] = np.full(len(world), env.max_episode_length * dt)
    out["fall_s"] = np.where(fall_step.numpy() >= 0, fall_step.numpy() * dt, np.inf)[world]
    out["switched"] = switching.numpy()[world]
    order = np.lexsort((out["time_s"], out["episode"]))
    out = {c: v[order] for c, v in out.items()}
    out["dt"] = dt
    return out


def _states(env, policies, scorer, candidates, ids: torch.Tensor, obs, step: int) -> dict[str, np.ndarray]:
    gait, phase = env.gait[ids], env.phase[ids]
    latent = per_gait(policies, gait, obs, method="latent")
    offer, _ = scorer.offers(gait, latent, phase, candidates, len(env.clips))
    return {
        "world": ids.cpu().numpy(), "gait": gait.cpu().numpy(), "phase": phase.cpu().numpy().astype(np.float32),
        "latent": latent.cpu().numpy().astype(np.float32),
        "value": per_gait(policies, gait, obs, method="value").reshape(-1).cpu().numpy().astype(np.float32),
        "explicit": explicit_state(obs.policy).cpu().numpy().astype(np.float32),
        "imu": env.trunk_acceleration[ids].cpu().numpy().astype(np.float32),
        "offer": offer.cpu().numpy().astype(np.float32), "time_s": np.full(len(ids), step * env.dt),
    }


def _write(path: Path, header: dict, data: dict[str, np.ndarray]) -> None:
    import h5py

    buffer = io.BytesIO()  # made in memory, written by Python: a full disk is one OSError, HDF5 holds no failed file
    with h5py.File(buffer, "w") as f:
        f.attrs["header"] = json.dumps(header)
        for name in _COLUMNS:
            f.create_dataset(name, data=data[name], compression="gzip", compression_opts=1)
    write_bytes(path, buffer.getvalue())


def _read(path: Path) -> tuple[dict, dict[str, np.ndarray]]:
    import h5py

    try:
        with h5py.File(path, "r") as f:
            header = json.loads(f.attrs["header"])
            data = {name: f[name][()] for name in _COLUMNS if name in f or name not in _ADDED}
    except Exception as error:  # h5py and json raise several unrelated types for a foreign file
        raise GaitlibError(f"{path} is not a recorded survival-state file ({type(error).__name__})") from error
    if header.get("format") != _FORMAT or len({len(v) for v in data.values()}) != 1:
        raise GaitlibError(f"{path} is not a recorded survival-state file")
    _check_values(path, header, data)
    return header, data


_FINITE = ("phase", "latent", "value", "explicit", "imu", "time_s", "shove_s", "impulse_ns", "end_s")
"""Columns every number of which is finite (``fall_s`` is infinite where the episode never fell; ``offer`` is nan
where nothing is offered: the gait that runs)."""


def _check_values(path: Path, header: dict, data: dict[str, np.ndarray]) -> None:
    """Refuse, in one line naming the column and the first row, a file whose values no recording writes: a number
    that is not finite where every one is, a gait index outside the header's gaits, an offer outside [0, 1], a fall
    that is nan or before the start, a control period that is not a positive number."""
    gaits = header.get("gaits")
    dt = header.get("dt")
    if not isinstance(gaits, list) or not isinstance(dt, float) or not (math.isfinite(dt) and dt > 0):
        raise GaitlibError(f"{path} is not a recorded survival-state file (its header's gaits or control period)")
    shapes = {"offer": (len(gaits),), "imu": (3,), "latent": data["latent"].shape[1:2]}
    if any(data[name].shape[1:] != shape for name, shape in shapes.items() if name in data) or any(
            data[name].ndim != 1 for name in _COLUMNS if name not in ("latent", "explicit", "imu", "offer")):
        raise GaitlibError(f"{path} is not a recorded survival-state file (a column of another shape)")
    with np.errstate(invalid="ignore"):
        bad = {name: ~np.isfinite(data[name]) for name in _FINITE if name in data}
        bad["gait"] = (data["gait"] < 0) | (data["gait"] >= len(gaits)) | (data["gait"] != np.floor(data["gait"]))
        bad["episode"] = data["episode"] < 0
        bad["fall_s"] = np.isnan(data["fall_s"]) | (data["fall_s"] < 0)
        bad["offer"] = ~np.isnan(data["offer"]) & ~((data["offer"] >= 0) & (data["offer"] <= 1))
    for name, wrong in bad.items():
        if wrong.any():
            where = tuple(int(i) for i in np.argwhere(wrong)[0])
            at = f"row {where[0]}" + (f", column {where[1]}" if len(where) > 1 else "")
            raise GaitlibError(f"{path} holds {name} {data[name][where].item()!r} at {at}, which no recording "
                               "writes (a number that is not finite, or out of range): refused; record the states "
                               "again")
