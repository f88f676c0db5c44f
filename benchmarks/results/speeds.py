"""The generated tables of ``docs/benchmarks.md`` that ``python -m benchmarks.record_timings`` measures: simulation and
collection throughput, a benchmark's memory group after group, transition file writes and a library entry's load.

Each measurement (:data:`MEASURES`) is one documented command whose JSON output is stored as the evidence
``docs/results/timings/NAME.json`` (``command``, ``made``, ``result``); each table is made from the measurements of its
block (:data:`BLOCKS`), every figure against the reference the command measured in the same run, and names what is not
stored yet (:func:`benchmarks.results.evidence.not_yet`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from benchmarks.results.evidence import ROOT, cite, not_yet, read_evidence
from benchmarks.results.timings import _fixed

__all__ = [
    "BLOCKS", "MEASURES", "TIMINGS", "Measure", "collect_throughput_table", "entry_load_table", "evidence_path",
    "memory_table", "sim_throughput_table", "writes_table",
]

TIMINGS = ROOT / "docs" / "results" / "timings"
"""Where the measurements' evidence is stored, one file a measurement."""


@dataclass(frozen=True)
class Measure:
    """One measurement: the command as the page documents it (run from the repository's root), the generated block
    whose table it feeds, and whether it prints one JSON object a line (stored as their list) or one object."""

    command: str
    block: str
    lines: bool = False


MEASURES = {
    "sim-mujoco-256": Measure("gaitlib throughput sim --backend mujoco --worlds 256 --seconds 10 --json",
                              "sim-throughput"),
    "sim-mujoco-1024": Measure("gaitlib throughput sim --backend mujoco --worlds 1024 --seconds 10 --json",
                               "sim-throughput"),
    "sim-newton-16": Measure("gaitlib throughput sim --backend newton --worlds 16 --seconds 10 --json",
                             "sim-throughput"),
    "sim-newton-64": Measure("gaitlib throughput sim --backend newton --worlds 64 --seconds 10 --json",
                             "sim-throughput"),
    "collect-512": Measure("gaitlib throughput collect --worlds 512 --seconds 40 --json", "collect-throughput"),
    "backend-memory": Measure("python benchmarks/backend_memory.py --backends 8 --worlds 256", "backend-memory"),
    "transition-writes-2e5": Measure("python benchmarks/transition_writes.py --samples 2e5", "transition-writes"),
    "transition-writes-2e6": Measure("python benchmarks/transition_writes.py --samples 2e6", "transition-writes"),
    "entry-load": Measure("python -m benchmarks.entry_load --library library --loads 40", "entry-load", lines=True),
}
"""Every measurement by the name of its evidence file, in the order they are recorded and shown."""
BLOCKS = tuple(dict.fromkeys(measure.block for measure in MEASURES.values()))
"""The generated blocks the measurements feed, in the page's order."""


def evidence_path(name: str, folder: Path = TIMINGS) -> Path:
    """Where the measurement ``name`` is stored under ``folder``."""
    return Path(folder) / f"{name}.json"


def _stored(block: str, folder: Path) -> tuple[list[tuple[Path, dict]], list[Path]]:
    """The stored evidence of ``block``'s measurements (path, evidence) and the paths not stored yet."""
    stored, missing = [], []
    for name, measure in MEASURES.items():
        if measure.block == block:
            path = evidence_path(name, folder)
            evidence = read_evidence(path)
            if evidence is None:
                missing.append(path)
            else:
                stored.append((path, evidence))
    return stored, missing


def _table(block: str, folder: Path, header: str, rows) -> str:
    """``block``'s table: ``header`` (its two lines), the rows ``rows(result)`` makes of each stored result, the
    evidence cited, and what is not stored yet; only :func:`not_yet` when nothing is."""
    stored, missing = _stored(block, folder)
    if not stored:
        return not_yet(*missing)
    lines = [header, *(row for _, evidence in stored for row in rows(evidence["result"]))]
    cited = "; ".join(cite(path, evidence) for path, evidence in stored)
    return "\n".join([*lines, "", f"Evidence: {cited}." + (f" {not_yet(*missing)}" if missing else "")])


def _rate(value: float) -> str:
    return f"{value:,.0f}"


def sim_throughput_table(folder: Path = TIMINGS) -> str:
    """Each backend's control steps per second against the two plain MuJoCo C references of the same run; the ratio
    (to the faster reference) in bold for the ``mujoco`` backend, whose goal it is."""

    def rows(result: dict) -> list[str]:
        ratio = _fixed(result["ratio"], 3)
        shown = f"**{ratio}**" if result["backend"] == "mujoco" else ratio
        return [f"| {result['backend']} | {result['device']} | {result['worlds']:,} | "
                f"{_rate(result['env_steps_per_s'])} | {_rate(result['raw_mj_step_per_s'])} | "
                f"{_rate(result['raw_rollout_per_s'])} | {shown} |"]

    return _table("sim-throughput", folder, "| backend | device | worlds | backend steps/s | `mj_step` pool | "
                  "`rollout` chained | ratio |\n|---|---|---|---|---|---|---|", rows)


def collect_throughput_table(folder: Path = TIMINGS) -> str:
    """The collection's samples per second against what the plain rollout of the same run allows."""

    def rows(result: dict) -> list[str]:
        return [f"| {result['worlds']:,} | {_rate(result['env_steps_per_s'])} | "
                f"{_fixed(result['steps_per_sample'], 1)} | {_fixed(result['allowed_samples_per_s'], 1)} | "
                f"{_fixed(result['samples_per_s'], 1)} | **{_fixed(result['ratio'], 3)}** |"]

    return _table("collect-throughput", folder, "| worlds | rollout control steps/s | control steps per sample | "
                  "allowed samples/s | collected samples/s | ratio |\n|---|---|---|---|---|---|", rows)


def memory_table(folder: Path = TIMINGS) -> str:
    """Resident memory after the first and the last backend's close, the heap kept (the reference) and trimmed."""
    stored, missing = _stored("backend-memory", folder)
    if not stored:
        return not_yet(*missing)
    result = stored[0][1]["result"]
    after, growth = result["resident_mb_after_each_close"], result["growth_mb_first_to_last"]
    share = result.get("growth_trimmed_vs_kept")
    header = (f"| backends of {result['worlds']:,} worlds, built, stepped {result['steps']} times and closed in turn | "
              f"resident after the first close | after the last ({len(after['keep'])}) | growth |\n|---|---|---|---|")

    def rows(_: dict) -> list[str]:
        return [f"| {label} | {_fixed(after[mode][0], 0)} MB | {_fixed(after[mode][-1], 0)} MB | "
                f"{_fixed(growth[mode], 1)} MB{extra} |"
                for mode, label, extra in (
                    ("keep", "heap kept (the reference)", ""),
                    ("trim", "heap trimmed at close (gaitlib's)",
                     "" if share is None else f" ({_fixed(share, 3)} of the reference)"))]

    return _table("backend-memory", folder, header, rows)


def writes_table(folder: Path = TIMINGS) -> str:
    """gaitlib's transition writer against in-place HDF5 appends of the same batches in the same run."""

    def times(ms: dict) -> str:
        return f"{_fixed(ms['median'], 1)} / {_fixed(ms['mean'], 1)} / {_fixed(ms['max'], 0)} ms"

    def rows(result: dict) -> list[str]:
        return [f"| {result['samples']:,} | {times(result['gaitlib_append_ms'])} | "
                f"{times(result['in_place_append_ms'])} | {_fixed(result['ratio_of_totals'], 2)} | {result['files']} | "
                f"{_fixed(result['read_whole_s'], 1)} s |"]

    return _table("transition-writes", folder, "| samples | gaitlib append, median / mean / max | in-place append, "
                  "median / mean / max | ratio of totals | files | read whole |\n|---|---|---|---|---|---|", rows)


def entry_load_table(folder: Path = TIMINGS) -> str:
    """Each entry's load with gaitlib's checks against the same loads checked by the naming walk, in the same run."""

    def rows(result: list[dict]) -> list[str]:
        return [f"| {line['gait']} | {_fixed(line['load_ms'], 1)} ms | {_fixed(line['reference_walk_ms'], 1)} ms | "
                f"{_fixed(line['ratio'], 2)} |" for line in sorted(result, key=lambda line: line["gait"])]

    return _table("entry-load", folder, "| entry | load | reference (the naming walk) | ratio |\n|---|---|---|---|",
                  rows)
