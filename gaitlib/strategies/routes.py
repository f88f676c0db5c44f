"""Routes: a switch that the library does badly directly, made through another gait instead (trot -> stand -> pace).

A library's route table (``switching/routes.json``) holds the measured success of every ordered pair with one
strategy at one push magnitude (a benchmark group: :func:`gaitlib.benchmark.routes.routes_from_results`; 0 N by
default), the magnitude the routes are for: a routed transition meets the pushes of each of its requests. A route's
predicted success is the product of its legs' measured rates (each switch starts from a robot that has run the
intermediate gait for a while, as the measured ones did). The planner takes the route of at most ``max_legs``
switches with the highest predicted success, and only where that exceeds the direct switch's upper 95% bound
(Wilson), so that a detour, which costs a switch and seconds, is not taken on noise; everywhere else the switch is
direct.

The table is read here, beside the library's other switching models (:mod:`gaitlib.strategies`). It records the
policies and the switching models it was measured with; a refit replaces the switching folder and so removes it,
and a table for other policies or models, or not of the format (:func:`check_routes`), is refused in one line
(:func:`load_routes`).
"""

from __future__ import annotations

import math
import shlex
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from itertools import pairwise, product
from pathlib import Path

from gaitlib.atomic import read_json, stale_temporaries, write_json
from gaitlib.checks import GAIT_NAME, SHA256, check_content, items, number, record, table, text
from gaitlib.defaults import Falls
from gaitlib.errors import GaitlibError
from gaitlib.library.layout import ordered_pairs, protection
from gaitlib.library.store import Library
from gaitlib.stats import wilson_interval

__all__ = ["ROUTES_FILE", "RouteTable", "check_routes", "load_routes"]

ROUTES_FILE = Library.ROUTES
"""The route table's name in the library's switching folder."""
_FORMAT = {"format": "gaitlib.routes", "format_version": 1}
_PUSH_N = number(0, 2000, unit="N")
_COUNT = number(0, whole=True)
_SECONDS = number(0, 600, unit="s")
_PAIR = text(pattern="[^-, ]+-[^-, ]+", what="a pair of gaits 'm-n'")
_MEASURED_WITH = record({
    "samples": number(1, 1e6, whole=True), "seed": number(0, 2**32 - 1, whole=True),
    "num_worlds": number(1, 65536, whole=True), "warmup_s": _SECONDS, "source_extra_s": _SECONDS,
    "horizon_s": number(0, 600, low_open=True, unit="s"), "deadline_s": _SECONDS, "falls": text(tuple(Falls)),
})


@dataclass(frozen=True, kw_only=True)
class RouteTable:
    """Measured success of every ordered pair of ``gaits`` with ``strategy`` at ``push_n``, and the routes it
    implies."""

    gaits: tuple[str, ...]
    strategy: str
    """The strategy every switch of a route is made with (``gaitlib benchmark --strategies``)."""
    push_n: float = 0.0
    """Push magnitude the pairs were measured at, N (the benchmark's push window around each request)."""
    rates: dict[str, tuple[int, int]]
    """``"m-n"`` -> (successes, transitions) measured."""
    max_legs: int = 2
    """Most switches a route may take (2: at most one gait in between)."""
    policies: dict[str, str]
    """Gait -> identity of the policy measured."""
    switching: str
    """SHA-256 of the switching models' checksum list (``switching/checksums.json``) measured with."""
    measured_with: dict
    """The benchmark settings the rates come from (samples, seed, protocol times, what a fall is)."""

    def __post_init__(self) -> None:
        missing = [f"{m}-{n}" for m, n in product(self.gaits, repeat=2) if m != n and f"{m}-{n}" not in self.rates]
        if missing:
            raise GaitlibError(f"the route table lacks the pairs {', '.join(missing)}: measure every ordered pair")
        if self.max_legs < 1:
            raise GaitlibError(f"a route takes at least one switch, not {self.max_legs}")

    @property
    def falls(self) -> Falls:
        """The definition of a fall the rates were counted with (``measured_with``; a table without it:
        ``contact``, the only one there was)."""
        return Falls(self.measured_with.get("falls", Falls.CONTACT))

    def success(self, source: str, dest: str) -> float:
        """Measured success rate of the direct switch ``source`` -> ``dest`` (0-1)."""
        successes, samples = self.rates[f"{source}-{dest}"]
        return successes / samples if samples else 0.0

    def predicted(self, path: tuple[str, ...]) -> float:
        """Predicted success of switching along ``path`` (source, ..., destination): the product of its legs."""
        return math.prod(self.success(a, b) for a, b in pairwise(path))

    def route(self, source: str, dest: str) -> tuple[str, ...]:
        """The gaits to request in turn to go from ``source`` to ``dest`` (ending with ``dest``): through others
        where that beats the direct switch's upper 95% bound, else ``(dest,)``."""
        for gait in (source, dest):
            if gait not in self.gaits:
                raise GaitlibError(f"the route table knows {', '.join(self.gaits)}, not {gait}")
        if source == dest:
            raise GaitlibError(f"'{source}' is requested while the robot already runs it")
        best = (source, dest)
        paths = [(source, dest)]
        for _ in range(self.max_legs - 1):  # extend each path by one gait it has not visited
            paths = [(*p[:-1], g, dest) for p in paths for g in self.gaits if g not in p]
            best = max([best, *paths], key=lambda p: (self.predicted(p), -len(p)))
        successes, samples = self.rates[f"{source}-{dest}"]
        if len(best) > 2 and self.predicted(best) > wilson_interval(successes, samples)[1]:
            return best[1:]
        return (dest,)

    def expand(self, source: str, dests: tuple[str, ...]) -> tuple[str, ...]:
        """A requested sequence (``dests`` one after the other from ``source``) with each switch routed."""
        out: list[str] = []
        for a, b in pairwise((source, *dests)):
            out += self.route(a, b)
        return tuple(out)

    def detours(self) -> dict[str, tuple[str, ...]]:
        """``"m-n"`` -> the full path (m, ..., n) of every pair routed through another gait."""
        found = {}
        for m, n in product(self.gaits, repeat=2):
            if m != n and len(route := self.route(m, n)) > 1:
                found[f"{m}-{n}"] = (m, *route)
        return found

    def as_dict(self) -> dict:
        return _FORMAT | {
            "gaits": list(self.gaits), "strategy": self.strategy, "push_n": self.push_n, "max_legs": self.max_legs,
            "rates": {pair: list(r) for pair, r in self.rates.items()}, "policies": self.policies,
            "switching": self.switching, "measured_with": self.measured_with,
            "detours": {pair: list(path) for pair, path in self.detours().items()},  # for readers: derived
        }

    def save(self, library: Library) -> Path:
        """Write the table into ``library``'s switching folder, atomically, and remove the temporaries a killed
        writer of it left there (call it holding the library's writer lock: no other writer runs)."""
        path = library.switching_dir / ROUTES_FILE
        for leftover in stale_temporaries(path):
            leftover.unlink(missing_ok=True)
        return write_json(path, self.as_dict(), checksum=True)


def load_routes(library: Library, gaits: tuple[str, ...]) -> RouteTable:
    """``library``'s route table for ``gaits``; one line when it has none, when it is not of the format (types,
    ranges, counts, pairs, strategy and gaits: :func:`check_routes`), or when it was
    measured on other policies or switching models than the library holds now."""
    from gaitlib.strategies import strategy_names

    path = library.switching_dir / ROUTES_FILE
    if not path.is_file():
        raise GaitlibError(f"library {library.root} has no route table; measure one: gaitlib routes --library "
                           f"{library.root}")
    saved = read_json(path, header=_FORMAT, what="a gaitlib route table", error=GaitlibError)
    again = f"; measure it again: gaitlib routes --library {library.root}"
    check_routes(saved, path=path, strategies=strategy_names(), again=again)
    again = f"; measure it again: {_measure_again(library, saved)}"
    if saved["switching"] != library.switching_identity():
        raise GaitlibError(f"{path} was measured with other switching models than the library's{again}")
    if set(saved["gaits"]) != set(gaits) or saved["policies"] != library.identities(gaits):
        raise GaitlibError(f"{path} was measured with other policies than the library's{again}")
    table = RouteTable(
        gaits=tuple(saved["gaits"]), strategy=saved["strategy"], push_n=float(saved["push_n"]),
        max_legs=saved["max_legs"], rates={pair: (r[0], r[1]) for pair, r in saved["rates"].items()},
        policies=saved["policies"], switching=saved["switching"], measured_with=saved["measured_with"],
    )
    if "detours" in saved and saved["detours"] != {pair: list(p) for pair, p in table.detours().items()}:
        raise GaitlibError(f"{path} is damaged: detours are not the routes its rates give{again}")
    return table


def _measure_again(library: Library, saved: Mapping) -> str:
    """The ``gaitlib routes`` command that measures the (checked) table ``saved`` again as it was measured, on the
    library's current policies and switching models."""
    measured = saved["measured_with"]
    words = ["gaitlib", "routes", "--library", library.root, "--strategy", saved["strategy"], "--push",
             f"{saved['push_n']:g}", "--max-legs", saved["max_legs"], "--samples", measured["samples"], "--worlds",
             measured["num_worlds"], "--seed", measured["seed"], "--falls", Falls(measured.get("falls", Falls.CONTACT))]
    if protection(library.root):
        words.append("--replace")
    return " ".join(shlex.quote(str(w)) for w in words)


def check_routes(saved: Mapping, *, path: Path, strategies: Sequence[str], again: str = "") -> None:
    """Refuse, in one line ending with ``again``, a route table (as :func:`~gaitlib.atomic.read_json` returns it)
    that is not of the format: types and ranges, a rate of more successes than transitions or of other transitions
    than it was measured with, pairs not of its gaits, an unknown strategy."""
    schema = record(
        {
            "format": text(), "format_version": number(whole=True),
            "gaits": items(GAIT_NAME, low=2, unique=True, ordered=True),
            "strategy": text(tuple(strategies)),
            "push_n": _PUSH_N,
            "max_legs": number(1, 5, whole=True),
            "rates": table(_PAIR, items(_COUNT, length=2), low=2),
            "policies": table(GAIT_NAME, SHA256, low=2),
            "switching": SHA256,
            "measured_with": _MEASURED_WITH,
        },
        {"detours": table(_PAIR, items(GAIT_NAME, low=3))},
    )
    check_content(saved, schema, error=GaitlibError, prefix=f"{path} is damaged: ", suffix=again)
    gaits, rates, measured = saved["gaits"], saved["rates"], saved["measured_with"]
    pairs = ordered_pairs(gaits)
    for pair in rates:
        if pair not in pairs:
            raise _refuse(path, f"rates.{pair}", f"is not a pair of the table's gaits ({', '.join(gaits)})", again)
    for pair in pairs:
        if pair not in rates:
            raise _refuse(path, "rates", f"lacks the pair {pair}", again)
        successes, transitions = rates[pair]
        if transitions != measured["samples"]:
            raise _refuse(path, f"rates.{pair}", f"counts {transitions} transitions, measured_with.samples "
                          f"{measured['samples']}", again)
        if successes > transitions:
            raise _refuse(path, f"rates.{pair}", f"counts {successes} successes of {transitions} transitions", again)
    if set(saved["policies"]) != set(gaits):
        raise _refuse(path, "policies", f"name {', '.join(sorted(saved['policies']))}, the table's gaits are "
                      f"{', '.join(gaits)}", again)
    if measured["horizon_s"] < measured["deadline_s"]:
        raise _refuse(path, "measured_with.horizon_s", "is shorter than the deadline", again)


def _refuse(path: Path, field: str, problem: str, suffix: str = "") -> GaitlibError:
    return GaitlibError(f"{path} is damaged: {field} {problem}{suffix}")
