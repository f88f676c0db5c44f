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
"""

from __future__ import annotations

import contextlib
from typing import TYPE_CHECKING

import mujoco_warp
import newton
import torch
import warp as wp
from newton.solvers import SolverMuJoCo

from gaitlib.errors import SimulationError
from gaitlib.robots import RobotSpec
from gaitlib.sim.contract import KinematicState, SimBackend, SimState, standing_state
from gaitlib.sim.mujoco_backend import load_model

if TYPE_CHECKING:
    import mujoco

__all__ = ["NewtonBackend"]

wp.config.log_level = wp.LOG_WARNING  # Warp's init and module-load lines would mix into --json output

_DIVERGENCE_LIMIT = 1.0e4
"""A world whose |qpos| or |qvel| entry exceeds this (m, rad, m/s, rad/s) or is non-finite has diverged."""

_CAPACITY_BITS = (
    int(mujoco_warp.OverflowType.ALL)
    & ~int(mujoco_warp.OverflowType.ITERATIONS | mujoco_warp.OverflowType.LS_ITERATIONS)
) | int(SolverMuJoCo.OverflowBits.SOLVER_NCONMAX | SolverMuJoCo.OverflowBits.CONTACT_PIPELINE)
"""Overflow bits that mean lost contacts or constraints (solver iteration limits are not errors)."""

_ROLE_OTHER = wp.constant(-1)
"""Contact role of a geom that is neither the floor nor part of the robot."""
_ROLE_FLOOR = wp.constant(-2)
"""Contact role of the floor geom (feet are 0..F-1, other robot geoms F)."""


@wp.kernel
def _ground_contacts_kernel(
    nacon: wp.array[int],
    contact_world: wp.array[int],
    contact_geom: wp.array[wp.vec2i],
    contact_type: wp.array[int],
    geom_role: wp.array[wp.int32],
    num_feet: int,
    foot_contact: wp.array2d[wp.int32],
    body_contact: wp.array[wp.int32],
):
    """Flag floor contacts per world: role k < num_feet is foot k, role num_feet any other robot geom."""
    i = wp.tid()
    if i >= nacon[0]:
        return
    if (contact_type[i] & 1) == 0:  # not a constraint contact
        return
    g = contact_geom[i]
    if g[0] < 0 or g[1] < 0:
        return
    role0 = geom_role[g[0]]
    role1 = geom_role[g[1]]
    other = int(_ROLE_OTHER)
    if role0 == _ROLE_FLOOR:
        other = role1
    elif role1 == _ROLE_FLOOR:
        other = role0
    world = contact_world[i]
    if other >= 0 and other < num_feet:
        foot_contact[world, other] = 1
    elif other == num_feet:
        body_contact[world] = 1


class NewtonBackend(SimBackend):
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
        self.device, self._wp_device = _resolve_device(device)
        self._contacts_per_world = contacts_per_world
        mj = load_model(robot)  # the MJCF as MuJoCo C compiles it: checks it and gives the solver options
        self._dt = float(mj.opt.timestep)
        with wp.ScopedDevice(self._wp_device):
            self._build(robot, mj)
        self.reset(torch.arange(num_worlds, device=self.device), standing_state(robot, num_worlds, device=self.device))

    # ----------------------------------------------------------------------------------------- construction
    def _build(self, robot: RobotSpec, mj: mujoco.MjModel) -> None:
        template = newton.ModelBuilder()
        template.rigid_gap = 0.0  # MuJoCo's default geom gap; Newton's own default (0.1 m) is not in the MJCF
        SolverMuJoCo.register_custom_attributes(template)
        try:
            template.add_mjcf(str(robot.mjcf_path))
        except (ValueError, KeyError) as error:
            raise SimulationError(f"Newton cannot import {robot.mjcf_path}: {error}") from error

        joints = [_find(template.joint_label, name, "joint") for name in robot.joint_names]
        for j in joints:
            dof = template.joint_qd_start[j]
            if template.joint_target_mode[dof] != int(newton.JointTargetMode.POSITION):
                raise SimulationError(f"joint '{template.joint_label[j]}' has no <position> actuator")
            template.joint_target_ke[dof] = robot.kp_default
            template.joint_target_kd[dof] = robot.kd_default
            template.joint_effort_limit[dof] = robot.torque_limit
        trunk = _find(template.body_label, robot.trunk_body, "body")
        root = [j for j, child in enumerate(template.joint_child) if child == trunk]
        if len(root) != 1 or template.joint_type[root[0]] != newton.JointType.FREE:
            raise SimulationError(f"body '{robot.trunk_body}' must hang from a free joint")
        site = int(newton.ShapeFlags.SITE)
        geoms = [s for s, flags in enumerate(template.shape_flags) if not flags & site]
        sites = [s for s, flags in enumerate(template.shape_flags) if flags & site]
        floor = _find(template.shape_label, "floor", "geom", among=geoms)
        foot_geoms = [_find(template.shape_label, f, "geom", among=geoms) for f in robot.foot_names]
        foot_sites = [_find(template.shape_label, f, "site", among=sites) for f in robot.foot_names]

        builder = newton.ModelBuilder()
        SolverMuJoCo.register_custom_attributes(builder)
        builder.replicate(template, self.num_worlds)
        model = builder.finalize()
        if model.articulation_count != self.num_worlds:
            raise SimulationError(f"the robot model must be one articulation, found {model.articulation_count}")
        self._model = model
        self._state = model.state()
        self._control = model.control()

        rows_per_contact = max(1, 2 * (int(mj.geom_condim.max()) - 1))  # pyramidal cone; elliptic needs fewer
        self._solver = SolverMuJoCo(
            model,
            separate_worlds=True,
            nconmax=self._contacts_per_world,
            njmax=self._contacts_per_world * rows_per_contact + 2 * mj.nv,  # + friction loss and limit rows
            integrator=int(mj.opt.integrator),
            cone=int(mj.opt.cone),
            solver=int(mj.opt.solver),
            iterations=int(mj.opt.iterations),
            ls_iterations=int(mj.opt.ls_iterations),
            tolerance=float(mj.opt.tolerance),
            ls_tolerance=float(mj.opt.ls_tolerance),
            impratio=float(mj.opt.impratio),
            kinematic_switchable_roots=False,
        )
        solver = self._solver
        self._observables = solver.observables({SolverMuJoCo.ObservableKind.OVERFLOW})

        # Template-world index maps: MuJoCo entity -> Newton entity (world 0 holds the template's indices).
        body_of_mj = solver.mjc_body_to_newton.numpy()[0].tolist()
        joint_of_mj = solver.mjc_jnt_to_newton_jnt.numpy()[0].tolist()
        shape_of_mj = solver.mjc_geom_to_newton_shape.numpy()[0].tolist()
        mj_model = solver.mj_model
        mj_joints = [joint_of_mj.index(j) for j in joints]
        mj_root = joint_of_mj.index(root[0])
        self._root_qpos = int(mj_model.jnt_qposadr[mj_root])
        self._root_qvel = int(mj_model.jnt_dofadr[mj_root])
        self._joint_qpos = self._long([mj_model.jnt_qposadr[j] for j in mj_joints])
        self._joint_qvel = self._long([mj_model.jnt_dofadr[j] for j in mj_joints])
        self._foot_bodies = self._long([body_of_mj.index(template.shape_body[s]) for s in foot_sites])
        self._foot_offsets = torch.tensor(
            [list(template.shape_transform[s])[:3] for s in foot_sites], dtype=torch.float32, device=self.device
        )
        roles = []
        for shape in shape_of_mj:
            if shape == floor:
                roles.append(_ROLE_FLOOR)
            elif shape in foot_geoms:
                roles.append(foot_geoms.index(shape))
            else:
                roles.append(robot.num_feet if template.shape_body[shape] >= 0 else _ROLE_OTHER)
        self._geom_role = wp.array(roles, dtype=wp.int32)

        # Newton-side layout of one world.
        n = self.num_worlds
        self._newton_root_q = template.joint_q_start[root[0]]
        self._newton_root_qd = template.joint_qd_start[root[0]]
        self._joint_coords = self._long([template.joint_q_start[j] for j in joints])
        self._joint_dofs = self._long([template.joint_qd_start[j] for j in joints])
        target_start = model.joint_target_q_start.numpy()
        self._target_coords = self._long([target_start[j] for j in joints])
        self._trunk = trunk
        self._collider_shapes = self._long(geoms)

        # Zero-copy torch views of the Warp arrays this backend writes or reads, one row per world.
        self._joint_q = wp.to_torch(self._state.joint_q).view(n, -1)
        self._joint_qd = wp.to_torch(self._state.joint_qd).view(n, -1)
        self._body_f = wp.to_torch(self._state.body_f).view(n, -1, 6)
        self._target_q = wp.to_torch(self._control.joint_target_q).view(n, -1)
        self._ke = wp.to_torch(model.joint_target_ke).view(n, -1)
        self._kd = wp.to_torch(model.joint_target_kd).view(n, -1)
        self._gravity = wp.to_torch(model.gravity)[:n]
        self._mass = wp.to_torch(model.body_mass).view(n, -1)
        self._inv_mass = wp.to_torch(model.body_inv_mass).view(n, -1)
        self._inertia = wp.to_torch(model.body_inertia).view(n, -1, 3, 3)
        self._inv_inertia = wp.to_torch(model.body_inv_inertia).view(n, -1, 3, 3)
        # MuJoCo's compiler puts a massless body's inertial frame (the feet here) at the body's offset from its
        # parent, Newton at the body origin; it sets the body's inverse weight, hence its contacts' softness.
        # Newton pushes body_com into MuJoCo on inertia updates, so give it MuJoCo's frames.
        mj_bodies = [b for b, newton_body in enumerate(body_of_mj) if newton_body >= 0]
        body_com = wp.to_torch(model.body_com).view(n, -1, 3)
        body_com[:, self._long(body_of_mj[b] for b in mj_bodies)] = torch.tensor(
            mj_model.body_ipos[mj_bodies], dtype=torch.float32, device=self.device
        )
        self._trunk_com = body_com[0, trunk].clone()  # Newton's free-joint velocity is that of this point
        self._mu = wp.to_torch(model.shape_material_mu).view(n, -1)
        data = solver.mjw_data
        self._qpos = wp.to_torch(data.qpos)
        self._qvel = wp.to_torch(data.qvel)
        self._xpos = wp.to_torch(data.xpos)
        self._xmat = wp.to_torch(data.xmat)
        self._overflow = wp.to_torch(self._observables.overflow)
        self._overflow_seen = torch.zeros_like(self._overflow)
        self._base = {
            name: view[0].clone()
            for name, view in (
                ("gravity", self._gravity),
                ("mass", self._mass),
                ("inv_mass", self._inv_mass),
                ("inertia", self._inertia),
                ("inv_inertia", self._inv_inertia),
            )
        }

        # World masks shared with Warp: (N + 1,) for SolverMuJoCo.reset (last entry: global world), (N,) for FK.
        self._mask = torch.zeros(n + 1, dtype=torch.bool, device=self.device)
        self._wp_world_mask = wp.from_torch(self._mask, dtype=wp.bool)
        self._wp_articulation_mask = wp.from_torch(self._mask[:n], dtype=wp.bool)

        # Readings (N rows) and the contact-flag scratch the kernel writes.
        nf = self.robot.num_feet
        self._wp_foot_contact = wp.zeros((n, nf), dtype=wp.int32)
        self._wp_body_contact = wp.zeros(n, dtype=wp.int32)
        self._foot_contact = torch.zeros(n, nf, dtype=torch.bool, device=self.device)
        self._body_contact = torch.zeros(n, dtype=torch.bool, device=self.device)
        self._foot_pos = torch.zeros(n, nf, 3, device=self.device)
        self._reset_state = standing_state(self.robot, n, device=self.device)

        # Recompute every derived MuJoCo constant once with mujoco_warp's own kernels, as later per-world edits
        # will: worlds an edit leaves alone then keep bit-identical constants.
        solver.notify_model_changed(
            newton.ModelFlags.MODEL_PROPERTIES
            | newton.ModelFlags.BODY_INERTIAL_PROPERTIES
            | newton.ModelFlags.SHAPE_PROPERTIES
            | newton.ModelFlags.JOINT_DOF_FORCE_PROPERTIES
        )
        wp.synchronize_device(self._wp_device)  # later work runs on torch's stream (see _scope)

    def _long(self, values) -> torch.Tensor:
        return torch.tensor([int(v) for v in values], dtype=torch.long, device=self.device)

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
        with self._scope():
            self._solver.notify_model_changed(newton.ModelFlags.JOINT_DOF_FORCE_PROPERTIES)

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
        with self._scope():
            self._solver.notify_model_changed(
                newton.ModelFlags.MODEL_PROPERTIES
                | newton.ModelFlags.BODY_INERTIAL_PROPERTIES
                | newton.ModelFlags.SHAPE_PROPERTIES
            )

    def set_trunk_force(self, world_ids: torch.Tensor, force: torch.Tensor) -> None:
        ids = self._ids(world_ids)
        values = force.to(self.device, torch.float32)
        if tuple(values.shape) != (ids.numel(), 3):
            raise SimulationError(f"trunk force must have shape {(ids.numel(), 3)}, got {tuple(values.shape)}")
        self._require(self._ids_valid(ids), "world ids out of range")
        self._body_f[ids, self._trunk, 0:3] = values

    def step(self) -> torch.Tensor:
        with self._scope():
            self._overflow_seen.zero_()
            for _ in range(self.substeps):
                self._solver.step(
                    self._state, self._state, self._control, None, self._dt, observables=self._observables
                )
                self._overflow_seen |= self._overflow
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
        )

    def close(self) -> None:
        """Drop the Newton model, the solver and every buffer and view (only ``robot``, ``num_worlds`` and
        ``device`` are kept)."""
        for name in [name for name in self.__dict__ if name not in ("robot", "num_worlds", "device")]:
            del self.__dict__[name]

    # ----------------------------------------------------------------------------------------- internals
    def _scope(self) -> contextlib.ExitStack:
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
        with self._scope():
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
            omega = _rotate(quat, ang)
            q, qd = self._joint_q.clone(), self._joint_qd.clone()
            r, rd = self._newton_root_q, self._newton_root_qd
            q[:, r : r + 3], q[:, r + 3 : r + 6], q[:, r + 6] = pos, quat[:, 1:], quat[:, 0]
            q[:, self._joint_coords] = s.joint_pos
            qd[:, rd : rd + 3] = lin + torch.linalg.cross(omega, _rotate(quat, self._trunk_com.expand_as(lin)))
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

    def _read_contacts_and_feet(self, mask: torch.Tensor | None) -> None:
        """Copy foot contacts, body contacts and foot positions from mujoco_warp's data (rows ``mask`` or all)."""
        data = self._solver.mjw_data
        self._wp_foot_contact.zero_()
        self._wp_body_contact.zero_()
        wp.launch(
            _ground_contacts_kernel,
            dim=data.naconmax,
            inputs=[
                data.nacon,
                data.contact.worldid,
                data.contact.geom,
                data.contact.type,
                self._geom_role,
                self.robot.num_feet,
            ],
            outputs=[self._wp_foot_contact, self._wp_body_contact],
        )
        foot_contact = wp.to_torch(self._wp_foot_contact) != 0
        body_contact = wp.to_torch(self._wp_body_contact) != 0
        rot = self._xmat[:, self._foot_bodies]
        foot_pos = self._xpos[:, self._foot_bodies] + (rot @ self._foot_offsets[:, :, None]).squeeze(-1)
        if mask is None:
            self._foot_contact.copy_(foot_contact)
            self._body_contact.copy_(body_contact)
            self._foot_pos.copy_(foot_pos)
        else:
            self._foot_contact.copy_(torch.where(mask[:, None], foot_contact, self._foot_contact))
            self._body_contact.copy_(torch.where(mask, body_contact, self._body_contact))
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


def _resolve_device(device: str | None) -> tuple[torch.device, wp.Device]:
    """Map a torch device string (``None``: ``cuda:0`` when CUDA is usable, else ``cpu``) to torch and Warp."""
    if device is None:
        device = "cuda:0" if torch.cuda.is_available() and wp.is_cuda_available() else "cpu"
    torch_device = torch.device(device)
    if torch_device.type == "cpu":
        return torch_device, wp.get_device("cpu")
    if torch_device.type != "cuda":
        raise SimulationError(f"the newton backend runs on 'cpu' or 'cuda', not on '{device}'")
    if not (torch.cuda.is_available() and wp.is_cuda_available()):
        raise SimulationError(f"device '{device}' requested but CUDA is not available to both torch and Warp")
    index = torch_device.index if torch_device.index is not None else torch.cuda.current_device()
    return torch.device("cuda", index), wp.get_device(f"cuda:{index}")


def _find(labels: list[str], name: str, what: str, *, among: list[int] | None = None) -> int:
    """Index of the one entry whose label's last path component is ``name`` (``among``: candidate indices)."""
    candidates = range(len(labels)) if among is None else among
    hits = [i for i in candidates if labels[i].rsplit("/", 1)[-1] == name]
    if len(hits) != 1:
        raise SimulationError(f"the robot model needs exactly one {what} named '{name}', found {len(hits)}")
    return hits[0]


def _rotate(quat: torch.Tensor, vec: torch.Tensor) -> torch.Tensor:
    """Rotate ``vec`` (k, 3) by unit quaternions ``quat`` (k, 4), (w, x, y, z)."""
    w, xyz = quat[:, :1], quat[:, 1:]
    t = 2.0 * torch.linalg.cross(xyz, vec)
    return vec + w * t + torch.linalg.cross(xyz, t)
