"""The paper's Fig. 4 in docs/results.md: every strategy on every pair under pushes from 0 to 500 N (its top), and
without pushes on another A1 (its bottom, the real robot there), the library shipped before (switch-start) beside
the shipped one (robust). :mod:`benchmarks.results.doc` writes them into the page with the others.

Each block is made from one evidence file in ``docs/results/switch-start/`` and in ``docs/results/library/`` (like
``bench-0n.json``, one benchmark over every strategy and magnitude): ``sweep`` from ``sweep.json``,
``strategies-menagerie`` from ``menagerie-strategies.json`` (MuJoCo Menagerie's A1 at 0 N). Each holds

- each strategy's success over every pair and magnitude (every magnitude has as many transitions as the others, so
  the pooled rate is the paper's mean over the sweep) and over the paper's dynamic-to-static pairs
  (:data:`TO_STATIC`), each library in its own columns, with the pooled touches, the ranking and the paper's net's
  margin over its other strategies;
- when more than one magnitude is swept, each library's success per strategy and magnitude, over every pair.

A library whose evidence is not stored yet is left out and named under the tables; neither stored says "not yet
measured".
"""

from __future__ import annotations

from pathlib import Path

from benchmarks.results.evidence import (
    EVIDENCE,
    SWITCH_START,
    arrow,
    cite,
    groups_at,
    libraries_line,
    not_yet,
    pooled,
    pooled_success,
    read_evidence,
    settings_line,
    shown,
)

__all__ = ["HELD_OUT", "NAME", "PAPER_OTHERS", "TO_STATIC", "sweep_table"]

NAME = "sweep"
"""The sweep's evidence file's name in each library's folder, without ``.json``."""
HELD_OUT = "menagerie-strategies"
"""The evidence file's name of every strategy on MuJoCo Menagerie's A1, without ``.json``."""
TO_STATIC = ("pace-stand", "trot-stand")
"""The paper's dynamic-to-static pairs, on which it reports the net 19 points over the second best (Fig. 4, top)."""
PAPER_OTHERS = ("random", "value", "tmt", "tmt-value")
"""The strategies the paper ranks its net (``net``) against."""

Counts = tuple[int, int, int]
"""Successes, transitions and touched transitions."""


def _by_strategy(name: str, result: dict) -> dict[str, dict[float, dict[str, dict]]]:
    """strategy -> magnitude (N) -> its cells (pair -> counts), strategies in the tables' order."""
    found: dict[str, dict[float, dict[str, dict]]] = {}
    for magnitude in sorted({float(g["magnitude_n"]) for g in result["groups"].values()}):
        for strategy, cells in groups_at(result, magnitude).items():
            found.setdefault(strategy, {})[magnitude] = cells
    if len({tuple(m) for m in found.values()}) != 1:
        raise ValueError(f"{name} does not sweep every strategy over the same push magnitudes")
    return found


def _over(sweep: dict[float, dict[str, dict]], pairs: tuple[str, ...] | None = None) -> Counts:
    """The counts over every magnitude and ``pairs`` (every pair when ``None``)."""
    return pooled(cell for cells in sweep.values() for pair, cell in cells.items() if pairs is None or pair in pairs)


def _share(counts: Counts) -> float:
    return counts[0] / counts[1]


def _margin(sweep: dict[str, dict[float, dict[str, dict]]]) -> str | None:
    """The paper's ``net`` over the best of :data:`PAPER_OTHERS` on :data:`TO_STATIC`, in points; ``None`` when the
    sweep lacks ``net``, the others or those pairs."""
    counts = {s: _over(sweep[s], TO_STATIC) for s in ("net", *PAPER_OTHERS) if s in sweep}
    if "net" not in counts or len(counts) == 1 or not all(c[1] for c in counts.values()):
        return None
    rates = {s: _share(c) for s, c in counts.items()}
    best = max((s for s in PAPER_OTHERS if s in rates), key=rates.get)
    points = (rates["net"] - rates[best]) * 100
    return f"{points:+.1f} points from the best of the paper's other strategies, `{best}`"


def sweep_table(switch_start_dir: Path = SWITCH_START, evidence_dir: Path = EVIDENCE, *, name: str = NAME) -> str:
    """Each strategy over every pair and magnitude of the evidence ``name`` and on the dynamic-to-static pairs, then,
    when it sweeps more than one magnitude, per magnitude, for each library whose evidence is stored."""
    paths = {"switch-start": Path(switch_start_dir) / f"{name}.json", "robust": Path(evidence_dir) / f"{name}.json"}
    stored = {library: e for library, path in paths.items() if (e := read_evidence(path)) is not None}
    if not stored:
        return not_yet(*paths.values())
    sweeps = {library: _by_strategy(shown(paths[library]), e["result"]) for library, e in stored.items()}
    strategies = list(dict.fromkeys(s for sweep in sweeps.values() for s in sweep))
    magnitudes = sorted({m for sweep in sweeps.values() for by_m in sweep.values() for m in by_m})
    span = f"{magnitudes[0]:g}-{magnitudes[-1]:g} N" if len(magnitudes) > 1 else f"{magnitudes[0]:g} N"
    where = f"over {span}" if len(magnitudes) > 1 else f"at {span}"
    static = ", ".join(arrow(p) for p in TO_STATIC)
    lines = ["| strategy | " + " | ".join(f"{library}: all pairs, {span} [95%] (touches)" for library in sweeps)
             + " | " + " | ".join(f"{library}: {static} [95%] (touches)" for library in sweeps) + " |",
             "|---|" + "---|" * (2 * len(sweeps))]
    for strategy in strategies:
        cells = [pooled_success(_over(sweep[strategy], pairs)) if strategy in sweep else "-"
                 for pairs in (None, TO_STATIC) for sweep in sweeps.values()]
        lines.append(f"| `{strategy}` | " + " | ".join(cells) + " |")
    run = libraries_line({library: settings_line(e["result"]["settings"]) for library, e in stored.items()})
    ranks = []
    for library, sweep in sweeps.items():
        ranked = sorted(sweep, key=lambda s: _share(_over(sweep[s])), reverse=True)
        margin = _margin(sweep)
        ranks.append(f"{library.capitalize()}: ranked by success {where}: " + ", ".join(f"`{s}`" for s in ranked)
                     + (f"; on {static}, `net` is {margin}." if margin else "."))
    parts = ["\n".join(lines), f"Success % with 95% Wilson intervals over the pooled transitions, touches (a non-foot "
             f"body on the ground, ridden through) in parentheses; {run}. " + " ".join(ranks)]
    for library, sweep in sweeps.items() if len(magnitudes) > 1 else ():
        rows = ["| push, N | " + " | ".join(f"`{s}`" for s in sweep) + " |", "|---|" + "---|" * len(sweep)]
        rows += [f"| {magnitude:g} | " + " | ".join(
            pooled_success(pooled(by_m[magnitude].values()), touches=False) if magnitude in by_m else "-"
            for by_m in sweep.values()) + " |" for magnitude in magnitudes]
        parts += [f"{library.capitalize()} library, each strategy's success % over every pair at each push magnitude "
                  "[95%]:", "\n".join(rows)]
    absent = [path for library, path in paths.items() if library not in stored]
    if absent:
        parts.append(not_yet(*absent))
    sources = [f"- {cite(paths[library], e)}" for library, e in stored.items()]
    return "\n\n".join([*parts, "Evidence:", "\n".join(sources)])
