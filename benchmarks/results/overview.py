"""The README's generated tables: the shipped library beside the paper, and what runs where, each figure read from the
same stored results as the results pages' tables (:mod:`benchmarks.results.doc` writes them into ``README.md``)."""

from __future__ import annotations

import json
from pathlib import Path

from benchmarks.results.evidence import EVIDENCE, arrow, groups_at, not_yet, pct, pooled, read_evidence
from benchmarks.results.growth import BENCHES, GROWTH
from benchmarks.results.guard import GUARD
from benchmarks.results.headline import ACCURACY, INPUTS
from benchmarks.results.sweep import HELD_OUT, NAME, PAPER_OTHERS, TO_STATIC, _by_strategy, _over, _share
from gaitlib.strategies.fitting import PAPER_PAIRS

__all__ = ["GPU_CHECK", "PAPER_MARGIN", "SHOVED", "readme_results", "runs_where"]

PAPER_MARGIN = 19.0
"""The paper's net over its second-best strategy on the dynamic-to-static pairs, points (Fig. 4, top)."""
SHOVED = ("pace", "walk", "stand")
"""The gaits whose falls after one 12 N s shove the README shows, unguarded and guarded."""
GPU_CHECK = Path(__file__).resolve().parents[2] / "docs" / "results" / "gpu_check" / "h100.jsonl"
"""The raw lines of the GPU check on one H100 (``benchmarks/gpu_check.py``)."""
RESULTS = "docs/results.md"
ACCURACY_LINK = f"[results]({RESULTS}#the-transition-nets-accuracy-paper-table-3)"
SWEEP_LINK = f"[results]({RESULTS}#the-papers-sweep-every-strategy-0-to-500-n)"


def _six(values: dict) -> float | None:
    """The mean over the paper's six pairs; ``None`` unless each has a figure."""
    known = [values.get(pair) for pair in PAPER_PAIRS]
    return None if None in known else sum(known) / len(known)


def _accuracy_rows(path: Path) -> list[str]:
    report = json.loads(Path(path).read_text(encoding="utf-8"))
    ours, paper = report["balanced_validation_accuracy"], report["paper_table_3"]
    names = {"latent": "transition-net accuracy, latent input, the paper's six pairs",
             "explicit": "the same, explicit state input", "phase": "the same, phase input"}
    return [f"| {names[kind]} | {pct(_six(paper[kind]))}% | {pct(_six(ours[kind]))}% | {ACCURACY_LINK} |"
            for kind in INPUTS
            if kind in ours and kind in paper and None not in (_six(paper[kind]), _six(ours[kind]))]


def _sweep_rows(evidence_dir: Path) -> list[str]:
    rows, rates = [], {}
    sweep = read_evidence(Path(evidence_dir) / f"{NAME}.json")
    if sweep is not None:
        by = _by_strategy(NAME, sweep["result"])
        counts = {s: _over(by[s], TO_STATIC) for s in ("net", *PAPER_OTHERS) if s in by}
        rates = {s: _share(c) for s, c in counts.items() if c[1]}
    if "net" in rates and len(rates) > 1:
        best = max((s for s in PAPER_OTHERS if s in rates), key=rates.get)
        span = sorted(m for m in by["net"])
        pairs = " and ".join(arrow(p) for p in TO_STATIC)
        rows.append(f"| net against the second-best strategy, {pairs}, {span[0]:g}-{span[-1]:g} N | "
                    f"{PAPER_MARGIN:+g} points | "
                    f"{(rates['net'] - rates[best]) * 100:+.1f} points | {SWEEP_LINK} |")
    held = read_evidence(Path(evidence_dir) / f"{HELD_OUT}.json")
    if held is not None and any(_over(v)[1] for v in _by_strategy(HELD_OUT, held["result"]).values()):
        by = _by_strategy(HELD_OUT, held["result"])
        ranked = sorted((s for s in by if _over(by[s])[1]), key=lambda s: _share(_over(by[s])), reverse=True)
        shown = [*ranked[:2], ranked[-1]] if len(ranked) > 3 else ranked
        rows.append("| the best strategy without pushes off the training simulator | net (real A1) | "
                    + ", ".join(f"{s} {pct(_share(_over(by[s])))}%" for s in shown)
                    + f" (Menagerie's A1) | {SWEEP_LINK} |")
    return rows


def _growth_rows(folder: Path = GROWTH) -> list[str]:
    """The new pairs the library grew by, at 0 N with ``net-lookahead``, pooled: the pairs fitted at the budget from
    the first of :data:`BENCHES`, the others from the second (as :func:`~benchmarks.results.growth.growth_pairs`)."""
    stored = [read_evidence(Path(folder) / name) for name in (*BENCHES, "growth.json")]
    if any(evidence is None for evidence in stored):
        return []
    fitted = set(stored[-1]["result"]["screen"]["fitted_pairs"])
    first, second = (groups_at(e["result"], 0.0).get("net-lookahead", {}) for e in stored[:2])
    cells = {p: c for p, c in first.items() if p in fitted} | {p: c for p, c in second.items() if p not in fitted}
    s, n, _ = pooled(cells.values())
    return [f"| switch success at 0 N, net-lookahead, the steering skills' pairs | - | {s / n:.2%} ({n - s} falls in "
            f"{n:,}, {len(cells)} pairs) | [results]({RESULTS}#the-steering-skills-pairs) |"]


def _guard_rows(folder: Path) -> list[str]:
    rows = []
    bench = read_evidence(Path(folder) / "bench-0n-unguarded-recover.json")
    cells = groups_at(bench["result"], 0.0).get("net-lookahead") if bench is not None else None
    if cells:
        s, n, _ = pooled(cells.values())
        rows.append(f"| switch success at 0 N, net-lookahead, the seven first entries' pairs | - | {s / n:.2%} "
                    f"({n - s} falls in {n:,}, {len(cells)} pairs) | "
                    f"[results]({RESULTS}#beside-the-paper-and-the-field) |")
    rows += _growth_rows()
    shoves = {g: read_evidence(Path(folder) / f"shove-12-{g}-catch.json") for g in SHOVED}
    if all(e is not None for e in shoves.values()):
        points = {g: e["result"] for g, e in shoves.items()}

        def rate(point: dict) -> str:
            return f"{pct(point['falls'] / point['episodes'])}%"

        figures = " / ".join(f"{rate(r['unguarded_points'][0])} → {rate(r['points'][0])}" for r in points.values())
        rows.append(f"| one 12 N s shove, {' / '.join(SHOVED)}, unguarded → guarded, catching into the catch skill | "
                    f"- | {figures} falls | [results]({RESULTS}#the-shipped-library-guarded) |")
    return rows


def readme_results(evidence_dir: Path = EVIDENCE, accuracy: Path = ACCURACY, guard: Path = GUARD) -> str:
    """The shipped library beside the paper: the net's accuracy on the paper's six pairs for each input, the net's
    margin on the dynamic-to-static pairs over the sweep, the strategies on Menagerie's A1, every pair at 0 N and
    one 12 N s shove; each row links the results page's section that shows it in full."""
    rows = [*(_accuracy_rows(accuracy) if Path(accuracy).is_file() else []), *_sweep_rows(evidence_dir),
            *_guard_rows(guard)]
    if not rows:
        return not_yet(Path(accuracy), Path(evidence_dir) / f"{NAME}.json")
    return "\n".join(["| measure | paper | gaitlib | where |", "|---|---|---|---|", *rows])


def runs_where(path: Path = GPU_CHECK) -> str:
    """Which engine runs on which device, with the GPU check's parity and training figures where they are stored."""
    lines = [json.loads(line) for line in Path(path).read_text(encoding="utf-8").splitlines() if line.strip()] \
        if Path(path).is_file() else []
    found = {line["measure"]: line for line in lines if "error" not in line}
    card = next((line["device"] for line in lines), None)
    if "parity" in found and "train" in found:
        parity = "passed" if found["parity"]["passed"] else "failed"
        gpu = (f"one {card.split()[1] if card.startswith('NVIDIA') else card} run: parity with MuJoCo C {parity}, "
               f"training at {found['train']['samples_per_s']:,} samples/s "
               "([benchmarks](docs/benchmarks.md#gpu-check-benchmarksgpu_checkpy))")
    else:
        gpu = "not yet measured on a GPU"
    return "\n".join([
        "| engine | device | status |", "|---|---|---|",
        "| MuJoCo C (`--backend mujoco`) | CPU, over all cores | everything shipped was trained and measured with it |",
        f"| Newton + mujoco_warp (`--backend newton`) | CUDA GPU (runs on the CPU, slowly) | {gpu} |"])
