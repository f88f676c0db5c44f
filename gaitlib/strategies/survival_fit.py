"""The fit of the survival estimate (:mod:`gaitlib.strategies.survival`, whose module doc gives the rule): the
split by episode, the model, its calibration, and the choice of horizon, margin and floor on the selection split.

An estimate is chosen on something or not at all: a margin (or a floor) is chosen only on at least
:data:`MIN_UNSHOVED_MINUTES` of unshoved running on the selection split (its false alarms are counted per minute of
it), a horizon shorter than one control step of the states is refused (nothing could be warned of), and a fit whose
model or calibration is not finite is refused, never returned.
"""

from __future__ import annotations

import itertools

import numpy as np
import torch

from gaitlib.defaults import MIN_UNSHOVED_MINUTES
from gaitlib.errors import GaitlibError
from gaitlib.strategies.calibration import platt
from gaitlib.strategies.survival import (
    FALSE_ALARMS_PER_MIN,
    FLOORS,
    HORIZONS_S,
    INPUTS,
    MARGINS,
    SurvivalEstimate,
    SurvivalNet,
    check_finite,
    check_guard,
    survival_features,
)
from gaitlib.values import number_text

__all__ = ["check_fit", "fit_survival"]

_SPLIT = (0.6, 0.2)
"""Shares of episodes the model trains on and the calibration is fitted on; the rest select and report."""


def _check_unshoved(data: dict[str, np.ndarray], select: np.ndarray, dt: float, *, minimum: float,
                    margin: float | None, floor: float | None) -> None:
    """Refuse, in one line, choosing a margin (``margin`` ``None``) or a floor (``floor`` ``None``) on less than
    ``minimum`` unshoved minutes of the selection split ``select`` (rows): the running each counts false alarms
    on (the margin: unshoved episodes without a switch; the floor: unshoved ones that stay up)."""
    calm = (data["impulse_ns"] == 0) & select
    wanted = {"margin": (margin, calm & ~data["switched"].astype(bool)), "floor": (floor, calm & ~np.isfinite(
        data["fall_s"]))}
    for what, (given, rows) in wanted.items():
        minutes = float(rows.sum() * dt / 60)
        if given is None and minutes < minimum:
            episodes = len(np.unique(data["episode"]))
            raise GaitlibError(
                f"the selection split of these {episodes} episodes holds {minutes:.2f} unshoved minutes; a {what} is "
                f"chosen on at least {number_text(minimum)} (its false alarms are counted per unshoved minute): "
                f"record more episodes, or give the {what}"
            )


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


def check_fit(data: dict[str, np.ndarray], *, dt: float, inputs: tuple[str, ...] = ("latent", "phase"),
              horizons_s: tuple[float, ...] = HORIZONS_S, margin: float | None = None, floor: float | None = 0.0,
              seed: int = 0, min_unshoved_minutes: float = MIN_UNSHOVED_MINUTES) -> np.ndarray:
    """Refuse, in one line, what :func:`fit_survival` would refuse before its fit (options as its own); returns the
    split of the rows (0 train, 1 calibrate, 2 select)."""
    for h in horizons_s:
        check_guard(horizon_s=h)
        if h < dt:
            raise GaitlibError(f"the horizon {number_text(h)} s is shorter than one control step of these states "
                               f"({1000 * dt:.1f} ms): nothing could be warned of; give horizons of at least a step")
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
    _check_unshoved(data, part == 2, dt, minimum=min_unshoved_minutes, margin=margin, floor=floor)
    return part


def fit_survival(data: dict[str, np.ndarray], *, gaits: tuple[str, ...], identities: dict[str, str], dt: float,
                 inputs: tuple[str, ...] = ("latent", "phase"), horizons_s: tuple[float, ...] = HORIZONS_S,
                 margin: float | None = None, floor: float | None = 0.0, epochs: int = 20, seed: int = 0,
                 min_unshoved_minutes: float = MIN_UNSHOVED_MINUTES) -> SurvivalEstimate:
    """Fit, calibrate and choose (module doc) on recorded states ``data`` (the columns of
    :mod:`gaitlib.collection.survival`, rows in episode and time order, control period ``dt`` s). ``margin``: use
    this one instead of choosing it. ``floor``: this one (by default 0: the guard never catches on the estimate
    alone; a chosen floor measured worse on the pace), or ``None``: choose it. ``min_unshoved_minutes``: the least
    unshoved running of the selection split a margin or floor is chosen on (:data:`MIN_UNSHOVED_MINUTES`). Bad input
    is refused in one line before any fit, and a fit that is not finite after it (nothing is returned)."""
    part = check_fit(data, dt=dt, inputs=inputs, horizons_s=horizons_s, margin=margin, floor=floor, seed=seed,
                     min_unshoved_minutes=min_unshoved_minutes)
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
    try:
        check_finite(estimate)
    except GaitlibError as error:
        raise GaitlibError(f"the fit is not finite ({error}): nothing is written; check the recorded states") from None
    given = "" if margin is None else f"; the margin given ({number_text(margin)}), not chosen"
    estimate.info = {
        "report": report, "choices": choices,
        "rule": f"horizon and margin chosen on the selection split (20% of episodes): the smallest margin of "
                f"{MARGINS[0]}-{MARGINS[-1]} with at most {FALSE_ALARMS_PER_MIN} firings per unshoved minute, then "
                "the horizon warning before the most falls; the highest floor of "
                f"{FLOORS[0]}-{FLOORS[-1]} with at most as many on unshoved episodes that stay up; Platt scaling per "
                "gait on the calibration split (20%)" + given,
        "states": len(data["gait"]), "episodes": len(np.unique(data["episode"])), "epochs": epochs,
        "seed": seed, "dt": dt,
        "armed_from_s": round(float(data["time_s"].min()), 6),
    }
    return estimate
