"""Gait descriptions: a gait as a handful of numbers, and the TOML file format that holds one.

A gait file (see ``gaitlib/gaits/descriptions/trot.toml``) has one key per :class:`GaitDescription` field and a
``[phase_offsets]`` table with one entry per leg::

    name = "trot"             # optional; defaults to the file name without ".toml"
    duty_factor = 0.6         # fraction of the cycle each foot is on the ground
    stride_frequency = 2.0    # Hz
    forward_speed = 0.5       # m/s, negative backward
    lateral_speed = 0.0       # m/s, optional: sideways, positive to the left
    yaw_rate = 0.0            # rad/s, optional: turning, positive counter-clockwise (to the left)
    swing_height = 0.06       # m
    body_height = 0.26        # m
    foot_lateral_offset = 0.0 # m, optional
    trunk_sway = false        # optional: the trunk sways sideways over its stance feet
    trunk_bounce = false      # optional: the trunk rises and falls as its feet push (needed for long flights)
    task = "imitation"        # optional: imitation (follow the clip) or catch (come to a calm stance, TASKS)

    [phase_offsets]           # touchdown phase of each leg, cycles
    FR = 0.0
    FL = 0.5
    RR = 0.5
    RL = 0.0
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

from gaitlib.errors import GaitError
from gaitlib.robots.a1.constants import FOOT_RADIUS, LEG_NAMES

__all__ = ["TASKS", "GaitDescription", "load_gait_file"]

TASKS = ("imitation", "catch")
"""What a policy trained on a description learns (:attr:`GaitDescription.task`): ``imitation``, to follow the
reference clip (the motion-imitation reward); ``catch``, to stay up and come to a calm stance from wherever it is
handed the robot (:mod:`gaitlib.envs.catch`), its clip only the stance it comes to."""


@dataclass(frozen=True, kw_only=True)
class GaitDescription:
    """A periodic gait of the A1, from which :func:`gaitlib.gaits.clip_from_description` builds a reference clip.

    Each foot is in stance for ``duty_factor`` of the cycle starting at its phase offset, then swings. The trunk
    moves at a constant velocity in its own frame (``forward_speed``, ``lateral_speed``) and turns at a constant
    ``yaw_rate`` with level orientation (a straight line without a yaw rate, a circle with one), straight or
    (``trunk_sway``) swaying sideways over its stance feet, at constant height or (``trunk_bounce``) rising and
    falling as its feet push.
    """

    name: str
    """Registry name, e.g. ``"trot"`` or ``"trot_slow"``; no ``-``, ``,`` or spaces (``--pairs trot-stand``)."""
    phase_offsets: tuple[float, float, float, float]
    """Touchdown phase of each leg in leg order FR, FL, RR, RL, cycles in [0, 1): the foot lands at that phase
    and stays on the ground for ``duty_factor`` of a cycle."""
    duty_factor: float
    """Fraction of the cycle each foot spends on the ground, in (0, 1]; 1 means the feet never lift."""
    stride_frequency: float
    """Gait cycles per second, Hz (the period is its inverse; a standing gait still has one, so phase is defined)."""
    forward_speed: float
    """Trunk speed along its x axis, m/s, negative backward (the stride length is
    ``forward_speed / stride_frequency``)."""
    swing_height: float
    """Highest lift of a swinging foot above the ground, m."""
    body_height: float
    """Trunk-frame origin height above the ground, m (feet on the ground have their sphere centres one foot
    radius up)."""
    foot_lateral_offset: float = 0.0
    """Sideways shift of each foot from below its thigh joint, m, positive away from the body midline (widens the
    stance)."""
    lateral_speed: float = 0.0
    """Trunk speed along its y axis, m/s, positive to the left (legged_gym's ``lin_vel_y`` command)."""
    yaw_rate: float = 0.0
    """Trunk turning rate about the vertical, rad/s, positive counter-clockwise (to the left; legged_gym's
    ``ang_vel_yaw`` command): the trunk turns ``yaw_rate / stride_frequency`` rad per cycle and runs on a circle
    of radius ``|velocity| / |yaw_rate|``."""
    trunk_sway: bool = False
    """Sway the trunk sideways as a linear inverted pendulum balanced over the stance feet
    (:func:`gaitlib.gaits.trunk_sway`), as a pacing animal does; false: the trunk runs straight. A gait whose
    stance feet are centred under the trunk at every phase (pronk, bound, stand) does not sway either way; a trot
    sways 1.4 cm (its diagonal support line lies to one side of the trunk at touchdown and lift-off)."""
    trunk_bounce: bool = False
    """Move the trunk up and down as the ground's push over the stance feet and gravity make it
    (:func:`gaitlib.gaits.trunk_height`): it falls freely in flight and is thrown up again by its stance feet, its
    mean height ``body_height``; false: it runs at ``body_height``. A level trunk cannot follow a long flight (the
    pronk's 156 ms: ``docs/training.md``)."""
    task: str = "imitation"
    """One of :data:`TASKS`. A ``catch`` is trained without a reference motion: its clip must be a stance (duty
    factor 1, no speed, no turn), the pose the robot comes to and the constant reference its observation shows."""

    def __post_init__(self) -> None:
        def fail(problem: str) -> GaitError:
            return GaitError(f"gait '{self.name}': {problem}")

        if not isinstance(self.name, str) or not self.name:
            raise GaitError(f"gait name must be a non-empty string, got {self.name!r}")
        if set(self.name) & set("-, "):
            raise GaitError(f"gait name {self.name!r} may not hold '-', ',' or spaces (they separate gaits in pairs)")
        for field in (
            "duty_factor",
            "stride_frequency",
            "forward_speed",
            "lateral_speed",
            "yaw_rate",
            "swing_height",
            "body_height",
            "foot_lateral_offset",
        ):
            value = getattr(self, field)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise fail(f"{field} must be a finite number, got {value!r}")
            object.__setattr__(self, field, float(value))
        offsets = tuple(self.phase_offsets)
        if len(offsets) != len(LEG_NAMES):
            raise fail(f"phase_offsets needs {len(LEG_NAMES)} values ({', '.join(LEG_NAMES)}), got {len(offsets)}")
        for leg, offset in zip(LEG_NAMES, offsets, strict=True):
            if isinstance(offset, bool) or not isinstance(offset, (int, float)) or not 0.0 <= offset < 1.0:
                raise fail(f"phase offset of {leg} must be a number in [0, 1) cycles, got {offset!r}")
        object.__setattr__(self, "phase_offsets", tuple(float(o) for o in offsets))
        for flag in ("trunk_sway", "trunk_bounce"):
            if not isinstance(getattr(self, flag), bool):
                raise fail(f"{flag} must be true or false, got {getattr(self, flag)!r}")
        if self.task not in TASKS:
            raise fail(f"task must be one of {', '.join(TASKS)}, got {self.task!r}")
        moving = (self.forward_speed, self.lateral_speed, self.yaw_rate) != (0.0, 0.0, 0.0)
        if self.task == "catch" and (self.duty_factor != 1.0 or moving):
            raise fail("a catch task's clip is the stance it comes to: duty_factor 1, forward_speed, lateral_speed "
                       "and yaw_rate 0")
        if not 0.0 < self.duty_factor <= 1.0:
            raise fail(f"duty_factor must be in (0, 1], got {self.duty_factor}")
        if self.stride_frequency <= 0.0:
            raise fail(f"stride_frequency must be positive (Hz), got {self.stride_frequency}")
        if self.duty_factor == 1.0 and (self.forward_speed, self.lateral_speed, self.yaw_rate) != (0.0, 0.0, 0.0):
            raise fail("a gait whose feet never lift (duty_factor 1) cannot move or turn (forward_speed, "
                       "lateral_speed and yaw_rate must be 0)")
        if abs(self.cycle_yaw) >= math.pi:
            raise fail(f"yaw_rate {self.yaw_rate:g} rad/s turns the trunk {self.cycle_yaw:.2f} rad per cycle; a gait "
                       "turns less than half a turn (pi rad) per cycle")
        if self.swing_height < 0.0:
            raise fail(f"swing_height must be >= 0 m, got {self.swing_height}")
        if self.body_height <= FOOT_RADIUS:
            raise fail(f"body_height must exceed the foot radius {FOOT_RADIUS} m, got {self.body_height}")

    def record(self) -> dict:
        """The description as a JSON-ready dict (a library entry's ``"description"``), without ``lateral_speed`` and
        ``yaw_rate`` where they are 0 and without ``task`` where it is ``imitation``: a gait that runs straight and
        imitates is recorded as before those fields existed, and a record without them reads back as the default."""
        record = dataclasses.asdict(self)
        for key, default in (("lateral_speed", 0.0), ("yaw_rate", 0.0), ("task", "imitation")):
            if record[key] == default:
                del record[key]
        return record

    @property
    def period(self) -> float:
        """Duration of one gait cycle, s."""
        return 1.0 / self.stride_frequency

    @property
    def stride_length(self) -> float:
        """Distance the trunk travels along its x axis per cycle of a gait without yaw rate, m (negative
        backward)."""
        return self.forward_speed / self.stride_frequency

    @property
    def cycle_yaw(self) -> float:
        """Angle the trunk turns per cycle, rad, counter-clockwise."""
        return self.yaw_rate / self.stride_frequency


_SCALAR_KEYS = ("duty_factor", "stride_frequency", "forward_speed", "swing_height", "body_height")
_OPTIONAL_KEYS = ("name", "lateral_speed", "yaw_rate", "foot_lateral_offset", "trunk_sway", "trunk_bounce", "task")


def load_gait_file(path: str | Path) -> GaitDescription:
    """Read a gait description from a TOML file (format in this module's docstring).

    Raises:
        GaitError: the file is unreadable, not TOML, lacks or misspells a key, or describes an impossible gait;
            the message names the file and the problem on one line.
    """
    path = Path(path)
    try:
        table = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as error:
        raise GaitError(f"{path}: cannot read gait file: {error}") from error
    unknown = sorted(set(table) - set(_SCALAR_KEYS) - set(_OPTIONAL_KEYS) - {"phase_offsets"})
    if unknown:
        raise GaitError(f"{path}: unknown key(s) {', '.join(unknown)}")
    missing = [key for key in (*_SCALAR_KEYS, "phase_offsets") if key not in table]
    if missing:
        raise GaitError(f"{path}: missing key(s) {', '.join(missing)}")
    offsets = table["phase_offsets"]
    if not isinstance(offsets, dict) or set(offsets) != set(LEG_NAMES):
        raise GaitError(f"{path}: [phase_offsets] must give exactly the legs {', '.join(LEG_NAMES)}")
    try:
        return GaitDescription(
            name=table.get("name", path.stem),
            phase_offsets=tuple(offsets[leg] for leg in LEG_NAMES),
            lateral_speed=table.get("lateral_speed", 0.0),
            yaw_rate=table.get("yaw_rate", 0.0),
            foot_lateral_offset=table.get("foot_lateral_offset", 0.0),
            trunk_sway=table.get("trunk_sway", False),
            trunk_bounce=table.get("trunk_bounce", False),
            task=table.get("task", "imitation"),
            **{key: table[key] for key in _SCALAR_KEYS},
        )
    except GaitError as error:
        raise GaitError(f"{path}: {error}") from error
