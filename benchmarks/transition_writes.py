"""What crash safety costs a collection: appends through gaitlib's transition writer (immutable parts, an atomic
index, fsync) against plain in-place HDF5 appends of the same batches (one file, resizable datasets, the same
compression), measured in the same run; then reading the file back whole.

    python benchmarks/transition_writes.py --samples 2e5      # about a minute
    python benchmarks/transition_writes.py --samples 2e6      # the mission's collection size

Synthetic batches of 256 samples with 16-dim latents (the shipped policies' size). Results: docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

from gaitlib.transitions import read, schema
from gaitlib.transitions.records import COLUMNS, TransitionBatch, TransitionHeader
from gaitlib.transitions.writer import open_writer

BATCH = 256
LATENT = 16


def batches(count: int) -> list[TransitionBatch]:
    """``count`` distinct synthetic batches (cycled through by the appends)."""
    out = []
    for seed in range(count):
        rng = np.random.default_rng(seed)
        source = rng.integers(0, 2, BATCH)
        out.append(
            TransitionBatch(
                source=source, dest=1 - source, latent=rng.normal(size=(BATCH, LATENT)),
                phase_source=rng.random(BATCH), phase_dest=rng.random(BATCH), explicit=rng.normal(size=(BATCH, 66)),
                value_source=rng.normal(size=BATCH), value_dest=rng.normal(size=BATCH),
                push_force=rng.random(BATCH) * 100, success=rng.integers(0, 2, BATCH), switch_time=rng.random(BATCH),
                world=np.arange(BATCH), chunk=np.full(BATCH, seed),
            )
        )
    return out


def gaitlib_appends(path: Path, data: list[TransitionBatch], appends: int) -> np.ndarray:
    header = TransitionHeader(gaits=("stand", "trot"), identities=("a" * 64, "b" * 64), latent_dim=LATENT, settings={})
    times = np.empty(appends)
    with open_writer(path, header=header) as writer:
        for i in range(appends):
            start = time.perf_counter()
            writer.append(data[i % len(data)])
            times[i] = time.perf_counter() - start
    return times


def in_place_appends(path: Path, data: list[TransitionBatch], appends: int) -> np.ndarray:
    """The reference: every column one resizable dataset of one file, grown and flushed at each append."""
    times = np.empty(appends)
    with h5py.File(path, "w") as f:
        for name, values in data[0].columns().items():
            f.create_dataset(
                name, shape=(0, *values.shape[1:]), maxshape=(None, *values.shape[1:]), dtype=COLUMNS[name].dtype,
                chunks=(BATCH, *values.shape[1:]), compression="gzip", compression_opts=4, shuffle=True,
                fletcher32=True,
            )
        for i in range(appends):
            start = time.perf_counter()
            for name, values in data[i % len(data)].columns().items():
                ds = f[name]
                ds.resize(ds.shape[0] + BATCH, axis=0)
                ds[-BATCH:] = values
            f.flush()
            times[i] = time.perf_counter() - start
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=float, default=2e5, help="samples written by each side")
    args = parser.parse_args()
    appends = int(args.samples) // BATCH
    data = batches(64)
    with tempfile.TemporaryDirectory(dir=Path.cwd()) as scratch:
        ours = gaitlib_appends(Path(scratch) / "t.h5", data, appends)
        files = len(list(schema.parts_folder(Path(scratch) / "t.h5").iterdir())) + 1
        start = time.perf_counter()
        samples = len(read(Path(scratch) / "t.h5").samples)
        read_s = time.perf_counter() - start
        reference = in_place_appends(Path(scratch) / "plain.h5", data, appends)
    print(json.dumps({
        "samples": samples,
        "appends": appends,
        "gaitlib_append_ms": {"median": round(1e3 * float(np.median(ours)), 1), "mean": round(1e3 * ours.mean(), 1),
                              "max": round(1e3 * ours.max())},
        "in_place_append_ms": {"median": round(1e3 * float(np.median(reference)), 1),
                               "mean": round(1e3 * reference.mean(), 1), "max": round(1e3 * reference.max())},
        "ratio_of_totals": round(ours.sum() / reference.sum(), 2),
        "files": files,
        "read_whole_s": round(read_s, 1),
    }))


if __name__ == "__main__":
    main()
