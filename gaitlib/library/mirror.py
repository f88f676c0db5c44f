"""A policy's left-right mirror image, made from its weights: the maps of :mod:`gaitlib.envs.mirror` folded into the
first and last layers of the actor and the critic and into their observation normalizers, so that the mirrored
policy is a policy like any other (same layers, same ``policy.onnx`` export, no wrapper when it runs).

With the maps ``M`` (observation, a signed permutation) and ``A`` (action), the mirror of an actor ``pi`` is
``pi'(o) = A pi(M^-1 o)``. A signed permutation commutes with the normalizer's elementwise scaling, so:
the normalizer's mean becomes ``M mean`` and its variance and standard deviation are permuted alike (unsigned); the
first layer's weight ``W`` becomes ``W M^-1``, whose column i is ``sign_i`` times column ``index_i`` (``M`` applied to
its rows); the last layer's weight rows and bias are mapped by ``A``; the action noise's deviation is permuted. The
critic's value is a scalar, its own mirror: only its input side changes. Every value is moved or negated, never
computed, so mirroring twice gives the same weights back, bit for bit.
"""

from __future__ import annotations

from collections.abc import Mapping

import torch

from gaitlib.envs.mirror import MirrorMaps, SignedPermutation

__all__ = ["mirror_state"]

_NORMALIZER = "obs_normalizer."
_SIGNED = ("_mean",)
_MAGNITUDES = ("_var", "_std")


def _layers(state: Mapping[str, torch.Tensor]) -> list[int]:
    """The indices ``i`` of the ``mlp.i`` linear layers of an rsl-rl ``MLPModel`` state, in order."""
    return sorted({int(k.split(".")[1]) for k in state if k.startswith("mlp.") and k.endswith(".weight")})


def _model(state: Mapping[str, torch.Tensor], inputs: SignedPermutation, outputs: SignedPermutation | None,
           what: str) -> dict[str, torch.Tensor]:
    """The state of the mirror image of an ``MLPModel`` whose inputs mirror by ``inputs`` and outputs by ``outputs``
    (``None``: a value, its own mirror)."""
    layers = _layers(state)
    if not layers:
        raise ValueError(f"the {what} holds no mlp layers (not an rsl-rl MLPModel state)")
    first, last = f"mlp.{layers[0]}.", f"mlp.{layers[-1]}."
    if state[first + "weight"].shape[1] != inputs.width:
        raise ValueError(f"the {what} reads {state[first + 'weight'].shape[1]} values; its mirror map is of "
                         f"{inputs.width}")
    out = {}
    for key, value in state.items():
        if key.startswith(_NORMALIZER) and key[len(_NORMALIZER):] in _SIGNED + _MAGNITUDES:
            out[key] = inputs.apply(value, signed=key[len(_NORMALIZER):] in _SIGNED)
        elif key == first + "weight":
            out[key] = inputs.apply(value)
        elif key.startswith(last) and outputs is not None:
            rows = value.T if key.endswith("weight") else value
            mapped = outputs.apply(rows)
            out[key] = mapped.T.contiguous() if key.endswith("weight") else mapped
        elif key.startswith("distribution.") and value.dim() >= 1 and outputs is not None:
            if value.shape[-1] != outputs.width:
                raise ValueError(f"the {what}'s {key} holds {value.shape[-1]} values for {outputs.width} actions")
            out[key] = outputs.apply(value, signed=False)  # a deviation (or its log): per action, unsigned
        else:
            out[key] = value.clone()
    return out


def mirror_state(state: Mapping[str, Mapping[str, torch.Tensor]], maps: MirrorMaps) -> dict[str, dict]:
    """The mirror image of a policy's weights ``state`` (``policy.pt``: ``{"actor": ..., "critic": ...}``, rsl-rl
    ``MLPModel`` states) under ``maps`` (:func:`gaitlib.envs.mirror.mirror_maps` of the policy's observation layout
    and the gaits' phase shift). ``ValueError`` for weights that do not fit the maps."""
    return {
        "actor": _model(state["actor"], maps.policy, maps.action, "actor"),
        "critic": _model(state["critic"], maps.critic, None, "critic"),
    }
