"""Parity of the two backends: the ``newton`` backend (mujoco_warp) and the ``mujoco`` backend (MuJoCo C) step the
same physics. One scenario, used by ``tests/test_sim_parity.py`` on the CPU and by ``benchmarks/gpu_check.py`` on
a GPU: two worlds start standing (or, ``airborne``, 1 m up with one pushed sideways by 50 N) and follow a
stepping-like motion for 1 s at the control rate, side by side on both backends."""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from gaitlib.robots import get_robot
from gaitlib.sim import make_backend, standing_state

__all__ = ["PARITY_LIMITS", "ParityResult", "parity_run", "stepping_targets"]

PARITY_LIMITS = {"root_pos": 2e-3, "root_quat": 5e-3, "joint_pos": 1e-2, "foot_pos": 2e-3}
"""Largest difference allowed between the backends over the run: trunk position (m), trunk quaternion, joint
angles (rad), foot positions (m)."""


@dataclass(frozen=True)
class ParityResult:
    """How far the backends drifted apart over one run."""

    worst: dict[str, float]
    """Largest absolute difference of each quantity of :data:`PARITY_LIMITS` over the run, in its units."""
    moved: float
    """Largest joint excursion from the start, rad (the motion is real)."""
    contact_mismatches: int
    """Control steps (after the first two, on the ground) whose foot contacts differ."""
    diverged: bool
    """A backend flagged a diverging world."""

    @property
    def passed(self) -> bool:
        return (
            not self.diverged
            and self.contact_mismatches == 0
            and all(self.worst[name] < limit for name, limit in PARITY_LIMITS.items())
        )


def stepping_targets(t: float, n: int) -> torch.Tensor:
    """(n, 12) PD targets at time ``t`` (s): thighs and calves oscillate at 1.5 Hz; world 1 also swings its hips."""
    targets = torch.tensor(get_robot("a1").default_joint_pos).repeat(n, 1)
    targets[:, 1::3] += 0.3 * math.sin(2 * math.pi * 1.5 * t)
    targets[:, 2::3] += 0.4 * math.sin(2 * math.pi * 1.5 * t + 0.7)
    targets[1, 0::3] += 0.2 * math.sin(2 * math.pi * 1.0 * t)
    return targets


def parity_run(*, airborne: bool, newton_device: str = "cpu") -> ParityResult:
    """The scenario with the ``newton`` backend on ``newton_device`` beside the ``mujoco`` backend."""
    n = 2
    backends = [make_backend("mujoco", num_worlds=n), make_backend("newton", num_worlds=n, device=newton_device)]
    try:
        start = standing_state(backends[0].robot, n)
        if airborne:
            start.root_pos[:, 2] = 1.0
        for backend in backends:
            backend.reset(torch.arange(n), start)
            if airborne:
                backend.set_trunk_force(torch.tensor([0]), torch.tensor([[0.0, 50.0, 0.0]]))
        worst, moved, mismatches, diverged = dict.fromkeys(PARITY_LIMITS, 0.0), 0.0, 0, False
        for k in range(round(backends[0].robot.control_hz)):  # 1 s
            states = []
            for backend in backends:
                backend.set_pd_targets(stepping_targets(k / backend.robot.control_hz, n))
                diverged |= bool(backend.step().any())
                states.append(backend.state())
            c, w = (type(s)(**{name: value.cpu() for name, value in vars(s).items()}) for s in states)
            for name in worst:
                worst[name] = max(worst[name], (getattr(c, name) - getattr(w, name)).abs().max().item())
            moved = max(moved, (c.joint_pos - start.joint_pos).abs().max().item())
            mismatches += int(not airborne and k >= 2 and not torch.equal(c.foot_contact, w.foot_contact))
    finally:
        for backend in backends:
            backend.close()
    return ParityResult(worst=worst, moved=moved, contact_mismatches=mismatches, diverged=diverged)
