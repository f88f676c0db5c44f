"""Inputs of the transition-net: which quantities, in which order, for each input kind.

Every input starts with one-hot m and one-hot n over the gaits of the data (G each). Then, by kind:

* ``"latent"`` (the paper's net): psi_m (L), then phi_n as (sin 2 pi phi_n, cos 2 pi phi_n);
* ``"phase"`` (ablation): phi_m and phi_n, each as (sin, cos) of 2 pi phi;
* ``"explicit"`` (ablation): the explicit state (66, :mod:`gaitlib.transitions.explicit`), then phi_n as (sin, cos).

Phases enter as points on the unit circle so that phi = 0.99 and phi = 0.01 are neighbours.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch

from gaitlib.errors import TransitionDataError, UnknownNameError
from gaitlib.transitions.explicit import EXPLICIT_DIM
from gaitlib.transitions.schema import TransitionBatch

__all__ = ["INPUT_KINDS", "FeatureSpec", "batch_features", "build_features", "check_input_kinds"]

INPUT_KINDS = ("latent", "phase", "explicit")
"""Accepted input kinds."""


def check_input_kinds(kinds: Sequence[str]) -> None:
    """Refuse, in one line, no input kind or one not in :data:`INPUT_KINDS`."""
    for kind in kinds or ("",):
        if kind not in INPUT_KINDS:
            raise UnknownNameError("input", kind, list(INPUT_KINDS))
_NEEDS = {"latent": "latent", "phase": "phase_source", "explicit": "explicit"}  # kind -> its specific input


@dataclass(frozen=True, kw_only=True)
class FeatureSpec:
    """Which inputs a transition-net takes."""

    kind: str
    """One of :data:`INPUT_KINDS`."""
    gaits: tuple[str, ...]
    """Gait names; the one-hot codes follow this order."""
    latent_dim: int
    """L: size of the source actors' last hidden layer (used by ``"latent"``)."""

    def __post_init__(self) -> None:
        if self.kind not in INPUT_KINDS:
            raise TransitionDataError(f"unknown transition-net input '{self.kind}' (known: {', '.join(INPUT_KINDS)})")

    @property
    def dim(self) -> int:
        """Length of one input vector."""
        extra = {"latent": self.latent_dim + 2, "phase": 4, "explicit": EXPLICIT_DIM + 2}[self.kind]
        return 2 * len(self.gaits) + extra


def _circle(phase: torch.Tensor) -> torch.Tensor:
    angle = 2 * torch.pi * phase.float()
    return torch.stack([torch.sin(angle), torch.cos(angle)], dim=-1)


def build_features(
    spec: FeatureSpec,
    *,
    source: torch.Tensor,
    dest: torch.Tensor,
    phase_dest: torch.Tensor,
    latent: torch.Tensor | None = None,
    phase_source: torch.Tensor | None = None,
    explicit: torch.Tensor | None = None,
) -> torch.Tensor:
    """(N, spec.dim) float32 inputs from gait indices ``source``/``dest`` (N,), ``phase_dest`` (N,) in cycles and
    what ``spec.kind`` needs: ``latent`` (N, L), ``phase_source`` (N,) in cycles, or ``explicit`` (N, 66)."""
    g = len(spec.gaits)
    parts = [
        torch.nn.functional.one_hot(source.long(), g).float(),
        torch.nn.functional.one_hot(dest.long(), g).float(),
    ]
    name = _NEEDS[spec.kind]
    needed = {"latent": latent, "phase_source": phase_source, "explicit": explicit}[name]
    if needed is None:
        raise TransitionDataError(f"a '{spec.kind}' transition-net needs '{name}' inputs")
    if spec.kind == "phase":
        parts.append(_circle(needed))
    else:
        parts.append(needed.float())
    parts.append(_circle(phase_dest))
    return torch.cat(parts, dim=-1)


def batch_features(spec: FeatureSpec, samples: TransitionBatch) -> torch.Tensor:
    """(n, spec.dim) inputs of stored samples (CPU)."""
    return build_features(
        spec,
        source=torch.from_numpy(samples.source),
        dest=torch.from_numpy(samples.dest),
        phase_dest=torch.from_numpy(samples.phase_dest),
        latent=torch.from_numpy(samples.latent),
        phase_source=torch.from_numpy(samples.phase_source),
        explicit=torch.from_numpy(samples.explicit),
    )
