"""``gaitlib fit --extend``: a library grown by a gait fits its new pairs alone and keeps its models for the old ones
(the old net's weights, calibration and TMT rows as they were), on tiny real policies and collections."""

from __future__ import annotations

import copy
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from cli_runner import gaitlib, gaitlib_quick
from conftest import built_once, copy_library

from gaitlib.errors import TransitionDataError
from gaitlib.library import Library
from gaitlib.transition_net import (
    ComposedNet,
    FeatureSpec,
    NetPart,
    TransitionNet,
    build_features,
    load_net,
    save_composed,
)
from gaitlib.transitions import read_all

NEW_PAIRS = {"pace-stand", "pace-trot", "stand-pace", "trot-pace"}
OLD_PAIRS = {"stand-trot", "trot-stand"}
TINY_FIT = ["--epochs", "2", "--min-per-label", "0"]


@pytest.fixture(scope="module")
def grown(switching_library, tmp_path_factory) -> Path:
    """A folder holding ``library``: the tests' switching library (stand and trot, models fitted) grown by a pace
    trained after the fit, and the collections ``pace.h5`` (the four new pairs alone) and ``trot-stand.h5`` (that
    old pair alone), beside ``old.h5``, the old models' own data."""
    from gaitlib.collection import CollectConfig, collect
    from gaitlib.gaits import get_gait
    from gaitlib.meta import TrialProtocol
    from gaitlib.training import get_preset
    from gaitlib.training.trainer import TrainRequest, train_gait

    def build(root: Path) -> None:
        library = copy_library(Library(switching_library), root / "library")
        shutil.copytree(switching_library.parent / "samples.h5.parts", root / "old.h5.parts")
        shutil.copy2(switching_library.parent / "samples.h5", root / "old.h5")
        train_gait(TrainRequest(description=get_gait("pace"), preset=get_preset("tiny"), iterations=1,
                                library=library.root, run_dir=root / "runs", backend="mujoco", eval_episodes=1,
                                eval_seconds=0.3))
        protocol = TrialProtocol.collection(horizon_s=1.0, warmup_s=0.3, source_extra_s=0.5)
        for name, pairs, samples in (("pace", [tuple(p.split("-")) for p in sorted(NEW_PAIRS)], 48),
                                     ("trot-stand", [("trot", "stand")], 16)):
            config = CollectConfig(samples=samples, num_worlds=8, push_max=400.0, backend="mujoco", protocol=protocol,
                                   pairs=tuple(pairs), seed=7)
            collect(root / f"{name}.h5", library=library, config=config)

    return built_once(tmp_path_factory, "extend", build)


def _copy(grown: Path, tmp_path: Path) -> Library:
    return copy_library(Library(grown / "library"), tmp_path / "library")


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _scores(net, data, gaits) -> torch.Tensor:
    """``net``'s scores of ``data``'s samples, their gait indices put into the order ``gaits``."""
    x, names = data.samples, data.header.gaits
    remap = torch.tensor([gaits.index(name) for name in names])
    return net.score(source=remap[torch.from_numpy(x.source).long()], dest=remap[torch.from_numpy(x.dest).long()],
                     phase_dest=torch.from_numpy(x.phase_dest), latent=torch.from_numpy(x.latent))


def _payload(path: Path) -> dict:
    return json.loads(path.read_text())


def _extend(library: Library, data: Path, *more: str):
    return gaitlib_quick("fit", "--extend", "--data", str(data), "--library", str(library.root), *TINY_FIT, *more)


def test_extension_keeps_the_old_pairs_models_and_fits_the_new_pairs(grown, tmp_path) -> None:
    library = _copy(grown, tmp_path)
    before = {p.name: p.read_bytes() for p in library.switching_dir.iterdir()}
    (tmp_path / "old-net.pt").write_bytes(before["net.pt"])
    shown = json.loads(gaitlib_quick("library", "--library", str(library.root), "--json").stdout)
    assert {p for p, v in shown["switching"]["pairs"].items() if v["state"] == "uncovered"} == NEW_PAIRS

    extended = gaitlib("fit", "--extend", "--data", str(grown / "pace.h5"), "--library", str(library.root),
                       *TINY_FIT, "--json")
    assert extended.returncode == 0, extended.stderr
    report = json.loads(extended.stdout)
    assert report["served_by"] == dict.fromkeys(sorted(OLD_PAIRS), "kept") | dict.fromkeys(sorted(NEW_PAIRS), "new")
    written = _payload(library.accuracy_path)
    assert written.pop("checksum") and {k: v for k, v in report.items() if k != "served_by"} == written
    assert written["uncovered_pairs"] == [] and written["input_written"] == "latent"
    assert [part["serves"] for part in written["parts"]] == [sorted(OLD_PAIRS), sorted(NEW_PAIRS)]
    assert written["data"] == [*json.loads(before["accuracy.json"])["data"], str(grown / "pace.h5")]
    assert written["samples"] == json.loads(before["accuracy.json"])["samples"] + 48
    accuracy = written["balanced_validation_accuracy"]["latent"]
    assert OLD_PAIRS & set(accuracy) and NEW_PAIRS & set(accuracy) and set(accuracy) <= OLD_PAIRS | NEW_PAIRS

    # (a) the old pairs are scored exactly as the old net scored them, by its very weights; the new ones by the new part
    identities = library.identities()
    net = load_net(library.net_path, identities=identities).net
    old = load_net(tmp_path / "old-net.pt", identities=identities).net
    assert isinstance(net, ComposedNet) and isinstance(old, TransitionNet)
    assert net.spec.gaits == ("pace", "stand", "trot") and [p.spec.gaits for p in net.parts] == [
        ("stand", "trot"), ("pace", "stand", "trot")]
    kept = net.parts[0].state_dict()
    assert all(torch.equal(kept[key], value) for key, value in old.state_dict().items())
    old_data = read_all([grown / "old.h5"], current=identities)
    assert torch.equal(_scores(net, old_data, net.spec.gaits), _scores(old, old_data, old.spec.gaits))
    new_data = read_all([grown / "pace.h5"], current=identities)
    new_scores = _scores(net, new_data, net.spec.gaits)
    assert torch.equal(new_scores, _scores(net.parts[1], new_data, net.parts[1].spec.gaits))

    # (b) calibration and TMT: the old pairs' entries copied, the new pairs' added
    calibration, old_calibration = _payload(library.calibration_path), json.loads(before["calibration.json"])
    assert {p: calibration["pairs"][p] for p in old_calibration["pairs"]} == old_calibration["pairs"]
    assert set(calibration["pairs"]) - set(old_calibration["pairs"]) == NEW_PAIRS
    assert calibration["info"]["falls"] == "trunk" and len(calibration["info"]["parts"]) == 2
    table, old_table = _payload(library.tmt_path), json.loads(before["tmt.json"])
    for pair in OLD_PAIRS:
        m, n = pair.split("-")
        i, j = (table["gaits"].index(g) for g in (m, n))
        k, q = (old_table["gaits"].index(g) for g in (m, n))
        for key in ("counts", "successes"):
            assert table[key][i][j] == old_table[key][k][q]
        for strategy, thresholds in table["thresholds"].items():
            assert thresholds.get(pair) == old_table["thresholds"][strategy].get(pair)
    counts = np.asarray(table["counts"]).sum(axis=(2, 3))
    assert {f"{table['gaits'][i]}-{table['gaits'][j]}" for i, j in zip(*np.nonzero(counts), strict=True)} == (
        OLD_PAIRS | NEW_PAIRS)
    assert all(set(thresholds) == OLD_PAIRS | NEW_PAIRS for thresholds in table["thresholds"].values())
    assert table["typical_value"][1:] == old_table["typical_value"]  # stand and trot's kept; pace's from its data
    assert table["info"]["falls"] == "trunk" and [p["serves"] for p in table["info"]["parts"]][1] == sorted(NEW_PAIRS)

    # (c) every pair of the grown library covered, each by its part
    status = json.loads(gaitlib_quick("library", "--library", str(library.root), "--json").stdout)
    assert status["problems"] == []
    pairs = status["switching"]["pairs"]
    assert {p: v["state"] for p, v in pairs.items()} == dict.fromkeys(OLD_PAIRS | NEW_PAIRS, "covered")
    assert {p: v["part"] for p, v in pairs.items()} == dict.fromkeys(OLD_PAIRS, 1) | dict.fromkeys(NEW_PAIRS, 2)
    shown = gaitlib_quick("library", "--library", str(library.root)).stdout
    assert "nothing stale" in shown and "2 of 2" in shown

    # (d) the strategies run on the composite: a benchmark of pairs of both parts, and fit --evaluate
    out = tmp_path / "bench"
    bench = gaitlib_quick("benchmark", "--library", str(library.root), "--strategies", "net-lookahead,net",
                          "--magnitudes", "0", "--samples", "1", "--worlds", "2", "--pairs",
                          "trot-stand,stand-pace,pace-trot", "--backend", "mujoco", "--out", str(out), "--json")
    assert bench.returncode == 0, bench.stderr
    cells = json.loads((out / "results.json").read_text())["groups"]["net-lookahead@0"]["cells"]
    assert set(cells) == {"trot-stand", "stand-pace", "pace-trot"}
    scored = gaitlib_quick("fit", "--evaluate", "--data", str(grown / "pace.h5"), "--library", str(library.root),
                           "--json")
    assert scored.returncode == 0, scored.stderr
    assert set(json.loads(scored.stdout)["accuracy"]) <= NEW_PAIRS


def test_extending_again_flattens_the_parts_and_a_full_takeover_is_a_plain_fit(grown, tmp_path) -> None:
    library = _copy(grown, tmp_path)
    identities = library.identities()
    old = load_net(library.net_path, identities=identities).net
    assert _extend(library, grown / "pace.h5").returncode == 0
    first = load_net(library.net_path, identities=identities).net

    again = _extend(library, grown / "trot-stand.h5", "--seed", "1", "--json")  # an old pair collected again
    assert again.returncode == 0, again.stderr
    assert json.loads(again.stdout)["served_by"] == dict.fromkeys(sorted(NEW_PAIRS), "kept") | {
        "stand-trot": "kept", "trot-stand": "new"}
    saved = load_net(library.net_path, identities=identities)
    served = [["stand-trot"], sorted(NEW_PAIRS), ["trot-stand"]]
    assert [part["pairs"] for part in saved.metadata["parts"]] == served
    assert saved.metadata["format_version"] == 2 and all(type(p) is TransitionNet for p in saved.net.parts)
    for part, before in ((saved.net.parts[0], old), (saved.net.parts[1], first.parts[1])):
        state = part.state_dict()
        assert all(torch.equal(state[key], value) for key, value in before.state_dict().items())
    for payload in (_payload(library.accuracy_path), _payload(library.calibration_path)["info"],
                    _payload(library.tmt_path)["info"]):
        assert [part["serves"] for part in payload["parts"]] == served
    status = json.loads(gaitlib_quick("library", "--library", str(library.root), "--json").stdout)
    assert {p: (v["state"], v["part"]) for p, v in status["switching"]["pairs"].items()} == {
        "stand-trot": ("covered", 1), "trot-stand": ("covered", 3)} | dict.fromkeys(NEW_PAIRS, ("covered", 2))

    third = _extend(library, grown / "old.h5", "--json")  # both old pairs taken over: the first part, emptied, goes
    assert third.returncode == 0, third.stderr
    saved = load_net(library.net_path, identities=identities)
    assert [part["pairs"] for part in saved.metadata["parts"]] == [sorted(NEW_PAIRS), sorted(OLD_PAIRS)]
    state = saved.net.parts[0].state_dict()
    assert all(torch.equal(state[key], value) for key, value in first.parts[1].state_dict().items())

    plain = copy_library(Library(grown / "library"), tmp_path / "plain")  # the new data hold every kept pair
    full = _extend(plain, grown / "old.h5", "--json")
    assert full.returncode == 0, full.stderr
    assert json.loads(full.stdout)["served_by"] == dict.fromkeys(sorted(OLD_PAIRS), "new")
    assert set(json.loads(full.stdout)["uncovered_pairs"]) == NEW_PAIRS
    assert load_net(plain.net_path, identities=identities).metadata["format_version"] == 1


def _stale_library(grown: Path, tmp_path: Path) -> Library:
    """The grown library with another trot policy (its mirror image) than the one its models were fitted for."""
    root = tmp_path / "stale"
    mirrored = gaitlib_quick("mirror", "trot", "--as", "trot", "--from", str(grown / "library"), "--library",
                             str(root))
    assert mirrored.returncode == 0, mirrored.stderr
    for name in ("stand", "pace", "switching"):
        shutil.copytree(grown / "library" / name, root / name)
    return Library(root)


def test_extension_refusals_are_one_line_and_write_nothing(grown, tiny_library, tmp_path, monkeypatch) -> None:
    library = _copy(grown, tmp_path)
    bare = copy_library(tiny_library, tmp_path / "bare")
    damaged = copy_library(Library(grown / "library"), tmp_path / "damaged")
    damaged.tmt_path.write_text(damaged.tmt_path.read_text() + " ")
    pace, old = str(grown / "pace.h5"), str(grown / "old.h5")
    cases = [
        (bare, old, TINY_FIT, "has no transition-net and TMT yet"),
        (damaged, pace, TINY_FIT, "tmt.json is missing or does not match its checksum"),
        (_stale_library(grown, tmp_path), pace, TINY_FIT, "was made for another 'trot' policy than the library's"),
        (library, pace, (*TINY_FIT, "--input", "phase"), "read 'latent' inputs, and an extension fits the kind the "
                                                         "kept net reads: --input latent"),
        (library, pace, (*TINY_FIT, "--falls", "contact"), "label falls by the trunk definition"),
        (library, pace, ("--evaluate",), "--extend has no effect with --evaluate"),
        (library, pace, ("--curve", "4"), "--extend has no effect with --curve"),
    ]
    for lib, data, more, message in cases:
        before = _files(lib.root)
        refused = gaitlib_quick("fit", "--extend", "--data", data, "--library", str(lib.root), *more)
        assert refused.returncode == 2 and refused.stderr.count("\n") == 1, refused.stderr
        assert message in refused.stderr, refused.stderr
        assert _files(lib.root) == before

    monkeypatch.chdir(tmp_path)  # no --library: the user's own library, copied from the shipped one on a first write
    monkeypatch.delenv("GAITLIB_LIBRARY", raising=False)
    refused = gaitlib_quick("fit", "--extend", "--input", "phase", "--data", pace, *TINY_FIT)
    assert refused.returncode == 2 and "read 'latent' inputs" in refused.stderr
    assert not (tmp_path / "runs").exists()  # refused before anything was copied


def test_a_damaged_composite_is_refused_in_one_line(grown, tmp_path) -> None:
    from gaitlib.transition_net import load_parts

    library = _copy(grown, tmp_path)
    assert _extend(library, grown / "pace.h5").returncode == 0
    identities = library.identities()
    sound = torch.load(library.net_path, weights_only=True)

    def missing_state(saved: dict) -> None:
        saved["state_dict"] = {k: v for k, v in saved["state_dict"].items() if not k.startswith("parts.1.")}

    def unknown_gait(saved: dict) -> None:
        saved["metadata"]["parts"][0]["pairs"].append("trot-moonwalk")

    for damage, message in ((missing_state, "is damaged: weights missing: parts.1.feature_mean and 9 more"),
                            (unknown_gait, "is damaged: part 1 of the composite transition-net serves pair "
                                           "trot-moonwalk, not an ordered pair of its gaits ['stand', 'trot']")):
        saved = copy.deepcopy(sound)
        damage(saved)
        torch.save(saved, library.net_path)
        library.write_checksums(library.switching_dir)  # as another writer could leave it, checksums and all
        with pytest.raises(TransitionDataError, match=re.escape(message)) as error:
            load_net(library.net_path, identities=identities)
        assert "\n" not in str(error.value)
        before = _files(library.root)
        refused = _extend(library, grown / "pace.h5")
        assert refused.returncode == 2 and refused.stderr.count("\n") == 1 and message in refused.stderr
        assert _files(library.root) == before
    torch.save(sound, library.net_path)
    library.write_checksums(library.switching_dir)

    # parts that cannot be one net, and a composite where one net must go: refused in one line, nothing written
    parts = load_parts(library.net_path, identities=identities, sources=())
    contact = parts[0].metadata | {"fit": parts[0].metadata["fit"] | {"falls": "contact"}}
    with pytest.raises(TransitionDataError, match=r"different definitions of a fall \(contact, trunk\)"):
        save_composed(tmp_path / "mixed.pt", [NetPart(parts[0].net, contact, parts[0].pairs, ()), parts[1]])
    assert not (tmp_path / "mixed.pt").exists()
    phase = TransitionNet(FeatureSpec(kind="phase", gaits=("pace", "stand"), latent_dim=parts[0].net.spec.latent_dim))
    with pytest.raises(TransitionDataError, match="must share one input kind and latent size: 'latent'"):
        ComposedNet([parts[0].net, phase], pairs=[{("stand", "trot")}, {("pace", "stand")}],
                    gaits=("pace", "stand", "trot"))
    composite = load_net(library.net_path, identities=identities).net
    with pytest.raises(TransitionDataError, match="no part of the composite transition-net was fitted on pair"):
        composite.score(source=torch.tensor([1]), dest=torch.tensor([1]), phase_dest=torch.zeros(1),
                        latent=torch.zeros(1, composite.spec.latent_dim))


def test_a_composite_exports_as_one_graph_with_each_pairs_own_logit(grown, tmp_path) -> None:
    """The guard's deployable ``net.onnx`` of a grown library: every served pair scores as its part does, through
    onnxruntime; a pair no part serves scores minus infinity (never switched to)."""
    import onnxruntime

    from gaitlib.strategies.guard_export import _DenseComposite, _export

    library = _copy(grown, tmp_path)
    assert _extend(library, grown / "pace.h5").returncode == 0
    composite = load_net(library.net_path, identities=library.identities()).net
    assert isinstance(composite, ComposedNet)
    g = len(composite.spec.gaits)
    served = [(m, n) for m in range(g) for n in range(g) if m != n]
    rows = torch.tensor(served * 8)
    generator = torch.Generator().manual_seed(0)
    latent = torch.randn(len(rows), composite.spec.latent_dim, generator=generator)
    features = build_features(composite.spec, source=rows[:, 0], dest=rows[:, 1],
                              phase_dest=torch.rand(len(rows), generator=generator), latent=latent)
    expected = composite.eval()(features).detach()
    _export(_DenseComposite(composite), composite.spec.dim, tmp_path / "net.onnx", inputs="features", output="logit")
    session = onnxruntime.InferenceSession(str(tmp_path / "net.onnx"), providers=["CPUExecutionProvider"])
    (logit,) = session.run(None, {"features": features.numpy()})
    torch.testing.assert_close(torch.from_numpy(logit), expected, rtol=1e-5, atol=1e-5)
    own = build_features(composite.spec, source=torch.tensor([1]), dest=torch.tensor([1]), phase_dest=torch.zeros(1),
                         latent=torch.zeros(1, composite.spec.latent_dim))
    (unserved,) = session.run(None, {"features": own.numpy()})
    assert unserved[0] == -np.inf
