"""Collection and the benchmark sweep on Ray workers (``--ray``, since 0.2.0): the same file and the same results as
without Ray for the same seed and chunking (two workers; one through the command line and in the last test), and a
killed worker loses no committed sample.
Ray comes with the test install (``.[test]``), so these run in CI; the one-line refusal of ``--ray`` without Ray is
tested in ``test_refusals.py``."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import time

import numpy as np
import pytest
import ray
from cli_runner import gaitlib_quick
from conftest import copy_library
from test_benchmark import TINY
from test_transitions import GAITS, assert_same

from gaitlib.benchmark.sweep import run_sweep
from gaitlib.cluster import WORKER_PREFIX, ClusterConfig
from gaitlib.collection import CollectConfig, collect
from gaitlib.meta import TrialProtocol, load_switching
from gaitlib.transitions import read, validate

SMALL = CollectConfig(
    samples=32, num_worlds=4, push_max=400.0, backend="mujoco", chunk=4,
    protocol=TrialProtocol.collection(horizon_s=1.0, warmup_s=0.3, source_extra_s=0.4),
)
"""Eight chunks of four samples on four worlds, short cycles, strong pushes (both labels). Eight, so that chunks
are still to be sent when a worker is killed after the first commit: the dead one is then handed one (and replaced)
even where its last chunk had finished before the kill, which with five chunks the live worker could all take."""


def test_collect_with_ray_writes_a_file_fit_reads(tiny_library, tmp_path) -> None:
    # Run first, before this process starts its own Ray: the command starts a local Ray for the run and stops it.
    # In this process, saving a fresh interpreter's imports (``collect`` runs in a fresh one in test_cli_transitions).
    lib, data = str(tiny_library.root), str(tmp_path / "ray.h5")
    quick = ["--worlds", "8", "--horizon", "1.0", "--push-max", "400", "--backend", "mujoco", "--chunk", "8",
             "--seed", "0"]  # the same seed for both runs (without it, each collection draws its own)
    ran = gaitlib_quick("collect", "--samples", "16", "--out", data, "--library", lib, *quick, "--ray",
                        "--workers", "1")  # the command's wiring; two workers share chunks in the tests below
    assert ran.returncode == 0, ran.stderr
    assert not ray.is_initialized()  # the local Ray was stopped with the run
    plain = str(tmp_path / "plain.h5")
    assert gaitlib_quick("collect", "--samples", "16", "--out", plain, "--library", lib, *quick).returncode == 0
    assert_same(read(data).samples, read(plain).samples)
    with_ray, without = validate(data), validate(plain)
    assert (with_ray.header, with_ray.count) == (without.header, without.count) == (validate(data).header, 16)
    writable = str(copy_library(tiny_library, tmp_path / "library").root)  # fit writes switching/ into it
    fitted = gaitlib_quick("fit", "--data", data, "--epochs", "2", "--library", writable, "--json",
                           "--min-per-label", "0")
    assert fitted.returncode == 0, fitted.stderr
    assert json.loads(fitted.stdout)["samples"] == 16


@pytest.fixture(scope="module")
def local_ray():
    """A Ray of two CPUs in this process for the module, shut down after it."""
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield ray
    ray.shutdown()


@pytest.fixture(scope="module")
def plain(tiny_library, tmp_path_factory):
    """The collection without Ray: the reference every Ray run must repeat exactly."""
    path = tmp_path_factory.mktemp("plain") / "t.h5"
    collect(path, library=tiny_library, gaits=GAITS, config=SMALL)
    return read(path)


def kill_and_wait(pid: int, timeout_s: float = 30.0) -> None:
    """SIGKILL a worker's process and return once it is gone, so the pool meets a dead worker on its next task (a
    ``ray.kill`` is asynchronous: a task sent just after it may still run, and the kill then tests nothing)."""
    os.kill(pid, signal.SIGKILL)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return
        time.sleep(0.01)
    raise AssertionError(f"worker process {pid} still alive {timeout_s} s after SIGKILL")


def test_a_killed_worker_loses_no_committed_sample(local_ray, tiny_library, plain, tmp_path) -> None:
    path, seen = tmp_path / "t.h5", []

    def kill_a_worker(progress) -> None:
        names = sorted(n for n in ray.util.list_named_actors() if n.startswith(WORKER_PREFIX))
        seen.append((progress.samples, read(path).samples, names))
        if len(seen) == 1:  # after the first commit, with chunks still to hand out: kill a worker's process
            kill_and_wait(ray.get(ray.get_actor(names[0]).pid.remote()))

    result = collect(path, library=tiny_library, gaits=GAITS, config=SMALL, progress=kill_a_worker,
                     cluster=ClusterConfig(workers=2))
    assert result.samples == result.written == 32 and [s for s, _, _ in seen] == list(range(4, 33, 4))
    for count, committed, _ in seen:  # every commit kept every sample committed before it, bit for bit
        assert_same(read(path).samples.select(slice(0, count)), committed)
    data = read(path)
    assert_same(data.samples, plain.samples)  # the lost chunk was collected again, identically
    assert data.header == plain.header  # schema, gaits, identities, settings
    assert set(data.samples.success.tolist()) == {0, 1} and sorted(set(data.samples.chunk.tolist())) == list(range(8))
    assert data.info.sessions[0]["ray"] is True and plain.info.sessions[0]["ray"] is False
    assert len(seen[0][2]) == 2 and any(n.endswith("-2") for n in seen[-1][2])  # the dead worker was replaced


def test_a_ray_sweep_gives_the_plain_results(local_ray, switching_library, tmp_path) -> None:
    setup = load_switching(switching_library)
    config = dataclasses.replace(TINY, magnitudes=(0.0, 300.0, 150.0), seed=3)
    plain = run_sweep(tmp_path / "plain", setup, config)
    calls = []
    with_ray = run_sweep(tmp_path / "ray", setup, config, cluster=ClusterConfig(workers=2),
                         progress=lambda *a: calls.append(a))
    assert list(with_ray["groups"]) == list(plain["groups"])  # written in group order
    for key, group in plain["groups"].items():
        assert with_ray["groups"][key]["cells"] == group["cells"]
    assert with_ray["settings"] == plain["settings"] and calls[-1][1:] == (6 * 3, 6 * 3)
    cells = [g["cells"]["trot-stand"] for g in plain["groups"].values()]
    assert all(c["samples"] == 3 for c in cells) and len({json.dumps(c) for c in cells}) > 1
    again = run_sweep(tmp_path / "ray", setup, config, cluster=ClusterConfig(workers=2),
                      progress=lambda *a: pytest.fail("a finished sweep must not run again"))
    assert again == with_ray


def test_workers_that_keep_dying_end_the_run_in_one_line(local_ray, tiny_library, tmp_path) -> None:
    from gaitlib.cluster import ClusterError

    def kill_every_worker(progress) -> None:
        for name in ray.util.list_named_actors():
            if name.startswith(WORKER_PREFIX):
                ray.kill(ray.get_actor(name))

    cluster = ClusterConfig(workers=1, max_replacements=1)
    with pytest.raises(ClusterError, match="keep dying") as caught:
        collect(tmp_path / "t.h5", library=tiny_library, gaits=GAITS, config=SMALL, progress=kill_every_worker,
                cluster=cluster)
    assert "\n" not in str(caught.value)
    assert validate(tmp_path / "t.h5").count in (4, 8)  # what was committed stays
    assert np.all(read(tmp_path / "t.h5").samples.chunk < 2)
