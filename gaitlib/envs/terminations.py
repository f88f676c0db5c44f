"""Early termination (docs/training.md) as small pure functions over N worlds; each returns (N,) bool.

What a fall is has two definitions (:class:`gaitlib.defaults.Falls`). ``trunk``, the default wherever
gaitlib reports a fall: the trunk too low, tilted past the limit, or the trunk itself on the ground, as legged_gym's
A1 (``terminate_after_contacts_on = ["base"]``, github.com/leggedrobotics/legged_gym, ``envs/a1/a1_config.py``) and
Isaac Lab's velocity task (``base_contact``) count one; a leg's touch that the robot rides through is not a fall,
and is reported beside every fall figure as a *touch*. ``contact``, gaitlib's stricter definition (and its
training's termination): any non-foot body on the ground is a fall too.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

import torch

from gaitlib.defaults import Falls
from gaitlib.rotations import quat_angle_between, quat_rotate

__all__ = [
    "FallTally",
    "TerminationConfig",
    "any_cause",
    "fall_causes",
    "fallen",
    "orientation_lost",
    "too_low",
]



@dataclass(frozen=True, kw_only=True)
class TerminationConfig:
    """Thresholds of early termination."""

    min_height: float = 0.12
    """Trunk height below which the robot has fallen, m (it stands at about 0.25 m)."""
    max_orientation_error: float = torch.pi / 2
    """Largest rotation between the trunk and the reference trunk, rad."""
    heading: bool = True
    """The rotation compared includes the heading (training: a policy that turns away fails); ``False``: only the
    tilt, the angle between the trunk's up axis and the reference trunk's (a fall, as evaluation counts it)."""
    body_contact: bool = True
    """A non-foot body on the ground ends the episode (gaitlib's training, and the ``contact`` definition of a
    fall); ``False``: only the trunk's height, its orientation and its own contact with the ground do (the
    ``trunk`` definition), as legged_gym's A1 ends an episode only when its base touches the ground and penalizes
    its legs' contacts."""

    def counting(self, falls: Falls, **fields) -> TerminationConfig:
        """These terminations (``fields`` replaced) counting falls by the definition ``falls``: the one place a
        definition becomes terminations."""
        return replace(self, body_contact=falls == Falls.CONTACT, **fields)

    @property
    def falls(self) -> Falls:
        """The definition of a fall these terminations count."""
        return Falls.CONTACT if self.body_contact else Falls.TRUNK


def too_low(root_height: torch.Tensor, *, min_height: float) -> torch.Tensor:
    """The trunk (N,) m is below ``min_height``."""
    return root_height < min_height


def orientation_lost(
    root_quat: torch.Tensor, ref_root_quat: torch.Tensor, *, max_error: float, heading: bool = True
) -> torch.Tensor:
    """The trunk is rotated more than ``max_error`` rad away from the reference trunk (``heading=False``: its up
    axis is tilted more than ``max_error`` away from the reference trunk's)."""
    if heading:
        return quat_angle_between(root_quat, ref_root_quat) > max_error
    up = torch.zeros_like(root_quat[:, 1:])
    up[:, 2] = 1.0
    cosine = (quat_rotate(root_quat, up) * quat_rotate(ref_root_quat, up)).sum(-1)
    return cosine < math.cos(max_error)


def fall_causes(
    body_contact: torch.Tensor,
    trunk_contact: torch.Tensor,
    root_height: torch.Tensor,
    root_quat: torch.Tensor,
    ref_root_quat: torch.Tensor,
    cfg: TerminationConfig,
) -> dict[str, torch.Tensor]:
    """Each termination in force apart, (N,) bool: ``body_contact`` (a non-foot body touches the ground; never,
    unless ``cfg.body_contact``), ``trunk_contact`` (the trunk itself on the ground), ``too_low`` (the trunk),
    ``orientation_lost``; a fall may meet several."""
    return {
        "body_contact": body_contact if cfg.body_contact else torch.zeros_like(body_contact),
        "trunk_contact": trunk_contact,
        "too_low": too_low(root_height, min_height=cfg.min_height),
        "orientation_lost": orientation_lost(
            root_quat, ref_root_quat, max_error=cfg.max_orientation_error, heading=cfg.heading
        ),
    }


def any_cause(causes: Mapping[str, torch.Tensor]) -> torch.Tensor:
    """(N,) bool: some cause of ``causes`` (as :func:`fall_causes` gives them) held."""
    return torch.stack(tuple(causes.values())).any(dim=0)


def fallen(
    body_contact: torch.Tensor,
    trunk_contact: torch.Tensor,
    root_height: torch.Tensor,
    root_quat: torch.Tensor,
    ref_root_quat: torch.Tensor,
    cfg: TerminationConfig,
) -> torch.Tensor:
    """Any termination: a non-foot body touches the ground (with ``cfg.body_contact``), the trunk touches it, the
    trunk is too low, or orientation is lost."""
    return any_cause(fall_causes(body_contact, trunk_contact, root_height, root_quat, ref_root_quat, cfg))


class FallTally:
    """Per world over one episode each: whether it fell, whether a non-foot body touched the ground while it was
    up, and its longest unbroken touch; fed one environment step at a time (:meth:`step`), the worlds' ``alive``
    mask kept by the caller and updated after each step."""

    def __init__(self, num_worlds: int, device: torch.device | str) -> None:
        self.fell = torch.zeros(num_worlds, dtype=torch.bool, device=device)
        """(N,) ended in a fall (not a time-out)."""
        self.touched = torch.zeros(num_worlds, dtype=torch.bool, device=device)
        """(N,) a non-foot body touched the ground while up (the step that ends an episode included)."""
        self._run = torch.zeros(num_worlds, device=device)
        self.longest = torch.zeros(num_worlds, device=device)
        """(N,) the longest unbroken touch, control steps."""

    def step(self, dones: torch.Tensor, extras: dict, alive: torch.Tensor) -> torch.Tensor:
        """Count one step of the worlds still ``alive`` before it (the environment's ``dones`` and ``extras``);
        returns the worlds that fell at it."""
        fell = dones & ~extras["time_outs"] & alive
        touch = extras["touch"].to(alive.device) & alive
        self.fell |= fell
        self.touched |= touch
        self._run = torch.where(touch, self._run + 1, 0.0)
        self.longest = torch.maximum(self.longest, self._run)
        return fell
