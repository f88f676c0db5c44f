"""The sweep's results file, ``OUT/results.json``: its format, its group keys, reading it, and opening it for a run
with given settings (a rerun resumes only a sweep of the same settings and policies)."""

from __future__ import annotations

from pathlib import Path

from gaitlib.atomic import read_json
from gaitlib.errors import GaitlibError

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "group_key", "load_results", "open_results"]

FORMAT_NAME = "gaitlib.benchmark"
FORMAT_VERSION = 3  # 2: pushes from push_lead_s before the request until deadline_s after it; 3: touches per cell,
# the definition of a fall always in the settings


def group_key(strategy: str, magnitude: float) -> str:
    """The key of a (strategy, magnitude) group in ``results.json``, e.g. ``net@300`` or ``net@12.5``: the magnitude
    to the millinewton (the sweep's :data:`~gaitlib.benchmark.sweep.MAGNITUDE_RESOLUTION_N`)."""
    return f"{strategy}@{magnitude:.3f}".rstrip("0").rstrip(".")


def load_results(out: Path) -> dict:
    """``OUT/results.json`` (a one-line error for a foreign or unreadable file, or one not of the format: types,
    ranges, counts, pairs, groups and strategies, :func:`~gaitlib.benchmark.validate.check_results`); ``{}`` when
    there is none."""
    from gaitlib.benchmark.validate import check_results
    from gaitlib.strategies import strategy_names

    path = Path(out) / "results.json"
    if not path.is_file():
        return {}
    header = {"format": FORMAT_NAME, "format_version": FORMAT_VERSION}
    results = read_json(path, header=header, what="gaitlib benchmark results", error=GaitlibError)
    check_results(results, path=path, strategies=strategy_names(), group_key=group_key)
    return results


def open_results(out: Path, settings: dict, identities: dict) -> dict:
    """The results in ``out`` if they are of these settings and policies (else one line), or new empty ones."""
    results = load_results(out)
    if not results:
        return {"format": FORMAT_NAME, "format_version": FORMAT_VERSION, "settings": settings,
                "library_identities": identities, "groups": {}}
    if results["library_identities"] != identities:
        raise GaitlibError(f"{out} holds a benchmark of other policies; use another --out or delete it")
    saved = results["settings"]
    differ = sorted(k for k in settings.keys() | saved.keys() if settings.get(k) != saved.get(k))
    if differ:
        raise GaitlibError(
            f"{out} holds a benchmark with other settings ({', '.join(differ)}); use another --out or delete it"
        )
    return results
