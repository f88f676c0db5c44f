"""Validation by schema of a library entry's ``metadata.json`` (:func:`check_metadata`), and of its ``deployment``
block against the one the entry's own settings give (:func:`deployment_difference`).

The observation layout and the action settings are checked by :mod:`gaitlib.library.store` itself; here are the
rest: the gait description (ranges, then :class:`~gaitlib.gaits.GaitDescription`'s own checks), the robot, the
networks (and that they are the preset's), the training record (its preset, randomization ranges, learning curve,
switch-start record; or, for an entry made as another's mirror image, its ``mirror`` record), the evaluation (rates
in [0, 1] inside their intervals, counts within the episodes, the figures of one generation of the record together),
the versions and the checksums. Free-form parts that later versions may extend pass if their numbers are finite. A
refusal is one line naming the field.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from gaitlib.checks import (
    GAIT_NAME,
    RANDOMIZATION,
    SHA256,
    Invalid,
    flag,
    items,
    number,
    plain,
    record,
    shown,
    span,
    table,
    text,
)
from gaitlib.defaults import Falls
from gaitlib.errors import GaitlibError

if TYPE_CHECKING:
    from gaitlib.envs.observations import ObservationConfig
    from gaitlib.gaits import ReferenceClip

__all__ = [
    "EVALUATION_FIGURES",
    "MIRROR_RECORD",
    "check_action",
    "check_deployment",
    "check_metadata",
    "deployment_difference",
]

_PUSH_N = number(0, 2000, unit="N")
_SEED = number(0, 2**32 - 1, whole=True)
_COUNT = number(0, whole=True)
_RATE = number(0, 1)
_SECONDS = number(0, 600, low_open=True, unit="s")
_LAYERS = items(number(1, 65536, whole=True), low=1, high=16)
_DELAYS = span(0, 10, whole=True)

_DESCRIPTION = record(
    {
        "name": GAIT_NAME, "phase_offsets": items(number(0, 1, high_open=True), length=4),
        "duty_factor": number(0, 1, low_open=True), "stride_frequency": number(0, 20, low_open=True, unit="Hz"),
        "forward_speed": number(-10, 10, unit="m/s"), "swing_height": number(0, 1, unit="m"),
        "body_height": number(0, 2, low_open=True, unit="m"),
    },
    {"lateral_speed": number(-10, 10, unit="m/s"), "yaw_rate": number(-20, 20, unit="rad/s"),
     "foot_lateral_offset": number(-1, 1, unit="m"), "trunk_sway": flag(), "trunk_bounce": flag(),
     "task": text()},  # recorded where it is not imitation; GaitDescription checks it is one of its TASKS
)
_PRESET = record(
    {"name": text()},
    {
        "num_envs": number(1, 65536, whole=True), "steps_per_env": number(1, whole=True),
        "epochs": number(1, whole=True), "mini_batches": number(1, whole=True),
        "learning_rate": number(0, 1, low_open=True), "gamma": _RATE, "lam": _RATE, "clip": number(0, low_open=True),
        "desired_kl": number(0, nullable=True), "entropy_coef": number(0), "actor_hidden": _LAYERS,
        "critic_hidden": _LAYERS, "init_std": number(0, low_open=True), "iterations": _COUNT,
        "episode_seconds": _SECONDS, "push_max": _PUSH_N, "push_force": _PUSH_N, "push_ramp": _RATE,
        "push_ramp_iterations": _COUNT, "activation": text(),
    },
    extra=plain(),
)
_RECIPE = record(
    {
        "push_kind": text(), "kick_max": number(0), "kick_interval": span(0, 600, unit="s"),
        "terminate": text(tuple(Falls)),
        "contact_penalty": number(), "gamma": number(0, 1, nullable=True), "lam": number(0, 1, nullable=True),
        "action_delay": number(0, 10, whole=True, nullable=True), "critic_delay": flag(),
    },
    {"kick_draw": text(), "cycle_sync": flag()},  # recorded since these levers existed
    extra=plain(),
)
_SWITCH_START = record(
    {
        "share": _RATE, "states": text(), "states_sha256": SHA256,
        "from_gaits": items(GAIT_NAME, low=1, unique=True), "from_identities": table(GAIT_NAME, SHA256, low=1),
        "states_used": number(1, whole=True),
        "recorded_with": record({"push_max": _PUSH_N, "warmup_s": number(0, 600, unit="s"),
                                 "spacing_s": _SECONDS, "num_worlds": number(1, 65536, whole=True)}),
    },
    {"handed_over": text()},
    extra=plain(),
)
_MIRROR = record(
    {"source": GAIT_NAME, "source_sha256": SHA256, "phase_shift": number(0, 1, high_open=True), "command": text()},
    {"source_library": text(), "source_description": _DESCRIPTION},
    extra=plain(),
)
_TRAINING = record(
    {},
    {
        "mirror": _MIRROR,
        "preset": _PRESET, "backend": text(("mujoco", "newton")), "iterations": _COUNT, "samples": _COUNT,
        "wall_clock_s": number(0, unit="s"), "seed": _SEED, "randomization": RANDOMIZATION, "recipe": _RECIPE,
        "episode_seconds": _SECONDS, "push_ramp_iterations": _COUNT,
        "curve": record({"columns": items(text(), low=1, unique=True), "rows": items(items(number(nullable=True)))}),
        "push_max_n": _PUSH_N, "push_force_max_n": _PUSH_N,
        "switch_start": lambda value, field: value is None or _SWITCH_START(value, field),
        "distributed": record({"world_size": number(1, whole=True), "parameters_in_sync": flag()}),
    },
    extra=plain(),
)
TRAINING_RECORD = ("preset", "backend", "iterations", "samples", "wall_clock_s", "seed", "randomization",
                   "episode_seconds", "push_ramp_iterations", "curve")
"""What ``gaitlib train`` records of a run, all or none (an entry saved through the Python API may record
nothing), with one of ``push_max_n`` and (before 0.2) ``push_force_max_n``."""
MIRROR_RECORD = ("mirror", "randomization")
"""What ``gaitlib mirror`` records of an entry it makes: how (``mirror``) and the randomization its source was
trained under (the action delay it runs with), nothing of a run."""
_EVALUATION = record(
    {},
    {
        "episodes": number(1, 65536, whole=True), "seconds": _SECONDS, "fall_rate": _RATE,
        "heading_loss_rate": _RATE, "median_heading_change_deg": number(0, unit="deg"),
        "joint_rmse": number(0, 20, unit="rad"), "forward_speed": number(-20, 20, unit="m/s"),
        "reference_speed": number(-20, 20, unit="m/s"), "speed_error": number(0),
        "mean_episode_seconds": number(0, unit="s"), "action_delay_steps": number(0, 10, whole=True, nullable=True),
        "fall_ci95": span(0, 1), "touch_rate": _RATE, "touch_ci95": span(0, 1), "longest_touch_s": number(0, unit="s"),
        "contact_agreement": _RATE, "push_max": _PUSH_N, "push_force": _PUSH_N, "falls": text(tuple(Falls)),
        "falls_by_cause": table(text(), _COUNT), "seed": _SEED, "command": text(),
        "late_steps": number(0, 10, whole=True),
        "steering": record({
            "lateral_speed": number(-20, 20, unit="m/s"), "reference_lateral_speed": number(-20, 20, unit="m/s"),
            "lateral_speed_error": number(0), "yaw_rate": number(-50, 50, unit="rad/s"),
            "reference_yaw_rate": number(-50, 50, unit="rad/s"), "yaw_rate_error": number(0),
            "median_heading_error_deg": number(0, 180, unit="deg"),
        }),
    },
    extra=plain(),
)
EVALUATION_FIGURES = (
    ("episodes", "seconds", "fall_rate", "heading_loss_rate", "median_heading_change_deg", "joint_rmse",
     "forward_speed", "reference_speed", "speed_error", "mean_episode_seconds", "action_delay_steps"),
    ("fall_ci95", "touch_rate", "touch_ci95", "longest_touch_s", "contact_agreement", "falls", "falls_by_cause",
     "push_max"),
    ("seed", "command"),
)
"""Figures of an evaluation that come together, each group all or none: every evaluation's (with one of
``push_max`` and, before 0.2, ``push_force``), the falls and touches of gaitlib 0.2 on, and the run that ``gaitlib
eval --record`` stores. An entry saved through the Python API may record no evaluation."""


def _robot(value: object, field: str) -> None:
    from gaitlib.robots import get_robot

    text()(value, field)
    try:
        get_robot(value)
    except GaitlibError as error:
        raise Invalid(field, f"must be a registered robot: {error}") from None


_METADATA = record(
    {
        "format_version": number(whole=True), "gait": GAIT_NAME, "description": _DESCRIPTION, "robot": _robot,
        "observation": plain(), "action": plain(),  # checked by the store with their own messages
        "networks": record({"actor_hidden": _LAYERS, "critic_hidden": _LAYERS, "activation": text()}),
        "training": _TRAINING, "evaluation": _EVALUATION,
        "versions": record({"gaitlib": text(), "torch": text(), "rsl-rl-lib": text(), "mujoco": text()}, extra=text()),
        "sha256": SHA256, "deployment": record({}, extra=plain()),
    },
    {"onnx_sha256": SHA256, "checksum": SHA256},
    extra=plain(),
)


def check_action(action: object) -> None:
    """The action settings every user of an entry reads: a type, and a finite positive scale (rad per action unit)
    and clip (action units); :class:`~gaitlib.checks.Invalid` otherwise."""

    def positive(value: object) -> bool:
        return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0

    if not (isinstance(action, dict) and isinstance(action.get("type"), str) and positive(action.get("scale"))
            and positive(action.get("clip"))):
        raise Invalid("'action'", f"needs a type and a finite positive scale and clip, got {json.dumps(action)}")


def check_metadata(metadata: Mapping) -> None:
    """Raise :class:`~gaitlib.checks.Invalid` naming the first field of ``metadata`` (an entry's ``metadata.json``,
    checksum and format version already checked) that is not of the format (the module doc)."""
    from gaitlib.gaits import GaitDescription

    _METADATA(metadata, "")
    try:
        GaitDescription(**metadata["description"])
    except GaitlibError as error:
        raise Invalid("description", f"is not a gait: {error}") from None
    training, networks = metadata["training"], metadata["networks"]
    if "mirror" in training:  # made from another entry's weights (gaitlib.training.mirror), not trained
        run = next((key for key in training if key not in MIRROR_RECORD), None)
        if run is not None:
            raise Invalid(f"training.{run}", "belongs to a training run, not to a mirror image (training.mirror)")
    else:
        _together("training", training, TRAINING_RECORD, ("push_max_n", "push_force_max_n"))
    for part, first in (("training", MIRROR_RECORD[0] if "mirror" in training else TRAINING_RECORD[0]),
                        ("evaluation", EVALUATION_FIGURES[0][0])):
        if metadata[part] and first not in metadata[part]:
            raise Invalid(f"{part}.{first}", f"is missing: a {part} record is empty or holds what gaitlib records")
    preset = training.get("preset", {})
    for key in ("actor_hidden", "critic_hidden", "activation"):
        if key in preset and preset[key] != networks[key]:
            raise Invalid(f"networks.{key}", f"is {shown(networks[key])}, training.preset.{key} "
                          f"{shown(preset[key])}")
    if "curve" in training:
        rows, columns = training["curve"]["rows"], training["curve"]["columns"]
        for i, row in enumerate(rows):
            if len(row) != len(columns):
                raise Invalid(f"training.curve.rows[{i}]", f"holds {len(row)} values for {len(columns)} columns")
    start = training.get("switch_start")
    if start is not None and set(start["from_identities"]) != set(start["from_gaits"]):
        raise Invalid("training.switch_start.from_identities", "does not name the gaits of from_gaits")
    _check_evaluation(metadata["evaluation"])


def _together(where: str, content: Mapping, keys: tuple[str, ...], one_of: tuple[str, ...] = ()) -> None:
    """``keys`` of ``content`` all or none, and with them exactly one of ``one_of`` (without them, none of it)."""
    held = [key for key in keys if key in content]
    if held and len(held) != len(keys):
        missing = next(key for key in keys if key not in content)
        raise Invalid(f"{where}.{missing}", f"is missing beside {', '.join(held[:3])}")
    if one_of:
        alternatives = [key for key in one_of if key in content]
        if len(alternatives) != (1 if held else 0):
            raise Invalid(where, f"must hold {'one' if held else 'none'} of {' and '.join(one_of)} "
                          f"{'beside' if held else 'without'} {keys[0]}, holds {len(alternatives)}")


def _check_evaluation(evaluation: Mapping) -> None:
    core, touches, run = EVALUATION_FIGURES
    _together("evaluation", evaluation, core, ("push_max", "push_force"))
    for figures in (touches, run):
        _together("evaluation", evaluation, figures)
        if figures[0] in evaluation and core[0] not in evaluation:
            raise Invalid(f"evaluation.{core[0]}", f"is missing beside {figures[0]}")
    if "push_force" in evaluation and touches[0] in evaluation:
        raise Invalid("evaluation.push_force", "belongs to a record without falls and touches (push_max with them)")
    if core[0] not in evaluation:
        return
    episodes, seconds = evaluation["episodes"], evaluation["seconds"]
    for rate, interval in (("fall_rate", "fall_ci95"), ("touch_rate", "touch_ci95"), ("heading_loss_rate", "")):
        if interval in evaluation:
            low, high = evaluation[interval]
            if not low - 1e-9 <= evaluation[rate] <= high + 1e-9:
                raise Invalid(f"evaluation.{rate}", f"is {evaluation[rate]:g}, outside its interval {interval}")
        if rate in evaluation and abs(evaluation[rate] * episodes - round(evaluation[rate] * episodes)) > 1e-6:
            raise Invalid(f"evaluation.{rate}", f"is {evaluation[rate]:g}, not a count of {episodes} episodes")
    for cause, count in evaluation.get("falls_by_cause", {}).items():
        if count > episodes:
            raise Invalid(f"evaluation.falls_by_cause.{cause}", f"is {count}, more than the {episodes} episodes")
    if evaluation.get("longest_touch_s", 0) > seconds + 1:
        raise Invalid("evaluation.longest_touch_s", f"is {evaluation['longest_touch_s']:g} s, longer than an "
                      f"episode ({seconds:g} s)")
    if evaluation["mean_episode_seconds"] > seconds + 1:
        raise Invalid("evaluation.mean_episode_seconds", f"is {evaluation['mean_episode_seconds']:g} s, longer than "
                      f"an episode ({seconds:g} s)")


def check_deployment(metadata: Mapping, clip: ReferenceClip, observation: ObservationConfig,
                     action_delay_steps: tuple[int, int], onnx_path: Path) -> None:
    """Raise :class:`~gaitlib.checks.Invalid` where ``metadata``'s ``deployment`` block differs from the one the
    entry's own ``clip``, action settings, ``observation``, trained delay and ``onnx_path`` give
    (:func:`deployment_difference`), or where ``policy.onnx`` cannot be read for it."""
    from gaitlib.library.deployment import deployment_block

    try:
        derived = deployment_block(clip=clip, action=metadata["action"], observation=observation,
                                   onnx_path=onnx_path, action_delay_steps=action_delay_steps, robot=metadata["robot"])
    except Exception as error:  # onnx raises several unrelated types for a file that is not a model
        raise Invalid("deployment", f"cannot be checked: policy.onnx is unreadable ({type(error).__name__})") from None
    where = None if _agrees(metadata["deployment"], derived) else deployment_difference(metadata["deployment"], derived)
    if where is not None:
        raise Invalid(where, "is not what the entry's own description, action, observation and policy.onnx give")


def deployment_difference(stored: object, derived: object, field: str = "deployment") -> str | None:
    """The first key path at which the ``deployment`` block ``stored`` differs from ``derived`` (the block the
    entry's own description, action, observation, delay and ``policy.onnx`` give:
    :func:`~gaitlib.library.deployment.deployment_block`), ``None`` where they agree: numbers to 2e-6 (the
    reference table is rounded to 1e-6), names exactly, prose (text with spaces) by its type only."""
    if isinstance(derived, Mapping):
        if not isinstance(stored, Mapping):
            return field
        for key in (*derived, *(k for k in stored if k not in derived)):
            if key not in stored or key not in derived:
                return f"{field}.{key}"
            found = deployment_difference(stored[key], derived[key], f"{field}.{key}")
            if found is not None:
                return found
        return None
    if isinstance(derived, (list, tuple)):
        if not isinstance(stored, (list, tuple)) or len(stored) != len(derived):
            return field
        return next((f for i, (s, d) in enumerate(zip(stored, derived, strict=True))
                     if (f := deployment_difference(s, d, f"{field}[{i}]")) is not None), None)
    if isinstance(derived, (int, float)) and not isinstance(derived, bool):
        close = (isinstance(stored, (int, float)) and not isinstance(stored, bool) and math.isfinite(stored)
                 and abs(stored - derived) <= 2e-6 + 1e-9 * abs(derived))
        return None if close else field
    if isinstance(derived, str) and any(c.isspace() for c in derived):
        return None if isinstance(stored, str) and stored else field
    return None if type(stored) is type(derived) and stored == derived else field


def _agrees(stored: object, derived: object) -> bool:
    """``True`` only where :func:`deployment_difference` finds no difference: JSON's own numbers, lists and objects
    compared in one loop, without a key path for each of the reference table's thousands of numbers; anything else
    (and every doubt) is left to it."""
    todo = [(stored, derived)]
    while todo:
        s, d = todo.pop()
        kind, stored_kind = type(d), type(s)
        if kind is float or kind is int:
            if not ((stored_kind is float or stored_kind is int) and math.isfinite(s)
                    and abs(s - d) <= 2e-6 + 1e-9 * abs(d)):
                return False
        elif kind is list or kind is tuple:
            if not (stored_kind is list or stored_kind is tuple) or len(s) != len(d):
                return False
            todo.extend(zip(s, d, strict=True))
        elif kind is dict:
            if stored_kind is not dict or s.keys() != d.keys():
                return False
            todo.extend((s[k], d[k]) for k in d)
        elif deployment_difference(s, d) is not None:
            return False
    return True
