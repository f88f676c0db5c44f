"""Ranges of numeric values and the parsing of value lists (``START:STOP:STEP`` or ``a,b,c``), shared by the
command line (:mod:`gaitlib.cli.options` declares its options with them) and the scripts that take the same values:
a value out of range is refused in one line naming the option, before any work starts."""

from __future__ import annotations

import math
from dataclasses import dataclass

from gaitlib.errors import GaitlibError

__all__ = [
    "GUARD_HORIZON_S", "GUARD_MARGIN", "IMPULSE_NS", "MAX_MAGNITUDES", "Bounds", "OptionError", "number_text",
    "parse_values",
]

MAX_MAGNITUDES = 1000
"""Most push magnitudes one benchmark sweeps (the paper's sweep has 11)."""


class OptionError(GaitlibError):
    """An option value the command does not accept (exit code 2, like other usage errors)."""


@dataclass(frozen=True, kw_only=True)
class Bounds:
    """The values a numeric option accepts."""

    low: float
    """Smallest value (excluded when ``low_open``), in ``unit``."""
    high: float
    """Largest value, in ``unit``."""
    unit: str = ""
    """Unit of the value (SI, or min for training time; empty for counts)."""
    whole: bool = False
    """Only whole numbers (counts, seeds)."""
    low_open: bool = False
    """``low`` itself is refused (durations that must be positive)."""
    high_open: bool = False
    """``high`` itself is refused (a margin below 1)."""

    def describe(self) -> str:
        """The range as the help and the errors write it, e.g. ``[0, 2000] N``, ``(0, 600] s`` or ``[0, 1)``."""
        text = (f"{'(' if self.low_open else '['}{number_text(self.low)}, {number_text(self.high)}"
                f"{')' if self.high_open else ']'}")
        return f"{text} {self.unit}" if self.unit else text

    def check(self, option: str, value: float | None, *, given: str | None = None) -> float | None:
        """``value`` if it lies in the range (``None`` passes: an unset optional option); else :class:`OptionError`
        naming it in full (``given``, the text it was read from, where that is not a finite number: ``1e400``)."""
        if value is None:
            return None
        number = float(value) if isinstance(value, float) or abs(value) < 1e300 else math.inf * (value > 0 or -1)
        above = number > self.low if self.low_open else number >= self.low
        below = number < self.high if self.high_open else number <= self.high
        if not (math.isfinite(number) and above and below and (number.is_integer() or not self.whole)):
            shown = str(value) if isinstance(value, int) else number_text(number)  # 2**70 in full, not 1.18e+21
            if given is not None and not math.isfinite(number):
                shown = given.strip()  # 1e400 as given, not as the inf it reads as
            raise OptionError(f"{option} must be {self.kind()} in {self.describe()}, got {shown}")
        return value

    def kind(self) -> str:
        """What a value must be, as the errors write it: ``a whole number`` or ``a finite number``."""
        return "a whole number" if self.whole else "a finite number"


def number_text(value: float) -> str:
    """``2000``, ``4294967295``, ``0.5``, ``1.0000001``, ``nan``: whole numbers written out, others with every digit
    they were given (the shortest text that reads back as the same number: ``:g`` would turn 1.0000001 into 1)."""
    value = float(value)
    return str(int(value)) if math.isfinite(value) and value.is_integer() and abs(value) < 1e15 else repr(value)


GUARD_MARGIN = Bounds(low=0, high=1, high_open=True)
"""The guard's margin: how much more, in survival probability, another gait must offer than staying."""
IMPULSE_NS = Bounds(low=0, high=200, unit="N s")
"""Impulses of a single push (200 N s: 16 m/s of speed change for the A1, beyond anything it survives)."""


def parse_values(text: str, *, option: str, bounds: Bounds, example: str) -> tuple[float, ...]:
    """``START:STOP:STEP`` (STOP included) or a comma-separated list -> values, each in ``bounds``, at most
    :data:`MAX_MAGNITUDES` of them (counted before any list is built)."""
    try:
        if ":" in text:
            start, stop, step = (float(v) for v in text.split(":"))
            for value in (start, stop):
                bounds.check(option, value)
            if not (math.isfinite(step) and step > 0 and stop >= start):
                raise ValueError
            span = (stop - start) / step  # STOP included: span + 1 values (a tolerance of float rounding)
            count = MAX_MAGNITUDES + 1 if span >= MAX_MAGNITUDES else math.floor(span + 1e-9) + 1
            values: tuple[float, ...] = ()
            if count <= MAX_MAGNITUDES:
                values = tuple(round(start + i * step, 6) for i in range(count))
        else:
            values = tuple(float(v) for v in text.split(",") if v.strip())
            count = len(values)
    except ValueError:
        raise OptionError(f"{option} '{text}': give START:STOP:STEP (e.g. {example}) or a list") from None
    if not 1 <= count <= MAX_MAGNITUDES:
        raise OptionError(f"{option} '{text}': give 1 to {MAX_MAGNITUDES} values")
    for value in values:
        bounds.check(option, value)
    values = tuple(v + 0.0 for v in values)  # -0 is 0
    if len(set(values)) != len(values):
        raise OptionError(f"{option} '{text}': a value is given twice")
    return values

GUARD_HORIZON_S = Bounds(low=0, high=5, unit="s", low_open=True)
"""How far ahead the guard's survival estimate may look (five seconds: far beyond a shove's consequences)."""
