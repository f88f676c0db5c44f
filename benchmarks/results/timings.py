"""The generated tables of ``docs/benchmarks.md``: training speed by recipe, the meta-controller's cost a control
step, a command's start, the test suite on a clean clone and the GPU check, each from its raw result stored under
``docs/results/`` (:mod:`benchmarks.results.doc` writes them into the page)."""

from __future__ import annotations

import json
from decimal import ROUND_HALF_UP, Decimal
from pathlib import Path

from benchmarks.results.evidence import EVIDENCE, GAITS, ROOT, not_yet, read_evidence
from benchmarks.results.guard import GUARD

__all__ = [
    "COMMAND_START", "COMMAND_START_POLICY", "GPU_CHECK", "SUITE", "command_start_table", "gpu_check_table",
    "gpu_graph_table", "guard_cost_table", "recipe_speed_table", "suite_table",
]

RESULTS = ROOT / "docs" / "results"
COMMAND_START = RESULTS / "command_start.json"
"""``gaitlib library --json`` timed as a whole process, the ONNX graph read two ways."""
COMMAND_START_POLICY = RESULTS / "command_start_policy.json"
"""Two commands timed as whole processes, the policy plain torch and rsl-rl's model."""
SUITE = RESULTS / "clean_clone_suite.json"
"""Every run of the test suite on a clean clone (``benchmarks/clean_clone_suite.py``)."""
GPU_CHECK = RESULTS / "gpu_check"
"""The raw lines of ``benchmarks/gpu_check.py``, one file a run."""
CODE = {
    "2dfce16": "the ONNX graph read from its protobuf bytes (`gaitlib.library.onnx_graph`, `2dfce16`)",
    "844b348": "`onnx` imported to read it (`844b348`)",
    "461a94f": "the plain-torch policy (`461a94f`)",
    "f209a43": "rsl-rl's model (`f209a43`)",
}
"""What each measured commit's code did, as the tables name it (the evidence's own words otherwise)."""
COMMANDS = {"library_json": ("`gaitlib library --json`", 5), "run_trot_stand": ("`gaitlib run --from trot --to stand "
                                                                                "--json`", 3)}
"""The commands of ``command_start_policy.json``, by its keys: as the table names them and the runs each got."""
PARTS = {
    "policy": "the gait policy (its actor, one observation; the reference)",
    "guard": "the guard (survival estimate, the net's offer of every other gait)",
    "lookahead": "`net-lookahead` (the waiting request)",
    "meta-controller": "the whole meta-controller",
}
"""The parts ``benchmarks/guard_cost.py`` times, as the table names them."""


def _fixed(value: float, places: int) -> str:
    """``value`` to ``places`` decimals, halves rounded up as written (6.305 is 6.31)."""
    return str(Decimal(str(value)).quantize(Decimal(1).scaleb(-places), rounding=ROUND_HALF_UP))


def _clock(seconds: float) -> str:
    whole = int(Decimal(str(seconds)).quantize(Decimal(1), rounding=ROUND_HALF_UP))
    return f"{whole // 60} min {whole % 60} s"


def _code(text: str) -> str:
    return CODE.get(text.split()[0], text)


def recipe_speed_table(path: Path = EVIDENCE / "recipe-speed.json") -> str:
    """Each gait's training speed with today's recipe and the robust one, and the robust one's time against it."""
    evidence = read_evidence(path)
    if evidence is None:
        return not_yet(path)
    result = evidence["result"]
    rows = []
    for gait in [g for g in GAITS if g in result] + sorted(set(result) - set(GAITS)):
        runs = {run["recipe"]: run for run in result[gait]}
        rows.append(f"| {gait} | {runs['today']['samples_per_s']:,} | {runs['robust']['samples_per_s']:,} | "
                    f"{_fixed(runs['robust']['time_vs_today'], 3)} |")
    return "\n".join(["| gait | today's recipe, samples/s | robust recipe, samples/s | time against today's recipe |",
                      "|---|---|---|---|", *rows])


def guard_cost_table(path: Path = GUARD / "guard-cost-recover.json") -> str:
    """Each part of the meta-controller's control step on one thread, every stored run's figure in a cell."""
    evidence = read_evidence(path)
    if evidence is None:
        return not_yet(path)
    runs = evidence["result"]["runs"]
    rows = []
    for part, name in PARTS.items():
        points = [next(p for p in run if p["part"] == part) for run in runs]

        def cell(key: str, places: int, scale: float = 1.0, unit: str = "", points: list = points,
                 bold: bool = part == "meta-controller") -> str:
            """The runs' figures of ``key``, one when they agree; the whole step's ratios in bold."""
            texts = [_fixed(p[key] * scale, places) + unit for p in points]
            text = texts[0] if len(set(texts)) == 1 else ", ".join(texts)
            return f"**{text}**" if bold and key != "median_ms" else text

        rows.append(f"| {name} | {cell('median_ms', 2)} | {', '.join(_fixed(p['p99_ms'], 2) for p in points)} | "
                    f"{cell('median_vs_policy', 1)} | {cell('p99_of_30hz_step', 1, 100, '%')} |")
    return "\n".join(["| part | median, ms | 99th percentile, ms | median against the policy's own step | 99th "
                      "percentile of a 33 ms step |", "|---|---|---|---|---|", *rows])


def _start_rows(pair: dict, label: str | None = None) -> list[str]:
    """The two sides of a command's start, the first (the newer code) in bold: wall, CPU and memory medians; the
    first row begins with ``label`` when given (a cell of its own)."""
    rows = []
    for side in ("A", "B"):
        figures = pair[side]
        wall = f"{_fixed(figures['wall_s'][1], 2)} s"
        lead = "| " if label is None else f"| {label} | " if side == "A" else "| | "
        rows.append(f"{lead}{_code(figures['code'])} | {f'**{wall}**' if side == 'A' else wall} | "
                    f"{_fixed(figures['cpu_s'][1], 2)} s | {_fixed(figures['peak_mib'][1], 0)} MiB |")
    return rows


def _ratio(pair: dict) -> str:
    low, median, high = pair["ratio_A_over_B"]["wall"]
    return f"{_fixed(median, 2)} ({_fixed(low, 2)}-{_fixed(high, 2)})"


def command_start_table(path: Path = COMMAND_START) -> str:
    """``gaitlib library --json`` as a whole process, the newer code against the older, medians of the runs."""
    if not Path(path).is_file():
        return not_yet(path)
    pair = json.loads(Path(path).read_text(encoding="utf-8"))
    return "\n".join(["| code | wall (median) | CPU | peak memory |", "|---|---|---|---|", *_start_rows(pair), "",
                      f"Ratio of the wall times {_ratio(pair)}: median, and the least and most over the runs."])


def command_start_policy_table(path: Path = COMMAND_START_POLICY) -> str:
    """Two commands as whole processes, the plain-torch policy against rsl-rl's model, medians of the runs."""
    if not Path(path).is_file():
        return not_yet(path)
    evidence = json.loads(Path(path).read_text(encoding="utf-8"))
    rows, ratios, saved, memory = [], [], [], []
    for key, (command, runs) in COMMANDS.items():
        pair = evidence[key]
        rows += _start_rows(pair, f"{command} ({runs} runs each)")
        ratios.append(_ratio(pair))
        less = {key: round(pair["B"][key][1] - pair["A"][key][1], 6) for key in ("wall_s", "peak_mib")}
        saved.append(f"{_fixed(less['wall_s'], 1)} s")
        memory.append(_fixed(less["peak_mib"], 0))
    return "\n".join(["| command | code | wall (median) | CPU | peak memory |", "|---|---|---|---|---|", *rows, "",
                      f"Ratios of the wall times {' and '.join(ratios)}: {' and '.join(saved)} less a command, and "
                      f"{' and '.join(memory)} MiB less memory."])


def suite_table(path: Path = SUITE) -> str:
    """The latest run of the test suite on a clean clone, as one row."""
    evidence = read_evidence(path)
    if evidence is None:
        return not_yet(path)
    run = evidence["result"][-1]
    cache = {"warm": "the machine's", "empty": "an empty one"}.get(run.get("warp_cache", "warm"), run.get("warp_cache"))
    reference = f"{_fixed(run['reference_s'], 2)} s" if "reference_s" in run else "-"
    return "\n".join([
        "| date | code | Warp kernel cache | result | install | tests | in all | reference |",
        "|---|---|---|---|---|---|---|---|",
        f"| {evidence['made']} | main at `{run['commit']}` | {cache} | {run['summary']} | {_clock(run['install_s'])} | "
        f"{_clock(run['tests_s'])} | {_clock(run['total_s'])} | {reference} |"])


def _lines(path: Path) -> list[dict]:
    return [json.loads(line) for line in Path(path).read_text(encoding="utf-8").splitlines() if line.strip()]


def _small(value: float) -> str:
    mantissa, exponent = f"{value:.1e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def gpu_check_table(path: Path = GPU_CHECK / "h100.jsonl") -> str:
    """Every line of one run of the GPU check: the figures of each measurement and its seconds."""
    if not Path(path).is_file():
        return not_yet(path)
    rows, first = [], True
    for line in _lines(path):
        measure, worlds = line["measure"], f"{line['worlds']:,}"
        if "error" in line:
            rows.append(f"| `{measure}` | {worlds} | failed: {line['error']} | {line['seconds']:.1f} |")
        elif measure == "sim":
            unit = " control steps/s" if first else ""
            seconds = f"{line['seconds']:.1f}" + (f" (build {line['build_s']:.1f} and settle {line['settle_s']:.1f}: "
                                                  "Warp's first compilation)" if first else "")
            rows.append(f"| `sim` | {worlds} | backend {line['env_steps_per_s']:,}{unit}; raw eager "
                        f"{line['raw_eager_steps_per_s']:,}; raw graph {line['raw_graph_steps_per_s']:,}; ratio "
                        f"**{line['ratio']:.3f}** | {seconds} |")
            first = False
        elif measure == "parity":
            rows.append(f"| `parity` | {worlds} | {'passed' if line['passed'] else 'failed'}; trunk position "
                        f"{_small(line['max_root_pos_diff_m'])} m, quaternion {_small(line['max_root_quat_diff'])}, "
                        f"joints {_small(line['max_joint_pos_diff_rad'])} rad, "
                        f"feet {_small(line['max_foot_pos_diff_m'])} m, {line['foot_contact_mismatches']} contact "
                        f"mismatches | {line['seconds']:.1f} |")
        elif measure == "train":
            rows.append(f"| `train` (`--preset {line['preset']}`, `{line['backend']}`) | {worlds} | "
                        f"{line['iterations']} iterations in {line['train_s']:.1f} s: **{line['samples_per_s']:,} "
                        f"samples/s** (last iteration {line['last_iteration_samples_per_s']:,}); the evaluation fell "
                        f"{line['eval_fall_rate']:.1%} | {line['seconds']:.1f} |")
        elif measure == "collect":
            rows.append(f"| `collect` | {worlds} | **{line['samples_per_s']:,} samples/s**; plain rollout "
                        f"{line['env_steps_per_s']:,} control steps/s, {line['steps_per_sample']:g} a sample; ratio "
                        f"**{line['ratio']:.3f}** | {line['seconds']:.1f} |")
    return "\n".join(["| measure | worlds | figure | seconds |", "|---|---|---|---|", *rows])


def gpu_graph_table(path: Path = GPU_CHECK / "cpu-tiny-graph.jsonl") -> str:
    """The ``sim`` line of a run of the GPU check: the backend against raw mujoco_warp eager and as one graph."""
    if not Path(path).is_file():
        return not_yet(path)
    line = next(line for line in _lines(path) if line["measure"] == "sim")
    return "\n".join([
        "| backend | raw mujoco_warp, eager | raw mujoco_warp, one graph | ratio to the faster raw side |",
        "|---|---|---|---|",
        f"| {line['env_steps_per_s']:,} control steps/s | {line['raw_eager_steps_per_s']:,} | "
        f"{line['raw_graph_steps_per_s']:,} | **{_fixed(line['ratio'], 2)}** |"])
