"""The A1's left-right mirror image as maps of the actions and observations: signed permutations derived field by
field from the observation layout (:mod:`gaitlib.envs.observations`) and the robot's symmetry
(:mod:`gaitlib.robots.a1.constants`, ``MIRROR_*``: legs FR <-> FL and RR <-> RL, the abduction angle negated).

A robot in a state S imitating a gait, and its mirror image S' (positions and velocities reflected in the trunk's
x-z plane, the joints of each leg given to its mirror leg) imitating the mirrored gait (:mod:`gaitlib.gaits.mirror`)
``shift`` cycles further on, observe ``o' = policy.apply(o)`` and ``p' = privileged.apply(p)``; an action ``a`` in S
is the action ``action.apply(a)`` in S'. A policy's mirror image acts in S' as the policy acts in S
(:func:`gaitlib.library.mirror.mirror_state` changes its weights so): ``pi'(o') = action.apply(pi(o))``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import torch

from gaitlib.envs.observations import DYNAMICS, Field, ObservationConfig
from gaitlib.robots.a1.constants import (
    MIRROR_AXIAL,
    MIRROR_JOINT_SIGNS,
    MIRROR_JOINTS,
    MIRROR_LEGS,
    MIRROR_VECTOR,
    NUM_LEGS,
)

__all__ = ["FIELD_MIRRORS", "PHASE_SHIFTS", "MirrorMaps", "SignedPermutation", "action_mirror", "mirror_maps"]

FIELD_MIRRORS: dict[str, str] = {
    "joint_pos": "joints",  # joint angles, rad: each from its mirror joint, the abduction negated
    "prev_action": "joints",  # residuals of the joint targets, in joint order as the angles
    "projected_gravity": "vector",  # a vector in the trunk frame: y negated
    "ang_vel_trunk": "axial",  # an angular velocity in the trunk frame: roll and yaw rates negated, pitch kept
    "foot_contact": "legs",  # each foot's flag from its mirror foot
    "root_height": "same",
    "forward_speed": "same",  # along the heading, which lies in the mirror plane
    "heading_error": "negated",  # a yaw difference: both yaws negate
    "lin_vel_trunk": "vector",
    "phase_sin": "phase",  # the mirrored gait's phase runs `shift` cycles ahead (PHASE_SHIFTS)
    "phase_cos": "phase",
    **{f.name: "same" for f in DYNAMICS},  # the world's scalars (one kp and kd for every joint): unchanged
    "push_force": "vector",  # world frame: y negated
    "action_delay": "same",
}
"""How the mirror image reads each field of the observation layout, by name. A field without a rule here has no
mirror: :func:`mirror_maps` refuses the layout that holds it."""

PHASE_SHIFTS = (0.0, 0.25, 0.5, 0.75)
"""The phase shifts (cycles) under which the critic's phase (sin, cos) maps by a signed permutation."""


@dataclass(frozen=True)
class SignedPermutation:
    """The map ``y[..., i] = sign[i] * x[..., index[i]]`` of the last axis: a permutation with signs, orthogonal."""

    index: tuple[int, ...]
    sign: tuple[float, ...]

    def __post_init__(self) -> None:
        if sorted(self.index) != list(range(len(self.index))) or len(self.sign) != len(self.index):
            raise ValueError("a signed permutation needs each index once and one sign per index")
        if any(s not in (-1.0, 1.0) for s in self.sign):
            raise ValueError("a signed permutation's signs are +1 or -1")

    @property
    def width(self) -> int:
        """Number of values it maps."""
        return len(self.index)

    def apply(self, x: torch.Tensor, *, signed: bool = True) -> torch.Tensor:
        """``x`` (..., width) mapped along its last axis; ``signed=False``: permuted only (a magnitude, such as a
        standard deviation)."""
        index = torch.tensor(self.index, device=x.device)
        moved = x.index_select(-1, index)
        return moved * torch.tensor(self.sign, dtype=x.dtype, device=x.device) if signed else moved

    def inverse(self) -> SignedPermutation:
        """The map that undoes this one."""
        index, sign = [0] * self.width, [1.0] * self.width
        for i, (j, s) in enumerate(zip(self.index, self.sign, strict=True)):
            index[j], sign[j] = i, s
        return SignedPermutation(tuple(index), tuple(sign))

    def __add__(self, other: SignedPermutation) -> SignedPermutation:
        """This map on the first values, ``other`` on those after them."""
        return SignedPermutation(self.index + tuple(self.width + i for i in other.index), self.sign + other.sign)

    def matrix(self) -> torch.Tensor:
        """(width, width) the map as a matrix: ``y = M x``."""
        m = torch.zeros(self.width, self.width)
        m[range(self.width), self.index] = torch.tensor(self.sign)
        return m


def _identity(width: int, sign: float = 1.0) -> SignedPermutation:
    return SignedPermutation(tuple(range(width)), (sign,) * width)


def action_mirror() -> SignedPermutation:
    """The mirror of a joint vector (angles, velocities, actions, in ``JOINT_NAMES`` order)."""
    return SignedPermutation(MIRROR_JOINTS, MIRROR_JOINT_SIGNS)


def _phase(field: str, shift: float, starts: dict[str, int]) -> tuple[int, float]:
    """(index into the layout, sign) of the value that ``field`` (phase_sin or phase_cos) takes in the mirror image:
    sin(2 pi (p + d)) = c sin + s cos and cos(2 pi (p + d)) = c cos - s sin, (c, s) = (cos, sin)(2 pi d), of which
    one is 0 at a quarter cycle."""
    quarters = 4 * (shift % 1.0)
    if abs(quarters - round(quarters)) > 1e-9:
        raise ValueError(f"a phase shift of {shift:g} cycles is no signed permutation of the phase (one of "
                         f"{', '.join(f'{s:g}' for s in PHASE_SHIFTS)})")
    c, s = ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))[round(quarters) % 4]
    if c != 0.0:
        return starts[field], c
    return (starts["phase_cos"], s) if field == "phase_sin" else (starts["phase_sin"], -s)


def _field_map(fields: tuple[Field, ...], shift: float) -> SignedPermutation:
    """The mirror of a layout of ``fields`` (each by its rule in :data:`FIELD_MIRRORS`)."""
    by_rule = {"joints": action_mirror(), "legs": SignedPermutation(MIRROR_LEGS, (1.0,) * NUM_LEGS),
               "vector": SignedPermutation((0, 1, 2), MIRROR_VECTOR),
               "axial": SignedPermutation((0, 1, 2), MIRROR_AXIAL)}
    firsts = [sum(f.width for f in fields[:i]) for i in range(len(fields))]
    starts = {f.name: at for f, at in zip(fields, firsts, strict=True)}  # a repeated field: the last (phase: once)
    index: list[int] = []
    sign: list[float] = []
    for f, start in zip(fields, firsts, strict=True):
        rule = FIELD_MIRRORS.get(f.name)
        if rule is None:
            raise ValueError(f"observation field '{f.name}' has no mirror rule (gaitlib.envs.mirror.FIELD_MIRRORS)")
        if rule == "phase":
            at, s = _phase(f.name, shift, starts)
            index.append(at)
            sign.append(s)
            continue
        local = by_rule.get(rule) or _identity(f.width, -1.0 if rule == "negated" else 1.0)
        if local.width != f.width:
            raise ValueError(f"observation field '{f.name}' holds {f.width} values; its rule '{rule}' maps "
                             f"{local.width}")
        index += [start + i for i in local.index]
        sign += local.sign
    return SignedPermutation(tuple(index), tuple(sign))


class MirrorMaps(NamedTuple):
    """The mirror image's maps of one observation layout at one phase shift."""

    policy: SignedPermutation
    """The actor's observation."""
    privileged: SignedPermutation
    """The critic's extras."""
    action: SignedPermutation
    """The actions (and every joint vector)."""

    @property
    def critic(self) -> SignedPermutation:
        """The critic's input: the actor's observation, then the extras."""
        return self.policy + self.privileged


def mirror_maps(cfg: ObservationConfig, *, shift: float = 0.0) -> MirrorMaps:
    """The maps of the layout ``cfg`` when the mirrored gait's phase runs ``shift`` cycles ahead of the source's
    (:func:`gaitlib.gaits.mirror.mirror_shift`; one of :data:`PHASE_SHIFTS`, else ``ValueError``)."""
    return MirrorMaps(policy=_field_map(cfg.policy, shift), privileged=_field_map(cfg.privileged, shift),
                      action=action_mirror())
