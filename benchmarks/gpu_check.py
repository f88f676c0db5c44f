"""GPU check: the ``newton`` backend's speed against raw mujoco_warp, parity with MuJoCo C, training and collection.

Prints one JSON line per measurement on stdout (everything else, Warp's and MuJoCo's own output included, goes to
stderr); a measurement that fails prints a line with an ``"error"`` and the check goes on to the next one. The exit
status is 1 when any line has an error or parity failed. Sized for one H100 in under 8 minutes, Warp's kernel
compilation on a fresh machine included; ``--tiny`` runs every measurement on the CPU at a few worlds (one world
count for ``sim``) in about 20 s. The tests run :func:`check` at :data:`TINY` in their own process, where Newton is
imported already, and this script without CUDA at its real sizes, where every line is an error.

    python benchmarks/gpu_check.py            # on a CUDA machine
    python benchmarks/gpu_check.py --tiny     # on the CPU
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
import traceback
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import torch

__all__ = [
    "FULL",
    "TINY",
    "CheckSizes",
    "check",
    "has_failed",
    "main",
    "measure_collect",
    "measure_parity",
    "measure_sim",
    "measure_train",
]


@dataclass(frozen=True, kw_only=True)
class CheckSizes:
    """Sizes and durations of one check."""

    device: str
    """Torch device of the ``newton`` backend everywhere (``cuda:0`` or ``cpu``)."""
    sim_worlds: tuple[int, ...]
    """World counts of the newton-against-raw-mujoco_warp measurement."""
    sim_seconds: float
    """Wall-clock time given to each side (backend, each raw reference) of that measurement, s."""
    jobs_backend: str
    """Backend of the training and collection measurements."""
    train_preset: str
    """Training preset of ``gaitlib train trot``."""
    train_seconds: float
    """Training time limit (training stops after the iteration that passes it), s."""
    eval_episodes: int
    """Episodes of the evaluation that ends the training run."""
    eval_seconds: float
    """Length of those episodes, s."""
    collect_worlds: int
    """Worlds of the collection measurement."""
    collect_seconds: float
    """Wall-clock time of each of its three parts (reference rollout, collection, reference rollout), s."""
    collect_chunk: int
    """Samples per chunk of that collection: it runs whole chunks, so one sample a world keeps it near its time."""
    push_max: float
    """Largest push of the collection, N."""


FULL = CheckSizes(
    device="cuda:0",
    sim_worlds=(1024, 4096),
    sim_seconds=5.0,
    jobs_backend="newton",
    train_preset="paper",
    train_seconds=90.0,
    eval_episodes=64,
    eval_seconds=5.0,
    collect_worlds=4096,
    collect_seconds=15.0,
    collect_chunk=4096,  # one sample a world: collect's default 16 a world held one chunk past 7 min on an H100
    push_max=400.0,
)
"""One H100, under 8 minutes."""

TINY = CheckSizes(
    device="cpu",
    sim_worlds=(8,),
    sim_seconds=0.25,
    jobs_backend="mujoco",
    train_preset="tiny",
    train_seconds=0.5,
    eval_episodes=2,
    eval_seconds=0.5,
    collect_worlds=8,
    collect_seconds=0.35,
    collect_chunk=8,
    push_max=400.0,
)
"""The CPU in CI: every measurement, a few worlds, a second or two each."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tiny", action="store_true", help="run on the CPU at a few worlds (what the tests run)")
    args = parser.parse_args()
    out = _take_stdout()
    failed = False
    for line in check(TINY if args.tiny else FULL):
        failed |= has_failed(line)
        out.write(json.dumps(line) + "\n")
        out.flush()
    sys.exit(1 if failed else 0)


def check(sizes: CheckSizes) -> Iterator[dict[str, object]]:
    """Every measurement at ``sizes``, one line each as it ends: its figures, or its error."""
    jobs: list[tuple[str, int | None, Callable[[], dict[str, object]]]] = [
        ("sim", n, lambda n=n: measure_sim(sizes, worlds=n)) for n in sizes.sim_worlds
    ]
    jobs += [
        ("parity", 2, lambda: measure_parity(sizes)),
        ("train", None, lambda: measure_train(sizes)),  # its worlds come with its figures
        ("collect", sizes.collect_worlds, lambda: measure_collect(sizes)),
    ]
    for measure, worlds, job in jobs:
        yield _run_one(measure, worlds, job, sizes)


def has_failed(line: Mapping[str, object]) -> bool:
    """Whether a measurement's line is an error or a failed parity (the check then exits with status 1)."""
    return "error" in line or line.get("passed") is False


def _take_stdout() -> TextIO:
    """A private handle on the real stdout; file descriptor 1 (and ``sys.stdout``) then lead to stderr, so that
    lines printed by Warp, MuJoCo or rsl-rl, from Python or C, cannot mix into the JSON lines."""
    sys.stdout.flush()
    out = os.fdopen(os.dup(1), "w")
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    return out


def _run_one(
    measure: str, worlds: int | None, job: Callable[[], dict[str, object]], sizes: CheckSizes
) -> dict[str, object]:
    """Run one measurement: its line, or a line with the error's first line (``worlds``: None where the
    measurement's own figures give it)."""
    print(f"gpu_check: {measure}, {worlds or 'preset'} worlds ...", file=sys.stderr, flush=True)
    start = time.perf_counter()
    head: dict[str, object] = {"measure": measure, "device": _device_name(sizes.device), "worlds": worlds}
    try:
        _require_device(sizes.device)
        values = job()
    except Exception as error:  # one failed measurement must not stop the others
        traceback.print_exc(file=sys.stderr)
        message = (str(error).splitlines() or [""])[0]
        values = {"error": f"{type(error).__name__}: {message}"}
    return {**head, **values, "seconds": round(time.perf_counter() - start, 2)}


def _device_name(device: str) -> str:
    return torch.cuda.get_device_name(device) if device.startswith("cuda") and torch.cuda.is_available() else "cpu"


def _require_device(device: str) -> None:
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise RuntimeError("CUDA is not available here; on the CPU run with --tiny")


# ------------------------------------------------------------------------------------------------- measurements
def measure_sim(sizes: CheckSizes, *, worlds: int) -> dict[str, object]:
    """Control steps/s of the newton backend and of raw mujoco_warp stepping of its own model and data.

    The raw side advances the backend's mujoco_warp model and data from the same settled standing state, with the
    same substeps and controls, and no Newton or gaitlib work: eagerly, and as one captured Warp graph per control
    step (a CUDA graph on the GPU); the faster is the reference. Every side waits for the device once per control
    step. Newton writes its own state into that data at the start of each of its steps, so the raw steps in
    between do not change what the backend steps; the sides are timed in alternating rounds
    (:mod:`gaitlib.throughput.sim`)."""
    from gaitlib.sim import make_backend
    from gaitlib.throughput.sim import mujoco_warp_references, settle, timed_rates

    start = time.perf_counter()
    backend = make_backend("newton", num_worlds=worlds, device=sizes.device)
    build_s = time.perf_counter() - start
    try:
        targets = torch.tensor(backend.robot.default_joint_pos, device=backend.device).repeat(worlds, 1)
        start = time.perf_counter()
        settle(backend, targets)  # 1 s of simulated time; on a fresh machine, also Warp's compilation of the step
        settle_s = time.perf_counter() - start

        def run_backend() -> None:
            backend.set_pd_targets(targets)
            backend.step()
            backend.state()

        references = mujoco_warp_references(backend)
        rate = timed_rates({"env": run_backend, **references}, worlds=worlds, seconds=sizes.sim_seconds, rounds=4)
    finally:
        backend.close()
    raw = max(rate[key] for key in references)
    return {
        "backend": "newton",
        "substeps": backend.robot.substeps,
        "build_s": round(build_s, 2),
        "settle_s": round(settle_s, 2),
        "env_steps_per_s": round(rate["env"]),
        "raw_eager_steps_per_s": round(rate["raw_eager"]),
        "raw_graph_steps_per_s": round(rate["raw_graph"]) if "raw_graph" in rate else None,  # None: no capture
        "raw_steps_per_s": round(raw),
        "ratio": round(rate["env"] / raw, 3),
    }


def measure_parity(sizes: CheckSizes) -> dict[str, object]:
    """The parity scenario of ``tests/test_sim_parity.py`` (:mod:`gaitlib.sim.parity`) with the newton backend on
    ``sizes.device``: two worlds stepping (and, in a second run, falling and pushed) for 1 s beside MuJoCo C."""
    from gaitlib.sim.parity import PARITY_LIMITS, parity_run

    cases = {
        name: parity_run(airborne=name == "falling-pushed", newton_device=sizes.device)
        for name in ("ground", "falling-pushed")
    }
    worst = {name: max(case.worst[name] for case in cases.values()) for name in PARITY_LIMITS}
    failed = [name for name, case in cases.items() if not case.passed]
    return {
        "passed": not failed,
        "failed_cases": failed,
        "max_root_pos_diff_m": worst["root_pos"],
        "max_root_quat_diff": worst["root_quat"],
        "max_joint_pos_diff_rad": worst["joint_pos"],
        "max_foot_pos_diff_m": worst["foot_pos"],
        "foot_contact_mismatches": cases["ground"].contact_mismatches,
    }


def measure_train(sizes: CheckSizes) -> dict[str, object]:
    """``gaitlib train trot --preset <preset>`` for ``sizes.train_seconds`` into a temporary library and run
    folder."""
    from gaitlib.gaits import get_gait
    from gaitlib.training import get_preset
    from gaitlib.training.trainer import TrainRequest, train_gait

    last: dict[str, float] = {}

    def on_iteration(stats) -> None:
        last["samples_per_s"] = stats.samples_per_s
        print(f"gpu_check: train iteration {stats.iteration}, {stats.samples_per_s:,.0f} samples/s", file=sys.stderr)

    preset = get_preset(sizes.train_preset)
    with tempfile.TemporaryDirectory() as scratch:
        request = TrainRequest(
            description=get_gait("trot"),
            preset=preset,
            iterations=10**6,
            time_limit_s=sizes.train_seconds,
            library=Path(scratch) / "library",
            run_dir=Path(scratch) / "run",
            backend=sizes.jobs_backend,
            eval_episodes=sizes.eval_episodes,
            eval_seconds=sizes.eval_seconds,
        )
        result = train_gait(request, on_iteration=on_iteration)
    return {
        "worlds": preset.num_envs,
        "backend": sizes.jobs_backend,
        "preset": sizes.train_preset,
        "iterations": result.iterations,
        "samples": result.samples,
        "train_s": round(result.wall_clock_s, 2),
        "samples_per_s": round(result.samples / result.wall_clock_s),
        "last_iteration_samples_per_s": round(last["samples_per_s"]),
        "eval_fall_rate": round(result.evaluation.fall_rate, 3),
    }


def measure_collect(sizes: CheckSizes) -> dict[str, object]:
    """``gaitlib throughput collect``: samples/s of a collection (into a temporary file) from the shipped library,
    against what a plain policy rollout allows."""
    from gaitlib.library import Library
    from gaitlib.throughput.collect import measure_collect_throughput

    result = measure_collect_throughput(
        Library(None),
        worlds=sizes.collect_worlds,
        seconds=sizes.collect_seconds,
        push_max=sizes.push_max,
        chunk=sizes.collect_chunk,
        backend=sizes.jobs_backend,
    )
    return {
        "backend": sizes.jobs_backend,
        "push_max": result.push_max,
        "samples_per_s": round(result.samples_per_s, 1),
        "env_steps_per_s": round(result.env_steps_per_s),
        "steps_per_sample": round(result.steps_per_sample, 1),
        "ratio": round(result.ratio, 3),
    }


if __name__ == "__main__":
    main()
