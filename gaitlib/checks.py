"""Checks by schema of the files gaitlib reads: the types, ranges and shapes a file's content must have, so that a
file edited with its checksum kept valid (or written by another tool) is refused in one line naming the field,
instead of failing deep inside a command or being used with an impossible value.

A check is a callable ``check(value, field)`` that returns nothing or raises :class:`Invalid` naming the field, a
key path such as ``rates.trot-stand[0]`` (``""``: the whole content). The builders below make them: :func:`number`,
:func:`text`, :func:`flag`, :func:`items`, :func:`span`, :func:`record`, :func:`table`, :func:`either` and
:func:`plain` (any JSON whose numbers are finite, for the free-form parts of a record). A reader runs a schema with
:func:`check_content`, which turns a failure into the reader's own error type, one line naming the file and the
field. Every number must be finite: gaitlib's writer never writes a nan or an infinity (:func:`gaitlib.atomic.
write_json`), so one in a file was put there by someone else.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping

__all__ = [
    "GAIT_NAME",
    "RANDOMIZATION",
    "SHA256",
    "Check",
    "Invalid",
    "at",
    "check_content",
    "either",
    "flag",
    "items",
    "number",
    "plain",
    "record",
    "shown",
    "span",
    "table",
    "text",
]


class Invalid(Exception):
    """A value its schema refuses: ``field`` (a key path, ``""`` for the whole content) and ``problem``, which
    reads after the field's name (``"must be a whole number in [0, 1000], got 1200"``)."""

    def __init__(self, field: str, problem: str) -> None:
        super().__init__(f"{field or 'the content'} {problem}")
        self.field, self.problem = field, problem


Check = Callable[[object, str], None]
"""A field check: ``check(value, field)`` raises :class:`Invalid` or returns nothing."""


def at(field: str, key: object) -> str:
    """The key path of ``key`` (a list index or a mapping key) inside ``field``."""
    if isinstance(key, int):
        return f"{field}[{key}]"
    return f"{field}.{key}" if field else str(key)


def shown(value: object, width: int = 40) -> str:
    """``value`` as a short one-line text for a message (JSON-like, cut at ``width`` characters)."""
    if isinstance(value, float) and not math.isfinite(value):
        text_ = str(value)
    elif isinstance(value, str):
        text_ = repr(value)
    elif isinstance(value, bool) or value is None:
        text_ = {True: "true", False: "false", None: "null"}[value]
    elif isinstance(value, (int, float)):
        text_ = repr(value)
    elif isinstance(value, Mapping):
        text_ = "an object"
    elif isinstance(value, (list, tuple)):
        text_ = f"a list of {len(value)}"
    else:
        text_ = type(value).__name__
    return text_ if len(text_) <= width else text_[: width - 3] + "..."


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _bound(value: float) -> str:
    return str(int(value)) if float(value).is_integer() and abs(value) < 1e15 else f"{value:g}"


def number(low: float = -math.inf, high: float = math.inf, *, whole: bool = False, low_open: bool = False,
           high_open: bool = False, nullable: bool = False, unit: str = "") -> Check:
    """A finite number (``whole``: a JSON integer) in the range given (``low_open``/``high_open``: that end
    excluded); ``nullable``: ``null`` too."""
    kind = "a whole number" if whole else "a finite number"
    if math.isinf(low) and math.isinf(high):
        where = ""
    elif math.isinf(high):
        where = f" {'>' if low_open else '>='} {_bound(low)}"
    elif math.isinf(low):
        where = f" {'<' if high_open else '<='} {_bound(high)}"
    else:
        where = f" in {'(' if low_open else '['}{_bound(low)}, {_bound(high)}{')' if high_open else ']'}"
    wanted = f"must be {kind}{where}{f' {unit}' if unit else ''}{' or null' if nullable else ''}"

    def check(value: object, field: str) -> None:
        if value is None and nullable:
            return
        ok = isinstance(value, int) and not isinstance(value, bool) if whole else _is_number(value)
        if not (ok and (isinstance(value, int) or math.isfinite(value)) and (low < value if low_open else low <= value)
                and (value < high if high_open else value <= high)):
            raise Invalid(field, f"{wanted}, got {shown(value)}")

    return check


def text(choices: tuple[str, ...] | list[str] | None = None, *, pattern: str | None = None, what: str = "a text",
         nullable: bool = False) -> Check:
    """A non-empty string, one of ``choices`` if given, matching the regular expression ``pattern`` whole if given
    (``what`` names what it must be); ``nullable``: ``null`` too."""
    compiled = re.compile(pattern) if pattern is not None else None

    def check(value: object, field: str) -> None:
        if value is None and nullable:
            return
        if not isinstance(value, str) or not value:
            raise Invalid(field, f"must be {what}, got {shown(value)}")
        if choices is not None and value not in choices:
            raise Invalid(field, f"must be one of {', '.join(choices)}, got {shown(value)}")
        if compiled is not None and not compiled.fullmatch(value):
            raise Invalid(field, f"must be {what}, got {shown(value)}")

    return check


SHA256 = text(pattern="[0-9a-f]{64}", what="a SHA-256 (64 hex digits)")
"""A SHA-256 in lower-case hex: an identity or a file's checksum."""

GAIT_NAME = text(pattern="[^-, ]+", what="a gait name (no '-', ',' or space)")
"""A gait's name, as :class:`~gaitlib.gaits.GaitDescription` allows one."""


def flag() -> Check:
    """``true`` or ``false``."""

    def check(value: object, field: str) -> None:
        if not isinstance(value, bool):
            raise Invalid(field, f"must be true or false, got {shown(value)}")

    return check


def items(item: Check, *, length: int | None = None, low: int = 0, high: int | None = None, unique: bool = False,
          ordered: bool = False) -> Check:
    """A list (a JSON array) each of whose items passes ``item``: of ``length`` items if given, else of ``low`` to
    ``high``; ``unique``: no item twice; ``ordered``: items sorted (the canonical order of gaits)."""

    def check(value: object, field: str) -> None:
        if not isinstance(value, (list, tuple)):
            raise Invalid(field, f"must be a list, got {shown(value)}")
        if length is not None and len(value) != length:
            raise Invalid(field, f"must hold {length} values, got {len(value)}")
        if len(value) < low or (high is not None and len(value) > high):
            most = f" to {high}" if high is not None else " or more"
            raise Invalid(field, f"must hold {low}{most} values, got {len(value)}")
        for i, v in enumerate(value):
            item(v, at(field, i))
        if unique and len({repr(v) for v in value}) != len(value):
            raise Invalid(field, "names a value twice")
        if ordered and list(value) != sorted(value):
            raise Invalid(field, f"must be in sorted order, got {', '.join(map(str, value))}")

    return check


def span(low: float = -math.inf, high: float = math.inf, *, whole: bool = False, unit: str = "") -> Check:
    """A range ``[a, b]``: two numbers in [``low``, ``high``] with ``a <= b``."""
    bound = number(low, high, whole=whole, unit=unit)
    pair = items(bound, length=2)

    def check(value: object, field: str) -> None:
        pair(value, field)
        if value[0] > value[1]:
            raise Invalid(field, f"must be a range [low, high] with low <= high, got [{value[0]}, {value[1]}]")

    return check


def record(required: Mapping[str, Check], optional: Mapping[str, Check] | None = None, *,
           extra: Check | None = None) -> Check:
    """An object holding every key of ``required`` and any of ``optional``, each passing its check; other keys pass
    ``extra`` (``None``: none is allowed)."""
    optional = optional or {}

    def check(value: object, field: str) -> None:
        if not isinstance(value, Mapping):
            raise Invalid(field, f"must be an object, got {shown(value)}")
        for key, sub in required.items():
            if key not in value:
                raise Invalid(at(field, key), "is missing")
            sub(value[key], at(field, key))
        for key, v in value.items():
            if key in required:
                continue
            if key in optional:
                optional[key](v, at(field, key))
            elif extra is None:
                raise Invalid(at(field, key), "is not a field of this file")
            else:
                extra(v, at(field, key))

    return check


def table(key: Check, value: Check, *, low: int = 0) -> Check:
    """An object of any keys passing ``key``, each value passing ``value``; at least ``low`` entries."""

    def check(content: object, field: str) -> None:
        if not isinstance(content, Mapping):
            raise Invalid(field, f"must be an object, got {shown(content)}")
        if len(content) < low:
            raise Invalid(field, f"must hold at least {low} entries, got {len(content)}")
        for k, v in content.items():
            key(k, at(field, k))
            value(v, at(field, k))

    return check


def either(*checks: Check) -> Check:
    """A value passing one of ``checks`` (the first one's refusal is reported)."""

    def check(value: object, field: str) -> None:
        first = None
        for one in checks:
            try:
                one(value, field)
                return
            except Invalid as refused:
                first = first or refused
        raise first

    return check


def plain() -> Check:
    """Any JSON value whose numbers are all finite (a free-form part of a record)."""

    def check(value: object, field: str) -> None:
        if _all_finite(value):  # the common case, without a field name for each of thousands of numbers
            return
        if isinstance(value, float) and not math.isfinite(value):
            raise Invalid(field, f"must be a finite number, got {shown(value)}")
        if isinstance(value, Mapping):
            for k, v in value.items():
                check(v, at(field, k))
        elif isinstance(value, (list, tuple)):
            for i, v in enumerate(value):
                check(v, at(field, i))

    return check


def _all_finite(value: object) -> bool:
    """Whether every float in ``value`` (nested mappings, lists and tuples) is finite; JSON's own types first."""
    todo = [value]
    while todo:
        item = todo.pop()
        kind = type(item)
        if kind is float:
            if not math.isfinite(item):
                return False
        elif kind is dict:
            todo.extend(item.values())
        elif kind is list or kind is tuple:
            todo.extend(item)
        elif isinstance(item, Mapping):
            todo.extend(item.values())
        elif isinstance(item, (list, tuple)):
            todo.extend(item)
        elif isinstance(item, float) and not math.isfinite(item):
            return False
    return True


def check_content(content: object, schema: Check, *, error: type[Exception], prefix: str, suffix: str = "") -> None:
    """Run ``schema`` on ``content``; a refusal raises ``error`` with one line: ``prefix``, the field and what is
    wrong, then ``suffix`` (``prefix`` names the file: ``"library/switching/routes.json is damaged: "``)."""
    try:
        schema(content, "")
    except Invalid as refused:
        raise error(f"{prefix}{refused}{suffix}") from None


RANDOMIZATION = record(
    {
        "enabled": flag(), "gravity_scale": span(0, 10), "action_noise": number(0), "observation_noise": number(0),
        "mass_scale": span(0, 10), "friction": span(0, 10), "latency": span(0, 1, unit="s"),
        "action_delay_steps": span(0, 10, whole=True), "kp": span(0, 10000), "kd": span(0, 1000),
        "nominal_friction": number(0, 10),
    },
    extra=plain(),
)
"""The randomization settings (:class:`gaitlib.envs.randomization.RandomizationConfig`) as a library entry's
training record and a handover-states file's settings hold them."""
