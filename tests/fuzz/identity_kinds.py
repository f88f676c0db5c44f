"""The identity kinds of the fault-injection harness (byte_flips.py): what a run or a fit reads, changed or read twice.

- **resume identity**: a training run was started from a gait file and a handover-states file; each is changed (a
  flipped byte, or a structured edit of the gait file: another body height, stride, phase, name, ...) and the run is
  resumed as ``gaitlib train --resume`` checks it, before any simulation
  (:func:`gaitlib.training.trainer.resume_point`). A change of what is read must be refused; only a change that
  leaves the description the same (its keys in another order, its name left to the file's) may resume.
- **data overlap**: the samples of a transition file are given to a fit a second time under another guise (the same
  path twice, a hard link, a symbolic link, a copy, a copy with its index written again, a subset of its samples,
  its samples in another order, a collection with the same seed and settings) and read as ``gaitlib fit`` reads
  several files (:func:`gaitlib.transitions.read_all`): every sample must be counted once.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import random
import shutil
import tomllib
from collections.abc import Callable
from pathlib import Path

from structured_edits import EditTarget, _at, _reorder

from gaitlib.atomic import file_sha256
from gaitlib.errors import GaitlibError
from gaitlib.gaits import load_gait_file
from gaitlib.training import get_preset
from gaitlib.training.trainer import TrainRequest, resume_point, train_gait
from gaitlib.transitions import read, read_all, schema
from gaitlib.transitions.writer import open_writer

__all__ = ["OVERLAPS", "overlap", "resume_reader", "resume_target", "start_resumable_run"]

_SWITCH_START = 0.5


def _request(root: Path, *, resume: bool) -> TrainRequest:
    """The run of :func:`start_resumable_run`, as its resume asks for it (the gait file read now)."""
    return TrainRequest(
        description=load_gait_file(root / "stand.toml"), preset=get_preset("tiny"), iterations=1 + resume,
        library=root / "resumed", run_dir=root / "runs" / "resume", backend="mujoco", eval_episodes=1,
        eval_seconds=0.3, states=root / "states.npz", switch_start=_SWITCH_START, resume=resume,
    )


def start_resumable_run(root: Path, gait_file: Path) -> None:
    """Train one iteration of the stand from a copy of ``gait_file`` (``root/stand.toml``) and the states
    ``root/states.npz``, into a library of its own: the run whose resume the kind checks."""
    shutil.copyfile(gait_file, root / "stand.toml")
    train_gait(_request(root, resume=False))


def resume_reader(root: Path) -> Callable[[], object]:
    """What a resume of the run uses: the description read, the states file's SHA-256 and the iteration it would
    continue from (a refusal raises)."""

    def resumed() -> object:
        request = _request(root, resume=True)
        saved = resume_point(request)
        return dataclasses.asdict(request.description), file_sha256(request.states), saved["iter"]

    return resumed


def _toml(value: object) -> str:
    """``value`` as TOML (nan and infinities as TOML spells them; an object as an inline table)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float) and not math.isfinite(value):
        return "nan" if value != value else ("inf" if value > 0 else "-inf")
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return "{ " + ", ".join(f"{json.dumps(str(k))} = {_toml(v)}" for k, v in value.items()) + " }"


def _save_toml(path: Path, content: dict) -> None:
    """``content`` as a TOML file: plain keys first, each object after them as a table."""
    plain = [f"{json.dumps(str(k))} = {_toml(v)}" for k, v in content.items() if not isinstance(v, dict)]
    tables = [f"[{json.dumps(str(k))}]\n" + "\n".join(f"{json.dumps(str(key))} = {_toml(v)}" for key, v in t.items())
              for k, t in content.items() if isinstance(t, dict)]
    path.write_text("\n".join(plain) + "\n\n" + "\n\n".join(tables) + "\n")


def resume_target(root: Path) -> EditTarget:
    """The gait file of the resumable run as a target of structured edits, read by its resume."""
    return EditTarget(
        path=root / "stand.toml", load=lambda path: tomllib.loads(path.read_text()), save=_save_toml,
        read=resume_reader(root),
        required=("duty_factor", "stride_frequency", "forward_speed", "swing_height", "body_height", "phase_offsets",
                  "phase_offsets.*"),
        semantic={
            "the trunk 4 cm higher": _at("body_height", 0.30),
            "another stride frequency": _at("stride_frequency", 2.0),
            "feet that lift": _at("duty_factor", 0.9),
            "a swing height": _at("swing_height", 0.05),
            "a leg half a cycle out of phase": _at("phase_offsets.FR", 0.5),
            "another gait's name": _at("name", "trot"),
            "a wider stance": _at("foot_lateral_offset", 0.02),
            "a swaying trunk": _at("trunk_sway", True),
            "a bouncing trunk": _at("trunk_bounce", True),
            "a moving stand": _at("forward_speed", 0.3),
            "an unknown key": _at("stiffness", 60.0),
            "a body height as text": _at("body_height", "0.26"),
            "(the keys in another order)": _reorder,
            "(the name left to the file's)": lambda content: content.pop("name"),
        },
    )


def _twice(data: Path, other: Path) -> Path:
    return data


def _linked(data: Path, other: Path, *, how: Callable[[Path, Path], object]) -> Path:
    how(data, other)
    shutil.copytree(schema.parts_folder(data), schema.parts_folder(other), copy_function=how)
    return other


def _symlinked(data: Path, other: Path) -> Path:
    other.symlink_to(data)
    schema.parts_folder(other).symlink_to(schema.parts_folder(data), target_is_directory=True)
    return other


def _index_again(data: Path, other: Path) -> Path:
    """A copy whose index is written anew (another creation time, one more collection run in its ``sessions`` list,
    the same parts)."""
    _linked(data, other, how=shutil.copy2)
    index, _ = schema.scan(other)
    schema.write_index(other, dataclasses.replace(
        index, sessions=(*index.sessions, {"note": "written again"}),
        provenance=index.provenance | {"created": "2000-01-01T00:00:00+00:00"}))
    return other


def _rewritten(order: Callable[[int], object]) -> Callable[[Path, Path], Path]:
    """A new file of ``data``'s samples picked by ``order(count)`` (an index array or slice): other parts."""

    def make(data: Path, other: Path) -> Path:
        loaded = read(data)
        with open_writer(other, header=loaded.header) as writer:
            writer.append(loaded.samples.select(order(len(loaded.samples))))
        return other

    return make


OVERLAPS: dict[str, Callable[[Path, Path], Path]] = {
    "the same path twice": _twice,
    "a hard link": lambda data, other: _linked(data, other, how=os.link),
    "a symbolic link": _symlinked,
    "a copy": lambda data, other: _linked(data, other, how=shutil.copy2),
    "a copy with its index written again": _index_again,
    "half its samples in a new file": _rewritten(lambda n: slice(0, n // 2)),
    "its samples in another order": _rewritten(lambda n: slice(None, None, -1)),
}
"""The guises the data-overlap kind gives a file's samples a second time (``other``: a new path to make it at)."""


def overlap(data: Path, same_seed: Path, scratch: Path, count: int, rng: random.Random,
            same: Callable[[object, object], bool]) -> dict:
    """``count`` fits' reads of ``data`` and its samples a second time, the guises of :data:`OVERLAPS` and a
    collection with the same seed and settings (``same_seed``) drawn in turn in a shuffled order; counted
    ``harmless`` when every sample is read once, else ``wrong`` (or ``refused``, ``crashed``)."""
    expected = read(data).samples.columns()
    guises = {**OVERLAPS, "a collection with the same seed": lambda data, other: same_seed}
    order = list(guises)
    rng.shuffle(order)
    counts = {"count": count, "refused": 0, "harmless": 0, "wrong": 0, "crashed": 0}
    named: dict[str, list[str]] = {"harmless_edits": [], "bad_edits": []}
    for i in range(count):
        label = order[i % len(order)]
        other = guises[label](data, scratch / f"overlap-{i}.h5")
        try:
            merged = read_all([data, other])
        except GaitlibError:
            counts["refused"] += 1
            continue
        except Exception as error:  # a traceback instead of one line
            counts["crashed"] += 1
            named["bad_edits"].append(f"{label}: {type(error).__name__}: {error}"[:200])
            continue
        if same(merged.samples.columns(), expected) and "counted once" in (merged.info.note or ""):
            counts["harmless"] += 1
            named["harmless_edits"].append(label)
        else:
            counts["wrong"] += 1
            named["bad_edits"].append(f"{label}: {len(merged.samples)} samples read, not {len(read(data).samples)}")
    return {"file": data.name, **counts, **named}
