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

import hashlib
import math
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import torch

from gaitlib.atomic import file_sha256, torch_bytes, write_bytes
from gaitlib.errors import GaitlibError, TransitionDataError
from gaitlib.evaluation import SECTORS, sector_of
from gaitlib.library.checksums import write_listed
from gaitlib.library.layout import check_identities, is_shipped
from gaitlib.library.publish import staged_folder
from gaitlib.library.store import Library
from gaitlib.values import GUARD_HORIZON_S, number_text

__all__ = [
    "FALSE_ALARMS_PER_MIN", "FLOORS", "HORIZONS_S", "INPUTS", "MARGINS", "SURVIVAL_FILE", "SurvivalEstimate",
    "SurvivalFileError", "SurvivalNet", "check_finite", "check_guard", "load_survival",
    "save_catch_table", "save_survival", "shove_sector", "survival_features",
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


class SurvivalFileError(GaitlibError):
    """The library's survival estimate is damaged: refused by every command that would use it (``run`` and
    ``drive`` too, which run unguarded only where there is no estimate, or a stale one)."""


def check_guard(*, horizon_s: float | None = None, margin: float | None = None, floor: float | None = None) -> None:
    """Refuse, in one line, a horizon outside (0, 5] s, or a margin or floor outside [0, 1)."""
    if horizon_s is not None and not 0 < horizon_s <= GUARD_HORIZON_S.high:
        raise GaitlibError(f"the guard's horizon ({number_text(horizon_s)} s) must lie in {GUARD_HORIZON_S.describe()}")
    if margin is not None and not 0 <= margin < 1:
        raise GaitlibError(f"the guard's margin ({number_text(margin)}) must lie in [0, 1)")
    if floor is not None and not 0 <= floor < 1:
        raise GaitlibError(f"the guard's floor ({number_text(floor)}) must lie in [0, 1)")


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


def check_finite(estimate: SurvivalEstimate) -> None:
    """Refuse, in one line naming the first, an estimate with a number that is not finite: a weight or buffer of
    its model, a Platt parameter, its horizon, margin or floor (a model that reads nan gives nan, and the guard
    compares nan as never firing: on, and never catching)."""
    for name, tensor in estimate.net.state_dict().items():
        if not bool(torch.isfinite(tensor).all()):
            raise SurvivalFileError(f"the survival estimate's {name} holds a number that is not finite")
    for k, ab in estimate.platt.items():
        if not all(math.isfinite(v) for v in ab):
            raise SurvivalFileError(f"the survival estimate's Platt parameters of {estimate.gaits[k]} are not finite")
    check_guard(horizon_s=estimate.horizon_s, margin=estimate.margin, floor=estimate.floor)


def save_survival(library: Library, estimate: SurvivalEstimate, *, data: Path) -> Path:
    """Write ``estimate`` into ``library``'s switching folder, recording the data file's SHA-256, with its own
    SHA-256 listed in the folder's ``checksums.json``, published with it in one step; an estimate that is not
    finite (:func:`check_finite`) is refused and nothing is written."""
    check_finite(estimate)
    metadata = _FORMAT | {
        "gaits": list(estimate.gaits), "library_identities": estimate.identities, "inputs": list(estimate.inputs),
        "horizon_s": estimate.horizon_s, "margin": estimate.margin, "floor": estimate.floor,
        "dim": int(estimate.net.mean.numel()),
        "platt": {estimate.gaits[k]: list(ab) for k, ab in estimate.platt.items()}, "info": estimate.info,
        "data": {"path": str(data), "sha256": file_sha256(data)},
    }
    return _publish(library, torch_bytes({"metadata": metadata, "state_dict": estimate.net.state_dict()}))


def save_catch_table(library: Library, table: dict, *, measured: str) -> Path:
    """Write the catch table (:func:`gaitlib.benchmark.catches.fit_catch_table`) into ``library``'s survival
    estimate, the rest of it as it was (a refit of the estimate drops it: measure it again), published as
    :func:`save_survival` publishes; refused in one line, nothing written, when the estimate is no longer the one
    the table was measured on (``measured``: the SHA-256 of its file then)."""
    path = library.switching_dir / SURVIVAL_FILE
    if not path.is_file() or file_sha256(path) != measured:
        raise GaitlibError(f"{path} changed while its catch table was measured (another writer replaced it); the "
                           "table is not written: measure it again")
    saved = torch.load(path, map_location="cpu", weights_only=True)
    saved["metadata"]["info"]["catches"] = table
    return _publish(library, torch_bytes(saved), replacing=measured)


def _publish(library: Library, data: bytes, *, replacing: str | None = None) -> Path:
    """Publish ``data`` as the switching folder's survival estimate with its SHA-256 listed in ``checksums.json``,
    every other switching file and its listed checksum as they were (the models checked first: a damaged one is
    refused, never listed anew); a reader sees the old folder or the new one, whole. ``replacing``: the SHA-256 the
    estimate replaced must still have (checked under the folder's lock)."""
    folder = library.switching_dir
    with staged_folder(folder) as staging:
        library.check_switching()
        listed = library.listed_checksums()
        if replacing is not None and (listed.get(SURVIVAL_FILE) != replacing
                                      or file_sha256(folder / SURVIVAL_FILE) != replacing):
            raise GaitlibError(f"{folder / SURVIVAL_FILE} changed, or does not match its checksum in "
                               f"{folder / Library.CHECKSUMS}; nothing written")
        for item in folder.iterdir():
            if item.is_file() and not item.name.startswith(".") and item.name not in (SURVIVAL_FILE,
                                                                                      Library.CHECKSUMS):
                shutil.copy2(item, staging / item.name)
        write_bytes(staging / SURVIVAL_FILE, data)
        files = {name: listed[name] for name in Library.BUNDLE} | {SURVIVAL_FILE: hashlib.sha256(data).hexdigest()}
        write_listed(staging / Library.CHECKSUMS, files)
    return folder / SURVIVAL_FILE


def load_survival(library: Library, gaits: tuple[str, ...]) -> SurvivalEstimate:
    """``library``'s survival estimate for ``gaits``; one line when it has none, when it is damaged
    (:class:`SurvivalFileError`: it does not match its checksum in ``checksums.json``, is not listed there, cannot
    be read, or holds a number that is not finite), or when it was recorded with other policies (stale: record it
    again)."""
    path = library.switching_dir / SURVIVAL_FILE
    commands = (f"gaitlib survival record --library {library.root} --out data/survival.h5 && gaitlib survival fit "
                f"data/survival.h5 --library {library.root}" + (" --replace" if is_shipped(library.root) else ""))
    again = f"record and fit it again: {commands}"
    if not path.is_file():
        raise GaitlibError(f"library {library.root} has no survival estimate; make one: {commands}")
    listed = library.listed_checksums().get(SURVIVAL_FILE)
    if listed != file_sha256(path):
        why = "has no checksum in" if listed is None else "does not match its checksum in"
        raise SurvivalFileError(f"{path} is damaged: it {why} {library.switching_dir / Library.CHECKSUMS}; {again}")
    try:
        saved = torch.load(path, map_location="cpu", weights_only=True)
        meta = saved["metadata"]
        if {k: meta.get(k) for k in _FORMAT} != _FORMAT:
            raise ValueError
        names = tuple(meta["gaits"])
        net = SurvivalNet(int(meta["dim"]))
        net.load_state_dict(saved["state_dict"])
        ab = {names.index(name): (float(v[0]), float(v[1])) for name, v in meta["platt"].items()}
        estimate = SurvivalEstimate(names, dict(meta["library_identities"]), tuple(meta["inputs"]),
                                    float(meta["horizon_s"]), float(meta["margin"]), ab, net.eval(), meta["info"],
                                    float(meta.get("floor", 0.0)))  # none before floors existed
    except Exception as error:  # torch and the reads above raise several unrelated types, none a user's concern
        raise SurvivalFileError(f"{path} is damaged: it is not a gaitlib survival estimate of this version; "
                                f"{again}") from error
    try:
        check_finite(estimate)
    except GaitlibError as error:
        raise SurvivalFileError(f"{path} is damaged ({error}); {again}") from error
    if names != tuple(gaits):
        raise GaitlibError(f"{path} was fitted for gaits {list(names)}, not {list(gaits)}; {again}")
    try:
        check_identities(estimate.identities, library.identities(gaits), what=f"survival estimate {path}")
    except TransitionDataError as stale:
        raise GaitlibError(f"{path} was recorded with other policies than the library's (stale); {again}") from stale
    return estimate
