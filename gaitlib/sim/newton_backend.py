"""The ``newton`` backend: N worlds in one batched Newton model, stepped by mujoco_warp on a GPU (or the CPU).

The robot MJCF is parsed once into a :class:`newton.ModelBuilder`, replicated into ``num_worlds`` worlds (each
world gets its own copy of the MJCF's ``floor`` plane, so ground friction can differ per world) and stepped by
:class:`newton.solvers.SolverMuJoCo` on mujoco_warp with the MJCF's own solver options (timestep, integrator,
cone, iterations, tolerances). PD control is the MJCF's ``<position>`` actuator, which Newton maps to a
``JOINT_TARGET`` actuator: targets in ``Control.joint_target_q``, gains in ``Model.joint_target_ke/kd``, torque
clamp in the actuator ``forcerange`` and in ``Model.joint_effort_limit`` (set here from the robot spec).

Newton 1.8 facts this module relies on (read from its source):

* A free joint's ``joint_q`` is ``(x, y, z, qx, qy, qz, qw)`` of the trunk frame; its ``joint_qd`` is the
  velocity of the trunk's centre of mass and the angular velocity, both in the world frame. mujoco_warp's
  ``qpos``/``qvel`` use the contract's convention (quaternion ``w`` first, origin velocity in the world frame,
  angular velocity in the trunk frame), so readings come from mujoco_warp's data and resets write both.
* ``State.body_f`` is a spatial vector ``(force, torque)`` in the world frame, applied at the body's centre of
  mass (MuJoCo ``xfrc_applied``) at every substep until changed.
* ``Model.gravity`` holds one gravity vector per world (``MODEL_PROPERTIES`` notification).
* Newton's default ``rigid_gap`` of 0.1 m would become MuJoCo ``geom_gap``; the MJCF's value (0) is kept instead.
* Newton pushes ``Model.body_com`` into MuJoCo's ``body_ipos`` on inertia updates; for a massless body (the feet)
  MuJoCo's compiler uses a different point, which changes contact softness, so MuJoCo's value is copied back.
* mujoco_warp's contact buffer holds ``nconmax * num_worlds`` contacts shared by all worlds (``nconmax`` >= 8);
  the per-world ``Observables.overflow`` bitmask (reset at every substep) reports what did not fit.

All tensors stay on the device; :meth:`NewtonBackend.step` reads one pair of flags back to the host (capacity
overflow, divergence) and :meth:`NewtonBackend.reset` and the ``set_*`` commands one validity flag each.

A control step's substeps run as one captured Warp graph (a CUDA graph on a GPU), the way mujoco_warp's and
Newton's own examples step: launching their kernels one by one costs most of a step's time (``benchmarks/
gpu_check.py``, ``sim``). The first step runs them eagerly, which loads the kernels, and captures them; later steps
replay the capture. A graph holds the addresses of the arrays it reads and writes, so the backend checks after every
model change (``set_pd_gains``, ``set_dynamics``) and every reset that no array moved, and captures again where one
did. Where capture fails, every step runs eagerly.
"""

from __future__ import annotations

import contextlib

import mujoco_warp
import newton
import torch
import warp as wp
from newton.solvers import SolverMuJoCo

from gaitlib.errors import SimulationError
from gaitlib.robots import RobotSpec
from gaitlib.rotations import quat_rotate
from gaitlib.sim.contract import KinematicState, SimBackend, SimState, standing_state
from gaitlib.sim.mujoco_backend import load_model
from gaitlib.sim.newton_model import (
    NewtonConstruction,
    array_addresses,
    fold_overflow_kernel,
    ground_contacts_kernel,
    resolve_device,
)

__all__ = ["NewtonBackend"]

wp.config.log_level = wp.LOG_WARNING  # Warp's init and module-load lines would mix into --json output

_DIVERGENCE_LIMIT = 1.0e4
"""A world whose |qpos| or |qvel| entry exceeds this (m, rad, m/s, rad/s) or is non-finite has diverged."""

_CAPACITY_BITS = (
    int(mujoco_warp.OverflowType.ALL)
    & ~int(mujoco_warp.OverflowType.ITERATIONS | mujoco_warp.OverflowType.LS_ITERATIONS)
) | int(SolverMuJoCo.OverflowBits.SOLVER_NCONMAX | SolverMuJoCo.OverflowBits.CONTACT_PIPELINE)
"""Overflow bits that mean lost contacts or constraints (solver iteration limits are not errors)."""


class NewtonBackend(NewtonConstruction, SimBackend):
    """N robot worlds in one Newton model, stepped by ``SolverMuJoCo`` (mujoco_warp) on a CUDA GPU or the CPU.

    ``contacts_per_world`` sizes mujoco_warp's contact buffer (``nconmax``, contacts per world) and, with it, the
    constraint buffer (``njmax``); running out raises :class:`~gaitlib.errors.SimulationError` instead of
    silently dropping contacts.
    """

    name = "newton"

    def __init__(
        self,
        robot: RobotSpec,
        num_worlds: int,
        *,
        device: str | None = None,
        contacts_per_world: int = 32,
    ) -> None:
        if num_worlds < 1:
            raise SimulationError(f"need at least one world, got {num_worlds}")
        if contacts_per_world < 1:
            raise SimulationError(f"contacts_per_world must be positive, got {contacts_per_world}")
        self.robot = robot
        self.num_worlds = num_worlds
        self.device, self._wp_device = resolve_device(device)
        self._contacts_per_world = contacts_per_world
        mj = load_model(robot)  # the MJCF as MuJoCo C compiles it: checks it and gives the solver options
        self._dt = float(mj.opt.timestep)
        self._graph, self._addresses, self._eager_only = None, (), False
        with wp.ScopedDevice(self._wp_device):
            self._build(robot, mj)
        self.reset(torch.arange(num_worlds, device=self.device), standing_state(robot, num_worlds, device=self.device))

    # ----------------------------------------------------------------------------------------- commands
    def reset(self, world_ids: torch.Tensor, state: KinematicState) -> None:
        ids = self._ids(world_ids)
        k = ids.numel()
        nj = self.robot.num_joints
        shapes = {"root_pos": 3, "root_quat": 4, "root_lin_vel": 3, "root_ang_vel": 3, "joint_pos": nj, "joint_vel": nj}
        values = {}
        for name, width in shapes.items():
            value = getattr(state, name).to(self.device, torch.float32)
            if tuple(value.shape) != (k, width):
                raise SimulationError(f"reset {name} must have shape {(k, width)}, got {tuple(value.shape)}")
            values[name] = value
        norm = values["root_quat"].norm(dim=1, keepdim=True)
        ok = torch.stack([torch.isfinite(v).all() for v in values.values()]).all() & (norm > 0).all()
        self._require(ok & self._ids_valid(ids), "reset state is not finite or world ids are out of range")
        values["root_quat"] = values["root_quat"] / norm
        for name, value in values.items():
            getattr(self._reset_state, name)[ids] = value
        mask = torch.zeros(self.num_worlds, dtype=torch.bool, device=self.device)
        mask[ids] = True
        self._restore(mask)

    def set_pd_targets(self, targets: torch.Tensor) -> None:
        values = targets.to(self.device, torch.float32)
        if tuple(values.shape) != (self.num_worlds, self.robot.num_joints):
            raise SimulationError(
                f"PD targets must have shape {(self.num_worlds, self.robot.num_joints)}, got {tuple(values.shape)}"
            )
        finite = torch.isfinite(values).all(dim=1)
        if not bool(finite.all()):
            bad = torch.nonzero(~finite).flatten()[:8].tolist()
            raise SimulationError(f"non-finite PD targets for worlds {bad}")
        self._target_q[:, self._target_coords] = values

    def set_pd_gains(self, world_ids: torch.Tensor, kp: torch.Tensor, kd: torch.Tensor) -> None:
        ids = self._ids(world_ids)
        shape = (ids.numel(), self.robot.num_joints)
        kp, kd = kp.to(self.device, torch.float32), kd.to(self.device, torch.float32)
        if tuple(kp.shape) != shape or tuple(kd.shape) != shape:
            raise SimulationError(f"PD gains must have shape {shape}, got {tuple(kp.shape)} and {tuple(kd.shape)}")
        ok = torch.isfinite(kp).all() & torch.isfinite(kd).all() & (kp >= 0).all() & (kd >= 0).all()
        self._require(ok & self._ids_valid(ids), "PD gains must be finite and non-negative, world ids in range")
        rows = ids[:, None]
        self._ke[rows, self._joint_dofs] = kp
        self._kd[rows, self._joint_dofs] = kd
        with self.warp_scope():
            self._solver.notify_model_changed(newton.ModelFlags.JOINT_DOF_FORCE_PROPERTIES)
        self._check_graph()

    def set_dynamics(
        self,
        world_ids: torch.Tensor,
        *,
        gravity_scale: torch.Tensor,
        mass_scale: torch.Tensor,
        friction: torch.Tensor,
    ) -> None:
        ids = self._ids(world_ids)
        k = ids.numel()
        g, s, mu = (x.to(self.device, torch.float32).reshape(-1) for x in (gravity_scale, mass_scale, friction))
        if not g.numel() == s.numel() == mu.numel() == k:
            raise SimulationError(f"set_dynamics needs {k} values per argument")
        ok = torch.isfinite(torch.cat([g, s, mu])).all() & (g >= 0).all() & (s > 0).all() & (mu >= 0).all()
        self._require(ok & self._ids_valid(ids), "dynamics must be finite, masses positive, world ids in range")
        base = self._base
        self._gravity[ids] = base["gravity"] * g[:, None]
        self._mass[ids] = base["mass"] * s[:, None]
        self._inv_mass[ids] = base["inv_mass"] / s[:, None]
        self._inertia[ids] = base["inertia"] * s[:, None, None, None]
        self._inv_inertia[ids] = base["inv_inertia"] / s[:, None, None, None]
        # Every collision shape of the world, floor included: MuJoCo combines a pair's frictions with max().
        self._mu[ids[:, None], self._collider_shapes] = mu[:, None]
        with self.warp_scope():
            self._solver.notify_model_changed(
                newton.ModelFlags.MODEL_PROPERTIES
                | newton.ModelFlags.BODY_INERTIAL_PROPERTIES
                | newton.ModelFlags.SHAPE_PROPERTIES
            )
        self._check_graph()

    def set_trunk_force(self, world_ids: torch.Tensor, force: torch.Tensor) -> None:
        ids = self._ids(world_ids)
        values = force.to(self.device, torch.float32)
        if tuple(values.shape) != (ids.numel(), 3):
            raise SimulationError(f"trunk force must have shape {(ids.numel(), 3)}, got {tuple(values.shape)}")
        self._require(self._ids_valid(ids), "world ids out of range")
        self._body_f[ids, self._trunk, 0:3] = values

    def step(self) -> torch.Tensor:
        with self.warp_scope():
            if self._graph is not None:
                wp.capture_launch(self._graph)
            else:
                self._substeps()
        if self._graph is None and not self._eager_only:
            self._capture()
        with self.warp_scope():
            diverged = ~(
                (self._qpos.abs() <= _DIVERGENCE_LIMIT).all(dim=1) & (self._qvel.abs() <= _DIVERGENCE_LIMIT).all(dim=1)
            )
            # A diverged world's garbage may also overflow the buffers; it is restored, not reported as overflow.
            short = ((self._overflow_seen & _CAPACITY_BITS) != 0) & ~diverged
            overflowed, any_diverged = torch.stack([short.any(), diverged.any()]).tolist()
            if overflowed:
                raise SimulationError(self._overflow_message(short))
            self._read_contacts_and_feet(None)
            if any_diverged:
                self._restore(diverged)
        return diverged

    def state(self) -> SimState:
        qpos, qvel = self._qpos, self._qvel
        p, v = self._root_qpos, self._root_qvel
        return SimState(
            root_pos=qpos[:, p : p + 3].clone(),
            root_quat=qpos[:, p + 3 : p + 7].clone(),
            root_lin_vel=qvel[:, v : v + 3].clone(),
            root_ang_vel=qvel[:, v + 3 : v + 6].clone(),
            joint_pos=qpos[:, self._joint_qpos],
            joint_vel=qvel[:, self._joint_qvel],
            foot_contact=self._foot_contact.clone(),
            foot_pos=self._foot_pos.clone(),
            body_contact=self._body_contact.clone(),
            trunk_contact=self._trunk_contact.clone(),
        )

    def close(self) -> None:
        """Drop the Newton model, the solver and every buffer and view (only ``robot``, ``num_worlds`` and
        ``device`` are kept)."""
        for name in [name for name in self.__dict__ if name not in ("robot", "num_worlds", "device")]:
            del self.__dict__[name]

    # ----------------------------------------------------------------------------------------- internals
    def _substeps(self) -> None:
        """One control step's substeps and the OR of their overflow bits, on the current Warp device and stream."""
        for k in range(self.substeps):
            self._solver.step(self._state, self._state, self._control, None, self._dt, observables=self._observables)
            wp.launch(fold_overflow_kernel, dim=self.num_worlds,
                      inputs=[self._wp_overflow_seen, self._observables.overflow, int(k == 0)])

    def _capture(self) -> None:
        """Capture :meth:`_substeps` as one graph (kernels loaded by an eager step first); on CUDA on Warp's own
        stream, as torch's default stream cannot be captured, and replayed on torch's (see :meth:`warp_scope`)."""
        wp.synchronize_device(self._wp_device)
        try:
            with wp.ScopedDevice(self._wp_device), wp.ScopedCapture(force_module_load=False) as capture:
                self._substeps()
        except Exception:  # Warp raises several types where a capture is not possible: step eagerly
            self._eager_only = True
            return
        self._graph, self._addresses = capture.graph, self._arrays()

    def _arrays(self) -> tuple[int, ...]:
        return array_addresses(self._solver.mjw_model, self._solver.mjw_data, self._state, self._control,
                                self._observables, self._model)

    def _check_graph(self) -> None:
        """Drop the captured step where a model change moved an array it uses (it is captured again next step)."""
        if self._graph is not None and self._arrays() != self._addresses:
            self._graph = None

    @property
    def mujoco_warp(self) -> tuple:
        """The ``mujoco_warp`` (Model, Data) this backend steps, for references that step them without Newton or
        gaitlib work (``benchmarks/gpu_check.py``); Newton writes its state into the Data at each of its steps."""
        return self._solver.mjw_model, self._solver.mjw_data

    @property
    def warp_device(self):
        """The Warp device the backend runs on."""
        return self._wp_device

    def warp_scope(self) -> contextlib.ExitStack:
        """Warp's device and, on CUDA, torch's current stream, so Warp and torch work stays in order."""
        stack = contextlib.ExitStack()
        stack.enter_context(wp.ScopedDevice(self._wp_device))
        if self._wp_device.is_cuda:
            stack.enter_context(wp.ScopedStream(wp.stream_from_torch(torch.cuda.current_stream(self.device))))
        return stack

    def _ids(self, world_ids: torch.Tensor) -> torch.Tensor:
        return world_ids.to(self.device, torch.long).reshape(-1)

    def _ids_valid(self, ids: torch.Tensor) -> torch.Tensor:
        return ((ids >= 0) & (ids < self.num_worlds)).all()

    @staticmethod
    def _require(ok: torch.Tensor, message: str) -> None:
        if not bool(ok):
            raise SimulationError(message)

    def _restore(self, mask: torch.Tensor) -> None:
        """Put worlds ``mask`` (N,) into ``self._reset_state``: coordinates, targets, no force, cold solver."""
        s = self._reset_state
        rows = mask[:, None]
        pos, quat, lin, ang = s.root_pos, s.root_quat, s.root_lin_vel, s.root_ang_vel
        with self.warp_scope():
            # mujoco_warp's coordinates use the contract's conventions.
            p, v = self._root_qpos, self._root_qvel
            qpos, qvel = self._qpos.clone(), self._qvel.clone()
            qpos[:, p : p + 3], qpos[:, p + 3 : p + 7] = pos, quat
            qpos[:, self._joint_qpos] = s.joint_pos
            qvel[:, v : v + 3], qvel[:, v + 3 : v + 6] = lin, ang
            qvel[:, self._joint_qvel] = s.joint_vel
            self._qpos.copy_(torch.where(rows, qpos, self._qpos))
            self._qvel.copy_(torch.where(rows, qvel, self._qvel))
            # Newton's: quaternion w last; centre-of-mass velocity and angular velocity in the world frame.
            omega = quat_rotate(quat, ang)
            q, qd = self._joint_q.clone(), self._joint_qd.clone()
            r, rd = self._newton_root_q, self._newton_root_qd
            q[:, r : r + 3], q[:, r + 3 : r + 6], q[:, r + 6] = pos, quat[:, 1:], quat[:, 0]
            q[:, self._joint_coords] = s.joint_pos
            qd[:, rd : rd + 3] = lin + torch.linalg.cross(omega, quat_rotate(quat, self._trunk_com.expand_as(lin)))
            qd[:, rd + 3 : rd + 6] = omega
            qd[:, self._joint_dofs] = s.joint_vel
            self._joint_q.copy_(torch.where(rows, q, self._joint_q))
            self._joint_qd.copy_(torch.where(rows, qd, self._joint_qd))
            target = self._target_q.clone()
            target[:, self._target_coords] = s.joint_pos
            self._target_q.copy_(torch.where(rows, target, self._target_q))
            self._body_f[:, self._trunk] = torch.where(rows, 0.0, self._body_f[:, self._trunk])

            self._mask[: self.num_worlds] = mask
            # flags=0: keep our joint state, clear mujoco_warp's warm start, applied forces and controls there.
            self._solver.reset(self._state, world_mask=self._wp_world_mask, flags=0)
            newton.eval_fk(
                self._model, self._state.joint_q, self._state.joint_qd, self._state, mask=self._wp_articulation_mask
            )
            # Kinematics and collision at the new coordinates give these worlds' readings; the next step
            # recomputes both from qpos/qvel for every world, so the other worlds' physics is untouched.
            mujoco_warp.fwd_kinematics(self._solver.mjw_model, self._solver.mjw_data)
            mujoco_warp.collision(self._solver.mjw_model, self._solver.mjw_data)
            self._read_contacts_and_feet(mask)
        self._check_graph()  # the solver's reset and kinematics ran outside the graph

    def _read_contacts_and_feet(self, mask: torch.Tensor | None) -> None:
        """Copy foot, body and trunk contacts and foot positions from mujoco_warp's data (rows ``mask`` or all)."""
        data = self._solver.mjw_data
        self._wp_foot_contact.zero_()
        self._wp_body_contact.zero_()
        self._wp_trunk_contact.zero_()
        wp.launch(
            ground_contacts_kernel,
            dim=data.naconmax,
            inputs=[
                data.nacon,
                data.contact.worldid,
                data.contact.geom,
                data.contact.type,
                self._geom_role,
                self.robot.num_feet,
            ],
            outputs=[self._wp_foot_contact, self._wp_body_contact, self._wp_trunk_contact],
        )
        foot_contact = wp.to_torch(self._wp_foot_contact) != 0
        body_contact = wp.to_torch(self._wp_body_contact) != 0
        trunk_contact = wp.to_torch(self._wp_trunk_contact) != 0
        rot = self._xmat[:, self._foot_bodies]
        foot_pos = self._xpos[:, self._foot_bodies] + (rot @ self._foot_offsets[:, :, None]).squeeze(-1)
        if mask is None:
            self._foot_contact.copy_(foot_contact)
            self._body_contact.copy_(body_contact)
            self._trunk_contact.copy_(trunk_contact)
            self._foot_pos.copy_(foot_pos)
        else:
            self._foot_contact.copy_(torch.where(mask[:, None], foot_contact, self._foot_contact))
            self._body_contact.copy_(torch.where(mask, body_contact, self._body_contact))
            self._trunk_contact.copy_(torch.where(mask, trunk_contact, self._trunk_contact))
            self._foot_pos.copy_(torch.where(mask[:, None, None], foot_pos, self._foot_pos))

    def _overflow_message(self, short: torch.Tensor) -> str:
        bits = 0
        for value in self._overflow_seen[short].tolist():
            bits |= value
        names = [
            name
            for name, flag in mujoco_warp.OverflowType.__members__.items()
            if name != "ALL" and bits & int(flag) & _CAPACITY_BITS
        ]
        names += [flag.name for flag in SolverMuJoCo.OverflowBits if bits & int(flag)]
        return (
            f"mujoco_warp ran out of buffer capacity ({', '.join(names)}) in {int(short.sum())} world(s); "
            f"raise contacts_per_world (now {self._contacts_per_world})"
        )
