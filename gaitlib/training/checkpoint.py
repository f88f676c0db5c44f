"""A training run's identity, as its checkpoints record it, and the check that a resumed run is the same run.

A run is identified by everything it trains from: the gait description (its content, whatever file it came
from), the handover-states file (SHA-256 of its bytes), the recipe, the preset, the seed, the switch-start share
and the library it writes into. ``--resume`` continues a checkpoint only when every one of these is what the
checkpoint recorded; otherwise it is refused in one line that names the first input that differs. A checkpoint
written before the content of the gait description and the states file was recorded cannot be shown to be the
same run and is refused too (:data:`IDENTITY_KEYS`).

Every refusal of a checkpoint that cannot be continued gives the same advice as the refusal of a fresh run in a
folder that holds one (:func:`gaitlib.training.trainer.train_gait`): give the new run its own ``--run-dir``, or
remove the checkpoint to start over in this one.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from gaitlib.atomic import file_sha256
from gaitlib.errors import GaitlibError

__all__ = ["IDENTITY_KEYS", "check_same_run", "read_checkpoint", "run_identity", "start_over"]

IDENTITY_KEYS = ("gait", "description", "states_sha256", "preset", "worlds", "recipe", "switch_start", "seed",
                 "library")
"""The run record's keys that identify the run, in the order a refusal looks for the one that differs."""

_RECORD = {"gait": str, "preset": str, "samples": int, "elapsed_s": (int, float), "curve": list}
"""The run record a gaitlib checkpoint keeps in ``infos``: key -> type."""

_OPTION = {"description": "--gait-file", "states_sha256": "--states", "preset": "--preset", "worlds": "--worlds",
           "seed": "--seed", "switch_start": "--switch-start", "library": "--library", "gait": "GAIT"}
"""Identity key -> the option of ``gaitlib train`` that sets it (the recipe's keys name their own options)."""


def run_identity(request) -> dict:
    """The identity of the training run ``request`` (a :class:`~gaitlib.training.trainer.TrainRequest`): the
    :data:`IDENTITY_KEYS` of its run record. The states file is hashed as it is read, in blocks."""
    return {
        "gait": request.description.name,
        "description": _plain(request.description.record()),
        "states_sha256": None if request.states is None else file_sha256(request.states),
        "preset": request.preset.name,
        "worlds": request.preset.num_envs,
        "recipe": request.recipe.as_dict(),
        "switch_start": request.switch_start,
        "seed": request.seed,
        "library": str(Path(request.library).resolve()),
    }


def start_over(path: Path) -> str:
    """The advice for a checkpoint at ``path`` that cannot be continued (the same words everywhere)."""
    return f"give this run its own --run-dir, or remove {path} to start over in its folder"


def read_checkpoint(path: Path, *, device: str) -> dict:
    """The checkpoint at ``path`` (tensors and plain data only: ``weights_only``), with a complete run record; a
    one-line :class:`GaitlibError` for a missing, truncated or foreign file."""
    import torch

    if not path.is_file():
        raise GaitlibError(f"nothing to resume: no checkpoint at {path}")
    try:
        saved = torch.load(path, map_location=device, weights_only=True)
    except Exception as error:  # torch raises several unrelated types for a truncated or foreign file
        raise GaitlibError(
            f"checkpoint {path} is unreadable (truncated, or not a plain torch checkpoint) and cannot be resumed; "
            f"{start_over(path)}"
        ) from error
    record = saved.get("infos") if isinstance(saved, dict) else None
    complete = isinstance(record, dict) and all(isinstance(record.get(k), t) for k, t in _RECORD.items())
    if not (complete and isinstance(saved.get("iter"), int)):
        raise GaitlibError(
            f"checkpoint {path} is not a gaitlib training checkpoint (no complete run record) and cannot be "
            f"resumed; {start_over(path)}"
        )
    return saved


def check_same_run(record: Mapping, asked: Mapping, *, path: Path) -> None:
    """Refuse, in one line naming the first input that differs, to continue the run ``record`` (a checkpoint's
    run record) as the run ``asked`` (:func:`run_identity`)."""
    missing = [k for k in ("description", "states_sha256") if k not in record]
    if missing:
        raise GaitlibError(
            f"checkpoint {path} records no content of its gait description or states file (written by an older "
            f"gaitlib), so resuming it could train on other inputs unnoticed; {start_over(path)}"
        )
    for key in IDENTITY_KEYS:
        then, now = record.get(key), asked[key]
        if key == "switch_start":
            then = record.get(key, 0.0)
        if key == "worlds" and key not in record:  # recorded since --worlds: before it, every run had its preset's
            then = _preset_worlds(record.get("preset"))
        if then != now:
            raise GaitlibError(f"checkpoint {path} is of another training run: {_difference(key, then, now)}; resume "
                               f"it with the inputs it was started with, or {start_over(path)}")


def _preset_worlds(name: object) -> int | None:
    """The worlds of the preset called ``name``, ``None`` for a name no preset has."""
    from gaitlib.training.presets import get_preset

    try:
        return get_preset(str(name)).num_envs
    except GaitlibError:
        return None


def _difference(key: str, then: object, now: object) -> str:
    """One input that differs, named by its option and, for a description or a recipe, its first differing field."""
    if key == "states_sha256":
        if then is None or now is None:
            given = ("no states file", "a states file")
            return f"--states: {given[then is not None]} then, {given[now is not None]} now"
        return f"--states: the file's content differs (SHA-256 {then[:12]} then, {now[:12]} now)"
    if isinstance(then, Mapping) and isinstance(now, Mapping):
        field = next(k for k in sorted(set(then) | set(now)) if then.get(k) != now.get(k))
        option = _OPTION.get(key, f"--{field.replace('_', '-')}")
        return f"{option}: {field} {_value(then.get(field))} then, {_value(now.get(field))} now"
    return f"{_OPTION.get(key, key)}: {key} {_value(then)} then, {_value(now)} now"


def _value(value: object) -> str:
    """A recorded value as it was given (``repr`` keeps every digit of a float)."""
    return repr(value)


def _plain(value: object) -> object:
    """``value`` with tuples as lists (what a checkpoint's record holds, and compares equal to after loading)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value
