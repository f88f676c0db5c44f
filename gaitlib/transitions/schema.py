"""The transition file: one versioned, self-describing HDF5 schema that a killed writer cannot damage.

Layout (schema ``gaitlib.transitions``, version :data:`SCHEMA_VERSION`) of a file at ``PATH``:

* ``PATH``, the index: a small HDF5 file holding the header and the list of committed parts. It is only ever
  replaced whole (written beside it, flushed to disk, renamed over it), never changed in place.
* ``PATH.parts/part-<first row>-<end row>.h5``: the samples, one row per sample in each dataset of
  :data:`COLUMNS` (chunked, gzip-compressed with shuffle and Fletcher-32 checksums; each carries ``description``
  and ``units`` attributes). A part is written under a temporary name, flushed and renamed into place before the
  index that lists it; it is never changed afterwards. ``L`` is the source actors' latent size (``latent_dim``),
  ``E`` = 66 the explicit state (layout in ``explicit_layout``).

Index attributes: ``schema`` (str), ``schema_version`` (int); ``gaits`` (str list: ``source``/``dest`` index it);
``library_identities`` (str list, same order: SHA-256 of each library entry's weights, so samples never mix
policies); ``latent_dim`` (int); ``explicit_layout`` (JSON); ``settings`` (JSON: everything that defines how samples
are drawn; a resumed collection must use the same); ``sessions`` (JSON list: one record per collection run that
committed samples); ``created_by`` (JSON versions); ``created`` (UTC ISO time); ``count`` (int: committed samples);
``index_sha256`` (SHA-256 of the other attributes as stored and of the part list, checked by every reader).
Index dataset ``parts`` (rows in sample order): ``file`` (name in ``PATH.parts``), ``rows``, ``sha256`` (of the
part file's bytes). Readers use the listed parts only; part files that are not listed and temporaries (left by a
killed writer) are ignored, and removed by the next writer (:mod:`gaitlib.transitions.writer`). Parts and
index are made by HDF5 in memory and written by Python (:func:`gaitlib.atomic.write_bytes`): a full disk fails one
``OSError`` naming the file, and HDF5 never holds a file whose writes failed (it crashes at exit on one).

Version 1 (one HDF5 file appended in place, the ``count`` attribute committed last) is read, never appended to.
"""

from __future__ import annotations

import hashlib
import io
import json
import re
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from gaitlib.atomic import fsync_folder, write_bytes
from gaitlib.errors import TransitionDataError
from gaitlib.transitions.explicit import EXPLICIT_DIM, EXPLICIT_LAYOUT
from gaitlib.transitions.records import (
    COLUMNS,
    Column,
    TransitionBatch,
    TransitionData,
    TransitionFileInfo,
    TransitionHeader,
    content_sha256,
)

__all__ = [
    "COLUMNS",
    "SCHEMA_NAME",
    "SCHEMA_VERSION",
    "Column",
    "Part",
    "TransitionBatch",
    "TransitionData",
    "TransitionFileInfo",
    "TransitionHeader",
    "TransitionIndex",
    "compare_header",
    "parts_folder",
    "read",
    "read_part",
    "recorded_settings",
    "scan",
    "validate",
    "write_index",
    "write_part",
]

SCHEMA_NAME = "gaitlib.transitions"
"""Value of the ``schema`` attribute of an index."""
SCHEMA_VERSION = 4
"""Version of this layout (3: the index carries ``index_sha256``; 4: each sample has both outcomes, by the ``trunk``
and the ``contact`` definition of a fall, and its longest touch); files of other versions are refused."""
_PART_SCHEMA = "gaitlib.transitions.part"
_PART_NAME = re.compile(r"part-(\d{12})-(\d{12})\.h5")
_PART_DTYPE = np.dtype([("file", "S40"), ("rows", "<i8"), ("sha256", "S64")])
_DIGESTED = ("gaits", "library_identities", "latent_dim", "explicit_layout", "settings", "sessions", "created_by",
             "created", "count")
"""The index attributes ``index_sha256`` covers, with the part list."""


@dataclass(frozen=True)
class Part:
    """One committed part file."""

    file: str
    """Name in the parts folder: ``part-<first row>-<end row>.h5`` (12 digits each)."""
    rows: int
    """Samples in it."""
    sha256: str
    """SHA-256 of the file's bytes (hex)."""


@dataclass(frozen=True, kw_only=True)
class TransitionIndex:
    """What an index says."""

    header: TransitionHeader
    parts: tuple[Part, ...]
    """Committed parts in sample order."""
    sessions: tuple[dict, ...]
    """One record per collection run (seed, first chunk, samples at its start, ...)."""
    provenance: dict
    """``created_by`` (versions, as JSON text) and ``created`` (UTC ISO time)."""
    count: int
    """Committed samples."""


def parts_folder(path: Path) -> Path:
    """Where the parts of the transition file ``path`` live."""
    return Path(path).with_name(Path(path).name + ".parts")


def write_part(path: Path, batch: TransitionBatch, *, start: int) -> Part:
    """Write ``batch`` (rows ``start`` on, at least one) as a part of the transition file ``path``, durably; it is
    committed only once an index lists it."""
    folder = parts_folder(path)
    if not folder.is_dir():
        folder.mkdir()
        fsync_folder(folder.parent)
    name = f"part-{start:012d}-{start + len(batch):012d}.h5"
    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as f:
        f.attrs["schema"] = _PART_SCHEMA
        for column_name, values in batch.columns().items():
            column = COLUMNS[column_name]
            row_bytes = values.itemsize * int(np.prod(values.shape[1:]))
            rows = int(np.clip(2**18 // row_bytes, 64, 4096))
            ds = f.create_dataset(
                column_name, data=values, chunks=(min(rows, len(values)), *values.shape[1:]),
                compression="gzip", compression_opts=4, shuffle=True, fletcher32=True,
            )
            ds.attrs["description"] = column.description
            ds.attrs["units"] = column.units
    data = buffer.getvalue()
    write_bytes(folder / name, data, durable=True)
    return Part(name, len(batch), hashlib.sha256(data).hexdigest())


def write_index(path: Path, index: TransitionIndex) -> None:
    """Replace the index of ``path`` with ``index`` (durably: what it lists is on disk before, and the new index
    after this returns)."""
    header = index.header
    attrs = {
        "gaits": list(header.gaits),
        "library_identities": list(header.identities),
        "latent_dim": int(header.latent_dim),
        "explicit_layout": json.dumps(EXPLICIT_LAYOUT),
        "settings": json.dumps(header.settings, sort_keys=True),
        "sessions": json.dumps(list(index.sessions)),
        "created_by": index.provenance["created_by"],
        "created": index.provenance["created"],
        "count": sum(p.rows for p in index.parts),
    }
    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as f:
        f.attrs["schema"] = SCHEMA_NAME
        f.attrs["schema_version"] = SCHEMA_VERSION
        for name, value in attrs.items():
            f.attrs[name] = np.array(value, dtype=h5py.string_dtype()) if isinstance(value, list) else value
        f.attrs["index_sha256"] = _index_digest(attrs, index.parts)
        table = np.array([(p.file, p.rows, p.sha256) for p in index.parts], dtype=_PART_DTYPE)
        f.create_dataset("parts", data=table, maxshape=(None,))
    write_bytes(path, buffer.getvalue(), durable=True)


def scan(path: Path, *, keep: tuple[str, ...] = ()) -> tuple[TransitionIndex, dict[str, np.ndarray]]:
    """Check ``path`` completely (index, every committed part and row) and return its index and the committed
    rows of the columns ``keep``.

    Raises a one-line :class:`TransitionDataError` for: a missing, empty, non-HDF5, truncated or corrupt file or
    part, HDF5 that is not transition data, another schema version, a malformed index, a missing part or one that
    does not match its checksum, malformed datasets, gait indices out of range.
    """
    path = Path(path)
    if not path.is_file():
        raise TransitionDataError(f"no transition file at {path}")
    seen = None
    while True:
        with _open(path, str(path)) as f:
            index = _read_index(f, path)
        kept: dict[str, list[np.ndarray]] = {name: [] for name in keep}
        try:
            for part in index.parts:
                columns = read_part(path, part, index.header)
                for name in keep:
                    kept[name].append(columns[name])
        except _PartGone as gone:
            if index == seen:  # not a writer's merge under way: the index lists a part that is not there
                raise TransitionDataError(f"{path} is damaged: part {gone} listed in its index is missing") from None
            seen = index
            continue
        return index, {name: _joined(values, COLUMNS[name], index.header) for name, values in kept.items()}


def recorded_settings(path: Path) -> dict | None:
    """The collection settings the index of ``path`` records (its parts unread), or ``None`` where there is no
    sound transition index at ``path`` (:func:`scan` says what is wrong with it)."""
    try:
        with _open(Path(path), str(path)) as f:
            return _read_index(f, Path(path)).header.settings
    except (OSError, TransitionDataError):
        return None


def validate(path: Path) -> TransitionFileInfo:
    """Check ``path`` completely (see :func:`scan`) and describe it."""
    return _info(Path(path), scan(path)[0])


def read(path: Path) -> TransitionData:
    """Read the committed samples of ``path`` (checked as by :func:`validate`)."""
    index, columns = scan(path, keep=tuple(COLUMNS))
    return TransitionData(_info(Path(path), index), TransitionBatch(**columns))


def read_part(path: Path, part: Part, header: TransitionHeader) -> dict[str, np.ndarray]:
    """Every column of the committed ``part`` of ``path``, checked against its checksum and ``header``."""
    where = f"{path} part {part.file}"
    try:
        data = (parts_folder(path) / part.file).read_bytes()
    except FileNotFoundError:
        raise _PartGone(part.file) from None
    if hashlib.sha256(data).hexdigest() != part.sha256:
        raise TransitionDataError(f"{path} is damaged: part {part.file} does not match its checksum")
    try:
        with h5py.File(io.BytesIO(data), "r") as f:
            columns = {name: _rows(f, name, 0, part.rows, header, where) for name in COLUMNS}
    except OSError as error:
        raise TransitionDataError(f"{where} is corrupt ({_first_line(error)})") from error
    _check_rows(columns, part.rows, header, where)
    return columns


def compare_header(found: TransitionHeader, expect: TransitionHeader, path: Path) -> None:
    """Raise a one-line :class:`TransitionDataError` unless ``found`` (a file's) is ``expect``."""
    if found.gaits != tuple(expect.gaits):
        raise TransitionDataError(f"{path} holds gaits {list(found.gaits)}, not {list(expect.gaits)}")
    changed = [g for g, a, b in zip(found.gaits, found.identities, expect.identities, strict=True) if a != b]
    if changed:
        raise TransitionDataError(
            f"{path} was collected with other library policies for {', '.join(changed)} "
            "(library identities differ); write to a new file"
        )
    if found.latent_dim != expect.latent_dim:
        raise TransitionDataError(f"{path} holds latents of size {found.latent_dim}, not {expect.latent_dim}")
    wanted = json.loads(json.dumps(expect.settings, sort_keys=True))
    if found.settings != wanted:
        keys = sorted(k for k in set(found.settings) | set(wanted) if found.settings.get(k) != wanted.get(k))
        diffs = ", ".join(f"{k}: {found.settings.get(k)!r} in the file, {wanted.get(k)!r} now" for k in keys)
        raise TransitionDataError(f"{path} was collected with other settings ({diffs}); write to a new file")


# ---------------------------------------------------------------------------------------------------- internals
class _PartGone(Exception):
    """A listed part is not there: damage, or a writer merged it away after the index was read (read again)."""


def _width(column: Column, latent_dim: int) -> tuple[int, ...]:
    return {None: (), "latent": (latent_dim,), "explicit": (EXPLICIT_DIM,)}[column.width]


def _first_line(error: BaseException) -> str:
    text = str(error).strip()
    return text.splitlines()[0] if text else type(error).__name__


def _open(file: Path, name: str) -> h5py.File:
    """Open ``file`` (an index, or a part described as ``name``) for reading."""
    if file.stat().st_size == 0:
        raise TransitionDataError(f"{name} is an empty file (0 bytes), not transition data")
    try:
        return h5py.File(file, "r")
    except OSError as error:
        if not h5py.is_hdf5(file):
            raise TransitionDataError(f"{name} is not an HDF5 file") from error
        raise TransitionDataError(f"{name} is a corrupt or truncated HDF5 file ({_first_line(error)})") from error


def _text_list(values: object) -> tuple[str, ...]:
    return tuple(v.decode() if isinstance(v, bytes) else str(v) for v in np.atleast_1d(values))


def _read_index(f: h5py.File, path: Path) -> TransitionIndex:
    """The index of an open file; raises on anything malformed."""
    try:
        attrs = dict(f.attrs)
    except (OSError, RuntimeError) as error:
        raise TransitionDataError(f"{path} is corrupt or truncated ({_first_line(error)})") from error
    schema = attrs.get("schema")
    schema = schema.decode() if isinstance(schema, bytes) else schema
    if schema != SCHEMA_NAME:
        what = "no 'schema' attribute" if schema is None else f"schema '{schema}'"
        raise TransitionDataError(f"{path} is an HDF5 file but not gaitlib transition data ({what})")
    version = attrs.get("schema_version")
    if version != SCHEMA_VERSION:
        raise TransitionDataError(
            f"{path} has transition schema version {version}; this gaitlib reads version {SCHEMA_VERSION} only "
            "(collect into a new file: CHANGELOG.md)"
        )
    try:
        header = TransitionHeader(
            gaits=_text_list(attrs["gaits"]),
            identities=_text_list(attrs["library_identities"]),
            latent_dim=int(attrs["latent_dim"]),
            settings=json.loads(attrs["settings"]),
        )
        count = int(attrs["count"])
        sessions = tuple(json.loads(attrs["sessions"]))
        provenance = {"created_by": str(attrs["created_by"]), "created": str(attrs["created"])}
        listed = f["parts"]
        if listed.size * listed.dtype.itemsize > Path(path).stat().st_size:  # a damaged shape, not a part list
            raise ValueError(f"a part list of {listed.size} rows in a file of {Path(path).stat().st_size} bytes")
        parts = tuple(Part(row["file"].decode(), int(row["rows"]), row["sha256"].decode()) for row in listed[()])
        stored = {name: attrs[name] for name in _DIGESTED}
        stored |= {name: list(_text_list(stored[name])) for name in ("gaits", "library_identities")}
        sound = _index_digest(stored, parts) == str(attrs["index_sha256"])
    except (KeyError, TypeError, ValueError, OSError) as error:
        raise TransitionDataError(f"{path} is damaged: index attribute or part list missing or malformed") from error
    if not sound:
        raise TransitionDataError(f"{path} is damaged: its index does not match its checksum (index_sha256)")
    if len(header.gaits) != len(header.identities) or not 2 <= len(header.gaits) <= 127:
        raise TransitionDataError(f"{path} is damaged: {len(header.gaits)} gaits, {len(header.identities)} identities")
    index = TransitionIndex(
        header=header, parts=parts, sessions=sessions, provenance=provenance, count=count
    )
    _check_parts(index, path)
    return index


def _check_parts(index: TransitionIndex, path: Path) -> None:
    if index.count < 0:
        raise TransitionDataError(f"{path} is damaged: its sample count is negative ({index.count})")
    start = 0
    for part in index.parts:
        match = _PART_NAME.fullmatch(part.file)
        if not match or (int(match[1]), int(match[2])) != (start, start + part.rows) or part.rows < 1:
            raise TransitionDataError(
                f"{path} is damaged: its part list has '{part.file}' ({part.rows} rows) at row {start}"
            )
        start += part.rows
    if start != index.count:
        raise TransitionDataError(f"{path} is damaged: count {index.count} but its parts hold {start} samples")


def _rows(f: h5py.File, name: str, start: int, stop: int, header: TransitionHeader, where: str) -> np.ndarray:
    """Rows ``start`` to ``stop`` of dataset ``name``, checked against the column's dtype and width."""
    column = COLUMNS[name]
    width = _width(column, header.latent_dim)
    try:
        ds = f[name]
        if ds.shape[1:] != width or ds.dtype != np.dtype(column.dtype) or ds.shape[0] < stop:
            raise TransitionDataError(
                f"{where} is damaged: dataset '{name}' is {ds.dtype} {ds.shape}, expected {column.dtype} "
                f"({stop}, {', '.join(map(str, width))})"
            )
        return ds[start:stop]
    except (KeyError, OSError, ValueError) as error:
        raise TransitionDataError(
            f"{where} is corrupt or truncated: dataset '{name}' rows {start}-{stop} unreadable ({_first_line(error)})"
        ) from error


def _check_rows(columns: dict[str, np.ndarray], rows: int, header: TransitionHeader, where: str) -> None:
    for name in ("source", "dest"):
        values = columns[name][:rows]
        bad = values[(values < 0) | (values >= len(header.gaits))]
        if len(bad):
            raise TransitionDataError(
                f"{where} is damaged: '{name}' holds gait index {int(bad[0])}, the file has {len(header.gaits)} gaits"
            )


def _index_digest(attrs: dict, parts: tuple[Part, ...]) -> str:
    """SHA-256 of the index attributes :data:`_DIGESTED` (as stored) and the part list."""
    values = [attrs[name] if isinstance(attrs[name], list) else str(attrs[name]) for name in _DIGESTED]
    table = [[p.file, p.rows, p.sha256] for p in parts]
    return hashlib.sha256(json.dumps([values, table]).encode()).hexdigest()


def _joined(values: list[np.ndarray], column: Column, header: TransitionHeader) -> np.ndarray:
    if values:
        return np.concatenate(values)
    return np.zeros((0, *_width(column, header.latent_dim)), dtype=column.dtype)


def _info(path: Path, index: TransitionIndex) -> TransitionFileInfo:
    listed = {p.file for p in index.parts}
    folder = parts_folder(path)
    stray = [p for p in folder.glob("part-*.h5") if p.name not in listed] if folder.is_dir() else []
    note = f"{path}: {len(stray)} uncommitted part files are ignored" if stray else None
    content = content_sha256(tuple(p.sha256 for p in index.parts))
    return TransitionFileInfo(index.header, index.count, list(index.sessions), note, ((str(path), content),))
