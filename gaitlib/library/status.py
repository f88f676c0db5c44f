"""What state a library is in: its gaits, the pairs its switching models cover, and each problem with the exact
commands that fix it (``gaitlib library``; the refusals of ``run`` and ``benchmark`` quote the same commands).

A pair ``m-n`` of the library's gaits is *covered* when the switching models (net, TMT and calibration, fitted
together) hold samples of it collected with the policies the library holds now; *stale* when they were fitted on
another policy of ``m`` or ``n`` (the gait was retrained since); *uncovered* when they never saw it (a gait added
since, or a fit on data of some pairs only). The fix for stale and uncovered pairs collects only those pairs, with
the settings of each file the models were fitted on, and fits again on the old files and the new ones: ``gaitlib
fit`` leaves out the old files' samples of policies the library no longer holds
(:func:`gaitlib.transitions.read_all`).
"""

from __future__ import annotations

import json
import shlex
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gaitlib.defaults import DEFAULT_FALLS, Falls
from gaitlib.errors import GaitlibError
from gaitlib.library.layout import first_fit, is_shipped, ordered_pairs, protection
from gaitlib.library.store import Library

__all__ = ["Bundle", "GaitStatus", "LibraryStatus", "Problem", "library_status", "read_bundle"]


@dataclass(frozen=True)
class GaitStatus:
    """One entry as ``metadata.json`` records it."""

    name: str
    identity: str | None
    """SHA-256 of ``policy.pt`` (``None``: the entry cannot be loaded)."""
    metadata: dict
    """``metadata.json`` (empty when unreadable)."""
    problem: str | None = None
    """Why the entry cannot be used, else ``None``."""

    @property
    def summary(self) -> dict:
        """Description, training recipe (or the entry it is the mirror image of) and evaluation figures in a few
        numbers."""
        m = self.metadata
        d, t, e = m.get("description", {}), m.get("training", {}), m.get("evaluation", {})
        return {
            "speed_m_s": d.get("forward_speed"),
            "cycle_s": 1.0 / d["stride_frequency"] if d.get("stride_frequency") else None,
            "duty_factor": d.get("duty_factor"),
            "preset": t.get("preset", {}).get("name"),
            "iterations": t.get("iterations"),
            "train_minutes": None if t.get("wall_clock_s") is None else round(t["wall_clock_s"] / 60, 1),
            "switch_start": t.get("switch_start"),
            "mirror_of": t.get("mirror", {}).get("source"),
            "eval_episodes": e.get("episodes"),
            "eval_fall_rate": e.get("fall_rate"),
            "eval_touch_rate": e.get("touch_rate"),
            "eval_falls": e.get("falls", "contact") if e else None,
            "eval_speed_m_s": e.get("forward_speed"),
        }


@dataclass(frozen=True)
class Bundle:
    """The switching models of a library as their files record them."""

    gaits: tuple[str, ...]
    identities: dict[str, str]
    """Gait -> identity of the policy the models were fitted on."""
    pair_samples: dict[str, int]
    """``"m-n"`` -> samples the fit saw (pairs without samples are absent)."""
    accuracy: dict[str, float]
    """``"m-n"`` -> balanced validation accuracy of the net written (0-1)."""
    data: tuple[dict, ...]
    """One record per transition file fitted on: ``path`` and its collection ``settings``."""
    inputs: tuple[str, ...]
    """Input kinds fitted (the first is the net written; several: ``--ablation``)."""
    falls: dict[str, Falls]
    """File name -> the definition of a fall its labels followed (files from before it was recorded: ``contact``,
    the only one there was)."""
    parts: dict[str, int] = field(default_factory=dict)
    """``"m-n"`` -> the part of a composite transition-net that serves it (1, 2, ...: the order of the fits, the
    last the newest; ``gaitlib fit --extend``); empty for one net, which serves every pair."""


@dataclass(frozen=True)
class Problem:
    """Something that stops a command from working on the library, and the commands that fix it."""

    text: str
    commands: tuple[str, ...] = ()
    about: str = "switching"
    """What it concerns: ``entry`` (one gait), ``settings`` (gaits that cannot run together) or ``switching``
    (the switching models)."""

    def line(self) -> str:
        """The problem and its fix in one line."""
        return self.text + ("; fix: " + " && ".join(self.commands) if self.commands else "")


@dataclass(frozen=True)
class LibraryStatus:
    """A library's gaits, switching models, pair coverage and problems."""

    root: Path
    shipped: bool
    """The library that ships with gaitlib (training never replaces its entries without ``--replace``)."""
    gaits: tuple[GaitStatus, ...]
    bundle: Bundle | None
    pairs: dict[str, str] = field(default_factory=dict)
    """``"m-n"`` of the library's usable gaits -> ``covered``, ``stale`` or ``uncovered``."""
    problems: tuple[Problem, ...] = ()

    def uncovered(self, gaits: Sequence[str]) -> list[str]:
        """The pairs of ``gaits`` that the switching models do not drive (stale or uncovered)."""
        return [p for p in ordered_pairs(gaits) if self.pairs.get(p) != "covered"]

    def falls(self) -> dict[str, str]:
        """Each artefact that depends on what a fall is (``GAIT/metadata.json``'s evaluation, the switching files)
        -> the definition it used."""
        used = {f"{g.name}/metadata.json": g.summary["eval_falls"] for g in self.gaits if g.summary["eval_falls"]}
        if self.bundle is not None:
            used |= {f"{Library.SWITCHING}/{name}": falls for name, falls in self.bundle.falls.items()}
        return used

    def other_falls(self) -> dict[str, str]:
        """The artefacts of :meth:`falls` that used another definition than the default (``trunk``)."""
        return {name: falls for name, falls in self.falls().items() if falls != DEFAULT_FALLS}

    def as_dict(self) -> dict:
        return {
            "library": str(self.root),
            "shipped": self.shipped,
            "gaits": {g.name: {"identity": g.identity, "problem": g.problem, **g.summary} for g in self.gaits},
            "switching": None if self.bundle is None else {
                "gaits": list(self.bundle.gaits),
                "inputs": list(self.bundle.inputs),
                "data": [d["path"] for d in self.bundle.data],
                "parts": len(set(self.bundle.parts.values())) or 1,
                "pairs": {
                    p: {"state": s, "samples": self.bundle.pair_samples.get(p), "accuracy": self.bundle.accuracy.get(p),
                        "part": self.bundle.parts.get(p)}
                    for p, s in self.pairs.items()
                },
            },
            "problems": [{"text": p.text, "commands": list(p.commands)} for p in self.problems],
            "falls": self.falls(),
            "other_falls": self.other_falls(),
        }


def library_status(library: Library) -> LibraryStatus:
    """Read everything ``library`` holds (entries loaded, switching files read) and say what is wrong."""
    root, problems = library.root, []
    gaits = tuple(_gait_status(library, name) for name in library.gaits())
    for g in gaits:
        if g.problem is not None:
            problems.append(Problem(f"entry {g.name}: {g.problem}", (_train(g.name, root),), about="entry"))
    usable = [g.name for g in gaits if g.identity is not None]
    try:
        library.shared_policy_settings(usable)
    except GaitlibError as error:
        problems.append(Problem(str(error), about="settings"))
        usable = []
    bundle, pairs = None, {}
    if library.switching_dir.is_dir():
        try:
            bundle = read_bundle(library)
        except GaitlibError as error:
            problems.append(Problem(str(error), _collect_all(root, usable)))
    if bundle is not None:
        current = {g.name: g.identity for g in gaits if g.identity is not None}
        for pair in ordered_pairs(usable):
            m, n = pair.split("-")
            if any(g in bundle.identities and bundle.identities[g] != current[g] for g in (m, n)):
                pairs[pair] = "stale"
            else:
                pairs[pair] = "covered" if pair in bundle.pair_samples else "uncovered"
        gone = [g for g in bundle.gaits if g not in current]
        if gone:
            text = f"the switching models were fitted with {', '.join(gone)}, which the library no longer holds"
            keep = [d["path"] for d in bundle.data]
            fit = _command("gaitlib", "fit", "--library", root, *[w for path in keep for w in ("--data", path)])
            problems.append(Problem(text, (fit,) if _data_here(bundle) else first_fit(root)))
        todo = [p for p, state in pairs.items() if state != "covered"]
        if todo:
            retrained = sorted({g for p in todo for g in p.split("-") if g in bundle.identities
                                and bundle.identities[g] != current[g]})
            why = f"retrained since the fit: {', '.join(retrained)}" if retrained else "not in the fitted data"
            text = f"the switching models do not drive {len(todo)} pair(s), {', '.join(todo)} ({why})"
            if not _data_here(bundle):
                text += "; the data they were fitted on are not here, so every pair is collected again"
            problems.append(Problem(text, _refit(root, bundle, todo, usable)))
    elif len(usable) >= 2 and not library.switching_dir.is_dir():
        problems.append(Problem("no switching models yet (transition-net, TMT)", _collect_all(root, usable)))
    return LibraryStatus(root, is_shipped(root), gaits, bundle, pairs, tuple(problems))


def read_bundle(library: Library) -> Bundle:
    """The switching models' gaits, identities, coverage and data, as their four files record them; a
    :class:`~gaitlib.errors.GaitlibError` naming the file when one is missing, unreadable or from another fit."""
    import torch

    library.check_switching()  # every file matches the checksum written with it
    folder = library.switching_dir
    records = {}
    for name in (Library.TMT, Library.CALIBRATION, Library.ACCURACY):
        try:
            records[name] = json.loads((folder / name).read_text())
        except (OSError, ValueError) as error:
            raise GaitlibError(f"{folder / name} is missing or unreadable ({type(error).__name__})") from None
    try:
        records[Library.NET] = torch.load(folder / Library.NET, map_location="cpu", weights_only=True)["metadata"]
    except Exception as error:  # torch raises several unrelated types for a file that is not a checkpoint
        raise GaitlibError(f"{folder / Library.NET} is missing or unreadable ({type(error).__name__})") from None
    try:
        tmt, accuracy, net = records[Library.TMT], records[Library.ACCURACY], records[Library.NET]
        fits = {name: (tuple(records[name]["gaits"]), dict(records[name]["library_identities"]))
                for name in (Library.NET, Library.TMT, Library.CALIBRATION)}
        if len(set(map(str, fits.values()))) != 1:
            raise GaitlibError(f"the files in {folder} come from different fits (their gaits or policies differ)")
        gaits, identities = fits[Library.NET]
        counts = np.asarray(tmt["counts"], dtype=np.int64).sum(axis=(2, 3))
        pair_samples = {f"{gaits[m]}-{gaits[n]}": int(counts[m, n])
                        for m in range(len(gaits)) for n in range(len(gaits)) if counts[m, n] > 0}
        written = accuracy["input_written"]
        settings = net["data"]["settings"]
        files = settings["files"] if "files" in settings else [{"path": accuracy["data"][0], "settings": settings}]
        return Bundle(
            gaits=gaits,
            identities=identities,
            pair_samples=pair_samples,
            accuracy=dict(accuracy["balanced_validation_accuracy"][written]),
            data=tuple({"path": str(f["path"]), "settings": dict(f["settings"])} for f in files),
            inputs=tuple(accuracy["balanced_validation_accuracy"]),
            falls={
                Library.NET: Falls(net["fit"].get("falls", Falls.CONTACT)),
                Library.TMT: Falls(tmt["info"].get("falls", Falls.CONTACT)),
                Library.CALIBRATION: Falls(records[Library.CALIBRATION]["info"].get("falls", Falls.CONTACT)),
                Library.ACCURACY: Falls(accuracy.get("falls", Falls.CONTACT)),
            },
            parts={str(pair): k + 1 for k, part in enumerate(net.get("parts", ())) for pair in part["pairs"]},
        )
    except (KeyError, TypeError, ValueError, IndexError) as error:
        raise GaitlibError(f"the switching models in {folder} are damaged ({type(error).__name__}: {error})") from None


def _gait_status(library: Library, name: str) -> GaitStatus:
    try:
        entry = library.entry(name)
    except GaitlibError as error:
        try:
            metadata = json.loads((library.root / name / "metadata.json").read_text())
        except (OSError, ValueError):
            metadata = {}
        return GaitStatus(name, None, metadata if isinstance(metadata, dict) else {}, str(error))
    return GaitStatus(name, entry.identity, entry.metadata)


def _command(*words: object) -> str:
    return " ".join(shlex.quote(str(w)) for w in words)


def _train(gait: str, root: Path) -> str:
    return _command("gaitlib", "train", gait, "--library", root, *(["--replace"] if protection(root) else []))


def _collect_all(root: Path, gaits: Sequence[str]) -> tuple[str, ...]:
    """Collect every pair and fit: the commands for a library without usable switching models."""
    return first_fit(root) if len(gaits) >= 2 else ()


def _data_here(bundle: Bundle) -> bool:
    """Whether every file the switching models were fitted on is here (a fresh clone has none of them)."""
    return all(Path(d["path"]).is_file() for d in bundle.data)


def _refit(root: Path, bundle: Bundle, pairs: Sequence[str], gaits: Sequence[str]) -> tuple[str, ...]:
    """Collect ``pairs`` with the settings of each file the models were fitted on (as many samples per pair as the
    fit had on average, split evenly over the files), then fit on the old files and the new ones; where the old
    files are not here, every pair of ``gaits`` is collected again."""
    per_pair = sum(bundle.pair_samples.values()) / max(1, len(bundle.pair_samples))
    files, keep = list(bundle.data), [d["path"] for d in bundle.data]
    if not _data_here(bundle):
        pairs, keep = ordered_pairs(gaits), []
    commands, new = [], []
    for k, record in enumerate(files):
        s = record["settings"]
        out = Path("data") / f"{root.name}-refit-{k}.h5"
        samples = max(len(pairs), round(per_pair * len(pairs) / len(files)))
        words = ["gaitlib", "collect", "--library", root, "--pairs", ",".join(pairs), "--samples", samples]
        words += ["--push-max", f"{s.get('push_max_n', 0):g}", "--horizon", f"{s.get('horizon_s', 2.5):g}"]
        commands.append(_command(*words, "--seed", s.get("seed", 0), "--out", out))
        new.append(out)
    fit = ["gaitlib", "fit", "--library", root]
    for path in [*keep, *new]:
        fit += ["--data", path]
    if len(bundle.inputs) > 1:
        fit.append("--ablation")
    if bundle.inputs and bundle.inputs[0] != "latent":
        fit += ["--input", bundle.inputs[0]]
    return (*commands, _command(*fit))
