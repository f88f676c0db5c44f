"""The switch-success budget: nets fitted on the first samples of each pair (``gaitlib fit --per-pair``), and
benchmarked on the pairs they were fitted on alone (``gaitlib benchmark --pairs``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gaitlib.collection import CollectConfig, collect
from gaitlib.errors import TransitionDataError
from gaitlib.library import Library
from gaitlib.meta import TrialProtocol, load_switching
from gaitlib.strategies.fitting import fit_library
from gaitlib.transitions import read, read_all
from tests.cli_runner import gaitlib_quick
from tests.conftest import copy_library


def _pair_rows(data) -> dict[tuple[int, int], np.ndarray]:
    """Per ordered pair, its samples' latents in order."""
    s = data.samples
    return {(m, n): s.latent[(s.source == m) & (s.dest == n)] for m, n in s.pairs()}


def test_a_budget_keeps_the_first_samples_of_each_pair_of_each_file(switching_library, tmp_path) -> None:
    samples = switching_library.parent / "samples.h5"
    whole = _pair_rows(read(samples))
    assert len(whole) == 2 and all(len(rows) > 5 for rows in whole.values())
    for budget in (1, 5):
        kept = read_all([samples], per_pair=budget)
        rows = _pair_rows(kept)
        assert {pair: len(r) for pair, r in rows.items()} == dict.fromkeys(whole, budget)
        for pair, r in rows.items():
            np.testing.assert_array_equal(r, whole[pair][:budget])  # the first ones, in file order: nested
        assert f"the first {budget:,} samples of each ordered pair of each file kept" in kept.info.note
    assert sum(len(r) for r in _pair_rows(read_all([samples], per_pair=10_000)).values()) == 32
    with pytest.raises(ValueError, match="at least 1"):
        read_all([samples], per_pair=0)

    second = tmp_path / "second.h5"  # a second file with its own samples: the budget is per file
    config = CollectConfig(samples=16, num_worlds=8, push_max=400.0, backend="mujoco", seed=7,
                           protocol=TrialProtocol.collection(horizon_s=1.0, warmup_s=0.3, source_extra_s=0.5))
    collect(second, library=Library(switching_library), config=config)
    both = _pair_rows(read_all([samples, second], per_pair=3))
    assert all(len(r) == 6 for r in both.values())

    library = copy_library(Library(switching_library), tmp_path / "library")
    fitted = gaitlib_quick("fit", "--data", str(samples), "--per-pair", "5", "--epochs", "1", "--min-per-label", "0",
                           "--library", str(library.root), "--json")
    assert fitted.returncode == 0, fitted.stderr
    report = json.loads(fitted.stdout)
    assert report["samples"] == 10 and "the first 5 samples of each ordered pair" in report["data_note"]


def test_a_benchmark_of_the_pairs_a_net_was_fitted_on_runs_and_others_are_refused(switching_library,
                                                                                  tmp_path) -> None:
    library = copy_library(Library(switching_library), tmp_path / "library")
    data = tmp_path / "stand-trot.h5"
    config = CollectConfig(samples=16, num_worlds=8, push_max=400.0, backend="mujoco", pairs=(("stand", "trot"),),
                           protocol=TrialProtocol.collection(horizon_s=1.0, warmup_s=0.3, source_extra_s=0.5))
    collect(data, library=library, config=config)
    fit_library(library, read(data), sources=[data], epochs=1, min_per_label=0)

    setup = load_switching(library)
    with pytest.raises(TransitionDataError, match="trot-stand"):  # every pair: the one not fitted is refused
        _ = setup.resources.net
    served = setup.serving([("stand", "trot")])
    assert served.resources.net is not None
    with pytest.raises(TransitionDataError, match="trot-stand"):
        _ = setup.serving([("trot", "stand")]).resources.net

    out = tmp_path / "bench"
    args = ["benchmark", "--library", str(library.root), "--strategies", "net-lookahead", "--magnitudes", "0",
            "--samples", "2", "--worlds", "2", "--backend", "mujoco", "--out", str(out), "--json"]
    ran = gaitlib_quick(*args, "--pairs", "stand-trot")
    assert ran.returncode == 0, ran.stderr
    cell = json.loads((out / "results.json").read_text())["groups"]["net-lookahead@0"]["cells"]["stand-trot"]
    assert cell["samples"] == 2
    refused = gaitlib_quick(*args[:-3], "--out", str(tmp_path / "other"), "--pairs", "trot-stand")
    assert refused.returncode != 0 and "trot-stand" in refused.stderr and not (tmp_path / "other").exists()


def test_the_budget_is_the_smallest_within_the_largest_s_interval() -> None:
    from benchmarks.results.budget import budget_per_pair

    def row(name: str, falls: int, strategy: str = "net-lookahead") -> dict:
        return {"row": name, "strategy": strategy, "falls": falls, "trials": 5000}

    rows = [row("random", 263, "random"), row("500", 82), row("1500", 39), row("4000", 30), row("6668", 31)]
    assert budget_per_pair({"rows": rows, "files": ["a", "b"]}) == 1500  # 39 of 5000 lies in 31's interval
    rows[2]["falls"] = 60  # outside it: the next budget that is inside
    assert budget_per_pair({"rows": rows, "files": ["a", "b"]}) == 4000

