"""Another MJCF of the Unitree A1 as a robot gaitlib's ``mujoco`` backend drives: the stand-in for the real robot.

The paper's real-robot half runs the policies on a robot that is not their training simulator. gaitlib's stand-in
is another model of the A1, for example MuJoCo Menagerie's ``unitree_a1``
(github.com/google-deepmind/mujoco_menagerie, BSD-3, derived from Unitree's URDF). :func:`load_variant` reads such a
file with ``mujoco.MjSpec`` and adapts it in memory (nothing is written to disk):

* **kept**: bodies, masses and inertias, joints (damping, armature, friction loss, ranges), every collision geom
  with its contact settings (friction, ``solimp``/``solref`` softness, margins, ``condim``, which pairs collide),
  the friction cone and ``impratio``, gravity;
* **found**: the 12 joints by gaitlib's names (``FR_hip_joint`` ... ``RL_calf_joint``, in gaitlib's order); the
  trunk (the body of the free joint); the ground (the world's plane geom); each leg's foot (the sphere geom of the
  calf joint's subtree farthest from that joint), named ``<leg>_foot`` with a site ``<leg>_foot`` at its centre;
* **replaced**: the model's actuators by gaitlib's PD servo (:data:`gaitlib.robots.a1.constants` gains and
  torque limit, the control range the joint range, one ``<position>`` actuator per joint with ``kv`` = kd and
  ``forcerange``, as gaitlib's ``a1.xml``), its sensors and keyframes by the sensors the backend reads, its
  timestep by 1/240 s (8 substeps per 30 Hz control step: 0.002 s does not divide 1/30 s) with the
  ``implicitfast`` integrator (the servo's damping term is integrated implicitly, as on gaitlib's A1). Soft
  contacts keep their time constants, which MuJoCo bounds below by twice the timestep (1/120 s, below
  Menagerie's 0.02 s);
* **a fall** there is a ground contact of a geom that is neither a foot nor a *stance geom*: a non-foot geom of a
  leg's calf subtree that contains the foot sphere's centre (Menagerie's lower calf capsules end at it, and touch
  the ground in normal stance as the soft feet sink about 10 mm). On gaitlib's own A1 there is none.

Units SI.
"""

from __future__ import annotations

import copy
import functools
import hashlib
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from gaitlib.errors import SimulationError
from gaitlib.robots import RobotSpec
from gaitlib.robots.a1 import constants as a1

__all__ = ["INTEGRATOR", "load_variant", "model_sha256"]

INTEGRATOR = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
"""Integrator of an adapted model (gaitlib's A1 uses it too): the PD servo's ``kv`` damping is integrated
implicitly."""

_CONTACT_FOUND = (1, 0, 1)  # contact sensor intprm: data="found", no reduction, num=1 (as in gaitlib's a1.xml)


@dataclass(frozen=True)
class _Layout:
    """What the adapter found in a model, by compiled ids."""

    joints: tuple[int, ...]
    trunk: int
    floor: int
    feet: tuple[int, ...]
    stance: tuple[tuple[int, ...], ...]
    """Per leg, the stance geoms of its calf subtree."""
    foot_pos: tuple[tuple[float, float, float], ...]
    """Each foot sphere's centre in its body's frame, m."""


def model_sha256(path: Path | str) -> str:
    """SHA-256 of an MJCF file's bytes followed by those of every file it includes (recursively, in document
    order); for a file without ``<include>``, what ``sha256sum`` prints. Raises :class:`SimulationError` when a
    file cannot be read."""
    digest = hashlib.sha256()
    for part in _model_files(Path(path), Path(path).parent, depth=0):
        digest.update(part)
    return digest.hexdigest()


def _model_files(path: Path, root: Path, *, depth: int) -> list[bytes]:
    try:
        data = path.read_bytes()
    except OSError as error:
        raise SimulationError(f"cannot read robot model {path}: {error.strerror or error}") from None
    try:
        includes = [e.get("file", "") for e in ET.fromstring(data).iter("include")] if depth < 8 else []
    except ET.ParseError:
        includes = []  # MuJoCo reports the XML error when it reads the file
    parts = [data]
    for name in includes:
        parts += _model_files(root / name, root, depth=depth + 1)
    return parts


def load_variant(path: Path | str, *, motor_strength: float = 1.0) -> RobotSpec:
    """A :class:`RobotSpec` of the A1 MJCF at ``path``, adapted in memory (see the module doc): gaitlib's joint
    order, default pose, PD gains, torque limit and timing; the file's joint ranges; a standing height from its
    kinematics; its stance geoms. ``motor_strength`` scales the torque the motors deliver (see
    :attr:`RobotSpec.motor_strength`). Raises :class:`SimulationError` in one line naming what is missing."""
    path = Path(path)
    spec, layout = _adapt(path, torque_limit=a1.TORQUE_LIMIT)
    model = _compile(spec, path)
    ranges = model.jnt_range[list(layout.joints)]
    return RobotSpec(
        name=f"a1 ({path.name})",
        mjcf_path=path,
        joint_names=a1.JOINT_NAMES,
        foot_names=a1.FOOT_NAMES,
        trunk_body=model.body(layout.trunk).name,
        default_joint_pos=a1.DEFAULT_JOINT_POS,
        joint_lower=tuple(float(v) for v in ranges[:, 0]),
        joint_upper=tuple(float(v) for v in ranges[:, 1]),
        standing_height=_standing_height(model, layout),
        torque_limit=a1.TORQUE_LIMIT,
        kp_default=a1.KP_DEFAULT,
        kd_default=a1.KD_DEFAULT,
        control_hz=a1.CONTROL_HZ,
        substeps=a1.SUBSTEPS,
        build_model=functools.partial(copy.copy, model),
        stance_contact_geoms=tuple(model.geom(g).name for leg in layout.stance for g in leg),
        motor_strength=motor_strength,
    )


# ------------------------------------------------------------------------------------------------ finding
def _read(path: Path) -> mujoco.MjSpec:
    if not path.is_file():
        raise SimulationError(f"robot model {path} does not exist or is not a file")
    try:
        return mujoco.MjSpec.from_file(str(path))
    except ValueError as error:
        raise SimulationError(f"cannot read robot model {path}: {_first_line(error)}") from None


def _compile(spec: mujoco.MjSpec, path: Path) -> mujoco.MjModel:
    try:
        return spec.compile()
    except ValueError as error:
        raise SimulationError(f"cannot compile robot model {path}: {_first_line(error)}") from None


def _first_line(error: Exception) -> str:
    text = str(error).strip()
    return text.splitlines()[0] if text else "compile error"


def _find(model: mujoco.MjModel, path: Path) -> _Layout:
    """The joints, trunk, ground, feet and stance geoms of ``model`` (compiled from ``path``)."""
    joints, missing = [], []
    for name in a1.JOINT_NAMES:
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if jid < 0 or model.jnt_type[jid] != mujoco.mjtJoint.mjJNT_HINGE:
            missing.append(name)
        joints.append(jid)
    if missing:
        raise SimulationError(f"robot model {path} has no hinge joint {', '.join(missing)} (an A1 names its joints "
                              "FR_hip_joint ... RL_calf_joint)")
    free = np.flatnonzero(model.jnt_type == mujoco.mjtJoint.mjJNT_FREE)
    if len(free) != 1:
        raise SimulationError(f"robot model {path} has {len(free)} free joints; the A1's trunk needs exactly one")
    if model.nq != 19 or model.jnt_qposadr[free[0]] != 0 or list(model.jnt_qposadr[joints]) != list(range(7, 19)):
        raise SimulationError(f"robot model {path} has other joints than the A1's, or its joints in another order "
                              "than FR, FL, RR, RL x (hip, thigh, calf) after the trunk's free joint")
    plane = mujoco.mjtGeom.mjGEOM_PLANE
    planes = [g for g in range(model.ngeom) if model.geom_bodyid[g] == 0 and model.geom_type[g] == plane]
    if not planes:
        raise SimulationError(f"robot model {path} has no ground: a plane geom in the worldbody")
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    feet, stance = [], []
    for leg, name in zip(a1.LEG_NAMES, a1.JOINT_NAMES[2::3], strict=True):
        calf = joints[a1.JOINT_NAMES.index(name)]
        subtree = _subtree_geoms(model, int(model.jnt_bodyid[calf]))
        foot = _foot(model, data, calf, subtree)
        if foot is None:
            raise SimulationError(f"robot model {path} has no foot sphere below {name} (leg {leg})")
        feet.append(foot)
        stance.append(tuple(g for g in subtree if g != foot and _holds_foot_centre(model, data, g, foot, planes[0])))
    foot_pos = tuple(tuple(float(v) for v in model.geom_pos[g]) for g in feet)
    return _Layout(tuple(joints), int(model.jnt_bodyid[free[0]]), planes[0], tuple(feet), tuple(stance), foot_pos)


def _subtree_geoms(model: mujoco.MjModel, body: int) -> list[int]:
    """Geoms of ``body`` and its descendants."""
    bodies = {body}
    for b in range(body + 1, model.nbody):  # MuJoCo numbers a parent before its children
        if int(model.body_parentid[b]) in bodies:
            bodies.add(b)
    return [g for g in range(model.ngeom) if int(model.geom_bodyid[g]) in bodies]


def _foot(model: mujoco.MjModel, data: mujoco.MjData, joint: int, geoms: list[int]) -> int | None:
    """The sphere among ``geoms`` farthest from ``joint``'s axis point (the end of the calf chain)."""
    spheres = [g for g in geoms if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE]
    if not spheres:
        return None
    return max(spheres, key=lambda g: float(np.linalg.norm(data.geom_xpos[g] - data.xanchor[joint])))


def _holds_foot_centre(model: mujoco.MjModel, data: mujoco.MjData, geom: int, foot: int, floor: int) -> bool:
    """``geom`` can touch the ground and contains the centre of the sphere ``foot``: its surface is at most the
    foot's radius from the foot sphere's, inside it."""
    touches = (model.geom_contype[geom] & model.geom_conaffinity[floor]) or (
        model.geom_contype[floor] & model.geom_conaffinity[geom]
    )
    radius = float(model.geom_size[foot, 0])
    return bool(touches) and mujoco.mj_geomDistance(model, data, foot, geom, 1.0, None) <= -radius + 1e-9


# ------------------------------------------------------------------------------------------------ adapting
def _adapt(path: Path, *, torque_limit: float) -> tuple[mujoco.MjSpec, _Layout]:
    """The spec of ``path`` adapted in memory, and what was found in it (ids valid for the adapted model too:
    bodies, joints and geoms are neither added nor removed)."""
    spec = _read(path)
    layout = _find(_compile(spec, path), path)
    geoms = {g.id: g for g in spec.geoms}
    if not geoms[layout.floor].name:
        geoms[layout.floor].name = "floor"
    bodies = {b.id: b for b in spec.bodies}
    if not bodies[layout.trunk].name:
        bodies[layout.trunk].name = a1.TRUNK_BODY
    for leg, foot_name, foot, stance in zip(a1.LEG_NAMES, a1.FOOT_NAMES, layout.feet, layout.stance, strict=True):
        geoms[foot].name = foot_name
        for k, g in enumerate(stance):
            geoms[g].name = geoms[g].name or f"{leg}_calf_stance{k}"
    _replace_sites(spec, geoms, layout)
    _replace_actuators(spec, layout, torque_limit)
    _replace_sensors(spec, layout, floor=geoms[layout.floor].name, trunk=bodies[layout.trunk].name, geoms=geoms)
    for key in list(spec.keys):  # a keyframe's ctrl and qpos belong to the replaced actuators; gaitlib resets itself
        spec.delete(key)
    spec.option.timestep = 1.0 / (a1.CONTROL_HZ * a1.SUBSTEPS)
    spec.option.integrator = INTEGRATOR
    return spec, layout


def _replace_sites(spec: mujoco.MjSpec, geoms: dict, layout: _Layout) -> None:
    """One site ``<leg>_foot`` at each foot sphere's centre, in the foot's body (any older site of that name
    goes)."""
    for site in list(spec.sites):
        if site.name in a1.FOOT_NAMES:
            spec.delete(site)
    for name, foot, pos in zip(a1.FOOT_NAMES, layout.feet, layout.foot_pos, strict=True):
        geoms[foot].parent.add_site(name=name, pos=list(pos), size=[1.25 * a1.FOOT_RADIUS, 0, 0])


def _replace_actuators(spec: mujoco.MjSpec, layout: _Layout, torque_limit: float) -> None:
    """gaitlib's PD servo per joint, in gaitlib's order: a position actuator with kp, kv = kd and the torque
    limit as ``forcerange``, its control range the joint's range."""
    for actuator in list(spec.actuators):
        spec.delete(actuator)
    joints = {j.name: j for j in spec.joints}
    for name in a1.JOINT_NAMES:
        actuator = spec.add_actuator(name=name.removesuffix("_joint"), target=name)
        actuator.trntype = mujoco.mjtTrn.mjTRN_JOINT
        actuator.set_to_position(kp=a1.KP_DEFAULT, kv=a1.KD_DEFAULT)
        actuator.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        actuator.ctrlrange = joints[name].range
        actuator.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        actuator.forcerange = [-torque_limit, torque_limit]


def _replace_sensors(spec: mujoco.MjSpec, layout: _Layout, *, floor: str, trunk: str, geoms: dict) -> None:
    """The sensors the ``mujoco`` backend reads (as in gaitlib's ``a1.xml``), plus one contact sensor per stance
    geom; the model's own sensors go."""
    for sensor in list(spec.sensors):
        spec.delete(sensor)
    touch = mujoco.mjtSensor.mjSENS_CONTACT
    geom_obj = mujoco.mjtObj.mjOBJ_GEOM

    def contact(name: str, objtype: mujoco.mjtObj, objname: str) -> None:
        spec.add_sensor(name=name, type=touch, objtype=objtype, objname=objname, reftype=geom_obj, refname=floor,
                        intprm=list(_CONTACT_FOUND))

    for name in a1.FOOT_NAMES:
        contact(f"{name}_contact", geom_obj, name)
    contact("robot_contacts", mujoco.mjtObj.mjOBJ_XBODY, trunk)
    contact("trunk_contact", mujoco.mjtObj.mjOBJ_BODY, trunk)
    for g in (g for leg in layout.stance for g in leg):
        contact(f"{geoms[g].name}_contact", geom_obj, geoms[g].name)
    for name in a1.FOOT_NAMES:
        spec.add_sensor(name=f"{name}_pos", type=mujoco.mjtSensor.mjSENS_FRAMEPOS, objtype=mujoco.mjtObj.mjOBJ_SITE,
                        objname=name)


def _standing_height(model: mujoco.MjModel, layout: _Layout) -> float:
    """Trunk height, m, at which the default pose's lowest foot sphere just touches the ground (level trunk)."""
    data = mujoco.MjData(model)
    data.qpos[:7] = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)  # the free joint comes first (checked by _find)
    data.qpos[7:] = a1.DEFAULT_JOINT_POS
    mujoco.mj_kinematics(model, data)
    feet = list(layout.feet)
    return float(-(data.geom_xpos[feet, 2] - model.geom_size[feet, 0]).min())
