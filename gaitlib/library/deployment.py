"""The deployment contract of a trained policy: every fact needed to run ``policy.onnx`` in one's own control loop.

:func:`deployment_block` returns the JSON-able ``deployment`` block of a library entry's ``metadata.json``: the
joints and feet by name, the timing and the PD law, the observation layout segment by segment (units, frames,
history order and its fill at reset), the action convention, the reference the policy imitates as a table over
its phase, and the ONNX model's inputs and outputs. Every number comes from the code that trains and runs the
policy (the robot's spec, :mod:`gaitlib.envs.observations`, the environment's own reference tracker, the action
settings and the exported file), so the block cannot drift from it. ``docs/deploying.md`` explains it and shows
a loop (``examples/deploy_onnx.py``) that runs a policy from the entry folder alone.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import torch

from gaitlib.envs import observations as obs_fn
from gaitlib.envs.reference import ReferenceTracker
from gaitlib.gaits import ReferenceClip
from gaitlib.library.onnx_graph import graph_signature
from gaitlib.robots import RobotSpec, get_robot
from gaitlib.rotations import yaw_of

__all__ = ["deployment_block"]

_DECIMALS = 6
"""Reference table values are rounded to 1e-6 (rad, m, m/s): far below the policy's sensitivity, and short."""

# What each field of obs_fn.FRAME and obs_fn.REFERENCE_FRAME holds: (meaning, SI unit, frame).
_SEGMENTS = {
    "joint_pos": ("joint angles, in joint_names order", "rad", "joint"),
    "projected_gravity": (
        "unit vector of gravity's direction (world -z) expressed in the trunk frame; see gravity",
        "1",
        "trunk (x forward, y left, z up)",
    ),
    "ang_vel_trunk": ("trunk angular velocity (MuJoCo free-joint qvel[3:6])", "rad/s", "trunk"),
    "foot_contact": ("1 if the foot geom touches the ground, else 0, in foot_names order", "1", "-"),
    "prev_action": ("the previous action, see previous_action", "action units", "joint"),
    "root_height": ("reference trunk height above the ground", "m", "world z"),
    "forward_speed": ("reference trunk speed along the reference's heading", "m/s", "reference heading"),
}


def deployment_block(
    *,
    clip: ReferenceClip,
    action: Mapping[str, object],
    observation: obs_fn.ObservationConfig,
    onnx_path: Path,
    action_delay_steps: tuple[int, int] = (0, 0),
    robot: str = "a1",
) -> dict:
    """The ``deployment`` block of a library entry (see the module docstring and ``docs/deploying.md``).

    Args:
        clip: the reference clip the policy was trained to imitate.
        action: the entry's action settings: ``type``, ``scale`` (rad per action unit), ``clip`` (action units).
        observation: the options of the observations the policy reads.
        onnx_path: the exported policy (read for its input and output names and shapes).
        action_delay_steps: the range of control steps every action waited in training.
        robot: the registered robot the policy drives.
    """
    spec = get_robot(robot)
    control_dt = 1.0 / spec.control_hz
    return {
        "robot": _robot_facts(spec),
        "control": _control_facts(spec),
        "action": {
            "type": action["type"],
            "scale": float(action["scale"]),
            "clip": float(action["clip"]),
            "pd_target": "clip(reference_joint_pos(phase + phase_per_step) + scale * clip(action, -clip, clip), "
            "joint_lower, joint_upper): the reference one control step ahead plus the scaled clipped action",
            "delay": {
                "trained_steps": [int(action_delay_steps[0]), int(action_delay_steps[1])],
                "meaning": "in training every PD target reached the servos this many control steps after the action "
                "was computed (one draw per episode, uniform in the range): run the policy with a delay in it",
                "at_start": "until the first delayed target arrives, the servos hold the start pose: the reference "
                "joint angles at the start phase",
            },
        },
        "observation": _observation_facts(observation),
        "reference": _reference_facts(clip, control_dt, observation),
        "onnx": _onnx_facts(onnx_path),
    }


def _robot_facts(spec: RobotSpec) -> dict:
    return {
        "name": spec.name,
        "joint_names": list(spec.joint_names),
        "foot_names": list(spec.foot_names),
        "trunk_body": spec.trunk_body,
        "default_joint_pos": list(spec.default_joint_pos),
        "joint_lower": list(spec.joint_lower),
        "joint_upper": list(spec.joint_upper),
        "standing_height": spec.standing_height,
        "base": "free joint of the trunk: qpos[0:3] position (world), qpos[3:7] quaternion (w, x, y, z), "
        "qvel[0:3] linear velocity (world), qvel[3:6] angular velocity (trunk frame)",
    }


def _control_facts(spec: RobotSpec) -> dict:
    return {
        "rate_hz": spec.control_hz,
        "substeps": spec.substeps,
        "physics_timestep_s": 1.0 / (spec.control_hz * spec.substeps),
        "kp": spec.kp_default,
        "kd": spec.kd_default,
        "torque_limit": spec.torque_limit,
        "pd_law": "tau = clip(kp * (pd_target - q) - kd * qdot, -torque_limit, torque_limit) at every physics "
        "substep, pd_target held for the whole control step (a MuJoCo <position> actuator with kv = kd and "
        "forcerange = +/- torque_limit evaluates exactly this, damping implicitly with implicitfast)",
    }


def _observation_facts(cfg: obs_fn.ObservationConfig) -> dict:
    frame = _segments(obs_fn.FRAME)
    size = {s["name"]: s["size"] for s in frame}
    frame_size = obs_fn.FRAME_DIM
    upright = obs_fn.proprioceptive_frame(
        torch.zeros(1, size["joint_pos"]),
        torch.tensor([[1.0, 0.0, 0.0, 0.0]]),
        torch.zeros(1, size["ang_vel_trunk"]),
        torch.zeros(1, size["foot_contact"]),
        torch.zeros(1, size["prev_action"]),
    )[0]
    gravity = next(s for s in frame if s["name"] == "projected_gravity")
    history = obs_fn.HISTORY
    facts = {
        "size": cfg.actor_dim,
        "dtype": "float32",
        "order": f"{history} proprioceptive frames of frame_size values (the state, {history * frame_size} "
        "values), then the reference (see reference)"
        + (", then the heading error (see heading)" if cfg.heading else ""),
        "frame_size": frame_size,
        "frame": frame,
        "history": {
            "frames": history,
            "order": "newest first: obs[0:frame_size] is the frame read after the last control step (or at the "
            "start), obs[frame_size:2 * frame_size] the one read a control step earlier, and so on",
            "reset_fill": f"at the start all {history} frames are copies of the first reading, whose previous "
            "action is 0",
        },
        "previous_action": "the action output at the previous control step, clipped to +/- action.clip, in action "
        "units (not scaled, no reference added); 0 before the first step",
        "gravity": {
            "world": "the unit vector pointing down, world -z",
            "observed": "R^T (0, 0, -1), R the trunk-to-world rotation of the quaternion qpos[3:7]",
            "upright_value": upright[gravity["start"] : gravity["start"] + gravity["size"]].tolist(),
        },
    }
    if cfg.heading:
        facts["heading"] = {
            "start": obs_fn.ACTOR_OBS_DIM,
            "size": obs_fn.width(obs_fn.HEADING),
            "meaning": "heading error: wrap(start_yaw - reference yaw(start_phase) + reference yaw(phase) - yaw) to "
            "[-pi, pi), rad, where yaw is the trunk's yaw (rotation about world z) now, start_yaw and start_phase "
            "the trunk's yaw and the phase when the policy started, and reference yaw(phase) the reference table's "
            "yaw column: the reference is anchored on the robot's heading at the start",
            "units": "rad",
        }
    return facts


def _reference_facts(clip: ReferenceClip, control_dt: float, cfg: obs_fn.ObservationConfig) -> dict:
    count = clip.num_frames
    identity = torch.zeros(count, 4)
    identity[:, 0] = 1.0
    tracker = ReferenceTracker([clip], count, torch.device("cpu"))
    phases = torch.arange(count) / (count - 1)
    tracker.start(torch.arange(count), torch.zeros(count, dtype=torch.long), phases, torch.zeros(count, 3), identity)
    frame = tracker.frame()
    rows = obs_fn.reference_features([frame]).double().numpy().round(_DECIMALS)
    facts = {
        "start": obs_fn.STATE_DIM,
        "offsets_steps": list(obs_fn.REFERENCE_OFFSETS),
        "phase": "phase counts reference cycles from 0 (or from the phase chosen) when the policy starts and grows "
        "by phase_per_step after every control step; the observation holds the rows at phase + k * phase_per_step "
        "for each k in offsets_steps, in that order",
        "phase_per_step": control_dt / clip.period,
        "period_s": clip.period,
        "loop": clip.loop,
        "lookup": "row i holds phase i / (len(rows) - 1); a looping clip reads the fractional part of the phase, a "
        "non-looping one the phase clamped to [0, 1]; interpolate linearly between neighbouring rows",
        "columns": _segments(obs_fn.REFERENCE_FRAME),
        "rows": rows.tolist(),
    }
    if cfg.heading:  # the reference trunk's own yaw at each row, rad (0 for a straight gait built from a description)
        facts["yaw"] = yaw_of(clip.frame(phases).root_quat).double().numpy().round(_DECIMALS).tolist()
        if clip.cycle_yaw != 0.0:  # a turning reference: its yaw grows from cycle to cycle
            facts["cycle_yaw"] = {
                "value": clip.cycle_yaw,
                "units": "rad",
                "meaning": "the reference turns this much per cycle: reference yaw(phase) is the yaw column read at "
                "the fractional part of the phase plus floor(phase) times this",
            }
    start = torch.cat([frame.root_quat, frame.root_lin_vel, frame.root_ang_vel, frame.joint_vel], dim=1)
    facts["start_state"] = {
        "meaning": "where training starts a robot at the phase of each row (reference state initialization), facing "
        "world x: trunk height (the rows' root_height) and joint angles (their joint_pos), and these",
        "columns": [
            {"name": "root_quat", "start": 0, "size": 4, "units": "1", "frame": "(w, x, y, z), yaw 0: qpos[3:7]"},
            {"name": "root_lin_vel", "start": 4, "size": 3, "units": "m/s", "frame": "world, facing x: qvel[0:3]"},
            {"name": "root_ang_vel", "start": 7, "size": 3, "units": "rad/s", "frame": "trunk: qvel[3:6]"},
            {"name": "joint_vel", "start": 10, "size": start.shape[1] - 10, "units": "rad/s",
             "frame": "joint, in joint_names order"},
        ],
        "rows": start.double().numpy().round(_DECIMALS).tolist(),
    }
    return facts


def _segments(fields: tuple[obs_fn.Field, ...]) -> list[dict]:
    """Observation fields as segments: offset, size, meaning, unit, frame, and the divisor the value is stored in."""
    segments, start = [], 0
    for field in fields:
        meaning, units, axes = _SEGMENTS[field.name]
        segments.append(
            {"name": field.name, "start": start, "size": field.width, "meaning": meaning, "units": units,
             "divided_by": field.unit, "frame": axes}
        )
        start += field.width
    return segments


def _onnx_facts(path: Path) -> dict:
    return {
        "file": path.name,
        **graph_signature(path),
        "note": "the observation normalizer is inside the model: feed the raw observation; the output is the "
        "deterministic action before clipping",
    }
