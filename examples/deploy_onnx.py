"""Run a gaitlib policy in a plain MuJoCo loop from its library entry alone (policy.onnx and metadata.json).

Only MuJoCo, onnxruntime and numpy: every fact comes from the entry's ``deployment`` block (docs/deploying.md).
Usage: python examples/deploy_onnx.py MODEL.xml library/trot [SECONDS]
"""

import json
import sys
from pathlib import Path

import mujoco
import numpy as np
import onnxruntime

__all__ = ["deploy"]


def deploy(m: mujoco.MjModel, d: mujoco.MjData, entry: Path, seconds: float, start_phase: float = 0.0):
    """Drive the robot of ``m`` from the state in ``d`` and the reference from ``start_phase``; yields (observation,
    action) before each control step. Each target is applied at once: a delay of 0 steps, in the trained range."""
    dep = json.loads((Path(entry) / "metadata.json").read_text())["deployment"]
    robot, ctl, obs, ref, act = (dep[k] for k in ("robot", "control", "observation", "reference", "action"))
    joints = [m.joint(name) for name in robot["joint_names"]]
    q, servo = [j.qposadr[0] for j in joints], [list(m.actuator_trnid[:, 0]).index(j.id) for j in joints]
    m.opt.timestep = ctl["physics_timestep_s"]  # the PD servo: tau = clip(kp (target - q) - kd qdot, +/- limit)
    m.actuator_biastype[servo], m.actuator_forcelimited[servo] = mujoco.mjtBias.mjBIAS_AFFINE, 1
    m.actuator_gainprm[servo, 0], m.actuator_biasprm[servo, :3] = ctl["kp"], [0.0, -ctl["kp"], -ctl["kd"]]
    m.actuator_forcerange[servo] = [-ctl["torque_limit"], ctl["torque_limit"]]
    feet = [m.geom(name).id for name in robot["foot_names"]]
    ground = np.flatnonzero(m.geom_type == mujoco.mjtGeom.mjGEOM_PLANE)
    width, last, step = len(ref["rows"][0]), len(ref["rows"]) - 1, ref["phase_per_step"]
    rows = np.column_stack([ref["rows"], ref.get("yaw", np.zeros(last + 1))])  # last column: the reference's yaw
    joint_cols = next(slice(c["start"], c["start"] + c["size"]) for c in ref["columns"] if c["name"] == "joint_pos")

    def yaw(quat: np.ndarray) -> float:  # rotation about world z of a (w, x, y, z) quaternion, rad
        return np.arctan2(2 * (quat[0] * quat[3] + quat[1] * quat[2]), 1 - 2 * (quat[2] ** 2 + quat[3] ** 2))

    turn = ref.get("cycle_yaw", {"value": 0.0})["value"]  # how far a turning reference turns per cycle, rad

    def row(phase: float) -> np.ndarray:  # the reference at a phase, linearly interpolated
        x = (phase % 1.0 if ref["loop"] else min(max(phase, 0.0), 1.0)) * last
        i = min(int(x), last - 1)
        return rows[i] + (x - i) * (rows[i + 1] - rows[i])

    def reference_yaw(phase: float) -> float:  # the yaw column, plus the turns of the cycles before
        return row(phase)[width] + turn * np.floor(phase)

    policy = onnxruntime.InferenceSession(str(Path(entry) / "policy.onnx"))
    action, phase, history, rot = np.zeros(len(q)), start_phase, [], np.zeros(9)
    anchor = yaw(d.qpos[3:7]) - reference_yaw(start_phase)  # the reference faces the robot's heading at the start
    mujoco.mj_forward(m, d)
    for _ in range(round(seconds * ctl["rate_hz"])):
        mujoco.mju_quat2Mat(rot, d.qpos[3:7])  # trunk-to-world rotation R, row-major: R^T (0, 0, -1) = -R[2]
        touching = set(d.contact.geom[np.isin(d.contact.geom, ground).any(axis=1)].ravel())
        values = {"joint_pos": d.qpos[q], "projected_gravity": -rot[6:9], "ang_vel_trunk": d.qvel[3:6],
                  "foot_contact": [float(f in touching) for f in feet], "prev_action": action}
        frame = np.concatenate([np.asarray(values[s["name"]]) / s["divided_by"] for s in obs["frame"]])
        history = [frame] * obs["history"]["frames"] if not history else [frame, *history[:-1]]  # newest first
        o = history + [row(phase + k * step)[:width] for k in ref["offsets_steps"]]
        if "heading" in obs:  # the reference's heading minus the trunk's, wrapped to [-pi, pi)
            o.append([(anchor + reference_yaw(phase) - yaw(d.qpos[3:7]) + np.pi) % (2 * np.pi) - np.pi])
        o = np.concatenate(o).astype(np.float32)
        action = np.clip(policy.run(None, {dep["onnx"]["inputs"][0]["name"]: o[None]})[0][0], -act["clip"], act["clip"])
        yield o, action
        target = row(phase + step)[joint_cols] + act["scale"] * action  # the reference one control step ahead
        d.ctrl[servo] = np.clip(target, robot["joint_lower"], robot["joint_upper"])
        mujoco.mj_step(m, d, ctl["substeps"])
        phase += step


if __name__ == "__main__":
    model, entry_dir = mujoco.MjModel.from_xml_path(sys.argv[1]), Path(sys.argv[2])
    block = json.loads((entry_dir / "metadata.json").read_text())["deployment"]
    ref = block["reference"]
    first = {c["name"]: ref["rows"][0][c["start"] : c["start"] + c["size"]] for c in ref["columns"]}
    start = ref["start_state"]
    state = {c["name"]: start["rows"][0][c["start"] : c["start"] + c["size"]] for c in start["columns"]}
    data = mujoco.MjData(model)  # start as training does: in the reference state at phase 0, facing world x
    data.qpos[2], data.qpos[3:7] = first["root_height"][0], state["root_quat"]
    data.qvel[0:3], data.qvel[3:6] = state["root_lin_vel"], state["root_ang_vel"]
    joints = [model.joint(name) for name in block["robot"]["joint_names"]]
    data.qpos[[j.qposadr[0] for j in joints]] = first["joint_pos"]
    data.qvel[[j.dofadr[0] for j in joints]] = state["joint_vel"]
    for _ in deploy(model, data, entry_dir, float(sys.argv[3]) if len(sys.argv) > 3 else 10.0):
        pass
    print(f"after the run the trunk is {data.qpos[2]:.3f} m high and {data.qpos[0]:.2f} m ahead")
