"""The disturbance sweep on the real simulator at a tiny size: well-formed outputs, resumption, intervals."""

from __future__ import annotations

import csv
import dataclasses
import json

import numpy as np
import pytest

from gaitlib.benchmark.report import (
    CellResult,
    cell_results,
    success_matrix,
    success_table,
    summary,
    write_csv,
    write_matrix,
    write_plot,
)
from gaitlib.benchmark.results import load_results
from gaitlib.benchmark.sweep import SweepConfig, run_sweep
from gaitlib.errors import GaitlibError
from gaitlib.meta import TrialProtocol, load_switching
from gaitlib.stats import wilson_interval

TINY = SweepConfig(
    strategies=("random", "net"),
    magnitudes=(0.0, 300.0),
    samples=3,
    pairs=(("trot", "stand"),),
    num_worlds=4,
    protocol=TrialProtocol(warmup_s=0.3, source_extra_s=0.2, horizon_s=0.5, deadline_s=0.3, push_lead_s=0.2),
    backend="mujoco",
)


def _with(config: SweepConfig, **protocol) -> SweepConfig:
    """``config`` with some of its protocol's fields changed."""
    return dataclasses.replace(config, protocol=dataclasses.replace(config.protocol, **protocol))


def test_wilson_interval_matches_hand_computed_values() -> None:
    low, high = wilson_interval(0, 10)
    assert low == 0.0 and high == pytest.approx(0.2775, abs=1e-4)
    low, high = wilson_interval(5, 10)
    assert (low, high) == (pytest.approx(0.2366, abs=1e-4), pytest.approx(0.7634, abs=1e-4))
    assert wilson_interval(0, 0) == (0.0, 1.0)
    for n in range(1, 60):  # the bounds hold the rate itself, even where rounding alone would put them past it
        for k in (0, n):
            low, high = wilson_interval(k, n)
            assert low <= k / n <= high


def test_the_net_margin_has_a_hand_computed_interval() -> None:
    def cell(strategy: str, magnitude: float, successes: int, pair: str = "trot-stand") -> CellResult:
        return CellResult(strategy, pair, magnitude, 100, successes, successes / 100, 0, 1, 0, 0, 0, 0.0, 0, 1, 0.0)

    rows = [cell("net", 0, 90), cell("net", 100, 50), cell("tmt", 0, 80), cell("tmt", 100, 40)]
    rows.append(cell("random", 0, 100, pair="pace-stand"))  # better, but on another pair
    margin = summary(rows)["margins"]["net"]["trot-stand"]
    assert margin["second_best"] == "tmt" and margin["margin_pp"] == pytest.approx(10.0)
    # variance of each mean: (p1 (1 - p1) / 100 + p2 (1 - p2) / 100) / 2^2
    variance = (0.09 / 100 + 0.25 / 100) / 4 + (0.16 / 100 + 0.24 / 100) / 4
    assert margin["ci95_pp"] == pytest.approx(100 * 1.959964 * variance**0.5, rel=1e-6)
    rows += [cell("random", 0, 70), cell("random", 100, 30)]  # below tmt: not the second best, still reported
    rows += [cell("net-lookahead", 0, 96), cell("net-lookahead", 100, 50)]
    facts = summary(rows)
    assert facts["margins"]["net"]["trot-stand"]["second_best"] == "net-lookahead"  # 73% against net's 70%
    over_random = facts["margins"]["net"]["trot-stand"]["over_random"]
    assert over_random["margin_pp"] == pytest.approx(20.0)
    variance = (0.09 / 100 + 0.25 / 100) / 4 + (0.21 / 100 + 0.21 / 100) / 4
    assert over_random["ci95_pp"] == pytest.approx(100 * 1.959964 * variance**0.5, rel=1e-6)
    lookahead = facts["margins"]["net-lookahead"]["trot-stand"]  # every net strategy gets its own margins
    assert lookahead["second_best"] == "net" and lookahead["margin_pp"] == pytest.approx(3.0)
    assert lookahead["over_random"]["margin_pp"] == pytest.approx(23.0)
    assert "pace-stand" not in facts["margins"]["net"]  # no net there
    assert set(summary(rows, focus=("tmt",))["margins"]) == {"tmt"}



def test_the_pair_matrix_puts_each_cell_at_its_source_row_and_destination_column(tmp_path) -> None:
    def cell(strategy: str, pair: str, magnitude: float, successes: int) -> CellResult:
        return CellResult(strategy, pair, magnitude, 100, successes, successes / 100, 0, 1, 0, 0, 0, 0.0, 0, 1, 0.0)

    rows = [cell("net", "trot-stand", 0, 90), cell("net", "stand-pace", 0, 80), cell("net", "trot-stand", 100, 10)]
    rows.append(cell("random", "pace-trot", 0, 70))
    gaits, matrix = success_matrix(rows, strategy="net", magnitude_n=0)
    assert gaits == ["trot", "stand", "pace"]  # as they first appear
    expected = np.full((3, 3), np.nan)
    expected[0, 1], expected[1, 2] = 0.9, 0.8  # trot -> stand, stand -> pace; pace -> trot is random's
    np.testing.assert_array_equal(matrix, expected)
    assert success_matrix(rows, strategy="net", magnitude_n=100)[1][0, 1] == pytest.approx(0.1)
    figure = write_matrix(tmp_path / "matrix.png", rows)
    assert figure.read_bytes().startswith(b"\x89PNG")


def test_a_tiny_sweep_is_well_formed_and_resumes(switching_library, tmp_path) -> None:
    setup = load_switching(switching_library)
    out = tmp_path / "bench"
    calls = []

    def stop_after_first_group(group: str, done: int, total: int) -> None:
        calls.append((group, done, total))
        if group != "random@0":
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_sweep(out, setup, TINY, progress=stop_after_first_group)
    first = load_results(out)
    assert list(first["groups"]) == ["random@0"]  # the finished group is kept, the interrupted one is not
    assert calls[-1][2] == 4 * 3 and calls[0][1] >= 1

    results = run_sweep(out, setup, TINY)
    assert list(results["groups"]) == ["random@0", "random@300", "net@0", "net@300"]
    assert results["groups"]["random@0"] == first["groups"]["random@0"]
    for group in results["groups"].values():
        cell = group["cells"]["trot-stand"]
        assert cell["samples"] == 3 and 0 <= cell["successes"] <= 3
        assert cell["switched"] <= 3 and cell["forced"] <= cell["switched"]
    assert results["groups"]["random@0"]["cells"]["trot-stand"]["wait_s"] == 0.0  # random switches at once
    net = results["groups"]["net@0"]["cells"]["trot-stand"]
    assert net["wait_s"] <= net["switched"] * (TINY.protocol.deadline_s + 1e-6)

    again = run_sweep(out, setup, TINY, progress=lambda *a: pytest.fail("a finished sweep must not run again"))
    assert again == results

    rows = cell_results(results)
    assert len(rows) == 4 and all(r.ci95_low <= r.success_rate <= r.ci95_high for r in rows)
    table = success_table(rows)
    assert set(table) == {"random", "net"} and set(table["net"]["trot-stand"]) == {"0", "300"}
    facts = summary(rows)
    assert set(facts["ranking"]) == {"random", "net"} and "trot-stand" in facts["margins"]["net"]
    write_csv(tmp_path / "r.csv", rows)
    with open(tmp_path / "r.csv") as handle:
        lines = list(csv.DictReader(handle))
    assert len(lines) == 4 and {line["strategy"] for line in lines} == {"random", "net"}
    plot = write_plot(tmp_path / "r.png", rows)
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_pushes_come_only_inside_the_disturbance_window(tmp_path) -> None:
    setup = load_switching(None)  # the shipped library: unpushed, 99% of its pace-to-stand switches stay up
    base = dataclasses.replace(
        TINY, strategies=("random",), magnitudes=(1500.0,), pairs=(("pace", "stand"),), samples=8, num_worlds=8,
        protocol=dataclasses.replace(TINY.protocol, push_lead_s=0.0),
    )
    # The quiet time before the first push (0.2-1.0 s) outlasts a 0.1 s window: no push ever lands.
    calm = run_sweep(tmp_path / "calm", setup, _with(base, deadline_s=0.1))
    # A 1.2 s window always holds one, and no 12.45 kg robot rides out a push of 1,500 N.
    pushed = run_sweep(tmp_path / "pushed", setup, _with(base, deadline_s=1.2, horizon_s=1.2))
    for results, successes in ((calm, range(7, 9)), (pushed, range(1))):
        cell = results["groups"]["random@1500"]["cells"]["pace-stand"]
        assert cell["successes"] in successes
        assert cell["source_falls"] == 0  # no push before the request with no lead


def test_a_horizon_shorter_than_the_deadline_is_refused(switching_library, tmp_path) -> None:
    with pytest.raises(GaitlibError, match="horizon must be at least the deadline"):
        run_sweep(tmp_path, load_switching(switching_library), _with(TINY, horizon_s=0.2))


def test_resuming_with_other_settings_is_refused(switching_library, tmp_path) -> None:
    setup = load_switching(switching_library)
    small = dataclasses.replace(TINY, strategies=("random",), magnitudes=(0.0,), samples=1)
    run_sweep(tmp_path, setup, small)
    with pytest.raises(GaitlibError, match="other settings"):
        run_sweep(tmp_path, setup, dataclasses.replace(small, samples=2))
    (tmp_path / "results.json").write_text(json.dumps({"format": "something else"}))
    with pytest.raises(GaitlibError, match="not gaitlib benchmark results"):
        run_sweep(tmp_path, setup, small)
