"""Switching strategies on constructed inputs: each makes the decision its definition implies."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
import torch
from conftest import copy_library

from gaitlib.errors import TransitionDataError, UnknownNameError
from gaitlib.library import Library
from gaitlib.meta.episode import run_episode
from gaitlib.meta.setup import load_switching
from gaitlib.strategies import (
    PHASE_GRID,
    SwitchQuery,
    SwitchResources,
    TransitionTable,
    build_table,
    get_strategy,
    load_table,
    phase_grid,
    register_strategy,
    save_table,
    strategy_names,
)
from gaitlib.strategies.calibration import Calibration, calibrate, platt
from gaitlib.strategies.lookahead import LookaheadStrategy
from gaitlib.strategies.net import NetStrategy
from gaitlib.strategies.random_switch import RandomStrategy
from gaitlib.strategies.tmt import TMTStrategy, TMTValueStrategy, best_threshold
from gaitlib.strategies.value import ValueStrategy
from gaitlib.transition_net import FeatureSpec, TransitionNet
from gaitlib.transitions.schema import TransitionBatch, TransitionData, TransitionFileInfo, TransitionHeader

GAITS = ("stand", "trot")
IDENTITIES = {"stand": "a" * 64, "trot": "b" * 64}


def query(k: int = 3, *, latent_dim: int = 4, dest_value: torch.Tensor | None = None, phase_source=0.1):
    return SwitchQuery(
        source=torch.ones(k, dtype=torch.long),
        dest=torch.zeros(k, dtype=torch.long),
        phase_source=torch.full((k,), phase_source),
        latent=torch.zeros(k, latent_dim),
        candidates=phase_grid(),
        dest_value=dest_value,
    )


def empty_table(bins: int = PHASE_GRID) -> TransitionTable:
    return TransitionTable(
        gaits=GAITS,
        identities=IDENTITIES,
        successes=np.zeros((2, 2, bins, bins), dtype=np.int64),
        counts=np.zeros((2, 2, bins, bins), dtype=np.int64),
        typical_value=np.ones(2),
        thresholds={"value": {(1, 0): 0.8}, "tmt": {(1, 0): 0.7}, "tmt-value": {(1, 0): 0.6}},
        info={},
    )


def test_the_phase_grid_is_bin_centres() -> None:
    grid = phase_grid(4)
    assert torch.allclose(grid, torch.tensor([0.125, 0.375, 0.625, 0.875]))
    assert len(phase_grid()) == PHASE_GRID


def test_registry_holds_the_five_strategies_and_takes_new_ones(monkeypatch) -> None:
    from gaitlib import strategies

    assert strategy_names()[:5] == ["random", "value", "tmt", "tmt-value", "net"]
    resources = SwitchResources(library=None, gaits=GAITS)  # type: ignore[arg-type]
    with pytest.raises(UnknownNameError, match="unknown strategy 'oracle'"):
        get_strategy("oracle", resources)
    monkeypatch.setattr(strategies._STRATEGIES, "_items", dict(strategies._STRATEGIES._items))  # restored after
    register_strategy("always", lambda r: ValueStrategy(threshold=-math.inf))
    assert isinstance(get_strategy("always", resources), ValueStrategy) and "always" in strategy_names()


def test_random_switches_every_world_at_once_at_random_phases() -> None:
    decision = RandomStrategy(seed=1).decide(query(64))
    assert decision.switch.all()
    assert torch.all((decision.phase >= 0) & (decision.phase < 1)) and decision.phase.std() > 0.1
    assert torch.isnan(decision.score).all()


def test_value_switches_at_the_best_candidate_once_it_reaches_its_threshold() -> None:
    values = torch.full((2, PHASE_GRID), 0.5)
    values[0, 5] = 0.9  # above the pair's threshold 0.8
    values[1, 9] = 0.7  # below it
    decision = ValueStrategy(threshold={(1, 0): 0.8}).decide(query(2, dest_value=values))
    assert decision.switch.tolist() == [True, False]
    assert decision.phase.tolist() == pytest.approx([phase_grid()[5].item(), phase_grid()[9].item()])
    assert decision.score.tolist() == pytest.approx([0.9, 0.7])


def test_a_pair_without_a_calibrated_threshold_never_switches() -> None:
    values = torch.full((1, PHASE_GRID), 10.0)
    q = query(1, dest_value=values)
    q.source[:] = 0  # the pair (0, 0) has no threshold
    assert not ValueStrategy(threshold={(1, 0): 0.8}).decide(q).switch.any()


def test_tmt_picks_the_best_destination_bin_at_the_current_source_bin() -> None:
    table = empty_table()
    source_bin = 1  # phase_source 0.1 lies in bin 1 of 16
    table.counts[1, 0, source_bin] = 10
    table.successes[1, 0, source_bin] = 3
    table.successes[1, 0, source_bin, 11] = 9  # best: (9 + 1) / (10 + 2)
    table.successes[1, 0, 4, 2] = 10  # a better cell at another source bin does not count
    table.counts[1, 0, 4, 2] = 10
    decision = TMTStrategy(table).decide(query(1))
    assert decision.phase.item() == pytest.approx(phase_grid()[11].item())
    assert decision.score.item() == pytest.approx(10 / 12)
    assert decision.switch.item()  # 0.833 >= 0.7
    table.successes[1, 0, source_bin, 11] = 6  # now (6 + 1) / 12 = 0.58 < 0.7
    assert not TMTStrategy(table).decide(query(1)).switch.item()


def test_tmt_value_multiplies_the_alive_rate_by_the_value() -> None:
    table = empty_table()
    table.counts[1, 0, 1] = 8
    table.successes[1, 0, 1] = 6  # alive rate 0.7 everywhere in this source bin
    values = torch.ones(1, PHASE_GRID)
    values[0, 3] = 1.2
    decision = TMTValueStrategy(table).decide(query(1, dest_value=values))
    assert decision.phase.item() == pytest.approx(phase_grid()[3].item())
    assert decision.score.item() == pytest.approx(0.7 * 1.2)
    assert decision.switch.item()  # 0.84 >= 0.6


def phase_net(bias: float) -> TransitionNet:
    """A net whose probability is sigmoid(4 relu(sin 2 pi phi_n) + bias): best near phi_n = 0.25."""
    spec = FeatureSpec(kind="latent", gaits=GAITS, latent_dim=4)
    net = TransitionNet(spec)
    with torch.no_grad():
        for layer in net.mlp:
            if isinstance(layer, torch.nn.Linear):
                layer.weight.zero_()
                layer.bias.zero_()
        linears = [m for m in net.mlp if isinstance(m, torch.nn.Linear)]
        linears[0].weight[0, spec.dim - 2] = 1.0  # sin 2 pi phi_n
        linears[1].weight[0, 0] = 1.0
        linears[2].weight[0, 0] = 1.0
        linears[3].weight[0, 0] = 4.0
        linears[3].bias[0] = bias
    return net.eval()


def test_net_searches_the_phase_grid_and_never_switches_below_its_threshold() -> None:
    low = NetStrategy(phase_net(bias=math.log(0.9 / 0.1) - 4.0))  # best probability about 0.9 < 0.95
    decision = low.decide(query(5))
    assert not decision.switch.any()
    assert torch.all(decision.score < 0.95) and torch.all(decision.score > 0.85)
    assert min(abs(decision.phase[0].item() - p) for p in (7 / 32, 9 / 32)) < 1e-6  # the candidates nearest 0.25
    high = NetStrategy(phase_net(bias=0.0))  # best probability sigmoid(3.92) = 0.98
    assert high.decide(query(5)).switch.all()
    assert high.threshold == 0.95


def test_best_threshold_maximizes_balanced_accuracy() -> None:
    scores = np.array([0.1, 0.2, 0.3, 0.4, 0.6, 0.7, 0.8, 0.9])
    labels = np.array([0, 0, 0, 1, 0, 1, 1, 1])
    assert best_threshold(scores, labels) == pytest.approx(0.7)  # balanced accuracy 0.875 (0.4 ties; the first wins)
    assert best_threshold(scores, np.ones(8)) == -math.inf
    assert best_threshold(scores, np.zeros(8)) == math.inf


def synthetic_data(n: int = 4000, seed: int = 0) -> TransitionData:
    """trot -> stand and back; success iff the destination phase is in the first half (and value follows it)."""
    rng = np.random.default_rng(seed)
    source = rng.integers(0, 2, n)
    phase_dest = rng.random(n)
    success = (phase_dest < 0.5).astype(np.uint8)
    batch = TransitionBatch(
        source=source, dest=1 - source, latent=rng.normal(size=(n, 4)), phase_source=rng.random(n),
        phase_dest=phase_dest, explicit=rng.normal(size=(n, 66)), value_source=np.full(n, 2.0),
        value_dest=np.where(success == 1, 2.0, 1.0) + 0.1 * rng.normal(size=n), push_force=np.zeros(n),
        success=success, switch_time=np.ones(n), world=np.zeros(n), chunk=np.zeros(n),
    )
    header = TransitionHeader(gaits=GAITS, identities=tuple(IDENTITIES.values()), latent_dim=4, settings={})
    return TransitionData(TransitionFileInfo(header, n, [], None), batch)


def test_table_built_from_data_counts_outcomes_and_calibrates_thresholds(tmp_path) -> None:
    data = synthetic_data()
    table = build_table(data, identities=IDENTITIES, source="synthetic", falls="trunk")
    assert table.counts.sum() == 4000 and table.successes.sum() == data.samples.success.sum()
    assert table.typical_value.tolist() == pytest.approx([2.0, 2.0])
    # values of successes are about 1.0 (normalized), of failures about 0.5: the threshold falls between
    assert 0.6 < table.thresholds["value"][(0, 1)] <= 1.0
    # alive rates of first-half bins are near 1, of second-half bins near 0
    assert 0.2 < table.thresholds["tmt"][(1, 0)] < 0.9
    decision = TMTStrategy(table).decide(query(1))
    assert decision.switch.item() and decision.phase.item() < 0.5
    path = save_table(tmp_path / "tmt" / "tmt.json", table)
    loaded = load_table(path, identities=IDENTITIES)
    assert np.array_equal(loaded.counts, table.counts) and loaded.thresholds == table.thresholds
    assert oct(path.stat().st_mode & 0o777) != oct(0o600)  # readable beside the library entries


def test_a_pair_that_never_fails_is_always_switched_and_its_table_is_strict_json(tmp_path) -> None:
    # Every stand -> trot switch succeeds, every trot -> stand one fails: thresholds -inf (switch at any score)
    # and +inf (never), written as strings JSON can hold and read back as the same decisions.
    data = synthetic_data()
    data.samples.success[:] = (data.samples.source == 0).astype(np.uint8)
    table = build_table(data, identities=IDENTITIES, source="synthetic", falls="trunk")
    assert table.thresholds["tmt"] == {(0, 1): -math.inf, (1, 0): math.inf}
    path = save_table(tmp_path / "tmt.json", table)
    strict = json.loads(path.read_text(), parse_constant=lambda name: pytest.fail(f"{name} is not JSON"))
    assert strict["thresholds"]["tmt"] == {"stand-trot": "-inf", "trot-stand": "inf"}
    loaded = load_table(path, identities=IDENTITIES)
    assert loaded.thresholds == table.thresholds
    trot_to_stand = query(1)
    stand_to_trot = dataclasses.replace(trot_to_stand, source=trot_to_stand.dest, dest=trot_to_stand.source)
    tmt = TMTStrategy(loaded)
    assert tmt.decide(stand_to_trot).switch.item() and not tmt.decide(trot_to_stand).switch.item()


def test_a_table_for_other_policies_or_a_foreign_file_is_refused(tmp_path) -> None:
    table = build_table(synthetic_data(400), identities=IDENTITIES, source="x", falls="trunk")
    path = save_table(tmp_path / "tmt.json", table)
    with pytest.raises(TransitionDataError, match="another 'trot' policy"):
        load_table(path, identities={"stand": "a" * 64, "trot": "c" * 64})
    foreign = tmp_path / "foreign.json"
    foreign.write_text(json.dumps({"weights": [1, 2]}))
    with pytest.raises(TransitionDataError, match="not a gaitlib TMT"):
        load_table(foreign, identities=IDENTITIES)
    with pytest.raises(TransitionDataError, match="no TMT"):
        load_table(tmp_path / "missing.json", identities=IDENTITIES)


# ----------------------------------------------------------------------------------- calibration and lookahead
HEADER = TransitionHeader(gaits=GAITS, identities=tuple(IDENTITIES.values()), latent_dim=4, settings={})


def synthetic_batch(n: int, success: np.ndarray) -> TransitionBatch:
    """n trot -> stand switches with the given outcomes (other columns random)."""
    rng = np.random.default_rng(2)
    return TransitionBatch(
        source=np.ones(n), dest=np.zeros(n), latent=rng.normal(size=(n, 4)), phase_source=rng.random(n),
        phase_dest=rng.random(n), explicit=rng.normal(size=(n, 66)), value_source=np.ones(n), value_dest=np.ones(n),
        push_force=np.zeros(n), success=success, switch_time=np.ones(n), world=np.zeros(n), chunk=np.zeros(n),
    )


def constant_net(probability: float) -> TransitionNet:
    """A net that scores every input ``probability``."""
    net = phase_net(bias=math.log(probability / (1 - probability)))
    with torch.no_grad():
        [m for m in net.mlp if isinstance(m, torch.nn.Linear)][3].weight.zero_()
    return net.eval()


def test_platt_recovers_the_map_the_labels_were_drawn_from() -> None:
    rng = np.random.default_rng(0)
    score = rng.uniform(0.02, 0.98, 20_000)
    truth = 1 / (1 + np.exp(-(2.0 * np.log(score / (1 - score)) - 1.0)))
    a, b = platt(score, rng.random(len(score)) < truth)
    assert (a, b) == (pytest.approx(2.0, abs=0.1), pytest.approx(-1.0, abs=0.1))
    # A weight is a repeated sample; and a pair that never fails keeps finite parameters.
    few, labels = np.array([0.3, 0.6, 0.8]), np.array([False, True, True])
    repeated = [0, 1, 1, 2]
    assert platt(few, labels, np.array([1.0, 2.0, 1.0])) == pytest.approx(platt(few[repeated], labels[repeated]))
    assert all(math.isfinite(v) for v in platt(few, np.ones(3, dtype=bool)))


def test_platt_is_the_likelihoods_maximum_where_a_plain_newton_step_overshoots() -> None:
    """A few successes at a score of 1e-6 (the lowest the calibration reads), beside ordinary ones: Newton's step
    from (1, 0) overshoots to parameters of 1e9 and more without a line search."""
    z = np.r_[np.full(5, math.log(1e-6 / (1 - 1e-6))), np.full(1100, 2.0), np.linspace(-5, 5, 50)]
    success = np.r_[np.ones(1005), np.zeros(100), np.linspace(-5, 5, 50) > 0].astype(bool)
    a, b = platt(1 / (1 + np.exp(-z)), success)
    positives, negatives = success.sum(), (~success).sum()
    target = np.where(success, (positives + 1) / (positives + 2), 1 / (negatives + 2))

    def loss(pa: float, pb: float) -> float:
        s = pa * z + pb
        return float(np.sum(np.logaddexp(0.0, s) - target * s))

    assert abs(a) < 10 and abs(b) < 10
    assert all(loss(a, b) <= loss(a + da, b + db) for da in (-1e-3, 0, 1e-3) for db in (-1e-3, 0, 1e-3))


def test_calibration_undoes_the_balanced_prior() -> None:
    """A score that says nothing (0.5 everywhere) on a pair where 90% of switches succeed, calibrated on held-out
    rows of which the training took as many failures as successes, is worth about 0.9."""
    n = 2000
    rng = np.random.default_rng(1)
    success = rng.random(n) < 0.9
    batch = synthetic_batch(n, success)
    data = TransitionData(TransitionFileInfo(HEADER, n, [], None), batch)
    failures, successes = np.flatnonzero(~success), np.flatnonzero(success)
    train = np.r_[failures[: int(0.8 * len(failures))], successes[: int(0.8 * len(failures))]]  # balanced
    calibration = calibrate(constant_net(0.5), data, train_rows=train, identities=IDENTITIES, falls="trunk")
    p = calibration.probability(torch.tensor([1]), torch.tensor([0]), torch.tensor([0.5]))
    assert p.item() == pytest.approx(success.mean(), abs=0.02)
    assert calibration.info["pairs"]["trot-stand"]["held_out"] == n - len(train)


def test_lookahead_switches_unless_a_better_moment_comes_before_the_deadline() -> None:
    table = empty_table()
    table.counts[1, 0] = 8
    table.successes[1, 0] = 2  # (2 + 1) / 10 = 0.3 at every source bin ...
    table.successes[1, 0, 8] = 8  # ... but 0.9 at source bin 8 (phase 0.5-0.5625)
    identity = Calibration(GAITS, IDENTITIES, {}, {})
    strategy = LookaheadStrategy(phase_net(bias=0.0), identity, table)
    strategy._net.scores = lambda q: torch.full((len(q.source), PHASE_GRID), 0.5)  # the net: 0.5 everywhere

    def decide(steps_left: int) -> bool:
        q = query(1, phase_source=0.0)
        q.steps_left, q.phase_step = torch.tensor([steps_left]), torch.tensor([1 / 16])  # one bin per step
        return bool(strategy.decide(q).switch.item())

    assert decide(4)  # bins 1-4 offer 0.3 < 0.5: switch now
    assert not decide(10)  # bin 8 comes in 8 steps and offers 0.9: wait
    assert decide(0)  # nothing left to wait for


def test_lookahead_runs_in_the_meta_controller_and_refuses_an_uncalibrated_library(switching_library, tmp_path):
    setup = load_switching(switching_library)
    trace = run_episode(
        setup, source="trot", dests=["stand"], strategy="net-lookahead", request_s=0.2, hold_s=0.6,
        deadline_s=0.3, seed=1, backend="mujoco",
    )
    (event,), (switch_s,) = trace.switches, trace.switches_s
    assert not event.forced  # at the latest at the deadline, by its own choice
    assert 0.2 - 1e-9 <= switch_s <= 0.5 + 1e-9
    uncalibrated = copy_library(Library(switching_library), tmp_path / "library")
    uncalibrated.calibration_path.unlink()
    with pytest.raises(TransitionDataError, match=r"calibration.json is missing or does not match its checksum"):
        get_strategy("net-lookahead", SwitchResources(library=uncalibrated, gaits=GAITS))
