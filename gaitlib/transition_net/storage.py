"""Transition-nets on disk: one ``.pt`` file of weights (normalization buffers included) and metadata, written
atomically, loaded only for the library policies it was fitted for.

The file is a ``torch.save`` dict ``{"metadata": ..., "state_dict": ...}`` readable with ``weights_only=True``.
Metadata: format name and version, input kind, gaits, the library identity (SHA-256) of each gait, latent and
feature sizes, network shape, normalization, data size and settings, the balanced split's sizes, accuracies, the
fit settings and versions.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import torch

from gaitlib.atomic import torch_bytes, write_bytes
from gaitlib.errors import TransitionDataError
from gaitlib.library.layout import check_identities
from gaitlib.transition_net.features import FeatureSpec
from gaitlib.transition_net.fit import FitResult
from gaitlib.transition_net.model import TransitionNet

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "SavedNet", "load_net", "read_metadata", "save_net"]

FORMAT_NAME = "gaitlib.transition_net"
"""Value of the metadata's ``format``."""
FORMAT_VERSION = 1
"""Version of this layout; files of another version are refused."""


@dataclass(frozen=True)
class SavedNet:
    """A loaded transition-net (eval mode) and its metadata."""

    net: TransitionNet
    metadata: dict


def save_net(path: Path, result: FitResult) -> Path:
    """Write ``result``'s net and metadata to ``path`` (a temporary file beside it, then renamed over it)."""
    import gaitlib

    path = Path(path)
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
        "versions": {"gaitlib": gaitlib.__version__, "torch": torch.__version__},
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
    }
    metadata = json.loads(json.dumps(metadata))  # plain lists and dicts only: loadable with weights_only=True
    write_bytes(path, torch_bytes({"metadata": metadata, "state_dict": net.state_dict()}))
    return path


def read_metadata(path: Path) -> dict:
    """The metadata of the transition-net at ``path`` (format, version and the presence of an identity per gait
    checked; the identities themselves not)."""
    return _read(Path(path))["metadata"]


def load_net(path: Path, *, identities: Mapping[str, str]) -> SavedNet:
    """Load the transition-net at ``path`` for the current library, given as gait name -> library identity.

    Raises :class:`TransitionDataError` if the file is missing, not a transition-net, of another format version, or
    fitted for policies other than the current library's entries of its gaits.
    """
    path = Path(path)
    saved = _read(path)
    metadata = saved["metadata"]
    check_identities(metadata["library_identities"], identities, what=f"transition-net {path}")
    try:
        spec = FeatureSpec(kind=metadata["input"], gaits=tuple(metadata["gaits"]), latent_dim=metadata["latent_dim"])
        network = metadata["network"]
        net = TransitionNet(spec, hidden=tuple(network["hidden"]), dropout=network["dropout"])
        net.load_state_dict(saved["state_dict"])
    except (KeyError, TypeError, RuntimeError) as error:
        raise TransitionDataError(f"transition-net {path} is damaged: {str(error).splitlines()[0]}") from error
    return SavedNet(net.eval(), metadata)


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
    if metadata.get("format_version") != FORMAT_VERSION:
        raise TransitionDataError(
            f"transition-net {path} has format version {metadata.get('format_version')}; "
            f"this gaitlib reads version {FORMAT_VERSION}"
        )
    gaits, identities = metadata.get("gaits"), metadata.get("library_identities")
    if not (isinstance(gaits, list) and isinstance(identities, dict) and set(identities) == set(gaits)):
        raise TransitionDataError(f"transition-net {path} is damaged: no library identity for each of its gaits")
    return saved
