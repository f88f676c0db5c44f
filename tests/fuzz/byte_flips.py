"""Fault injection: flip one random byte at a time in every kind of file gaitlib reads, and edit the content of
its files with their checksums kept valid; read each back the way the commands do, and count what happened.

A small library (two gaits, the tests' tiny preset), its switching models, a small transition file, a small benchmark
result, a handover-states file, a route table (from a second small benchmark, of both pairs) and a survival estimate
(read as the guard of ``run``, ``drive`` and ``eval --guard``) are made in a temporary folder. Then, for each kind
of file, ``--flips`` times: one byte is XOR-ed with a random non-zero value,
the file is read as the commands read it, and the outcome is counted:

- ``refused``: one :class:`~gaitlib.errors.GaitlibError` line (the file is named, nothing is used);
- ``same``: accepted, and everything read equals what the pristine file gives (the flip hit bytes nothing uses);
- ``different``: accepted with a different result: a silent wrong answer, the count that must be 0;
- ``crashed``: another exception (a traceback instead of one line).

The identity kinds (:mod:`identity_kinds`) flip bytes of what a resumed training run reads (its gait file, its
states file: the resume must be refused unless nothing it reads changed) and of a copy of the transition file read
beside the original (every sample counted once, or the copy refused).

Then, ``--edits`` times for the route table, the handover states, an entry's metadata and the benchmark results:
a *structured edit* that keeps the file parseable and its checksum valid (recomputed) but puts in wrong content (a
wrong type, a value out of range, a missing key, extra nesting, a nan or an infinity as Python's json writes them,
a count above its total, a zero quaternion, a wrong-width array, swapped gait names, ...). The edited file is read by
gaitlib's real reader and used as its command uses it, in process, and the outcome counted: ``refused`` (one line),
``harmless`` (accepted, everything read equal to the pristine file's), ``wrong`` (accepted with a different result)
or ``crashed`` (another exception, or a refusal of more than one line). About half the edits of a kind are edits of
meaning written for it (all of them from twice their number on), the rest generic edits of random fields; a kind's
controls (its keys in another order; the route table's derived detours left out) change nothing read and must come
out harmless. Two identity kinds follow (:mod:`identity_kinds`): ``resume identity``, structured edits of the gait
file a run was started from, each read by the run's resume (refused, unless the description read is the same), and
``data overlap``, a transition file's samples given to a fit a second time in another guise (a link, a copy, a
subset, a collection with the same seed, ...), where every outcome but ``harmless`` (each sample counted once) is
a failure.

Usage: python tests/fuzz/byte_flips.py [--flips 100] [--edits 100] [--seed 0] [--only KIND]; prints one JSON line
per kind of file and per kind of edited file, and exits non-zero if any flip or edit was accepted with a different
result or crashed. ``--flips 0`` or ``--edits 0`` (the default) skips that part; ``--only`` flips one kind alone.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import random
import shutil
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from identity_kinds import overlap, resume_reader, resume_target, start_resumable_run
from structured_edits import edit, edit_targets

from gaitlib import gaits
from gaitlib.benchmark.results import load_results
from gaitlib.benchmark.routes import routes_from_results
from gaitlib.benchmark.sweep import SweepConfig, run_sweep
from gaitlib.collection import CollectConfig, collect
from gaitlib.envs.handover import load_states
from gaitlib.envs.observations import ObservationBatch
from gaitlib.errors import GaitlibError
from gaitlib.gaits import get_gait
from gaitlib.library import Library
from gaitlib.meta import TrialProtocol, load_switching
from gaitlib.strategies import SwitchResources
from gaitlib.strategies.fitting import fit_library
from gaitlib.strategies.survival import SurvivalEstimate, SurvivalNet, save_survival
from gaitlib.training import get_preset
from gaitlib.training.trainer import TrainRequest, train_gait
from gaitlib.transitions import read, read_all, schema
from gaitlib.transitions.states import StatesConfig, record_states

GAITS = ("stand", "trot")


def build(root: Path) -> dict[str, tuple[Path, Callable[[], object]]]:
    """Make the artefacts under ``root``; kind of file -> (its path, a reader returning what the commands use)."""
    library = root / "library"
    for gait in GAITS:
        train_gait(TrainRequest(description=get_gait(gait), preset=get_preset("tiny"), iterations=1, library=library,
                                run_dir=root / "runs" / gait, backend="mujoco", eval_episodes=1, eval_seconds=0.3))
    data = root / "t.h5"
    collect_config = CollectConfig(
        samples=24, num_worlds=12, push_max=400.0, backend="mujoco", chunk=24,
        protocol=TrialProtocol.collection(horizon_s=1.0, warmup_s=0.3, source_extra_s=0.3))
    collect(data, library=Library(library), config=collect_config)
    fit_library(Library(library), read(data), sources=[data], epochs=2, min_per_label=0)  # too few to validate
    collect(root / "same-seed.h5", library=Library(library), config=collect_config)  # the same samples again
    copy = root / "copy.h5"
    shutil.copy2(data, copy)
    shutil.copytree(schema.parts_folder(data), schema.parts_folder(copy))
    out = root / "bench"
    run_sweep(out, load_switching(library), SweepConfig(
        strategies=("random",), magnitudes=(0.0,), samples=2, num_worlds=2, backend="mujoco",
        pairs=(("trot", "stand"),),
        protocol=TrialProtocol(warmup_s=0.3, source_extra_s=0.2, horizon_s=0.5, deadline_s=0.3, push_lead_s=0.2)))
    states = root / "states.npz"
    record_states(Library(library), config=StatesConfig(per_gait=4, num_worlds=2, warmup_s=0.2, spacing_s=0.1,
                                                        backend="mujoco")).save(states)
    both = run_sweep(root / "bench-routes", load_switching(library), SweepConfig(
        strategies=("random",), magnitudes=(0.0,), samples=2, num_worlds=2, backend="mujoco",
        protocol=TrialProtocol(warmup_s=0.3, source_extra_s=0.2, horizon_s=0.5, deadline_s=0.3, push_lead_s=0.2)))
    routes_from_results(both, Library(library), strategy="random").save(Library(library))
    _save_estimate(Library(library), data)
    start_resumable_run(root, Path(gaits.__file__).parent / "descriptions" / "stand.toml")  # the shipped stand
    probe = ObservationBatch(policy=torch.linspace(-1, 1, 159).unsqueeze(0), privileged=torch.zeros(1, 14))

    def entry() -> object:
        loaded = Library(library).entry("stand")
        return loaded.metadata, loaded.policy.act(probe).numpy(), (library / "stand" / "policy.onnx").read_bytes()

    def switching() -> object:
        resources = SwitchResources(library=Library(library), gaits=GAITS)
        table, calibration, net = resources.table, resources.calibration, resources.net
        features = torch.linspace(-1, 1, net.spec.dim).unsqueeze(0)
        with torch.no_grad():
            scores = net(features).numpy()
        accuracy = json.loads((library / "switching" / "accuracy.json").read_text())
        return dataclasses.asdict(table), calibration.pairs, calibration.identities, scores, accuracy

    def transitions() -> object:
        return read_all([data]).samples.columns(), read(data).header

    def overlapping() -> object:
        return read_all([data, copy]).samples.columns()

    def guard() -> object:  # as run, drive and eval --guard read it
        estimate = load_switching(library).guard().estimate
        features = torch.linspace(-1, 1, int(estimate.net.mean.numel())).unsqueeze(0)
        return (estimate.gaits, estimate.identities, estimate.inputs, estimate.horizon_s, estimate.margin,
                estimate.floor, estimate.platt, estimate.info, estimate.net.state_dict(),
                estimate.probability(features, torch.zeros(1, dtype=torch.long)).numpy())

    part = next(schema.parts_folder(data).glob("part-*.h5"))
    switching_dir = library / "switching"
    return {
        "entry metadata.json": (library / "stand" / "metadata.json", entry),
        "entry policy.pt": (library / "stand" / "policy.pt", entry),
        "entry policy.onnx": (library / "stand" / "policy.onnx", entry),
        "switching net.pt": (switching_dir / "net.pt", switching),
        "switching tmt.json": (switching_dir / "tmt.json", switching),
        "switching calibration.json": (switching_dir / "calibration.json", switching),
        "switching accuracy.json": (switching_dir / "accuracy.json", switching),
        "switching checksums.json": (switching_dir / "checksums.json", switching),
        "switching survival.pt": (switching_dir / "survival.pt", guard),
        "transition index": (data, transitions),
        "transition part": (part, transitions),
        "benchmark results.json": (out / "results.json", lambda: load_results(out)),
        "handover states": (states, lambda: dataclasses.asdict(load_states(states)[0])),
        "resume: its gait file": (root / "stand.toml", resume_reader(root)),
        "resume: its states file": (states, resume_reader(root)),
        "data overlap: a copy's index": (copy, overlapping),
        "data overlap: a copy's part": (next(schema.parts_folder(copy).glob("part-*.h5")), overlapping),
    }


def _save_estimate(library: Library, data: Path) -> None:
    """A survival estimate (untrained, its guard settings and catch table set) saved as ``gaitlib survival fit``
    saves one, into ``library``."""
    gaits = library.gaits()
    dim = len(gaits) + 2 + library.entry(gaits[0]).policy.latent_dim  # one-hot gait, psi_m, phase as sin, cos
    estimate = SurvivalEstimate(gaits, library.identities(gaits), ("latent", "phase"), 0.5, 0.05,
                                {0: (1.2, -0.3), 1: (0.8, 0.1)}, SurvivalNet(dim),
                                {"armed_from_s": 0.5, "catches": {"catch_into": {"trot": {"left": "stand"}}}}, 0.1)
    torch.manual_seed(0)
    save_survival(library, estimate, data=data)


def same(a: object, b: object) -> bool:
    """Deep equality of what the readers return (arrays compared exactly, nan equal to nan)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, (np.ndarray, torch.Tensor)) or isinstance(b, (np.ndarray, torch.Tensor)):
        a, b = np.asarray(a), np.asarray(b)
        return a.shape == b.shape and a.dtype == b.dtype and bool(np.array_equal(a, b, equal_nan=a.dtype.kind == "f"))
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (a != a and b != b)
    return type(a) is type(b) and a == b


def flip(path: Path, reader: Callable[[], object], flips: int, rng: random.Random) -> dict[str, int]:
    """Flip ``flips`` random bytes of ``path``, one at a time, restoring it after each; count the outcomes."""
    pristine, expected = path.read_bytes(), reader()
    counts = {"refused": 0, "same": 0, "different": 0, "crashed": 0}
    try:
        for _ in range(flips):
            damaged = bytearray(pristine)
            damaged[rng.randrange(len(damaged))] ^= rng.randrange(1, 256)
            path.write_bytes(bytes(damaged))
            try:
                got = reader()
            except GaitlibError:
                counts["refused"] += 1
                continue
            except Exception:  # a traceback instead of one line
                counts["crashed"] += 1
                continue
            counts["same" if same(got, expected) else "different"] += 1
    finally:
        path.write_bytes(pristine)
    assert hashlib.sha256(path.read_bytes()).digest() == hashlib.sha256(pristine).digest()
    return counts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--flips", type=int, default=100, help="flips per kind of file (0: none)")
    parser.add_argument("--edits", type=int, default=0, help="structured edits per kind of file (0: none)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--only", default=None, help="flip only this kind of file (e.g. 'switching survival.pt')")
    args = parser.parse_args()
    rng, bad = random.Random(args.seed), 0
    with tempfile.TemporaryDirectory() as scratch:
        root = Path(scratch)
        kinds = build(root)
        if args.flips:
            for kind, (path, reader) in kinds.items():
                if args.only is not None and kind != args.only:
                    continue
                counts = flip(path, reader, args.flips, rng)
                bad += counts["different"] + counts["crashed"]
                print(json.dumps({"file": kind, "bytes": path.stat().st_size, "flips": args.flips, **counts}),
                      flush=True)
        if args.edits:
            targets = edit_targets(root, GAITS) | {"resume identity": resume_target(root)}
            for kind, target in targets.items():
                line = edit(target, args.edits, random.Random(f"{args.seed}-{kind}"), same)
                bad += line["wrong"] + line["crashed"]
                print(json.dumps({"edits": kind, **line}), flush=True)
            line = overlap(root / "t.h5", root / "same-seed.h5", root, args.edits,
                           random.Random(f"{args.seed}-data overlap"), same)
            bad += line["wrong"] + line["crashed"] + line["refused"]
            print(json.dumps({"edits": "data overlap", **line}), flush=True)
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
