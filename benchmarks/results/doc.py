"""Write the generated tables of the results pages from the raw results stored beside them, or check them.

    python -m benchmarks.results            # rewrite the generated blocks of every results page
    python -m benchmarks.results --check    # exit 1 naming the first table that differs from its evidence

Each table sits between ``<!-- table: NAME -->`` and ``<!-- /table -->`` in the page :data:`PAGES` gives it:
``docs/results.md`` (the current state), ``docs/ablation.md`` (the robust recipe's ablation),
``docs/switching_results.md`` (the switches in detail), ``docs/transitions.md`` (the net's learning curve and
the switch-success budget),
``docs/skills.md`` (the staged skills beyond the six gaits), ``docs/switching.md`` (the guard),
``docs/results_history.md`` (the guard before the library grew), ``docs/benchmarks.md`` (today's speeds and times)
``README.md`` (the library beside the paper, what runs where), ``docs/failures.md`` (the fuzz runs' counts),
``docs/driving.md`` (the example drives over seeds) and ``library/README.md`` (how each shipped gait does).
Everything between the two markers is made here from the evidence and nothing else, so a figure edited by hand, or a
stored result replaced without rewriting the page, makes ``--check`` fail (tests/test_results_doc.py runs it). The
tables themselves are made in :mod:`benchmarks.results.headline`, :mod:`~benchmarks.results.robustness`,
:mod:`~benchmarks.results.switches`, :mod:`~benchmarks.results.sweep`, :mod:`~benchmarks.results.skills`,
:mod:`~benchmarks.results.guard`, :mod:`~benchmarks.results.timings`, :mod:`~benchmarks.results.speeds`,
:mod:`~benchmarks.results.overview`, :mod:`~benchmarks.results.budget`, :mod:`~benchmarks.results.fuzz`,
:mod:`~benchmarks.results.drive` and :mod:`~benchmarks.results.entries`; how
evidence is read and written is :mod:`benchmarks.results.evidence`.
"""

from __future__ import annotations

import argparse
import re
import sys
import textwrap
from collections.abc import Sequence
from pathlib import Path

from benchmarks.results.budget import budget_table, screen_table
from benchmarks.results.catch_skill import catch_alone, guard_with_catch
from benchmarks.results.drive import drive_table
from benchmarks.results.entries import entries_table
from benchmarks.results.evidence import EVIDENCE, ROOT, shown
from benchmarks.results.fuzz import edits_table, flips_table
from benchmarks.results.growth import growth_pairs, growth_pooled, growth_stages
from benchmarks.results.guard import PAIR_TABLES, guard_curve, guard_pairs, guard_pushes, guard_shoves, guard_summary
from benchmarks.results.headline import (
    ACCURACY,
    CURVE,
    ROBUST_GOAL,
    SWITCH_START_ACCURACY,
    accuracy_table,
    curve_table,
    pairs_table,
    quality_bar,
    routes_table,
)
from benchmarks.results.overview import readme_results, runs_where
from benchmarks.results.robustness import library_table, robustness_table, shove_table
from benchmarks.results.skills import skills_bar, skills_shoves
from benchmarks.results.speeds import (
    collect_throughput_table,
    entry_load_table,
    memory_table,
    sim_throughput_table,
    writes_table,
)
from benchmarks.results.sweep import HELD_OUT, sweep_table
from benchmarks.results.switches import map_table, switches_table
from benchmarks.results.timings import (
    command_start_policy_table,
    command_start_table,
    gpu_check_table,
    gpu_graph_table,
    guard_cost_table,
    recipe_speed_table,
    suite_table,
)
from gaitlib.atomic import atomic_path

__all__ = [
    "DOC", "DOCS", "GUARDS", "PAGES", "TABLES", "WIDTH", "check_doc", "fill", "first_difference", "main", "page_tables",
    "render_tables", "write_doc",
]

PAGES = {
    "docs/results.md": ("quality-bar", "shove-curves", "switches", "guard-summary", "growth-pairs", "growth-pooled",
                        "sweep", "strategies-menagerie", "net-accuracy"),
    "docs/ablation.md": ("robustness-gaits", "robust-library"),
    "docs/switching_results.md": ("pairs-0n", "routes", "routes-switch-start", "map", "net-accuracy-switch-start"),
    "docs/transitions.md": ("net-curve", "budget-curve", "budget-curve-50n", "budget-screen", "growth-stages"),
    "docs/skills.md": ("skills-bar", "skills-shoves", "catch-alone"),
    "docs/switching.md": ("guard-curve-recover", "guard-shoves-recover", "guard-pushes-recover", "guard-pairs-recover",
                          "guard-pairs-menagerie-recover", "guard-shoves-grown", "guard-catch",
                          "guard-pushes-catch"),
    "docs/results_history.md": ("guard-shoves-best-f0", "guard-pushes-best-f0", "guard-summary-recover"),
    "docs/benchmarks.md": ("sim-throughput", "recipe-speed", "collect-throughput", "backend-memory", "guard-cost",
                           "transition-writes", "command-start", "command-start-policy", "suite-latest", "entry-load",
                           "gpu-check-h100", "gpu-check-graph"),
    "README.md": ("readme-results", "runs-where"),
    "docs/failures.md": ("fuzz-flips", "fuzz-edits"),
    "docs/driving.md": ("drive-seeds",),
    "library/README.md": ("library-entries",),
}
"""Each results page by its path from the repository's root and its generated blocks, in the page's order."""
GUARDS = ("best-f0", "recover")
"""The guards whose tables the pages show, by the tag of their stored evaluations: the six gaits' (made before the
library grew, ``docs/results_history.md``) and the shipped library's, grown by the recovery skill (``recover``,
``docs/switching.md``)."""
DOCS = tuple(ROOT / page for page in PAGES)
"""The results pages, :data:`PAGES` in order."""
DOC = DOCS[0]
"""The results page of the current state, ``docs/results.md``."""
TABLES = tuple(name for names in PAGES.values() for name in names)
"""Every generated block, page by page."""
BLOCK = re.compile(r"<!-- table: ([a-z0-9-]+) -->\n(.*?)<!-- /table -->", re.S)
WIDTH = 120
"""The pages' line length: the tables' prose is wrapped to it (a table row or an inline code span is never broken)."""


def _fill(text: str) -> str:
    """One paragraph or list item wrapped at :data:`WIDTH`, its inline code spans whole."""
    kept = re.sub(r"`[^`]*`", lambda match: match.group(0).replace(" ", "\0"), " ".join(text.split("\n")))
    lines = textwrap.wrap(kept, WIDTH, subsequent_indent="  " if text.startswith("- ") else "",
                          break_long_words=False, break_on_hyphens=False)
    return "\n".join(lines).replace("\0", " ")


def _wrap(body: str) -> str:
    """``body`` with its prose wrapped (:func:`_fill`) and its tables as they are."""
    return "\n\n".join(p if p.startswith("|") else "\n".join(_fill(item) for item in re.split(r"\n(?=- )", p))
                       for p in body.split("\n\n"))



def render_tables(evidence_dir: Path = EVIDENCE, accuracy: Path = ACCURACY,
                  switch_start_accuracy: Path = SWITCH_START_ACCURACY) -> dict[str, str]:
    """Every generated block's content, by name, in :data:`TABLES` order; the ablation rows are read from the folder
    ``ablation`` beside ``evidence_dir``, the switch-start library's evidence from ``switch-start`` beside it."""
    ablation, earlier = Path(evidence_dir).parent / "ablation", Path(evidence_dir).parent / "switch-start"
    tables = {"quality-bar": quality_bar(evidence_dir), "shove-curves": shove_table(ablation),
              "pairs-0n": pairs_table(evidence_dir), "switches": switches_table(earlier, evidence_dir),
              "sweep": sweep_table(earlier, evidence_dir),
              "strategies-menagerie": sweep_table(earlier, evidence_dir, name=HELD_OUT),
              "net-accuracy": accuracy_table(accuracy),
              "net-accuracy-switch-start": accuracy_table(switch_start_accuracy),
              "robustness-gaits": robustness_table(ablation), "robust-library": library_table(ablation),
              "routes": routes_table(evidence_dir, goal=ROBUST_GOAL), "routes-switch-start": routes_table(earlier),
              "map": map_table(evidence_dir), "net-curve": curve_table(Path(evidence_dir) / CURVE.name),
              **{f"budget-curve{tag}": budget_table(Path(evidence_dir).parent / "budget" / f"success-curve{tag}.json")
                 for tag in ("", "-50n")},
              "budget-screen": screen_table(Path(evidence_dir).parent / "budget" / "screen-steer-0n.json"),
              "growth-stages": growth_stages(Path(evidence_dir).parent / "growth"),
              "growth-pairs": growth_pairs(Path(evidence_dir).parent / "growth"),
              "growth-pooled": growth_pooled(Path(evidence_dir).parent / "growth"),
              "skills-bar": skills_bar(Path(evidence_dir).parent),
              "skills-shoves": skills_shoves(Path(evidence_dir).parent),
              **{f"guard-{kind}-{tag}": table(tag, Path(evidence_dir).parent / "guard") for tag in GUARDS
                 for kind, table in (("shoves", guard_shoves), ("pushes", guard_pushes))},
              "guard-curve-recover": guard_curve("recover", Path(evidence_dir).parent / "guard"),
              "guard-shoves-grown": guard_shoves("grown", Path(evidence_dir).parent / "guard"),
              "catch-alone": catch_alone(Path(evidence_dir).parent / "catch"),
              "guard-catch": guard_with_catch(Path(evidence_dir).parent / "guard"),
              "guard-summary": guard_summary("catch", Path(evidence_dir).parent / "guard",
                                             section="The guard with the catch skill"),
              "guard-summary-recover": guard_summary("recover", Path(evidence_dir).parent / "guard"),
              "guard-pushes-catch": guard_pushes("catch", Path(evidence_dir).parent / "guard"),
              **{f"guard-pairs-{'' if robot == 'sim' else robot + '-'}recover":
                 guard_pairs("recover", Path(evidence_dir).parent / "guard", robot=robot) for robot in PAIR_TABLES},
              "recipe-speed": recipe_speed_table(Path(evidence_dir) / "recipe-speed.json"),
              "guard-cost": guard_cost_table(Path(evidence_dir).parent / "guard" / "guard-cost-recover.json"),
              "command-start": command_start_table(), "command-start-policy": command_start_policy_table(),
              "suite-latest": suite_table(), "gpu-check-h100": gpu_check_table(), "gpu-check-graph": gpu_graph_table(),
              "sim-throughput": sim_throughput_table(), "collect-throughput": collect_throughput_table(),
              "backend-memory": memory_table(), "transition-writes": writes_table(), "entry-load": entry_load_table(),
              "readme-results": readme_results(evidence_dir, accuracy, Path(evidence_dir).parent / "guard"),
              "runs-where": runs_where(), "fuzz-flips": flips_table(), "fuzz-edits": edits_table(),
              "drive-seeds": drive_table(Path(evidence_dir).parent / "drive"),
              "library-entries": entries_table(evidence_dir, Path(evidence_dir).parent / "recover")}
    return {name: _wrap(tables[name]) for name in TABLES}


def page_tables(doc: Path) -> tuple[str, ...]:
    """The generated blocks of the results page ``doc``: by its path from the repository's root (:data:`PAGES`), a
    file outside the repository (a copy) by its file name when that names one page alone; one line for another
    file."""
    path = Path(doc).resolve()
    named = [path.relative_to(ROOT).as_posix()] if path.is_relative_to(ROOT) else \
        [page for page in PAGES if Path(page).name == path.name]
    if len(named) != 1 or named[0] not in PAGES:
        raise ValueError(f"{doc} is not a results page (the pages: {', '.join(PAGES)})")
    return PAGES[named[0]]


def _block(name: str, body: str) -> str:
    return f"<!-- table: {name} -->\n\n{body}\n\n<!-- /table -->"


def _blocks(text: str, names: Sequence[str]) -> dict[str, str]:
    """name -> the whole block as the page holds it (markers included), for a page whose blocks are ``names``;
    one-line errors for an unknown, misplaced or repeated name."""
    blocks: dict[str, str] = {}
    for match in BLOCK.finditer(text):
        name = match.group(1)
        if name in blocks or name not in names:
            where = next((page for page, held in PAGES.items() if name in held), None)
            why = "repeated" if name in blocks else f"for {where}" if where else "unknown"
            raise ValueError(f"the table marker '{name}' is {why}")
        blocks[name] = match.group(0)
    return blocks


def first_difference(text: str, tables: dict[str, str]) -> str | None:
    """The first table (in the page's order, then any the page lacks) whose block differs from ``tables`` (the
    page's tables by name)."""
    blocks = _blocks(text, list(tables))
    for name in [*blocks, *(n for n in tables if n not in blocks)]:
        if blocks.get(name) != _block(name, tables[name]):
            return name
    return None


def fill(text: str, tables: dict[str, str]) -> str:
    """``text`` with every generated block made from ``tables`` (the page's tables by name; each table's markers
    must be there)."""
    absent = [name for name in tables if name not in _blocks(text, list(tables))]
    if absent:
        raise ValueError(f"no <!-- table: {absent[0]} --> ... <!-- /table --> block to write the table into")
    return BLOCK.sub(lambda match: _block(match.group(1), tables[match.group(1)]), text)


def _page(doc: Path, tables: dict[str, str]) -> dict[str, str]:
    """The tables of the page ``doc`` out of every table (:func:`render_tables`)."""
    return {name: tables[name] for name in page_tables(doc)}


def check_doc(doc: Path = DOC, evidence_dir: Path = EVIDENCE, accuracy: Path = ACCURACY,
              *, tables: dict[str, str] | None = None) -> str | None:
    """The first table of the page ``doc`` that differs from what its evidence makes (``tables``, when given, is
    what it makes), or ``None`` when all agree."""
    page_tables(doc)
    made = render_tables(evidence_dir, accuracy) if tables is None else tables
    return first_difference(Path(doc).read_text(encoding="utf-8"), _page(doc, made))


def write_doc(doc: Path = DOC, evidence_dir: Path = EVIDENCE, accuracy: Path = ACCURACY,
              *, tables: dict[str, str] | None = None) -> bool:
    """Rewrite the generated blocks of the page ``doc`` from the evidence (``tables``, when given, is what it
    makes; a temporary file beside it, then renamed over it); whether anything changed."""
    doc = Path(doc)
    page_tables(doc)
    text = doc.read_text(encoding="utf-8")
    filled = fill(text, _page(doc, render_tables(evidence_dir, accuracy) if tables is None else tables))
    if filled == text:
        return False
    with atomic_path(doc) as tmp:
        tmp.write_text(filled, encoding="utf-8")
    return True


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.results", description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="change nothing; exit 1 if a table differs")
    parser.add_argument("--doc", type=Path, action="append",
                        help="a results page, one of PAGES (default: every page; repeatable)")
    parser.add_argument("--evidence", type=Path, default=EVIDENCE, help="the stored results (docs/results/library)")
    parser.add_argument("--accuracy", type=Path, default=ACCURACY, help="the accuracy report (the shipped library's)")
    args = parser.parse_args(argv)
    docs, states, differing = args.doc or list(DOCS), [], []
    try:
        for doc in docs:  # every page named is checked before any is read or written
            page_tables(doc)
        tables = render_tables(args.evidence, args.accuracy)
        for doc in docs:
            if args.check:
                name = check_doc(doc, tables=tables)
                differing += [(doc, name)] if name else []
                states.append((doc, "every table agrees with its stored evidence"))
            else:
                states.append((doc, "rewritten" if write_doc(doc, tables=tables) else "up to date"))
    except (OSError, ValueError, KeyError, TypeError) as error:
        detail = f"a stored result has no {error}" if isinstance(error, KeyError) else str(error)
        print(f"benchmarks.results: {detail}", file=sys.stderr)
        return 2
    for doc, name in differing:
        print(f"{shown(doc)}: the table '{name}' differs from what its stored evidence makes (or has no block); "
              "python -m benchmarks.results rewrites it", file=sys.stderr)
    if differing:
        return 1
    for doc, state in states:
        print(f"{shown(doc)}: {state}")
    return 0
