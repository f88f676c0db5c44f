"""Building the ``newton`` backend's model: the robot MJCF parsed into a :class:`newton.ModelBuilder` template (its
joints, trunk, floor and feet found by name), the mujoco_warp solver configured from the MJCF's own options, the
per-geom contact roles and the kernel that turns mujoco_warp's contacts into foot and body contact flags.

Newton 1.8 facts relied on here are listed in :mod:`gaitlib.sim.newton_backend`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import newton
import torch
import warp as wp
from newton.solvers import SolverMuJoCo

from gaitlib.errors import SimulationError
from gaitlib.robots import RobotSpec
from gaitlib.sim.contract import standing_state

if TYPE_CHECKING:
    import mujoco

__all__ = [
    "NewtonConstruction",
    "RobotTemplate",
    "array_addresses",
    "find",
    "fold_overflow_kernel",
    "geom_roles",
    "ground_contacts_kernel",
    "make_solver",
    "parse_template",
    "resolve_device",
]

_ROLE_OTHER = wp.constant(-1)
"""Contact role of a geom that is neither the floor nor part of the robot."""
_ROLE_FLOOR = wp.constant(-2)
"""Contact role of the floor geom (feet are 0..F-1, the legs' other geoms F, the trunk's F + 1)."""


@wp.kernel
def fold_overflow_kernel(seen: wp.array(dtype=wp.int32), flags: wp.array(dtype=wp.int32), first: int):
    """``seen`` = the OR of every substep's per-world overflow bits ``flags`` (the first substep's replaces it)."""
    i = wp.tid()
    if first != 0:
        seen[i] = flags[i]
    else:
        seen[i] = seen[i] | flags[i]


def array_addresses(*owners) -> tuple[int, ...]:
    """The address of every Warp array held by ``owners`` and by the structs they hold (one level down)."""
    found = []
    for owner in owners:
        for value in vars(owner).values():
            if isinstance(value, wp.array):
                found.append(value.ptr or 0)
            elif hasattr(value, "__dict__") and not callable(value):
                found += [v.ptr or 0 for v in vars(value).values() if isinstance(v, wp.array)]
    return tuple(found)


@wp.kernel
def ground_contacts_kernel(
    nacon: wp.array[int],
    contact_world: wp.array[int],
    contact_geom: wp.array[wp.vec2i],
    contact_type: wp.array[int],
    geom_role: wp.array[wp.int32],
    num_feet: int,
    foot_contact: wp.array2d[wp.int32],
    body_contact: wp.array[wp.int32],
    trunk_contact: wp.array[wp.int32],
):
    """Flag floor contacts per world: role k < num_feet is foot k, role num_feet a leg's other geom, role
    num_feet + 1 a trunk geom (a body contact too)."""
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
    elif other == num_feet + 1:
        body_contact[world] = 1
        trunk_contact[world] = 1


@dataclass(frozen=True)
class RobotTemplate:
    """One world's robot as Newton parsed it, with the entities the backend drives (Newton indices)."""

    builder: newton.ModelBuilder
    joints: list[int]
    """Actuated joints, in the robot's joint order."""
    root: int
    """The trunk's free joint."""
    trunk: int
    """The trunk body."""
    geoms: list[int]
    """Every collision shape (sites excluded)."""
    floor: int
    foot_geoms: list[int]
    foot_sites: list[int]


def parse_template(robot: RobotSpec) -> RobotTemplate:
    """Parse ``robot``'s MJCF, set its PD gains and torque limits, and find its joints, trunk, floor and feet."""
    template = newton.ModelBuilder()
    template.rigid_gap = 0.0  # MuJoCo's default geom gap; Newton's own default (0.1 m) is not in the MJCF
    SolverMuJoCo.register_custom_attributes(template)
    try:
        template.add_mjcf(str(robot.mjcf_path))
    except (ValueError, KeyError) as error:
        raise SimulationError(f"Newton cannot import {robot.mjcf_path}: {error}") from error

    joints = [find(template.joint_label, name, "joint") for name in robot.joint_names]
    for j in joints:
        dof = template.joint_qd_start[j]
        if template.joint_target_mode[dof] != int(newton.JointTargetMode.POSITION):
            raise SimulationError(f"joint '{template.joint_label[j]}' has no <position> actuator")
        template.joint_target_ke[dof] = robot.kp_default
        template.joint_target_kd[dof] = robot.kd_default
        template.joint_effort_limit[dof] = robot.torque_limit
    trunk = find(template.body_label, robot.trunk_body, "body")
    root = [j for j, child in enumerate(template.joint_child) if child == trunk]
    if len(root) != 1 or template.joint_type[root[0]] != newton.JointType.FREE:
        raise SimulationError(f"body '{robot.trunk_body}' must hang from a free joint")
    site = int(newton.ShapeFlags.SITE)
    geoms = [s for s, flags in enumerate(template.shape_flags) if not flags & site]
    sites = [s for s, flags in enumerate(template.shape_flags) if flags & site]
    return RobotTemplate(
        builder=template,
        joints=joints,
        root=root[0],
        trunk=trunk,
        geoms=geoms,
        floor=find(template.shape_label, "floor", "geom", among=geoms),
        foot_geoms=[find(template.shape_label, f, "geom", among=geoms) for f in robot.foot_names],
        foot_sites=[find(template.shape_label, f, "site", among=sites) for f in robot.foot_names],
    )


def make_solver(model: newton.Model, mj: mujoco.MjModel, contacts_per_world: int) -> SolverMuJoCo:
    """``SolverMuJoCo`` on separate worlds with the MJCF's solver options (``mj``: the MJCF as MuJoCo compiles it)
    and buffers for ``contacts_per_world`` contacts per world."""
    rows_per_contact = max(1, 2 * (int(mj.geom_condim.max()) - 1))  # pyramidal cone; elliptic needs fewer
    return SolverMuJoCo(
        model,
        separate_worlds=True,
        nconmax=contacts_per_world,
        njmax=contacts_per_world * rows_per_contact + 2 * mj.nv,  # + friction loss and limit rows
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


def geom_roles(template: RobotTemplate, shape_of_mj: list[int], num_feet: int) -> wp.array:
    """The contact role of each MuJoCo geom of a world (see :func:`ground_contacts_kernel`)."""
    roles = []
    for shape in shape_of_mj:
        if shape == template.floor:
            roles.append(_ROLE_FLOOR)
        elif shape in template.foot_geoms:
            roles.append(template.foot_geoms.index(shape))
        else:
            body = template.builder.shape_body[shape]
            roles.append(_ROLE_OTHER if body < 0 else num_feet + 1 if body == template.trunk else num_feet)
    return wp.array(roles, dtype=wp.int32)


class NewtonConstruction:
    """The construction half of :class:`~gaitlib.sim.newton_backend.NewtonBackend`: builds the batched model, the
    solver, the index maps and the torch views the commands use. Expects ``robot``, ``num_worlds``, ``device``,
    ``_wp_device`` and ``_contacts_per_world`` to be set before :meth:`_build` runs."""

    robot: RobotSpec
    num_worlds: int
    device: torch.device
    _wp_device: wp.Device
    _contacts_per_world: int

    def _build(self, robot: RobotSpec, mj: mujoco.MjModel) -> None:
        template = parse_template(robot)
        builder = newton.ModelBuilder()
        SolverMuJoCo.register_custom_attributes(builder)
        builder.replicate(template.builder, self.num_worlds)
        model = builder.finalize()
        if model.articulation_count != self.num_worlds:
            raise SimulationError(f"the robot model must be one articulation, found {model.articulation_count}")
        self._model = model
        self._state = model.state()
        self._control = model.control()
        self._solver = make_solver(model, mj, self._contacts_per_world)
        self._observables = self._solver.observables({SolverMuJoCo.ObservableKind.OVERFLOW})
        self._map_entities(template)
        self._bind_views()
        self._take_mujoco_inertial_frames()
        self._allocate_readings()
        # Recompute every derived MuJoCo constant once with mujoco_warp's own kernels, as later per-world edits
        # will: worlds an edit leaves alone then keep bit-identical constants.
        self._solver.notify_model_changed(
            newton.ModelFlags.MODEL_PROPERTIES
            | newton.ModelFlags.BODY_INERTIAL_PROPERTIES
            | newton.ModelFlags.SHAPE_PROPERTIES
            | newton.ModelFlags.JOINT_DOF_FORCE_PROPERTIES
        )
        wp.synchronize_device(self._wp_device)  # later work runs on torch's stream (see warp_scope)

    def _map_entities(self, template: RobotTemplate) -> None:
        """Indices of the driven joints, trunk, feet and geoms in mujoco_warp's and in Newton's per-world layout."""
        t, solver = template.builder, self._solver
        # Template-world index maps: MuJoCo entity -> Newton entity (world 0 holds the template's indices).
        self._body_of_mj = solver.mjc_body_to_newton.numpy()[0].tolist()
        joint_of_mj = solver.mjc_jnt_to_newton_jnt.numpy()[0].tolist()
        shape_of_mj = solver.mjc_geom_to_newton_shape.numpy()[0].tolist()
        mj_model = solver.mj_model
        mj_joints = [joint_of_mj.index(j) for j in template.joints]
        mj_root = joint_of_mj.index(template.root)
        self._root_qpos = int(mj_model.jnt_qposadr[mj_root])
        self._root_qvel = int(mj_model.jnt_dofadr[mj_root])
        self._joint_qpos = self._long([mj_model.jnt_qposadr[j] for j in mj_joints])
        self._joint_qvel = self._long([mj_model.jnt_dofadr[j] for j in mj_joints])
        self._foot_bodies = self._long([self._body_of_mj.index(t.shape_body[s]) for s in template.foot_sites])
        self._foot_offsets = torch.tensor(
            [list(t.shape_transform[s])[:3] for s in template.foot_sites], dtype=torch.float32, device=self.device
        )
        self._geom_role = geom_roles(template, shape_of_mj, self.robot.num_feet)
        # Newton-side layout of one world.
        self._newton_root_q = t.joint_q_start[template.root]
        self._newton_root_qd = t.joint_qd_start[template.root]
        self._joint_coords = self._long([t.joint_q_start[j] for j in template.joints])
        self._joint_dofs = self._long([t.joint_qd_start[j] for j in template.joints])
        target_start = self._model.joint_target_q_start.numpy()
        self._target_coords = self._long([target_start[j] for j in template.joints])
        self._trunk = template.trunk
        self._collider_shapes = self._long(template.geoms)

    def _bind_views(self) -> None:
        """Zero-copy torch views of the Warp arrays this backend writes or reads, one row per world."""
        n, model, data = self.num_worlds, self._model, self._solver.mjw_data
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
        self._mu = wp.to_torch(model.shape_material_mu).view(n, -1)
        self._qpos = wp.to_torch(data.qpos)
        self._qvel = wp.to_torch(data.qvel)
        self._xpos = wp.to_torch(data.xpos)
        self._xmat = wp.to_torch(data.xmat)
        self._overflow = wp.to_torch(self._observables.overflow)
        self._wp_overflow_seen = wp.zeros_like(self._observables.overflow)
        self._overflow_seen = wp.to_torch(self._wp_overflow_seen)

    def _take_mujoco_inertial_frames(self) -> None:
        """MuJoCo's compiler puts a massless body's inertial frame (the feet here) at the body's offset from its
        parent, Newton at the body origin; it sets the body's inverse weight, hence its contacts' softness. Newton
        pushes body_com into MuJoCo on inertia updates, so give it MuJoCo's frames (then record the nominal
        per-world properties that set_dynamics scales)."""
        body_of_mj, mj_model = self._body_of_mj, self._solver.mj_model
        mj_bodies = [b for b, newton_body in enumerate(body_of_mj) if newton_body >= 0]
        body_com = wp.to_torch(self._model.body_com).view(self.num_worlds, -1, 3)
        body_com[:, self._long(body_of_mj[b] for b in mj_bodies)] = torch.tensor(
            mj_model.body_ipos[mj_bodies], dtype=torch.float32, device=self.device
        )
        self._trunk_com = body_com[0, self._trunk].clone()  # Newton's free-joint velocity is that of this point
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

    def _allocate_readings(self) -> None:
        """World masks shared with Warp, readings (N rows) and the contact-flag scratch the kernel writes."""
        n, nf = self.num_worlds, self.robot.num_feet
        # (N + 1,) for SolverMuJoCo.reset (last entry: global world), (N,) for FK.
        self._mask = torch.zeros(n + 1, dtype=torch.bool, device=self.device)
        self._wp_world_mask = wp.from_torch(self._mask, dtype=wp.bool)
        self._wp_articulation_mask = wp.from_torch(self._mask[:n], dtype=wp.bool)
        self._wp_foot_contact = wp.zeros((n, nf), dtype=wp.int32)
        self._wp_body_contact = wp.zeros(n, dtype=wp.int32)
        self._wp_trunk_contact = wp.zeros(n, dtype=wp.int32)
        self._foot_contact = torch.zeros(n, nf, dtype=torch.bool, device=self.device)
        self._body_contact = torch.zeros(n, dtype=torch.bool, device=self.device)
        self._trunk_contact = torch.zeros(n, dtype=torch.bool, device=self.device)
        self._foot_pos = torch.zeros(n, nf, 3, device=self.device)
        self._reset_state = standing_state(self.robot, n, device=self.device)

    def _long(self, values) -> torch.Tensor:
        return torch.tensor([int(v) for v in values], dtype=torch.long, device=self.device)


def resolve_device(device: str | None) -> tuple[torch.device, wp.Device]:
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


def find(labels: list[str], name: str, what: str, *, among: list[int] | None = None) -> int:
    """Index of the one entry whose label's last path component is ``name`` (``among``: candidate indices)."""
    candidates = range(len(labels)) if among is None else among
    hits = [i for i in candidates if labels[i].rsplit("/", 1)[-1] == name]
    if len(hits) != 1:
        raise SimulationError(f"the robot model needs exactly one {what} named '{name}', found {len(hits)}")
    return hits[0]
