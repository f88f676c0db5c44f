"""The ``mujoco`` backend: MuJoCo C stepping N worlds on all CPU cores.

Each world owns an ``MjModel`` copy (so domain randomization is per world) and a persistent ``MjData`` (so
the constraint solver keeps its warm start from step to step). The worlds are split into one contiguous chunk
per thread; ``mj_step`` releases the GIL, so the chunks advance in parallel. PD control is MuJoCo's own
``<position>`` actuator (``kp`` in ``gainprm[0]``/``-biasprm[1]``, ``kv`` in ``-biasprm[2]``, clamped by
``forcerange``), evaluated in C at every physics substep. A robot's ``motor_strength`` scales ``kp``, ``kv`` and
``forcerange`` alike. A robot adapted from another MJCF (:mod:`gaitlib.robots.variant`) comes compiled from its
``build_model``; ground contacts of its ``stance_contact_geoms`` are not body contacts.
"""

from __future__ import annotations

import copy
import ctypes
import itertools
import logging
import os
from concurrent.futures import ThreadPoolExecutor

import mujoco
import numpy as np
import torch

from gaitlib.errors import SimulationError
from gaitlib.robots import RobotSpec
from gaitlib.sim.contract import KinematicState, SimBackend, SimState, standing_state

__all__ = ["MujocoBackend", "load_model"]

_log = logging.getLogger(__name__)


def _trim_heap() -> None:
    """Return the C heap's free memory to the system (glibc's ``malloc_trim``; nothing where there is none). glibc
    keeps what a closed backend's worlds freed, many blocks of MuJoCo's own, and a process that builds backend after
    backend (a benchmark's groups) grew by every one without it: 11 GB over the paper's 66-group sweep
    (``benchmarks/backend_memory.py`` measures it)."""
    trim = getattr(ctypes.CDLL(None), "malloc_trim", None)
    if trim is not None:
        trim(0)


def load_model(robot: RobotSpec) -> mujoco.MjModel:
    """Compile ``robot.mjcf_path`` (or take ``robot.build_model()``), check it against the spec and scale its
    torque limits by ``robot.motor_strength``; raises :class:`SimulationError`."""
    try:
        model = robot.build_model() if robot.build_model else mujoco.MjModel.from_xml_path(str(robot.mjcf_path))
    except ValueError as error:  # MuJoCo reports XML and compile errors as ValueError
        first_line = str(error).strip().splitlines()[0] if str(error).strip() else "compile error"
        raise SimulationError(f"cannot load robot model {robot.mjcf_path}: {first_line}") from error
    if not 0.0 < robot.motor_strength < float("inf"):
        raise SimulationError(f"motor strength must be a positive finite number, got {robot.motor_strength:g}")
    model.actuator_forcerange[:] *= robot.motor_strength
    expected_dt = 1.0 / (robot.control_hz * robot.substeps)
    if abs(model.opt.timestep - expected_dt) > 1e-9:
        raise SimulationError(
            f"model timestep {model.opt.timestep:.6g} s does not match 1/(control_hz*substeps) = {expected_dt:.6g} s"
        )
    if model.nu != robot.num_joints or model.njnt != robot.num_joints + 1:
        raise SimulationError(
            f"model has {model.nu} actuators and {model.njnt} joints; expected {robot.num_joints} actuated "
            "hinges plus one free joint"
        )
    return model


class MujocoBackend(SimBackend):
    """N A1 worlds in MuJoCo C, stepped by a thread pool (one contiguous chunk of worlds per thread)."""

    name = "mujoco"

    def __init__(
        self, robot: RobotSpec, num_worlds: int, *, device: str | None = None, threads: int | None = None
    ) -> None:
        if device not in (None, "cpu"):
            raise SimulationError(f"the mujoco backend runs on the CPU only, not on '{device}'")
        self.robot = robot
        self.num_worlds = num_worlds
        self.device = torch.device("cpu")
        # Divergence is detected and reported per world by step(); MuJoCo's own stderr warning goes to logging.
        mujoco.set_mju_user_warning(lambda message: _log.debug("MuJoCo: %s", message))
        base = load_model(robot)
        self._base = base
        self._models = [copy.copy(base) for _ in range(num_worlds)]
        self._datas = [mujoco.MjData(m) for m in self._models]

        nj = robot.num_joints
        self._trunk = base.body(robot.trunk_body).id
        self._robot_bodies = np.arange(1, base.nbody)
        self._gravity = base.opt.gravity.copy()
        self._scratch = mujoco.MjData(base)  # mj_setConst overwrites its data's state: never a world's own
        # sensordata layout (see the MJCF): contacts per foot (F), all robot contacts (1), the trunk's (1), foot
        # positions (F x 3)
        adr = {base.sensor(i).name: int(base.sensor_adr[i]) for i in range(base.nsensor)}
        self._foot_contact_adr = np.array([adr[f"{f}_contact"] for f in robot.foot_names])
        self._robot_contact_adr = adr["robot_contacts"]
        if "trunk_contact" not in adr:
            raise SimulationError("robot model has no contact sensor trunk_contact (its trunk's geoms and the floor)")
        self._trunk_contact_adr = adr["trunk_contact"]
        missing = [g for g in robot.stance_contact_geoms if f"{g}_contact" not in adr]
        if missing:
            raise SimulationError(f"robot model has no contact sensor {missing[0]}_contact for its stance geom")
        self._stance_contact_adr = np.array([adr[f"{g}_contact"] for g in robot.stance_contact_geoms], dtype=int)
        self._foot_pos_adr = np.array([adr[f"{f}_pos"] + k for f in robot.foot_names for k in range(3)])

        # Host buffers written by the worker threads, one row per world: [time, qpos, qvel] and sensordata.
        self._spec = int(mujoco.mjtState.mjSTATE_TIME | mujoco.mjtState.mjSTATE_QPOS | mujoco.mjtState.mjSTATE_QVEL)
        self._phys = np.zeros((num_worlds, mujoco.mj_stateSize(base, self._spec)))
        self._sensors = np.zeros((num_worlds, base.nsensordata))
        self._ctrl = np.zeros((num_worlds, nj))
        self._diverged = np.zeros(num_worlds, dtype=bool)
        self._reset_phys = np.zeros_like(self._phys)

        n_threads = max(1, min(threads or os.cpu_count() or 1, num_worlds))
        bounds = np.linspace(0, num_worlds, n_threads + 1).astype(int)
        self._chunks = [(int(lo), int(hi)) for lo, hi in itertools.pairwise(bounds)]
        self._pool = ThreadPoolExecutor(n_threads, thread_name_prefix="gaitlib-mujoco")
        # torch's intra-op threads busy-wait between the many small tensor ops around each step and starve the
        # MuJoCo threads (measured: 10-25x slower small ops and updates on 2 cores); one torch thread it is.
        torch.set_num_threads(1)

        all_worlds = torch.arange(num_worlds)
        self.set_pd_gains(
            all_worlds,
            torch.full((num_worlds, nj), robot.kp_default),
            torch.full((num_worlds, nj), robot.kd_default),
        )
        self.reset(all_worlds, standing_state(robot, num_worlds))

    # ----------------------------------------------------------------------------------------- commands
    def reset(self, world_ids: torch.Tensor, state: KinematicState) -> None:
        ids = _indices(world_ids)
        qpos = np.concatenate(
            [_np(state.root_pos), _np(state.root_quat), _np(state.joint_pos)], axis=1, dtype=np.float64
        )
        qvel = np.concatenate(
            [_np(state.root_lin_vel), _np(state.root_ang_vel), _np(state.joint_vel)], axis=1, dtype=np.float64
        )
        if qpos.shape != (len(ids), self._base.nq) or qvel.shape != (len(ids), self._base.nv):
            raise SimulationError(f"reset state has the wrong shape for {len(ids)} worlds")
        if not (np.isfinite(qpos).all() and np.isfinite(qvel).all()):
            raise SimulationError("reset state is not finite")
        self._reset_phys[ids] = np.concatenate([np.zeros((len(ids), 1)), qpos, qvel], axis=1)
        self._ctrl[ids] = qpos[:, 7:]
        for i in ids:
            self._restore(int(i))

    def set_pd_targets(self, targets: torch.Tensor) -> None:
        values = _np(targets)
        if values.shape != self._ctrl.shape:
            raise SimulationError(f"PD targets must have shape {self._ctrl.shape}, got {values.shape}")
        if not np.isfinite(values).all():
            bad = np.flatnonzero(~np.isfinite(values).all(axis=1))
            raise SimulationError(f"non-finite PD targets for worlds {bad[:8].tolist()}")
        self._ctrl[:] = values

    def set_pd_gains(self, world_ids: torch.Tensor, kp: torch.Tensor, kd: torch.Tensor) -> None:
        ids = _indices(world_ids)
        strength = self.robot.motor_strength  # the motors deliver this multiple of the PD torque
        kp_np, kd_np = strength * _np(kp), strength * _np(kd)
        for row, i in enumerate(ids):
            m = self._models[i]
            m.actuator_gainprm[:, 0] = kp_np[row]
            m.actuator_biasprm[:, 1] = -kp_np[row]
            m.actuator_biasprm[:, 2] = -kd_np[row]

    def set_dynamics(
        self,
        world_ids: torch.Tensor,
        *,
        gravity_scale: torch.Tensor,
        mass_scale: torch.Tensor,
        friction: torch.Tensor,
    ) -> None:
        ids = _indices(world_ids)
        g, s, mu = _np(gravity_scale), _np(mass_scale), _np(friction)
        bodies = self._robot_bodies
        for row, i in enumerate(ids):
            m = self._models[i]
            m.opt.gravity[:] = self._gravity * g[row]
            m.body_mass[bodies] = self._base.body_mass[bodies] * s[row]
            m.body_inertia[bodies] = self._base.body_inertia[bodies] * s[row]
            m.geom_friction[:, 0] = mu[row]  # robot and floor alike: MuJoCo takes the max of the pair
            mujoco.mj_setConst(m, self._scratch)  # refresh derived masses (subtree mass, inverse weights)

    def set_trunk_force(self, world_ids: torch.Tensor, force: torch.Tensor) -> None:
        ids = _indices(world_ids)
        values = _np(force)
        for row, i in enumerate(ids):
            self._datas[i].xfrc_applied[self._trunk, :3] = values[row]

    def step(self) -> torch.Tensor:
        list(self._pool.map(lambda chunk: self._step_chunk(*chunk), self._chunks))
        return torch.from_numpy(self._diverged.copy())

    def state(self) -> SimState:
        nq = self._base.nq
        qpos = torch.from_numpy(self._phys[:, 1 : 1 + nq]).float()
        qvel = torch.from_numpy(self._phys[:, 1 + nq :]).float()
        sensors = self._sensors
        foot_contacts = sensors[:, self._foot_contact_adr]
        allowed = foot_contacts.sum(axis=1) + sensors[:, self._stance_contact_adr].sum(axis=1)
        return SimState(
            root_pos=qpos[:, 0:3],
            root_quat=qpos[:, 3:7],
            root_lin_vel=qvel[:, 0:3],
            root_ang_vel=qvel[:, 3:6],
            joint_pos=qpos[:, 7:],
            joint_vel=qvel[:, 6:],
            foot_contact=torch.from_numpy(foot_contacts > 0),
            foot_pos=torch.from_numpy(sensors[:, self._foot_pos_adr]).float().view(self.num_worlds, -1, 3),
            # Every robot-floor contact beyond the feet' and the stance geoms' is a body contact.
            body_contact=torch.from_numpy(sensors[:, self._robot_contact_adr] > allowed),
            trunk_contact=torch.from_numpy(sensors[:, self._trunk_contact_adr] > 0),
        )

    def close(self) -> None:
        """Stop the stepping threads and drop every world's model and data and every buffer (only ``robot``,
        ``num_worlds`` and ``device`` are kept), so that their memory is freed even while something still refers to
        the backend: an environment in a reference cycle keeps it until Python's collector finds the cycle, which
        does not count MuJoCo's own memory (about 0.6 MB a world). Then hand the freed memory back to the system
        (:func:`_trim_heap`)."""
        if "_pool" in self.__dict__:
            self._pool.shutdown(wait=True)
        for name in [name for name in self.__dict__ if name not in ("robot", "num_worlds", "device")]:
            del self.__dict__[name]
        _trim_heap()

    # ----------------------------------------------------------------------------------------- internals
    def _step_chunk(self, lo: int, hi: int) -> None:
        nstep, spec = self.robot.substeps, self._spec
        models, datas, ctrl, phys, sensors = self._models, self._datas, self._ctrl, self._phys, self._sensors
        time_before = phys[lo:hi, 0].copy()
        for i in range(lo, hi):
            m, d = models[i], datas[i]
            d.ctrl[:] = ctrl[i]
            mujoco.mj_step(m, d, nstep)
            mujoco.mj_getState(m, d, phys[i], spec)
            sensors[i] = d.sensordata
        # MuJoCo resets a world whose accelerations blow up (its clock restarts at 0); NaN can also slip through.
        rows = phys[lo:hi]
        clock_jumped = np.abs(rows[:, 0] - time_before - self.control_dt) > 1e-6
        bad = clock_jumped | ~np.isfinite(rows).all(axis=1)
        self._diverged[lo:hi] = bad
        for i in np.flatnonzero(bad) + lo:
            self._restore(int(i))

    def _restore(self, i: int) -> None:
        """Put world ``i`` back into its last reset state, with no force and a cold solver."""
        m, d = self._models[i], self._datas[i]
        mujoco.mj_resetData(m, d)
        mujoco.mj_setState(m, d, self._reset_phys[i], self._spec)
        d.ctrl[:] = self._ctrl[i]
        mujoco.mj_forward(m, d)
        mujoco.mj_getState(m, d, self._phys[i], self._spec)
        self._sensors[i] = d.sensordata


def _indices(world_ids: torch.Tensor) -> np.ndarray:
    return np.asarray(world_ids.detach().cpu().numpy(), dtype=np.int64).reshape(-1)


def _np(tensor: torch.Tensor) -> np.ndarray:
    return tensor.detach().cpu().numpy().astype(np.float64, copy=False)
