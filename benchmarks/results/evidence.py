"""What the results pages' tables share: where the stored evidence is, how a file of it is read and cited, how a
rate, an interval, a pair and a benchmark's settings are written, and how a benchmark's counts are pooled (the other
modules of :mod:`benchmarks.results` make the tables)."""

from __future__ import annotations

import json
from collections.abc import Iterable
from decimal import ROUND_HALF_UP, Decimal
from pathlib import Path

from gaitlib.defaults import BAR_FALLS, BAR_HEADING_DEG, BAR_SPEED, COMPARED
from gaitlib.stats import wilson_interval

__all__ = [
    "BAR_FALLS", "BAR_HEADING_DEG", "BAR_SPEED", "EVIDENCE", "GAITS", "HEADING_BAR", "ROOT", "SPEED_BAR",
    "SWITCH_START", "arrow", "cite", "groups_at", "interval", "libraries_line", "not_yet", "pct", "pooled",
    "pooled_success", "reached", "reaches", "read_evidence", "settings_line", "shown", "speed_heading_misses",
    "success",
]

ROOT = Path(__file__).resolve().parents[2]
"""The repository."""
EVIDENCE = ROOT / "docs" / "results" / "library"
"""The stored raw results of the shipped library (the robust recipe's)."""
SWITCH_START = ROOT / "docs" / "results" / "switch-start"
"""The stored raw results of the library shipped before it, ``library-switch-start/`` (the paper's recipe with
switch-start training), named as the shipped library's are."""
GAITS = ("trot", "pace", "stand", "walk", "bound", "pronk")
"""The shipped library's gaits in the order its README names them (``library/README.md``), the tables' row order:
a presentation order, not gaitlib's (gaitlib orders gaits by name, :func:`gaitlib.library.gait_order`)."""
SPEED_BAR, HEADING_BAR = f"speed within {BAR_SPEED:.0%}", f"heading within {BAR_HEADING_DEG:g} deg"
"""The quality bar's speed and heading bars as the tables name them."""


def read_evidence(path: Path) -> dict | None:
    """The evidence stored at ``path`` (``command``, ``made``, ``result``); ``None`` when there is none yet."""
    if not path.is_file():
        return None
    evidence = json.loads(path.read_text(encoding="utf-8"))
    missing = sorted({"command", "made", "result"} - set(evidence))
    if missing:
        raise ValueError(f"{path} is not an evidence file: no {', '.join(missing)}")
    return evidence


def shown(path: Path) -> str:
    """``path`` as the doc names it: from the repository root when under it."""
    path = Path(path).resolve()
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


def cite(path: Path, evidence: dict) -> str:
    return f"`{shown(path)}` (made {evidence['made']}): `{evidence['command']}`"


def not_yet(*paths: Path) -> str:
    return "Not yet measured: " + ", ".join(f"`{shown(p)}`" for p in paths) + " not stored yet."


def pct(rate: float) -> str:
    """A rate as a percentage to a tenth, halves rounded up as written (the paper's 0.8915 is 89.2, not 89.1)."""
    return str((Decimal(str(rate)) * 100).quantize(Decimal("0.1"), rounding=ROUND_HALF_UP))


def interval(low: float, high: float) -> str:
    return f"[{pct(low)}, {pct(high)}]"


def reaches(successes: int, samples: int, goal: float) -> bool:
    """Whether ``successes`` of ``samples`` reach ``goal`` (a fraction), by the counts, not a rounded rate."""
    return successes >= goal * samples


def reached(cells: Iterable[dict], goal: float) -> int:
    """How many of a benchmark's ``cells`` (each with ``successes`` and ``samples``) reach ``goal``."""
    return sum(reaches(c["successes"], c["samples"], goal) for c in cells)


def success(successes: int, samples: int, *, goal: float | None = None) -> str:
    """A success rate, %, with its Wilson 95% interval; bold when the counts reach ``goal`` (a fraction)."""
    text = pct(successes / samples)
    bold = goal is not None and reaches(successes, samples, goal)
    return f"{f'**{text}**' if bold else text} {interval(*wilson_interval(successes, samples))}"


def pooled_success(counts: tuple[int, int, int], *, touches: bool = True) -> str:
    """Pooled counts (:func:`pooled`) as :func:`success`, the share of touched transitions beside in parentheses;
    "-" without transitions."""
    successes, samples, touched = counts
    if samples == 0:
        return "-"
    text = success(successes, samples)
    return f"{text} ({pct(touched / samples)}%)" if touches else text


def arrow(pair: str) -> str:
    return pair.replace("-", " → ")


def groups_at(result: dict, magnitude: float) -> dict[str, dict]:
    """strategy -> its cells (pair -> counts) at ``magnitude`` N, strategies in the order ``gaitlib benchmark`` compares
them (:data:`gaitlib.defaults.COMPARED`), any other after them by name."""
    groups = {g["strategy"]: g["cells"] for g in result["groups"].values() if float(g["magnitude_n"]) == magnitude}
    order = {s: i for i, s in enumerate(COMPARED)}
    return dict(sorted(groups.items(), key=lambda item: (order.get(item[0], len(order)), item[0])))


def settings_line(settings: dict) -> str:
    """What a benchmark's cells are: size, seed, the definition of a fall and, when not the training simulator's,
    its robot."""
    robot = f", robot `{settings['robot']}`" if settings.get("robot") else ""
    return f"{settings['samples']:,} transitions a cell, seed {settings['seed']}; falls by the `{settings['falls']}` " \
           f"definition{robot}"


def libraries_line(lines: dict[str, str]) -> str:
    """Each library's :func:`settings_line` (library -> line), once as "each library: ..." when they agree."""
    if len(lines) > 1 and len(set(lines.values())) == 1:
        return f"each library: {next(iter(lines.values()))}"
    return "; ".join(f"{library}: {line}" for library, line in lines.items())


def pooled(cells: Iterable[dict]) -> tuple[int, int, int]:
    """Successes, transitions and touched transitions over ``cells`` (a benchmark's counts)."""
    cells = list(cells)
    return tuple(sum(c[k] for c in cells) for k in ("successes", "samples", "touched"))


def speed_heading_misses(evaluation: dict) -> dict[str, str]:
    """The quality bar's speed and heading bars an evaluation misses, each with its figure: ``speed_error`` (a
    fraction of the reference speed; m/s of drift for a gait standing still) over :data:`BAR_SPEED`, and
    ``median_heading_change_deg`` over :data:`BAR_HEADING_DEG`."""
    found = {}
    if evaluation["speed_error"] > BAR_SPEED:
        found[SPEED_BAR] = f"{pct(evaluation['speed_error'])}%"
    if evaluation["median_heading_change_deg"] > BAR_HEADING_DEG:
        found[HEADING_BAR] = f"{evaluation['median_heading_change_deg']:.1f} deg"
    return found
