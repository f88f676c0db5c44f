"""Fitting a library's switching models from its transition data, in one call.

:func:`fit_library` checks that the data were collected with the library's own policies, fits the transition-net
for each requested input kind (the paper's Table 3 ablation: latent, phase, explicit), builds the TMT with the
strategies' calibrated thresholds, calibrates the net's score to real success rates on the rows it did not train
on, and publishes the net of the first kind asked for (``latent`` by default), the TMT, an accuracy report
(``accuracy.json``) and the calibration (``calibration.json``) together as the library's ``switching/`` folder.
:func:`evaluate_library` scores the library's net on other data. ``gaitlib fit``, the examples and the tests all
go through these two functions; ``gaitlib fit --extend`` (:mod:`gaitlib.strategies.extend`) fits the pairs of new
data alone with :func:`fit_nets` and publishes them beside the library's kept models with :func:`publish_models`.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from gaitlib.atomic import write_json
from gaitlib.defaults import DEFAULT_FALLS, MIN_PER_LABEL, Falls
from gaitlib.errors import GaitlibError, TransitionDataError
from gaitlib.library.layout import ordered_pairs
from gaitlib.library.store import Library
from gaitlib.strategies.calibration import Calibration, calibrate, save_calibration
from gaitlib.strategies.tmt import TransitionTable, build_table, save_table
from gaitlib.transition_net import (
    EpochStats,
    FitConfig,
    FitResult,
    check_input_kinds,
    evaluate_net,
    fit,
    load_net,
    save_net,
)
from gaitlib.transitions import TransitionData

__all__ = [
    "ACCURACY_FORMAT",
    "PAPER_PAIRS",
    "PAPER_TABLE_3",
    "FitReport",
    "check_validatable",
    "evaluate_library",
    "fit_library",
    "fit_nets",
    "publish_fit",
    "publish_models",
]

ACCURACY_FORMAT = {"format": "gaitlib.accuracy", "format_version": 2}
"""Header of ``accuracy.json`` (version 2: accuracies as fractions everywhere, paths relative to the library)."""
PAPER_PAIRS = ("stand-pace", "stand-trot", "pace-trot", "pace-stand", "trot-pace", "trot-stand")
"""Column order of paper Table 3 (S-P, S-T, P-T, P-S, T-P, T-S)."""
PAPER_TABLE_3 = {
    "phase": (0.8894, 0.8759, 0.6386, 0.6742, 0.6614, 0.6501),
    "explicit": (0.8915, 0.8750, 0.8126, 0.7801, 0.7616, 0.7185),
    "latent": (0.8714, 0.8697, 0.8245, 0.7868, 0.7830, 0.7549),
}
"""Paper Table 3 (Christmann et al., arXiv:2306.08224): balanced validation accuracy per input kind, as fractions,
5,500 samples per pair, columns in :data:`PAPER_PAIRS` order."""


@dataclass(frozen=True)
class FitReport:
    """What :func:`fit_library` fitted and wrote."""

    data: tuple[str, ...]
    """The transition files fitted on."""
    samples: int
    """Samples in them."""
    results: dict[str, FitResult]
    """Input kind -> its fit (the first is the one written to the library)."""
    written: tuple[str, ...]
    """Files written, relative to the library."""
    uncovered: tuple[str, ...] = ()
    """Ordered pairs (``"m-n"``) of the library's gaits that the fitted models do not cover: no samples (as
    ``gaitlib library`` counts them; a pair whose samples all succeed is covered, with no accuracy to report)."""
    note: str | None = None
    """What reading the data left out or tolerated (samples of policies the library no longer holds), else
    ``None``."""
    falls: Falls = DEFAULT_FALLS
    """The definition of a fall the labels followed."""
    data_sha256: tuple[str, ...] = ()
    """The content SHA-256 of each file of :attr:`data`, same order
    (:attr:`~gaitlib.transitions.TransitionFileInfo.files`): which samples the fit saw, whatever the files are called
    now."""

    def accuracy(self) -> dict[str, dict[str, float]]:
        """Input kind -> ``"m-n"`` -> balanced validation accuracy (0-1)."""
        return {
            kind: {f"{m}-{n}": a for (m, n), a in result.validation_accuracy.items()}
            for kind, result in self.results.items()
        }

    def as_dict(self) -> dict:
        """The content of ``accuracy.json``."""
        return {
            **ACCURACY_FORMAT,
            "data": list(self.data),
            "data_sha256": list(self.data_sha256),
            "samples": self.samples,
            "input_written": next(iter(self.results)),
            "falls": self.falls,
            "balanced_samples": {
                kind: sum(2 * (t + v) for t, v in result.split.per_class.values())
                for kind, result in self.results.items()
            },
            "balanced_validation_accuracy": self.accuracy(),
            "paper_table_3": {kind: dict(zip(PAPER_PAIRS, row, strict=True)) for kind, row in PAPER_TABLE_3.items()},
            "written": list(self.written),
            "uncovered_pairs": list(self.uncovered),
            "data_note": self.note,
        }


def fit_library(
    library: Library,
    data: TransitionData,
    *,
    sources: Sequence[Path | str],
    inputs: Sequence[str] = ("latent",),
    epochs: int = 100,
    seed: int = 0,
    falls: Falls = DEFAULT_FALLS,
    min_per_label: int = MIN_PER_LABEL,
    on_epoch: Callable[[str, EpochStats], None] | None = None,
) -> FitReport:
    """Fit ``library``'s transition-net (one per kind in ``inputs``; the first is written), TMT and accuracy report
    on ``data`` (read from ``sources``) and write them into the library (:func:`fit_nets`, then
    :func:`publish_fit`).

    Refuses, before any work, an unknown input kind and data collected with other policies than the library's
    (:class:`~gaitlib.errors.TransitionDataError`), and data too few to validate (:func:`check_validatable`).
    ``falls``: the definition of a fall the labels follow (every sample holds both outcomes), recorded in each file
    written. The library's route table, if it has one, is kept: it names the switching models it was measured with,
    so ``gaitlib library`` then calls it stale and gives the command that measures it again. ``on_epoch(kind,
    stats)`` reports progress.
    """
    fitted = fit_nets(library, data, sources=sources, inputs=inputs, epochs=epochs, seed=seed, falls=falls,
                      min_per_label=min_per_label, on_epoch=on_epoch)
    publish_fit(library, data, fitted)
    return fitted


def fit_nets(
    library: Library,
    data: TransitionData,
    *,
    sources: Sequence[Path | str],
    inputs: Sequence[str] = ("latent",),
    epochs: int = 100,
    seed: int = 0,
    falls: Falls = DEFAULT_FALLS,
    min_per_label: int = MIN_PER_LABEL,
    on_epoch: Callable[[str, EpochStats], None] | None = None,
) -> FitReport:
    """The transition-nets of :func:`fit_library` (one per kind in ``inputs``), fitted and reported, nothing
    written; refused as :func:`fit_library` refuses."""
    check_input_kinds(inputs)
    _checked_identities(library, data, sources)
    check_validatable(data, falls=falls, min_per_label=min_per_label)
    results = {}
    for kind in dict.fromkeys(inputs):
        report = None if on_epoch is None else (lambda stats, kind=kind: on_epoch(kind, stats))
        results[kind] = fit(data, FitConfig(kind=kind, epochs=epochs, seed=seed, falls=falls), on_epoch=report)
    names = data.header.gaits
    covered = {f"{names[m]}-{names[n]}" for m, n in data.samples.pairs()}
    return FitReport(
        data=tuple(map(str, sources)),
        samples=len(data.samples),
        results=results,
        written=tuple(f"{Library.SWITCHING}/{name}" for name in (*Library.BUNDLE, Library.CHECKSUMS)),
        uncovered=tuple(pair for pair in ordered_pairs(library.gaits()) if pair not in covered),
        note=data.info.note,
        falls=falls,
        data_sha256=tuple(content for _, content in data.info.files),
    )


def publish_fit(library: Library, data: TransitionData, fitted: FitReport) -> None:
    """Calibrate the first net of ``fitted`` (fitted on ``data``) on the rows it did not train on, build the TMT of
    ``data``, and publish them with the net and the accuracy report as ``library``'s switching models."""
    written = next(iter(fitted.results.values()))
    identities = dict(zip(data.header.gaits, data.header.identities, strict=True))
    labelled = data.labelled(fitted.falls)
    calibration = calibrate(written.net, labelled, train_rows=written.split.train, identities=identities,
                            falls=fitted.falls)
    table = build_table(labelled, identities=identities, source=", ".join(fitted.data), falls=fitted.falls)
    publish_models(library, net=lambda path: save_net(path, written), table=table, accuracy=fitted.as_dict(),
                   calibration=calibration)


def publish_models(library: Library, *, net: Callable[[Path], object], table: TransitionTable, accuracy: dict,
                   calibration: Calibration) -> None:
    """Write the switching models into ``library`` together, or none of them: the net (``net(path)`` writes it),
    the TMT, the accuracy report (``accuracy.json``'s content) and the calibration, with their checksum list. The
    route table and survival estimate there are kept (made with the old models, each then reads as stale where it
    is, never as missing)."""
    with library.publish_switching() as staging:  # the four replace the library's together, or none does
        net(staging / Library.NET)
        save_table(staging / Library.TMT, table)
        write_json(staging / Library.ACCURACY, accuracy, checksum=True)
        save_calibration(staging / Library.CALIBRATION, calibration)
        for kept in (Library.ROUTES, Library.SURVIVAL):
            if (library.switching_dir / kept).is_file():
                shutil.copy2(library.switching_dir / kept, staging / kept)
        library.write_checksums(staging, survival=_listed_survival(library) if (staging / Library.SURVIVAL).is_file()
                                else None)


def _listed_survival(library: Library) -> str | None:
    """The checksum the library's list gives its survival estimate, kept for the estimate a refit keeps (never
    taken anew from the file: a damaged estimate stays refused); ``None`` where no sound list gives one."""
    try:
        return library.listed_checksums().get(Library.SURVIVAL)
    except GaitlibError:
        return None


def check_validatable(data: TransitionData, *, falls: Falls = DEFAULT_FALLS,
                      min_per_label: int = MIN_PER_LABEL) -> None:
    """Refuse, in one line naming the pairs short of it, data in which an ordered pair has fewer than
    ``min_per_label`` successful or failed switches (labels by ``falls``): its held-out accuracy would rest on a
    handful of switches, or on none (:data:`MIN_PER_LABEL`; 0 accepts any data)."""
    if min_per_label <= 0:
        return
    samples, names = data.labelled(falls).samples, data.header.gaits
    short = []
    for m, n in sorted(samples.pairs()):
        success = samples.success[(samples.source == m) & (samples.dest == n)]
        ok, failed = int(success.sum()), int((~success.astype(bool)).sum())
        if min(ok, failed) < min_per_label:
            short.append(f"{names[m]}-{names[n]} ({ok} successes, {failed} failures)")
    if short:
        raise TransitionDataError(
            f"too few samples to validate a fit: each ordered pair needs {min_per_label} successful and "
            f"{min_per_label} failed switches ({falls} definition of a fall), and {len(short)} pair(s) have fewer: "
            f"{', '.join(short)}; collect more of them (gaitlib collect resumes a file with a larger --samples), or "
            "pass --min-per-label 0 to write a fit that cannot be validated"
        )


def evaluate_library(library: Library, data: TransitionData, *, sources: Sequence[Path | str],
                     falls: Falls = DEFAULT_FALLS) -> dict:
    """Score ``library``'s transition-net on ``data`` (balanced per pair), labelled by the definition of a fall
    ``falls``: input kind, data, the definitions and accuracy per ``"m-n"`` (0-1). Data of other policies than the
    library's are refused."""
    _checked_identities(library, data, sources)
    library.check_switching()
    saved = load_net(library.net_path, identities=library.identities(data.header.gaits))
    accuracy = {f"{m}-{n}": a for (m, n), a in evaluate_net(saved.net, data.labelled(falls)).items()}
    return {"input": saved.metadata["input"], "data": [str(s) for s in sources], "falls": falls,
            "net_fitted_with_falls": Falls(saved.metadata["fit"].get("falls", Falls.CONTACT)),
            "accuracy": accuracy}


def _checked_identities(library: Library, data: TransitionData, sources: Sequence[Path | str]) -> dict[str, str]:
    """Gait name -> identity of the policies ``data`` were collected with, refused unless they are the library's."""
    identities = dict(zip(data.header.gaits, data.header.identities, strict=True))
    library.check_identities(identities, what=f"transition data {', '.join(map(str, sources))}")
    return identities
