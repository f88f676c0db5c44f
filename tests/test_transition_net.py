"""Transition-net: features, balanced split, fitting (it can overfit a separable set), storage and its checks."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from gaitlib.errors import TransitionDataError
from gaitlib.transition_net import (
    FeatureSpec,
    FitConfig,
    TransitionNet,
    balanced_split,
    batch_features,
    build_features,
    fit,
    learning_curve,
    load_net,
    read_metadata,
    save_net,
)
from gaitlib.transitions.schema import TransitionBatch, TransitionData, TransitionFileInfo, TransitionHeader

GAITS = ("stand", "trot")
IDENTITIES = {"stand": "a" * 64, "trot": "b" * 64}


def separable(n_per_class_pair: int = 16, latent_dim: int = 4, seed: int = 0) -> TransitionData:
    """Both ordered pairs, balanced labels, success decided by the sign of the first latent value (margin 1)."""
    rng = np.random.default_rng(seed)
    n = 4 * n_per_class_pair
    source = np.repeat([0, 1], n // 2)
    success = np.tile(np.repeat([1, 0], n_per_class_pair), 2)
    latent = rng.normal(size=(n, latent_dim))
    latent[:, 0] = np.where(success == 1, 1.0, -1.0) * (1.0 + rng.random(n))
    batch = TransitionBatch(
        source=source, dest=1 - source, latent=latent, phase_source=rng.random(n), phase_dest=rng.random(n),
        explicit=rng.normal(size=(n, 66)), value_source=np.zeros(n), value_dest=np.zeros(n), push_force=np.zeros(n),
        success=success, switch_time=np.ones(n), world=np.zeros(n), chunk=np.zeros(n),
    )
    header = TransitionHeader(gaits=GAITS, identities=tuple(IDENTITIES.values()), latent_dim=latent_dim, settings={})
    return TransitionData(TransitionFileInfo(header, n, [], None), batch)


def test_feature_layout_per_input_kind() -> None:
    data = separable()
    for kind, dim in (("latent", 2 + 2 + 4 + 2), ("phase", 2 + 2 + 4), ("explicit", 2 + 2 + 66 + 2)):
        spec = FeatureSpec(kind=kind, gaits=GAITS, latent_dim=4)
        x = batch_features(spec, data.samples)
        assert spec.dim == dim and x.shape == (len(data.samples), dim) and x.dtype == torch.float32
    spec = FeatureSpec(kind="phase", gaits=GAITS, latent_dim=4)
    x = build_features(spec, source=torch.tensor([1]), dest=torch.tensor([0]), phase_source=torch.tensor([0.25]),
                       phase_dest=torch.tensor([0.5]))
    np.testing.assert_allclose(x[0].numpy(), [0, 1, 1, 0, 1, 0, 0, -1], atol=1e-6)
    with pytest.raises(TransitionDataError, match="needs 'latent'"):
        build_features(FeatureSpec(kind="latent", gaits=GAITS, latent_dim=4), source=torch.tensor([0]),
                       dest=torch.tensor([1]), phase_dest=torch.tensor([0.0]))
    with pytest.raises(TransitionDataError, match="unknown transition-net input 'vision'"):
        FeatureSpec(kind="vision", gaits=GAITS, latent_dim=4)


def test_balancing_gives_equal_classes_per_pair_and_a_held_out_split() -> None:
    # pair (0, 1): 30 successes / 10 failures; (1, 0): 5 / 50; (0, 2): successes only.
    source = np.array([0] * 40 + [1] * 55 + [0] * 7)
    dest = np.array([1] * 40 + [0] * 55 + [2] * 7)
    success = np.array([1] * 30 + [0] * 10 + [1] * 5 + [0] * 50 + [1] * 7)
    split = balanced_split(source, dest, success, validation_fraction=0.2, seed=3)
    assert split.skipped == ((0, 2),)
    assert split.per_class == {(0, 1): (8, 2), (1, 0): (4, 1)}
    assert not set(split.train) & set(split.validation)
    for rows in (split.train, split.validation):
        for m, n in ((0, 1), (1, 0)):
            in_pair = rows[(source[rows] == m) & (dest[rows] == n)]
            assert success[in_pair].sum() * 2 == len(in_pair)
    again = balanced_split(source, dest, success, validation_fraction=0.2, seed=3)
    np.testing.assert_array_equal(split.train, again.train)
    other = balanced_split(source, dest, success, validation_fraction=0.2, seed=4)
    assert set(other.train) != set(split.train)
    capped = balanced_split(source, dest, success, validation_fraction=0.0, samples_per_pair=6, seed=3)
    assert capped.per_class == {(0, 1): (3, 0), (1, 0): (3, 0)} and len(capped.validation) == 0


def test_network_shape_follows_the_paper() -> None:
    net = TransitionNet(FeatureSpec(kind="latent", gaits=GAITS, latent_dim=4))
    linear = [m for m in net.mlp if isinstance(m, torch.nn.Linear)]
    assert [(m.in_features, m.out_features) for m in linear] == [(10, 128), (128, 64), (64, 32), (32, 1)]
    dropouts = [m.p for m in net.mlp if isinstance(m, torch.nn.Dropout)]
    assert dropouts == [0.4, 0.4, 0.4]


def test_the_net_overfits_a_small_separable_set() -> None:
    epochs = []
    result = fit(separable(), FitConfig(epochs=60, batch_size=16, validation_fraction=0.0), on_epoch=epochs.append)
    assert result.train_accuracy == 1.0
    assert len(epochs) == 60 and epochs[-1].loss < epochs[0].loss and math.isnan(epochs[-1].validation_accuracy)
    assert not result.net.training


def test_validation_accuracy_per_pair() -> None:
    data = separable(n_per_class_pair=20)
    result = fit(data, FitConfig(epochs=30, batch_size=16, kind="latent", seed=1))
    assert set(result.validation_accuracy) == {("stand", "trot"), ("trot", "stand")}
    assert len(result.split.validation) == 2 * 2 * 4  # 20% of 20 per class and pair
    s = data.samples
    predicted = (result.net.eval().probability(batch_features(result.net.spec, s)) >= 0.5).numpy()
    for (m, n), accuracy in result.validation_accuracy.items():  # each pair scored on its own held-out rows
        rows = [i for i in result.split.validation if (GAITS[s.source[i]], GAITS[s.dest[i]]) == (m, n)]
        assert len(rows) == 8
        assert accuracy == pytest.approx(np.mean(predicted[rows] == s.success[rows].astype(bool)))
    assert min(result.validation_accuracy.values()) >= 0.875  # the sign of one latent value decides: learnt


def test_fit_without_both_labels_is_refused() -> None:
    data = separable()
    data.samples.success[:] = 1
    with pytest.raises(TransitionDataError, match="no gait pair has both"):
        fit(data, FitConfig(epochs=1))


def test_save_and_load_give_identical_outputs(tmp_path) -> None:
    data = separable()
    result = fit(data, FitConfig(epochs=5, batch_size=16, kind="explicit"))
    path = save_net(tmp_path / "nets" / "explicit.pt", result)
    assert not list(path.parent.glob(".*.tmp"))
    loaded = load_net(path, identities=IDENTITIES)
    x = batch_features(result.net.spec, data.samples)
    torch.testing.assert_close(loaded.net.probability(x), result.net.probability(x), rtol=0, atol=0)
    meta = loaded.metadata
    assert meta["input"] == "explicit" and meta["gaits"] == list(GAITS) and meta["library_identities"] == IDENTITIES
    assert meta["data"]["samples"] == 64 and set(meta["accuracy"]["validation"]) == {"stand->trot", "trot->stand"}
    assert read_metadata(path) == meta
    scores = loaded.net.score(source=torch.tensor([0]), dest=torch.tensor([1]), phase_dest=torch.tensor([0.3]),
                              explicit=torch.zeros(1, 66))
    assert scores.shape == (1,) and 0.0 <= float(scores) <= 1.0


def test_loading_for_another_library_is_refused(tmp_path) -> None:
    path = save_net(tmp_path / "net.pt", fit(separable(), FitConfig(epochs=1)))
    with pytest.raises(TransitionDataError, match="another 'trot' policy"):
        load_net(path, identities=IDENTITIES | {"trot": "c" * 64})
    with pytest.raises(TransitionDataError, match="needs gait 'stand'"):
        load_net(path, identities={"trot": IDENTITIES["trot"]})
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"not a net")
    with pytest.raises(TransitionDataError, match="not a readable transition-net"):
        load_net(garbage, identities=IDENTITIES)
    with pytest.raises(TransitionDataError, match="no transition-net"):
        load_net(tmp_path / "missing.pt", identities=IDENTITIES)


def test_the_learning_curve_scores_nested_fits_on_samples_none_of_them_saw() -> None:
    data = separable(n_per_class_pair=100)  # 200 samples a pair; the sign of one latent value decides
    config = FitConfig(epochs=20, batch_size=16, seed=2)
    points = learning_curve(data, [2, 40, 160], config=config)
    assert [p.samples_per_pair for p in points] == [2, 40, 160]
    assert points[0].trained_on < points[1].trained_on < points[2].trained_on <= 2 * 160 * 0.8 + 4
    assert set(points[-1].accuracy) == {"stand-trot", "trot-stand"} and points[-1].mean_accuracy >= 0.95
    # Held out once, before any fit: the same 40 samples of each label score every point (20% of 200 a pair).
    held_out = [learning_curve(data, [160], config=config, test_fraction=f)[0] for f in (0.2, 0.5)]
    assert held_out[0].as_dict() == points[-1].as_dict() and held_out[1].trained_on < held_out[0].trained_on
    assert learning_curve(data, [40], config=config)[0].as_dict() == points[1].as_dict()  # one seed, one curve
