"""Transition-nets on disk: one ``.pt`` file of weights (normalization buffers included) and metadata, written
atomically, loaded only for the library policies it was fitted for.

The file is a ``torch.save`` dict ``{"metadata": ..., "state_dict": ...}`` readable with ``weights_only=True``.

Format version 1, one net: metadata holds the format name and version, input kind, gaits, the library identity
(SHA-256) of each gait, latent and feature sizes, network shape, normalization, data size and settings, the
balanced split's sizes, accuracies, the fit settings and versions; the state dict is the net's.

Format version 2, a composite (:class:`~gaitlib.transition_net.composed.ComposedNet`, written by ``gaitlib fit
--extend``): the top-level metadata holds the format, the input kind, the union of the parts' gaits in canonical
order with their identities, the latent and feature sizes, ``fit.falls``, ``data.settings.files`` (every part's
transition files, each ``{"path", "settings"}``), the validation accuracy of each pair by the part that serves it,
the versions, and ``parts``: per part its own version-1 metadata plus ``pairs`` (the ordered pairs it serves,
``"m-n"``) and ``data_files`` (its transition files). The state dict holds each part's under ``parts.K.`` (K from 0,
in the order of ``parts``).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import torch

from gaitlib.atomic import torch_bytes, write_bytes
from gaitlib.defaults import Falls
from gaitlib.errors import TransitionDataError
from gaitlib.library.layout import check_identities, gait_order
from gaitlib.transition_net.composed import ComposedNet
from gaitlib.transition_net.features import FeatureSpec
from gaitlib.transition_net.fit import FitResult
from gaitlib.transition_net.model import TransitionNet

__all__ = [
    "COMPOSED_VERSION",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "NetPart",
    "SavedNet",
    "load_net",
    "load_parts",
    "net_metadata",
    "read_metadata",
    "save_composed",
    "save_net",
]

FORMAT_NAME = "gaitlib.transition_net"
"""Value of the metadata's ``format``."""
FORMAT_VERSION = 1
"""Version of the layout of one net."""
COMPOSED_VERSION = 2
"""Version of the layout of a composite net; files of versions other than these two are refused."""


@dataclass(frozen=True)
class SavedNet:
    """A loaded transition-net (eval mode) and its metadata (a composite's top-level metadata)."""

    net: TransitionNet | ComposedNet
    metadata: dict


@dataclass(frozen=True)
class NetPart:
    """One part of a composite transition-net: a plain net, what it serves, and where it came from."""

    net: TransitionNet
    metadata: dict
    """Its own version-1 metadata (:func:`net_metadata`)."""
    pairs: frozenset[tuple[str, str]]
    """The ordered pairs (names) it serves."""
    files: tuple[dict, ...]
    """The transition files it was fitted on, each ``{"path", "settings"}``."""


def net_metadata(result: FitResult) -> dict:
    """The version-1 metadata of ``result``'s net (plain lists and dicts: loadable with ``weights_only=True``)."""
    net, gaits = result.net, result.net.spec.gaits
    metadata = {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "input": net.spec.kind,
        "gaits": list(gaits),
        "library_identities": dict(zip(gaits, result.identities, strict=True)),
        "latent_dim": net.spec.latent_dim,
        "feature_dim": net.spec.dim,
        "network": {"hidden": list(net.hidden), "dropout": net.dropout, "output": "logit (sigmoid at inference)"},
        "normalization": "inputs standardized with the training set's feature_mean / feature_std (in state_dict)",
        "data": {
            "samples": result.data_samples,
            "settings": result.data_settings,
            "balanced_per_class": {
                f"{gaits[m]}->{gaits[n]}": {"train": t, "validation": v}
                for (m, n), (t, v) in result.split.per_class.items()
            },
            "skipped_pairs": [f"{gaits[m]}->{gaits[n]}" for m, n in result.split.skipped],
        },
        "accuracy": {
            "validation": {f"{m}->{n}": a for (m, n), a in result.validation_accuracy.items()},
            "validation_overall": result.validation_overall,
            "train": result.train_accuracy,
        },
        "fit": dataclasses.asdict(result.config) | {"falls": result.config.falls.value},
        "versions": _versions(),
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
    }
    return json.loads(json.dumps(metadata))


def save_net(path: Path, result: FitResult) -> Path:
    """Write ``result``'s net and metadata to ``path`` (a temporary file beside it, then renamed over it)."""
    payload = {"metadata": net_metadata(result), "state_dict": result.net.state_dict()}
    return write_bytes(Path(path), torch_bytes(payload))


def save_composed(path: Path, parts: Sequence[NetPart]) -> Path:
    """Write a composite of ``parts`` (format version 2, module doc) to ``path``, atomically; its gaits are the union
    of theirs in canonical order. Parts of different input kinds, latent sizes, definitions of a fall or identities of
    one gait are refused in one line, and so is a pair served twice."""
    gaits = gait_order(name for part in parts for name in part.net.spec.gaits)
    composed = ComposedNet([p.net for p in parts], pairs=[p.pairs for p in parts], gaits=gaits)
    falls = {_falls(p.metadata) for p in parts}
    if len(falls) != 1:
        raise TransitionDataError(f"the parts of a composite transition-net were fitted with different definitions of "
                                  f"a fall ({', '.join(sorted(falls))}); fit them with one --falls")
    identities: dict[str, str] = {}
    for part in parts:
        for gait, identity in part.metadata["library_identities"].items():
            if identities.setdefault(gait, identity) != identity:
                raise TransitionDataError(f"the parts of a composite transition-net hold different '{gait}' policies")
    files = list({str(f["path"]): f for part in parts for f in part.files}.values())
    validation = {text: a for part in parts for text, a in part.metadata["accuracy"]["validation"].items()
                  if tuple(text.split("->")) in part.pairs}
    metadata = {
        "format": FORMAT_NAME,
        "format_version": COMPOSED_VERSION,
        "input": composed.spec.kind,
        "gaits": list(gaits),
        "library_identities": {gait: identities[gait] for gait in gaits},
        "latent_dim": composed.spec.latent_dim,
        "feature_dim": composed.spec.dim,
        "fit": {"falls": falls.pop()},
        "data": {"settings": {"files": files}},
        "accuracy": {"validation": validation},
        "parts": [p.metadata | {"pairs": [f"{m}-{n}" for m, n in sorted(p.pairs)], "data_files": list(p.files)}
                  for p in parts],
        "versions": _versions(),
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
    }
    metadata = json.loads(json.dumps(metadata))
    return write_bytes(Path(path), torch_bytes({"metadata": metadata, "state_dict": composed.state_dict()}))


def read_metadata(path: Path) -> dict:
    """The metadata of the transition-net at ``path`` (format, version and the presence of an identity per gait
    checked; the identities themselves not)."""
    return _read(Path(path))["metadata"]


def load_net(path: Path, *, identities: Mapping[str, str]) -> SavedNet:
    """Load the transition-net at ``path`` (one net or a composite) for the current library, given as gait name ->
    library identity.

    Raises :class:`TransitionDataError` if the file is missing, not a transition-net, of another format version,
    damaged, or fitted for policies other than the current library's entries of its gaits (each part's checked).
    """
    path = Path(path)
    saved = _read(path)
    metadata = saved["metadata"]
    check_identities(metadata["library_identities"], identities, what=f"transition-net {path}")
    if metadata["format_version"] == FORMAT_VERSION:
        return SavedNet(_plain(path, metadata, saved["state_dict"]), metadata)
    return SavedNet(_composed(path, saved, identities), metadata)


def load_parts(path: Path, *, identities: Mapping[str, str], sources: Sequence[str]) -> tuple[NetPart, ...]:
    """The parts of the transition-net at ``path``, checked as :func:`load_net` checks them: a composite's, or one
    net as one part serving the pairs it has samples of. ``sources``: the transition files a version-1 net was fitted
    on, as ``accuracy.json`` names them (its metadata records their settings, not their paths)."""
    path = Path(path)
    saved = _read(path)
    metadata = saved["metadata"]
    check_identities(metadata["library_identities"], identities, what=f"transition-net {path}")
    if metadata["format_version"] == FORMAT_VERSION:
        net = _plain(path, metadata, saved["state_dict"])
        data = metadata["data"]
        pairs = frozenset(_pair(text, "->") for text in [*data["balanced_per_class"], *data["skipped_pairs"]])
        settings = data["settings"]
        files = settings["files"] if "files" in settings else [{"path": str(sources[0]), "settings": settings}]
        return (NetPart(net, metadata, pairs, tuple(files)),)
    composed = _composed(path, saved, identities)
    return tuple(
        NetPart(net, {k: v for k, v in record.items() if k not in ("pairs", "data_files")}, pairs,
                tuple(record["data_files"]))
        for net, pairs, record in zip(composed.parts, composed.pairs, metadata["parts"], strict=True)
    )


def _plain(path: Path, metadata: dict, state: dict) -> TransitionNet:
    """The version-1 net ``metadata`` describes with the weights ``state``, in eval mode."""
    try:
        net = _unloaded(metadata)
        net.load_state_dict(state)
    except (KeyError, TypeError, RuntimeError) as error:
        raise TransitionDataError(f"transition-net {path} is damaged: {str(error).splitlines()[0]}") from error
    return net.eval()


def _unloaded(metadata: dict) -> TransitionNet:
    """A net of the shape version-1 ``metadata`` describes, its weights not loaded."""
    spec = FeatureSpec(kind=metadata["input"], gaits=tuple(metadata["gaits"]), latent_dim=metadata["latent_dim"])
    network = metadata["network"]
    return TransitionNet(spec, hidden=tuple(network["hidden"]), dropout=network["dropout"])


def _composed(path: Path, saved: dict, identities: Mapping[str, str]) -> ComposedNet:
    """The composite net a version-2 file holds, in eval mode, each part checked against ``identities``."""
    metadata = saved["metadata"]
    try:
        records = metadata["parts"]
        if not isinstance(records, list) or not records:
            raise ValueError("it lists no parts")
        nets = [_unloaded(record) for record in records]
        pairs = [frozenset(_pair(text, "-") for text in record["pairs"]) for record in records]
        for k, record in enumerate(records):
            if set(record["library_identities"]) != set(record["gaits"]) or any(
                    metadata["library_identities"].get(g) != i for g, i in record["library_identities"].items()):
                raise ValueError(f"part {k + 1}'s identities are not the composite's for its gaits")
            if _falls(record) != _falls(metadata) or record["input"] != metadata["input"]:
                raise ValueError(f"part {k + 1} was fitted with another input or definition of a fall than the "
                                 "composite records")
            if not isinstance(record["data_files"], list):
                raise ValueError(f"part {k + 1} lists no data files")
        gaits = gait_order(name for net in nets for name in net.spec.gaits)
        if tuple(metadata["gaits"]) != gaits:
            raise ValueError(f"its gaits {metadata['gaits']} are not the union of its parts' {list(gaits)}")
        composed = ComposedNet(nets, pairs=pairs, gaits=gaits)
        loaded = composed.load_state_dict(saved["state_dict"], strict=False)
        if loaded.missing_keys or loaded.unexpected_keys:
            keys = loaded.missing_keys or loaded.unexpected_keys
            raise ValueError(f"weights {'missing' if loaded.missing_keys else 'unexpected'}: {keys[0]}"
                             + (f" and {len(keys) - 1} more" if len(keys) > 1 else ""))
    except (KeyError, TypeError, ValueError, AttributeError, RuntimeError, TransitionDataError) as error:
        what = f"missing {error}" if isinstance(error, KeyError) else str(error).splitlines()[0]
        raise TransitionDataError(f"transition-net {path} is damaged: {what}") from error
    for k, record in enumerate(records):
        check_identities(record["library_identities"], identities, what=f"part {k + 1} of transition-net {path}")
    return composed.eval()


def _pair(text: str, separator: str) -> tuple[str, str]:
    """``("m", "n")`` of ``"m-n"`` (or ``"m->n"``); ``ValueError`` for text that names no pair."""
    m, found, n = str(text).partition(separator)
    if not (found and m and n):
        raise ValueError(f"'{text}' is not an ordered pair")
    return m, n


def _falls(metadata: dict) -> str:
    """The definition of a fall a net's metadata records (nets fitted before it was recorded: ``contact``)."""
    return Falls(metadata["fit"].get("falls", Falls.CONTACT)).value


def _versions() -> dict:
    import gaitlib

    return {"gaitlib": gaitlib.__version__, "torch": torch.__version__}


def _read(path: Path) -> dict:
    if not path.is_file():
        raise TransitionDataError(f"no transition-net at {path}")
    try:
        saved = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:  # torch raises several unrelated types for a non-checkpoint file
        raise TransitionDataError(f"{path} is not a readable transition-net ({type(error).__name__})") from error
    metadata = saved.get("metadata") if isinstance(saved, dict) else None
    if not isinstance(metadata, dict) or metadata.get("format") != FORMAT_NAME:
        raise TransitionDataError(f"{path} is not a gaitlib transition-net")
    if metadata.get("format_version") not in (FORMAT_VERSION, COMPOSED_VERSION):
        raise TransitionDataError(
            f"transition-net {path} has format version {metadata.get('format_version')}; "
            f"this gaitlib reads versions {FORMAT_VERSION} and {COMPOSED_VERSION}"
        )
    gaits, identities = metadata.get("gaits"), metadata.get("library_identities")
    if not (isinstance(gaits, list) and isinstance(identities, dict) and set(identities) == set(gaits)):
        raise TransitionDataError(f"transition-net {path} is damaged: no library identity for each of its gaits")
    return saved
