"""The route table (:mod:`gaitlib.strategies.routes`) of a library measured by the benchmark: every ordered pair with
one strategy at one push magnitude, a group of ``gaitlib benchmark``'s results (``gaitlib routes``)."""

from __future__ import annotations

from gaitlib.benchmark.results import group_key
from gaitlib.errors import GaitlibError
from gaitlib.library.store import Library
from gaitlib.strategies.routes import RouteTable

__all__ = ["routes_from_results"]


def routes_from_results(results: dict, library: Library, *, strategy: str, push_n: float = 0.0,
                        max_legs: int = 2) -> RouteTable:
    """The route table of ``library`` from a benchmark's results (``gaitlib benchmark``'s ``results.json``) holding
    every ordered pair of its gaits with ``strategy`` at ``push_n`` N, run on the library's current policies."""
    group = results["groups"].get(group_key(strategy, push_n))
    if group is None:
        raise GaitlibError(f"the benchmark has no group of '{strategy}' at {push_n:g} N to measure routes with")
    identities = results["library_identities"]
    library.check_identities(identities, what="the benchmark results")
    if results["settings"].get("switching") != library.switching_identity():
        raise GaitlibError("the benchmark was measured with other switching models than the library holds now; "
                           "measure it again into another --out")
    return RouteTable(
        gaits=library.order(identities),
        strategy=strategy,
        push_n=push_n,
        rates={pair: (c["successes"], c["samples"]) for pair, c in group["cells"].items()},
        max_legs=max_legs,
        policies=dict(identities),
        switching=library.switching_identity(),
        measured_with={k: results["settings"][k] for k in ("samples", "seed", "num_worlds", "warmup_s",
                                                           "source_extra_s", "horizon_s", "deadline_s")}
        | {"falls": results["settings"]["falls"]},
    )
