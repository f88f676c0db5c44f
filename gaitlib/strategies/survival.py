"""The survival estimate: the probability that a robot stays up over the next ``horizon_s`` if it keeps the gait it
runs, from what the transition-net already sees (the running gait, its actor's latent psi_m, its phase) and, as
candidate inputs, the gait's critic value (which reads the critic's privileged observation: an estimate using it
cannot run on a robot, :mod:`gaitlib.strategies.guard_export`) and the explicit state.

It is fitted on recorded states (:mod:`gaitlib.collection.survival`: single shoves of 0-30 N s in every direction,
switches before them), each labelled "no fall within ``horizon_s``" (a state whose episode ends sooner without a
fall is left out: its label is unknown). Episodes are split three ways, never a state of one episode on two sides:
the model trains on 60% of them, Platt scaling per gait (:func:`gaitlib.strategies.calibration.platt`, as the net is
calibrated) is fitted on 20%, and the horizon and the guard's margin are chosen, and the estimate reported, on the
last 20%. The guard (:mod:`gaitlib.meta.guard`) fires where the best switch the calibrated transition-net offers
beats the estimate by more than the margin; the margin chosen is the smallest of :data:`MARGINS` whose false alarms
on unshoved episodes stay within :data:`FALSE_ALARMS_PER_MIN`, and the horizon the one of those tried that then
warns before the most falls. Given a floor, it also fires where the estimate reads below it, whatever the offers, even
just after a switch its strategy chose; a floor chosen is the highest of :data:`FLOORS` whose false alarms (firings on
unshoved episodes that stay up, switched ones too from their switch on) stay within :data:`FALSE_ALARMS_PER_MIN`.
The estimate is written into the library's switching folder (``switching/survival.pt``) with the identities of the
policies it was recorded with.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from gaitlib.atomic import file_sha256, torch_bytes, write_bytes
from gaitlib.errors import GaitlibError, TransitionDataError
from gaitlib.evaluation import SECTORS, sector_of
from gaitlib.library.layout import check_identities, is_shipped
from gaitlib.library.store import Library
from gaitlib.strategies.calibration import platt
from gaitlib.values import GUARD_HORIZON_S

__all__ = [
    "FALSE_ALARMS_PER_MIN", "FLOORS", "HORIZONS_S", "INPUTS", "MARGINS", "SURVIVAL_FILE", "SurvivalEstimate",
    "SurvivalNet", "check_guard", "fit_survival", "load_survival", "save_catch_table", "save_survival",
    "shove_sector", "survival_features",
]

SURVIVAL_FILE = Library.SURVIVAL
"""The estimate's name in the library's switching folder."""
INPUTS = ("latent", "phase", "value", "explicit", "imu")
"""Inputs the estimate may take, besides the running gait (one-hot): psi_m, the phase as (sin, cos), the critic's
value, the explicit state (66), the trunk's acceleration in its own frame (3, m/s^2, gravity left out: an IMU's
accelerometer; :attr:`ImitationEnv.trunk_acceleration`)."""
HORIZONS_S = (0.5, 1.0, 1.5)
"""Horizons tried by default, s."""
MARGINS = tuple(round(0.05 * k, 2) for k in range(20))
"""Margins tried, in order (0 to 0.95): the guard switches where an offer beats staying by more than this."""
FLOORS = tuple(round(0.05 * k, 2) for k in range(11))
"""Floors tried (0 to 0.5): the guard catches where the estimate reads below the floor (0: never)."""
FALSE_ALARMS_PER_MIN = 0.1
"""Most guard firings per minute of unshoved running the chosen margin may give on the selection split (the goal:
at most one false catch per 10 minutes)."""
_FORMAT = {"format": "gaitlib.survival", "format_version": 1}
_SPLIT = (0.6, 0.2)
"""Shares of episodes the model trains on and the calibration is fitted on; the rest select and report."""


def check_guard(*, horizon_s: float | None = None, margin: float | None = None, floor: float | None = None) -> None:
    """Refuse, in one line, a horizon outside (0, 5] s, or a margin or floor outside [0, 1)."""
    if horizon_s is not None and not 0 < horizon_s <= GUARD_HORIZON_S.high:
        raise GaitlibError(f"the guard's horizon ({horizon_s:g} s) must lie in {GUARD_HORIZON_S.describe()}")
    if margin is not None and not 0 <= margin < 1:
        raise GaitlibError(f"the guard's margin ({margin:g}) must lie in [0, 1)")
    if floor is not None and not 0 <= floor < 1:
        raise GaitlibError(f"the guard's floor ({floor:g}) must lie in [0, 1)")


def survival_features(inputs: tuple[str, ...], gaits: int, *, gait: torch.Tensor, latent: torch.Tensor,
                      phase: torch.Tensor, value: torch.Tensor, explicit: torch.Tensor | None = None,
                      imu: torch.Tensor | None = None) -> torch.Tensor:
    """(k, dim) float32 inputs: one-hot ``gait`` (k,) over ``gaits``, then each of ``inputs`` in :data:`INPUTS`
    order: ``latent`` (k, L), ``phase`` (k,) in cycles as (sin, cos) of 2 pi phase, ``value`` (k,), ``explicit``
    (k, 66), ``imu`` (k, 3) m/s^2."""
    parts = [torch.nn.functional.one_hot(gait.long(), gaits).float()]
    angle = 2 * torch.pi * phase.float()
    given = {"latent": latent.float(), "phase": torch.stack([torch.sin(angle), torch.cos(angle)], -1),
             "value": value.float().reshape(-1, 1), "explicit": explicit, "imu": imu}
    for name in INPUTS:
        if name in inputs:
            if given[name] is None:
                raise TransitionDataError(f"the survival estimate needs '{name}' inputs")
            parts.append(given[name].float().to(parts[0].device))
    return torch.cat(parts, dim=-1)


def shove_sector(acceleration: torch.Tensor) -> torch.Tensor:
    """(k,) index into :data:`~gaitlib.evaluation.SECTORS` of where each trunk is pushed: the direction of the
    horizontal part of its acceleration (k, 3) in its own frame, m/s^2 (an IMU's, gravity left out)."""
    return sector_of(torch.atan2(acceleration[:, 1], acceleration[:, 0]))


class SurvivalNet(torch.nn.Module):
    """MLP over standardized inputs, hidden 64-64 with ReLU, one logit."""

    def __init__(self, dim: int, hidden: tuple[int, ...] = (64, 64)) -> None:
        super().__init__()
        layers: list[torch.nn.Module] = []
        width = dim
        for size in hidden:
            layers += [torch.nn.Linear(width, size), torch.nn.ReLU()]
            width = size
        self.mlp = torch.nn.Sequential(*layers, torch.nn.Linear(width, 1))
        self.register_buffer("mean", torch.zeros(dim))
        self.register_buffer("std", torch.ones(dim))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.mlp((x - self.mean) / self.std).squeeze(-1)


@dataclass
class SurvivalEstimate:
    """A fitted, calibrated survival estimate and the guard settings chosen with it."""

    gaits: tuple[str, ...]
    identities: dict[str, str]
    """Library identity of each gait's policy the states were recorded with."""
    inputs: tuple[str, ...]
    horizon_s: float
    """How far ahead "stays up" looks, s."""
    margin: float
    """How much more (probability) an offered switch must promise than staying for the guard to take it."""
    platt: dict[int, tuple[float, float]]
    """Gait index -> Platt's (a, b) on the model's logit."""
    net: SurvivalNet
    info: dict = field(default_factory=dict)
    """How it was fitted and chosen, its reliability table, lead times and false alarms (JSON-ready)."""
    floor: float = 0.0
    """Below this estimate the guard catches whatever the margin, even just after a switch its strategy chose (0:
    never)."""

    @property
    def armed_from_s(self) -> float:
        """The earliest time of an episode the estimate saw a state of (its recording's first), s: before it, the
        guard does not act (0 for an estimate fitted before this was recorded)."""
        return float(self.info.get("armed_from_s", 0.0))

    @property
    def catch_into(self) -> torch.Tensor | None:
        """(G, len(SECTORS)) long: the gait the guard catches each running gait into, by the sector of
        :data:`~gaitlib.evaluation.SECTORS` its trunk is pushed toward (:func:`shove_sector`); -1 where it is never
        caught (the catch table, ``gaitlib survival catches``). A table that names one gait for a running gait
        catches it there whatever the direction. ``None``: no table, the gait the transition-net offers most."""
        table = self.info.get("catches")
        if table is None:
            return None
        into = torch.full((len(self.gaits), len(SECTORS)), -1, dtype=torch.long)
        for gait, row in table["catch_into"].items():
            for k, sector in enumerate(SECTORS):
                dest = row if isinstance(row, str) else row.get(sector)
                if dest is not None:
                    into[self.gaits.index(gait), k] = self.gaits.index(dest)
        return into

    @torch.inference_mode()
    def probability(self, features: torch.Tensor, gait: torch.Tensor) -> torch.Tensor:
        """(k,) calibrated probability of staying up ``horizon_s`` keeping the gait, from :func:`survival_features`
        ``features`` (k, dim) of worlds running ``gait`` (k,)."""
        self.net.eval()
        z = self.net(features.to(self.net.mean.device)).to(gait.device)
        a, b = torch.ones_like(z), torch.zeros_like(z)
        for g, (pa, pb) in self.platt.items():
            rows = gait == g
            a[rows], b[rows] = pa, pb
        return torch.sigmoid(a * z + b)


def _labels(data: dict[str, np.ndarray], horizon_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(known, stays_up): states whose fate over ``horizon_s`` is known, and whether they stay up."""
    ahead = data["fall_s"] - data["time_s"]
    up = ahead > horizon_s
    known = ~up | (data["end_s"] - data["time_s"] >= horizon_s)
    return known, up


def _split(data: dict[str, np.ndarray], seed: int) -> np.ndarray:
    """(rows,) 0 train, 1 calibrate, 2 select: by episode, drawn with ``seed``."""
    episodes = np.unique(data["episode"])
    order = np.random.default_rng(seed).permutation(len(episodes))
    part = np.empty(len(episodes), dtype=np.int64)
    cut = np.cumsum([round(s * len(episodes)) for s in _SPLIT])
    part[order[: cut[0]]], part[order[cut[0]: cut[1]]], part[order[cut[1]:]] = 0, 1, 2
    return part[np.searchsorted(episodes, data["episode"])]


def _features(data: dict[str, np.ndarray], inputs: tuple[str, ...], gaits: int, rows: np.ndarray) -> torch.Tensor:
    columns = ("gait", "latent", "phase", "value", "explicit", "imu")
    t = {k: torch.from_numpy(data[k][rows]) for k in columns if k in data}
    return survival_features(inputs, gaits, gait=t["gait"], latent=t["latent"], phase=t["phase"],
                             value=t["value"], explicit=t["explicit"], imu=t.get("imu"))


def _train(x: torch.Tensor, y: torch.Tensor, *, epochs: int, seed: int) -> SurvivalNet:
    torch.manual_seed(seed)
    net = SurvivalNet(x.shape[1])
    net.mean.copy_(x.mean(0))
    net.std.copy_(x.std(0, unbiased=False).clamp(min=1e-3))
    optimizer = torch.optim.Adam(net.parameters(), lr=1e-3)
    positives = y.mean().clamp(1e-3, 1 - 1e-3)
    loss_fn = torch.nn.BCEWithLogitsLoss(pos_weight=(1 - positives) / positives)  # falls are rare: weigh them up
    gen = torch.Generator().manual_seed(seed)
    for _ in range(epochs):
        for batch in torch.randperm(len(x), generator=gen).split(1024):
            optimizer.zero_grad()
            loss_fn(net(x[batch]), y[batch]).backward()
            optimizer.step()
    return net.eval()


def _firing(offer: np.ndarray, p: np.ndarray, margin: float) -> np.ndarray:
    """(rows,) bool: some gait's offer beats staying by more than ``margin``."""
    return np.nan_to_num(offer, nan=-np.inf).max(axis=1) - p > margin


def _onsets(fire: np.ndarray, episode: np.ndarray) -> np.ndarray:
    """(rows,) bool: where ``fire`` turns on, rows in episode and time order (a firing the row before, in the same
    episode, is the same alarm)."""
    return fire & ~np.concatenate([[False], fire[:-1] & (episode[1:] == episode[:-1])])


def _judge(data: dict, rows: np.ndarray, p: np.ndarray, margin: float, dt: float) -> dict:
    """The guard's warnings on ``rows`` (in episode, time order) at ``margin``: falls warned before and lead times,
    firings per minute of unshoved running without a switch."""
    fire = _firing(data["offer"][rows], p, margin)
    episode, time_s, fall_s = data["episode"][rows], data["time_s"][rows], data["fall_s"][rows]
    after_shove = time_s >= data["shove_s"][rows]
    leads = []
    for e in np.unique(episode[np.isfinite(fall_s)]):
        here = (episode == e) & after_shove & (time_s < fall_s)
        warned = here & fire
        leads.append(float(fall_s[warned][0] - time_s[warned][0]) if warned.any() else 0.0)
    calm = (data["impulse_ns"][rows] == 0) & ~data["switched"][rows]
    onsets = _onsets(fire, episode) & calm
    minutes = calm.sum() * dt / 60
    leads_a = np.asarray(leads)
    return {
        "margin": margin, "falls": len(leads), "warned": int((leads_a > 0).sum()),
        "lead_median_s": float(np.median(leads_a)) if len(leads) else None,
        "lead_p10_s": float(np.percentile(leads_a, 10)) if len(leads) else None,
        "false_alarms_per_min": float(onsets.sum() / minutes) if minutes > 0 else None,
        "unshoved_minutes": float(minutes),
    }


def _floor(data: dict, rows: np.ndarray, p: np.ndarray, dt: float) -> tuple[float, float]:
    """(floor, its false alarms per unshoved minute): the highest of :data:`FLOORS` whose onsets of ``p`` below it
    on the states of ``rows`` (in episode, time order) of unshoved episodes that stay up (a switch may fell one:
    a firing before that fall is no false alarm) stay within :data:`FALSE_ALARMS_PER_MIN`."""
    calm = (data["impulse_ns"][rows] == 0) & ~np.isfinite(data["fall_s"][rows])
    episode, minutes = data["episode"][rows][calm], calm.sum() * dt / 60
    chosen = (0.0, 0.0)
    for floor in FLOORS[1:]:
        low = p[calm] < floor
        rate = float(_onsets(low, episode).sum() / minutes)
        if rate > FALSE_ALARMS_PER_MIN:
            break
        chosen = (floor, rate)
    return chosen


def _reliability(p: np.ndarray, up: np.ndarray, bins: int = 10) -> list[dict]:
    edges = np.linspace(0, 1, bins + 1)
    rows = []
    for lo, hi in itertools.pairwise(edges):
        inside = (p >= lo) & ((p < hi) | (hi == 1))
        if inside.any():
            rows.append({"bin": [float(lo), float(hi)], "states": int(inside.sum()),
                         "predicted": float(p[inside].mean()), "observed": float(up[inside].mean())})
    return rows


def fit_survival(data: dict[str, np.ndarray], *, gaits: tuple[str, ...], identities: dict[str, str], dt: float,
                 inputs: tuple[str, ...] = ("latent", "phase"), horizons_s: tuple[float, ...] = HORIZONS_S,
                 margin: float | None = None, floor: float | None = 0.0, epochs: int = 20,
                 seed: int = 0) -> SurvivalEstimate:
    """Fit, calibrate and choose (module doc) on recorded states ``data`` (the columns of
    :mod:`gaitlib.collection.survival`, rows in episode and time order, control period ``dt`` s). ``margin``: use
    this one instead of choosing it. ``floor``: this one (by default 0: the guard never catches on the estimate
    alone; a chosen floor measured worse on the pace), or ``None``: choose it. Bad input is refused in one line
    before any fit."""
    for h in horizons_s:
        check_guard(horizon_s=h)
    check_guard(margin=margin, floor=floor)
    if unknown := [i for i in inputs if i not in INPUTS]:
        raise GaitlibError(f"unknown survival input(s) {', '.join(unknown)} (known: {', '.join(INPUTS)})")
    if absent := [i for i in inputs if i not in data]:
        raise GaitlibError(f"these survival states hold no {', '.join(absent)} (recorded before it existed): record "
                           "them again with gaitlib survival record")
    part = _split(data, seed)
    if not all((part == k).any() for k in range(3)):
        raise GaitlibError(f"{len(np.unique(data['episode']))} recorded episode(s) are too few to split three ways "
                           "(train, calibrate, select); record more")
    g = len(gaits)
    choices, best = [], None
    for horizon in horizons_s:
        known, up = _labels(data, horizon)
        train, calib, select = (np.flatnonzero((part == k) & known) for k in range(3))
        x = _features(data, inputs, g, train)
        net = _train(x, torch.from_numpy(up[train].astype(np.float32)), epochs=epochs, seed=seed)
        with torch.inference_mode():
            z_cal = net(_features(data, inputs, g, calib)).numpy()
        ab = {}
        for k in range(g):
            rows = data["gait"][calib] == k
            if rows.any():
                ab[k] = platt(1 / (1 + np.exp(-z_cal[rows])), up[calib][rows])
        estimate = SurvivalEstimate(gaits, dict(identities), tuple(inputs), horizon, 0.0, ab, net)
        everything = np.flatnonzero(part == 2)  # the guard reads every state, known fate or not
        p_all = estimate.probability(_features(data, inputs, g, everything),
                                     torch.from_numpy(data["gait"][everything])).numpy()
        tried = [_judge(data, everything, p_all, m, dt) for m in ((margin,) if margin is not None else MARGINS)]
        quiet = [t for t in tried if (t["false_alarms_per_min"] or 0.0) <= FALSE_ALARMS_PER_MIN]
        chosen = quiet[0] if quiet else tried[-1]
        low, low_rate = _floor(data, everything, p_all, dt) if floor is None else (floor, None)
        chosen = chosen | {"floor": low, "floor_false_alarms_per_min": low_rate}
        p_sel = p_all[np.isin(everything, select)]
        chosen = chosen | {"horizon_s": horizon, "reliability": _reliability(p_sel, up[select]),
                           "log_loss": float(-np.mean(np.log(np.where(up[select], p_sel, 1 - p_sel).clip(1e-6))))}
        choices.append(chosen)
        if best is None or (chosen["warned"], -horizon) > (best[1]["warned"], -best[0].horizon_s):
            estimate.margin, estimate.floor = chosen["margin"], low
            best = (estimate, chosen)
    estimate, report = best
    estimate.info = {
        "report": report, "choices": choices,
        "rule": f"horizon and margin chosen on the selection split (20% of episodes): the smallest margin of "
                f"{MARGINS[0]}-{MARGINS[-1]} with at most {FALSE_ALARMS_PER_MIN} firings per unshoved minute, then "
                "the horizon warning before the most falls; the highest floor of "
                f"{FLOORS[0]}-{FLOORS[-1]} with at most as many on unshoved episodes that stay up; Platt scaling per "
                "gait on the calibration split (20%)",
        "states": len(data["gait"]), "episodes": len(np.unique(data["episode"])), "epochs": epochs,
        "seed": seed, "dt": dt,
        "armed_from_s": round(float(data["time_s"].min()), 6),
    }
    return estimate


def save_survival(library: Library, estimate: SurvivalEstimate, *, data: Path) -> Path:
    """Write ``estimate`` into ``library``'s switching folder, atomically, recording the data file's SHA-256."""
    path = library.switching_dir / SURVIVAL_FILE
    metadata = _FORMAT | {
        "gaits": list(estimate.gaits), "library_identities": estimate.identities, "inputs": list(estimate.inputs),
        "horizon_s": estimate.horizon_s, "margin": estimate.margin, "floor": estimate.floor,
        "dim": int(estimate.net.mean.numel()),
        "platt": {estimate.gaits[k]: list(ab) for k, ab in estimate.platt.items()}, "info": estimate.info,
        "data": {"path": str(data), "sha256": file_sha256(data)},
    }
    write_bytes(path, torch_bytes({"metadata": metadata, "state_dict": estimate.net.state_dict()}))
    return path


def save_catch_table(library: Library, table: dict) -> Path:
    """Write the catch table (:func:`gaitlib.benchmark.catches.fit_catch_table`) into ``library``'s survival
    estimate, atomically, the rest of it as it was (a refit of the estimate drops it: measure it again)."""
    path = library.switching_dir / SURVIVAL_FILE
    saved = torch.load(path, map_location="cpu", weights_only=True)
    saved["metadata"]["info"]["catches"] = table
    write_bytes(path, torch_bytes(saved))
    return path


def load_survival(library: Library, gaits: tuple[str, ...]) -> SurvivalEstimate:
    """``library``'s survival estimate for ``gaits``; one line when it has none, when it is damaged, or when it
    was recorded with other policies (stale: record it again)."""
    path = library.switching_dir / SURVIVAL_FILE
    commands = (f"gaitlib survival record --library {library.root} --out data/survival.h5 && gaitlib survival fit "
                f"data/survival.h5 --library {library.root}" + (" --replace" if is_shipped(library.root) else ""))
    again = f"record and fit it again: {commands}"
    if not path.is_file():
        raise GaitlibError(f"library {library.root} has no survival estimate; make one: {commands}")
    try:
        saved = torch.load(path, map_location="cpu", weights_only=True)
        meta = saved["metadata"]
        if {k: meta.get(k) for k in _FORMAT} != _FORMAT:
            raise ValueError("not a gaitlib survival estimate of this version")
        names = tuple(meta["gaits"])
        net = SurvivalNet(int(meta["dim"]))
        net.load_state_dict(saved["state_dict"])
        ab = {names.index(name): (float(v[0]), float(v[1])) for name, v in meta["platt"].items()}
        estimate = SurvivalEstimate(names, dict(meta["library_identities"]), tuple(meta["inputs"]),
                                    float(meta["horizon_s"]), float(meta["margin"]), ab, net.eval(), meta["info"],
                                    float(meta.get("floor", 0.0)))  # none before floors existed
        check_guard(horizon_s=estimate.horizon_s, margin=estimate.margin, floor=estimate.floor)
        if not all(math.isfinite(v) for pair in ab.values() for v in pair):
            raise ValueError("a gait's Platt parameters are not finite")
    except GaitlibError as error:
        raise GaitlibError(f"{path} is damaged ({error}); {again}") from error
    except Exception as error:  # torch and the checks above raise several unrelated types
        raise GaitlibError(f"{path} is damaged ({type(error).__name__}: {error}); {again}") from error
    if names != tuple(gaits):
        raise GaitlibError(f"{path} was fitted for gaits {list(names)}, not {list(gaits)}; {again}")
    try:
        check_identities(estimate.identities, library.identities(gaits), what=f"survival estimate {path}")
    except TransitionDataError as stale:
        raise GaitlibError(f"{path} was recorded with other policies than the library's (stale); {again}") from stale
    return estimate
