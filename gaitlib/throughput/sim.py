"""Simulation throughput: a backend's control steps per second against plain MuJoCo C in the same run.

The reference (``raw``) advances the same number of worlds, from the same settled in-contact standing states,
with the same substeps and thread count, and none of gaitlib's work: the faster of

* ``mj_step`` over persistent per-world ``MjData`` in a thread pool (keeps the solver warm start), and
* ``mujoco.rollout`` with a persistent thread pool, chained call to call (each call starts the solver cold).

Backend and references are timed in alternating rounds so that a change of machine load hits both alike.
"""

from __future__ import annotations

import contextlib
import itertools
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass

import numpy as np
import torch

from gaitlib.sim import SimBackend

__all__ = ["ThroughputResult", "measure_throughput", "mujoco_warp_references", "settle", "timed_rates"]


@dataclass(frozen=True)
class ThroughputResult:
    """Control steps per second (all worlds together) of a backend and of plain MuJoCo C."""

    backend: str
    """Backend measured."""
    device: str
    """Torch device of the backend."""
    worlds: int
    """Number of worlds N."""
    threads: int
    """CPU threads used by the references (and by the ``mujoco`` backend)."""
    control_hz: float
    """Control rate, Hz."""
    substeps: int
    """Physics steps per control step."""
    seconds: float
    """Wall-clock time spent on each side, s."""
    env_steps_per_s: float
    """Backend: control steps per second over all worlds (set targets, step, read state)."""
    raw_steps_per_s: float
    """Plain MuJoCo C: control steps per second over all worlds, the faster reference."""
    raw_mj_step_per_s: float
    """Reference 1: ``mj_step`` over persistent ``MjData`` in a thread pool."""
    raw_rollout_per_s: float
    """Reference 2: chained ``mujoco.rollout`` calls."""
    ratio: float
    """``env_steps_per_s / raw_steps_per_s``."""

    def as_dict(self) -> dict[str, object]:
        return asdict(self)


def measure_throughput(backend: SimBackend, *, seconds: float, threads: int, rounds: int = 4) -> ThroughputResult:
    """Time ``backend`` and the plain MuJoCo C references for about ``seconds`` each (s)."""
    n = backend.num_worlds
    targets = torch.tensor(backend.robot.default_joint_pos, device=backend.device).repeat(n, 1)
    qpos, qvel = settle(backend, targets)

    def run_backend() -> None:
        backend.set_pd_targets(targets)
        backend.step()
        backend.state()

    with _mujoco_references(backend, qpos, qvel, threads) as references:
        rate = timed_rates({"env": run_backend, **references}, worlds=n, seconds=seconds, rounds=rounds)
    raw = max(rate["mj_step"], rate["rollout"])
    return ThroughputResult(
        backend=backend.name,
        device=str(backend.device),
        worlds=n,
        threads=threads,
        control_hz=backend.robot.control_hz,
        substeps=backend.robot.substeps,
        seconds=seconds,
        env_steps_per_s=rate["env"],
        raw_steps_per_s=raw,
        raw_mj_step_per_s=rate["mj_step"],
        raw_rollout_per_s=rate["rollout"],
        ratio=rate["env"] / raw,
    )


def settle(backend: SimBackend, targets: torch.Tensor) -> tuple[np.ndarray, np.ndarray]:
    """Hold ``targets`` for 1 s so every world is in ground contact; its (N, nq) qpos and (N, nv) qvel."""
    backend.set_pd_targets(targets)
    for _ in range(int(backend.robot.control_hz)):
        backend.step()
    settled = backend.state()
    qpos = torch.cat([settled.root_pos, settled.root_quat, settled.joint_pos], 1).double().cpu().numpy()
    qvel = torch.cat([settled.root_lin_vel, settled.root_ang_vel, settled.joint_vel], 1).double().cpu().numpy()
    return qpos, qvel


@contextlib.contextmanager
def _mujoco_references(
    backend: SimBackend, qpos: np.ndarray, qvel: np.ndarray, threads: int
) -> Iterator[dict[str, Callable[[], None]]]:
    """One control step of every world in plain MuJoCo C, from the same states, two ways: ``mj_step`` on a
    thread pool, and chained ``rollout`` calls (each holding its joints at the starting pose)."""
    import mujoco
    from mujoco import rollout

    from gaitlib.sim.mujoco_backend import load_model

    n, substeps = len(qpos), backend.robot.substeps
    model = load_model(backend.robot)
    datas = [mujoco.MjData(model) for _ in range(n)]
    for d, qp, qv in zip(datas, qpos, qvel, strict=True):
        d.qpos[:], d.qvel[:], d.ctrl[:] = qp, qv, qp[7:]
        mujoco.mj_forward(model, d)
    bounds = np.linspace(0, n, threads + 1).astype(int)
    chunks = [range(lo, hi) for lo, hi in itertools.pairwise(bounds) if hi > lo]
    spec = int(mujoco.mjtState.mjSTATE_FULLPHYSICS)
    roll_state = np.empty((n, mujoco.mj_stateSize(model, spec)))
    for i, d in enumerate(datas):
        mujoco.mj_getState(model, d, roll_state[i], spec)
    roll_control = np.repeat(qpos[:, None, 7:], substeps, axis=1)
    roll_datas = [mujoco.MjData(model) for _ in range(threads)]

    def step_chunk(worlds: range) -> None:
        for i in worlds:
            mujoco.mj_step(model, datas[i], substeps)

    def run_rollout() -> None:
        nonlocal roll_state
        out, _ = roller.rollout([model] * n, roll_datas, roll_state, roll_control, nstep=substeps)
        roll_state = out[:, -1]

    with ThreadPoolExecutor(len(chunks)) as pool, rollout.Rollout(nthread=threads) as roller:
        yield {"mj_step": lambda: list(pool.map(step_chunk, chunks)), "rollout": run_rollout}


def timed_rates(
    runners: dict[str, Callable[[], None]], *, worlds: int, seconds: float, rounds: int
) -> dict[str, float]:
    """Control steps per second (all worlds) of each runner, timed in ``rounds`` interleaved turns of
    ``seconds / rounds`` each so that a change in machine load affects all alike."""
    steps = dict.fromkeys(runners, 0)
    elapsed = dict.fromkeys(runners, 0.0)
    for _ in range(rounds):
        for key, run in runners.items():
            start = time.perf_counter()
            while time.perf_counter() - start < seconds / rounds:
                run()
                steps[key] += worlds
            elapsed[key] += time.perf_counter() - start
    return {key: steps[key] / elapsed[key] for key in runners}


def mujoco_warp_references(backend) -> dict[str, Callable[[], None]]:
    """One control step (``substeps`` calls of ``mujoco_warp.step``) of every world of the newton ``backend``'s own
    mujoco_warp model and data, with no Newton or gaitlib work: ``raw_eager`` launches each kernel, ``raw_graph``
    replays one captured Warp graph (a CUDA graph on a GPU; left out where the capture fails). Each waits for the
    device at its end. Newton writes its state into that data at the start of each of its steps, so these steps
    between the backend's do not change what the backend computes."""
    import mujoco_warp
    import warp as wp

    (model, data), device, substeps = backend.mujoco_warp, backend.warp_device, backend.robot.substeps

    def eager() -> None:
        with backend.warp_scope():
            for _ in range(substeps):
                mujoco_warp.step(model, data)
        wp.synchronize_device(device)

    eager()  # makes and loads mujoco_warp's lazily created kernels before the capture
    # On CUDA the graph is captured and launched on Warp's own stream (torch's default stream cannot be captured);
    # every runner waits for the whole device at its end, so the two streams never overlap.
    try:
        with wp.ScopedDevice(device), wp.ScopedCapture(device=device, force_module_load=False) as capture:
            for _ in range(substeps):
                mujoco_warp.step(model, data)
    except Exception:  # Warp raises several types; the eager reference still measures
        return {"raw_eager": eager}
    graph = capture.graph

    def graphed() -> None:
        wp.capture_launch(graph)
        wp.synchronize_device(device)

    return {"raw_eager": eager, "raw_graph": graphed}

