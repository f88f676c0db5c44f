"""``switching/checksums.json``: the SHA-256 of each file of a library's switching folder, checked before the file
is used.

The four models a fit makes together (the transition-net, the TMT, the accuracy report, the calibration) are listed
by every fit; the guard's survival estimate (``survival.pt``), written apart from them (``gaitlib survival fit`` and
``survival catches``), is listed beside them by its writers, each of which publishes the list with the estimate in
one step. What a measurement made with the switching models records as their identity (:func:`models_identity`) is
the SHA-256 of the list of the four alone, as a fit writes it: a new survival estimate leaves it as it was, so that
a route table measured with the same models stays current.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable, Mapping
from pathlib import Path

from gaitlib.atomic import CHECKSUM_KEY, json_checksum, read_json, write_json

__all__ = ["CHECKSUMS_FORMAT", "listed_checksums", "models_identity", "write_listed"]

CHECKSUMS_FORMAT = {"format": "gaitlib.switching_checksums", "format_version": 1}
"""Header of ``switching/checksums.json``."""


def listed_checksums(path: Path, *, error: type[Exception]) -> dict[str, str]:
    """File name -> SHA-256 listed in the checksum list ``path`` (which exists); ``error`` with one line when the list
    is not one, or is damaged."""
    payload = read_json(path, header=CHECKSUMS_FORMAT, what="a gaitlib checksum list", error=error)
    files = payload.get("files")
    if not isinstance(files, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in files.items()):
        raise error(f"{path} is damaged: its files are not names with checksums")
    return files


def write_listed(path: Path, files: Mapping[str, str]) -> Path:
    """Write the checksum list ``path`` of ``files`` (name -> SHA-256, in the order given), atomically."""
    return write_json(path, CHECKSUMS_FORMAT | {"files": dict(files)}, checksum=True)


def models_identity(files: Mapping[str, str], models: Iterable[str]) -> str:
    """SHA-256 of the checksum list of ``models`` alone (in that order) as :func:`write_listed` writes it, from the
    listed ``files``: the file's own SHA-256 where it lists nothing else."""
    payload = CHECKSUMS_FORMAT | {"files": {name: files.get(name) for name in models}}
    text = json.dumps(payload | {CHECKSUM_KEY: json_checksum(payload)}, indent=2) + "\n"
    return hashlib.sha256(text.encode()).hexdigest()
