"""``gaitlib fit --extend``: a library's switching models grown by the pairs of new data only.

A plain fit (:func:`~gaitlib.strategies.fitting.fit_library`) fits every pair its data hold and replaces the
library's models, so a library grown by new skills would collect every pair again: the old pairs' collections are
not kept. :func:`extend_library` fits the transition-net, its calibration and a TMT on data of some pairs only (the
new ones, and any old pair collected again, which the new fit takes over) and keeps the library's models for every
other pair. The net becomes a composite (:class:`~gaitlib.transition_net.ComposedNet`, ``net.pt`` format version 2)
whose kept parts serve the old pairs with their weights as they were; the calibration, TMT and accuracy report copy
the kept pairs' entries and add the new ones, each recording its parts (the pairs each serves and how it was fitted),
in the net's order. Extending a composite again flattens it: its parts are kept, less the pairs the new data take
over (a part left with none is dropped), and the new one is appended. Where the new data take over every pair the
kept models serve, nothing is kept: the result is the plain fit of the new data.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from gaitlib.atomic import read_json
from gaitlib.defaults import DEFAULT_FALLS, MIN_PER_LABEL, Falls
from gaitlib.errors import TransitionDataError
from gaitlib.library.layout import gait_order, ordered_pairs
from gaitlib.library.store import Library
from gaitlib.strategies.base import PHASE_GRID
from gaitlib.strategies.calibration import Calibration, calibrate, load_calibration, merge_calibrations
from gaitlib.strategies.fitting import ACCURACY_FORMAT, FitReport, fit_nets, publish_fit, publish_models
from gaitlib.strategies.tmt import TransitionTable, build_table, load_table, merge_tables
from gaitlib.transition_net import EpochStats, NetPart, check_input_kinds, load_parts, net_metadata, save_composed
from gaitlib.transitions import TransitionData

__all__ = ["ExtendReport", "KeptModels", "extend_library", "kept_models"]

_ACCURACY_PART = ("data", "data_sha256", "samples", "input_written", "falls", "balanced_samples",
                  "balanced_validation_accuracy", "data_note")
"""What ``accuracy.json`` records of each part (a plain fit's report, less what describes the whole file)."""


@dataclass(frozen=True)
class KeptModels:
    """A library's switching models as an extension keeps them."""

    parts: tuple[NetPart, ...]
    """The transition-net's parts (a plain net is one, serving the pairs it has samples of)."""
    table: TransitionTable
    calibration: Calibration
    records: dict[str, tuple[dict, ...]]
    """``Library.ACCURACY``, ``Library.CALIBRATION``, ``Library.TMT`` -> what the file records of each part, in the
    order of :attr:`parts`."""


@dataclass(frozen=True)
class ExtendReport:
    """What :func:`extend_library` fitted and wrote."""

    fit: FitReport
    """The fit of the new data alone."""
    served: dict[str, str]
    """Each ordered pair the written models serve (``"m-n"``, canonical order) -> ``"kept"`` (by a part the library
    held) or ``"new"`` (by the new fit)."""
    accuracy: dict
    """The content of the ``accuracy.json`` written (its ``parts`` say which pairs each part serves, and its data)."""

    @property
    def note(self) -> str | None:
        """What reading the new data left out or tolerated, else ``None``."""
        return self.fit.note

    @property
    def uncovered(self) -> tuple[str, ...]:
        """Ordered pairs of the library's gaits that no part serves."""
        return tuple(self.accuracy["uncovered_pairs"])

    def as_dict(self) -> dict:
        """``accuracy.json``'s content, with what serves each pair (``served_by``)."""
        return self.accuracy | {"served_by": self.served}


def kept_models(library: Library, *, input_kind: str, falls: Falls) -> KeptModels:
    """The switching models ``library`` holds, checked for an extension that fits ``input_kind`` nets on labels by
    ``falls``: one line (:class:`~gaitlib.errors.TransitionDataError`) where there are none, where they are damaged
    or fitted for policies other than the library's, or read another input kind or definition of a fall."""
    library.check_switching()  # none, or files that do not match their checksums
    current = library.identities()
    accuracy = read_json(library.accuracy_path, header=ACCURACY_FORMAT, what="a gaitlib accuracy report",
                         error=TransitionDataError)
    try:
        parts = load_parts(library.net_path, identities=current, sources=accuracy["data"])
    except (KeyError, IndexError, TypeError) as error:
        raise TransitionDataError(f"{library.accuracy_path} is damaged: it names no data ({error!r})") from error
    table = load_table(library.tmt_path, identities=current)
    calibration = load_calibration(library.calibration_path, identities=current)
    kind = parts[0].net.spec.kind
    if kind != input_kind:
        raise TransitionDataError(f"the switching models of {library.root} read '{kind}' inputs, and an extension "
                                  f"fits the kind the kept net reads: --input {kind}")
    kept_falls = Falls(parts[0].metadata["fit"].get("falls", Falls.CONTACT))
    if kept_falls != falls:
        raise TransitionDataError(f"the switching models of {library.root} label falls by the {kept_falls} "
                                  f"definition, and an extension fits with the one the kept models used: --falls "
                                  f"{kept_falls}")
    if table.bins != PHASE_GRID:
        raise TransitionDataError(f"the TMT of {library.root} has {table.bins} phase bins a cycle, not "
                                  f"{PHASE_GRID}; fit it again without --extend")
    pairs = [_texts(part.pairs) for part in parts]
    accuracy_records = _records(accuracy, pairs, what=str(library.accuracy_path))
    return KeptModels(parts, table, calibration, {
        Library.ACCURACY: tuple({key: record.get(key, _absent(key, kept_falls)) for key in _ACCURACY_PART}
                                | {"serves": record["serves"]} for record in accuracy_records),
        Library.CALIBRATION: _records(calibration.info, pairs, what=str(library.calibration_path)),
        Library.TMT: _records(table.info, pairs, what=str(library.tmt_path)),
    })


def extend_library(
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
) -> ExtendReport:
    """Fit ``library``'s switching models on the pairs ``data`` hold (read from ``sources``; the nets of ``inputs``,
    the first written, as :func:`~gaitlib.strategies.fitting.fit_library` fits them) and keep the library's models
    for every other pair (module doc); publish them together.

    Refused in one line before any work: no, damaged or stale kept models, another input kind or definition of a
    fall than theirs (:func:`kept_models`), and what :func:`~gaitlib.strategies.fitting.fit_library` refuses. The
    route table and survival estimate are kept as a plain fit keeps them.
    """
    check_input_kinds(inputs)
    kept = kept_models(library, input_kind=inputs[0], falls=falls)
    fitted = fit_nets(library, data, sources=sources, inputs=inputs, epochs=epochs, seed=seed, falls=falls,
                      min_per_label=min_per_label, on_epoch=on_epoch)
    names = data.header.gaits
    new_pairs = frozenset((names[m], names[n]) for m, n in data.samples.pairs())
    left = [part.pairs - new_pairs for part in kept.parts]
    keep = [k for k, pairs in enumerate(left) if pairs]
    if not keep:  # the new data hold every pair the kept models serve: nothing is kept
        publish_fit(library, data, fitted)
        return ExtendReport(fitted, dict.fromkeys(_texts(new_pairs), "new"), fitted.as_dict())
    written = next(iter(fitted.results.values()))
    identities = dict(zip(names, data.header.identities, strict=True))
    labelled = data.labelled(falls)
    calibration = calibrate(written.net, labelled, train_rows=written.split.train, identities=identities,
                            falls=falls)
    table = build_table(labelled, identities=identities, source=", ".join(fitted.data), falls=falls,
                        typical_value=dict(zip(kept.table.gaits, kept.table.typical_value.tolist(), strict=True)))
    settings = data.header.settings
    files = settings["files"] if "files" in settings else [{"path": fitted.data[0], "settings": settings}]
    parts = [*(dataclasses.replace(kept.parts[k], pairs=left[k]) for k in keep),
             NetPart(written.net, net_metadata(written), new_pairs, tuple(files))]
    gaits = gait_order(name for part in parts for name in part.net.spec.gaits)

    def records(name: str, new: dict) -> list[dict]:
        """What file ``name`` records of each part: the kept ones less the pairs taken over, then the new one."""
        return [*(kept.records[name][k] | {"serves": _texts(left[k])} for k in keep),
                new | {"serves": _texts(new_pairs)}]

    merged_calibration = merge_calibrations(kept.calibration, calibration, new_pairs=new_pairs, gaits=gaits,
                                            parts=records(Library.CALIBRATION, calibration.info))
    merged_table = merge_tables(kept.table, table, new_pairs=new_pairs, gaits=gaits,
                                parts=records(Library.TMT, table.info))
    report = fitted.as_dict()
    accuracy = _merged_accuracy(report, records(Library.ACCURACY, {key: report[key] for key in _ACCURACY_PART}),
                                library_gaits=library.gaits())
    publish_models(library, net=lambda path: save_composed(path, parts), table=merged_table, accuracy=accuracy,
                   calibration=merged_calibration)
    served = {pair: "new" if tuple(pair.split("-")) in new_pairs else "kept" for pair in ordered_pairs(gaits)
              if any(tuple(pair.split("-")) in part.pairs for part in parts)}
    return ExtendReport(fitted, served, accuracy)


def _merged_accuracy(report: dict, parts: list[dict], *, library_gaits: Sequence[str]) -> dict:
    """``accuracy.json`` of a composite: the new fit's ``report`` with data and samples summed over ``parts``, each
    input kind's accuracies the union of the pairs each part serves (a kind fitted on one part's data only covers
    its pairs), the pairs no part serves recomputed over ``library_gaits``, and ``parts`` recorded."""
    kinds = dict.fromkeys([report["input_written"],
                           *(kind for part in parts for kind in part["balanced_validation_accuracy"])])
    served = {pair for part in parts for pair in part["serves"]}
    return report | {
        "data": [path for part in parts for path in part["data"]],
        "data_sha256": [content for part in parts for content in part["data_sha256"]],
        "samples": sum(part["samples"] for part in parts),
        "balanced_samples": {kind: sum(part["balanced_samples"].get(kind, 0) for part in parts) for kind in kinds},
        "balanced_validation_accuracy": {
            kind: {pair: accuracy for part in parts
                   for pair, accuracy in part["balanced_validation_accuracy"].get(kind, {}).items()
                   if pair in part["serves"]}
            for kind in kinds
        },
        "uncovered_pairs": [pair for pair in ordered_pairs(library_gaits) if pair not in served],
        "data_note": "; ".join(part["data_note"] for part in parts if part["data_note"]) or None,
        "parts": parts,
    }


def _records(payload: dict, pairs: list[list[str]], *, what: str) -> tuple[dict, ...]:
    """What ``payload`` (an ``accuracy.json``, or a calibration's or TMT's info) records of each of the net's parts,
    whose pairs are ``pairs``, each record with the pairs its part serves (``serves``): a plain fit's payload is its
    one part's record; a composite's lists its parts, which must be the net's."""
    if "parts" not in payload:
        if len(pairs) != 1:
            raise TransitionDataError(f"{what} records one fit, and the transition-net beside it {len(pairs)} parts: "
                                      "the switching models are damaged; run gaitlib fit")
        return (payload | {"serves": pairs[0]},)
    records = payload["parts"]
    if not (isinstance(records, list) and len(records) == len(pairs)
            and all(isinstance(r, dict) and r.get("serves") == p for r, p in zip(records, pairs, strict=True))):
        raise TransitionDataError(f"{what} is damaged: its parts are not the transition-net's; run gaitlib fit")
    return tuple(records)


def _absent(key: str, falls: Falls) -> object:
    """What an ``accuracy.json`` written before ``key`` was recorded means by its absence."""
    return {"data_sha256": [], "falls": falls, "data_note": None}.get(key)


def _texts(pairs: Iterable[tuple[str, str]]) -> list[str]:
    """``pairs`` as ``"m-n"``, in canonical order (gait names sorted)."""
    return [f"{m}-{n}" for m, n in sorted(pairs)]
