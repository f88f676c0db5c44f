"""A trained gait policy in deployment form: observation normalizer + actor MLP, and the critic beside it.

Plain torch, laid out as rsl-rl's ``MLPModel`` (``obs_normalizer``, ``mlp``: rsl-rl 5's state-dict keys) so that the
weights rsl-rl trains load as they are, without importing rsl-rl or TensorDict at all: every command that runs
policies without training them starts about 1.2 s sooner (``docs/benchmarks.md``, "A command's start"). The same
weights give the same numbers, bit for bit, as rsl-rl's model (``tests/test_training.py``). Exposes what switching
needs: the deterministic action, the actor's last hidden layer (the latent psi) and the critic value.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from itertools import pairwise
from typing import Literal

import torch

from gaitlib.envs.observations import ObservationBatch, ObservationConfig

__all__ = ["GaitPolicy", "per_gait"]

_ACTIVATIONS = {
    "elu": torch.nn.ELU, "selu": torch.nn.SELU, "relu": torch.nn.ReLU, "crelu": torch.nn.CELU,
    "lrelu": torch.nn.LeakyReLU, "tanh": torch.nn.Tanh, "sigmoid": torch.nn.Sigmoid, "softplus": torch.nn.Softplus,
    "gelu": torch.nn.GELU, "swish": torch.nn.SiLU, "mish": torch.nn.Mish, "identity": torch.nn.Identity,
}
"""The hidden layers' activations by the names rsl-rl gives them (``rsl_rl.utils.resolve_nn_activation``)."""


class _Normalizer(torch.nn.Module):
    """rsl-rl's ``EmpiricalNormalization`` with its statistics frozen: ``(x - mean) / (std + eps)``."""

    eps = 1e-2
    """rsl-rl's default, the one ``MLPModel`` uses."""

    def __init__(self, width: int) -> None:
        super().__init__()
        self.register_buffer("_mean", torch.zeros(1, width))
        self.register_buffer("_var", torch.ones(1, width))  # loaded with the rest; rsl-rl updates it in training
        self.register_buffer("_std", torch.ones(1, width))
        self.register_buffer("count", torch.tensor(0, dtype=torch.long))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self._mean) / (self._std + self.eps)


class _Model(torch.nn.Module):
    """Normalizer then MLP: linear layers with ``activation`` between them, the last one linear."""

    def __init__(self, width: int, hidden: Sequence[int], outputs: int, activation: str) -> None:
        super().__init__()
        self.obs_normalizer = _Normalizer(width)
        if activation.lower() not in _ACTIVATIONS:
            raise ValueError(f"unknown activation '{activation}' (rsl-rl's names: {', '.join(_ACTIVATIONS)})")
        act = _ACTIVATIONS[activation.lower()]()
        dims = [width, *hidden]
        layers: list[torch.nn.Module] = []
        for inputs, size in pairwise(dims):
            layers += [torch.nn.Linear(inputs, size), act]
        self.mlp = torch.nn.Sequential(*layers, torch.nn.Linear(dims[-1], outputs))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.mlp(self.obs_normalizer(x))


class GaitPolicy(torch.nn.Module):
    """Deterministic actor, latent and value of one trained gait (inputs: the environment's
    :class:`~gaitlib.envs.observations.ObservationBatch`)."""

    def __init__(self, actor: _Model, critic: _Model) -> None:
        super().__init__()
        self.actor = actor.eval()
        self.critic = critic.eval()
        layers = list(actor.mlp)
        self.hidden = torch.nn.Sequential(*layers[:-1])  # shares the actor's modules
        """The actor's hidden layers: normalized observation -> latent."""
        self._head = layers[-1]

    @classmethod
    def from_state(
        cls,
        state: Mapping[str, Mapping[str, torch.Tensor]],
        *,
        actor_hidden: Sequence[int],
        critic_hidden: Sequence[int],
        activation: str,
        num_actions: int,
        observation: ObservationConfig,
    ) -> GaitPolicy:
        """The policy of ``state`` (``{"actor": ..., "critic": ...}``: rsl-rl ``MLPModel`` state dicts) with the
        given layer sizes. Raises ``ValueError`` for an unknown activation and ``RuntimeError`` for weights that do not
        fit the sizes."""
        actor = _Model(observation.actor_dim, actor_hidden, num_actions, activation)
        critic = _Model(observation.actor_dim + observation.privileged_dim, critic_hidden, 1, activation)
        # The actor's action distribution (its noise) plays no part in the deterministic action.
        actor.load_state_dict({k: v for k, v in state["actor"].items() if not k.startswith("distribution.")})
        critic.load_state_dict(state["critic"])
        return cls(actor, critic)

    @property
    def latent_dim(self) -> int:
        """Size of the actor's last hidden layer."""
        return self._head.in_features

    @property
    def actor_dim(self) -> int:
        """Width of the actor's observation."""
        return self.actor.mlp[0].in_features

    @torch.inference_mode()
    def act(self, obs: ObservationBatch) -> torch.Tensor:
        """(N, 12) deterministic action (the Gaussian's mean), action units."""
        return self.actor(obs.policy)

    @torch.inference_mode()
    def latent(self, obs: ObservationBatch) -> torch.Tensor:
        """(N, latent_dim) the actor's last hidden layer activations (psi in the paper)."""
        return self.hidden(self.actor.obs_normalizer(obs.policy))

    @torch.inference_mode()
    def act_and_latent(self, obs: ObservationBatch) -> tuple[torch.Tensor, torch.Tensor]:
        """Action (N, 12) and latent (N, latent_dim) in one forward pass."""
        hidden = self.hidden(self.actor.obs_normalizer(obs.policy))
        return self._head(hidden), hidden

    @torch.inference_mode()
    def value(self, obs: ObservationBatch) -> torch.Tensor:
        """(N,) critic value."""
        return self.critic(torch.cat([obs.policy, obs.privileged], dim=-1)).squeeze(-1)


def per_gait(
    policies: Sequence[GaitPolicy],
    gait: torch.Tensor,
    obs: ObservationBatch,
    *,
    method: Literal["act", "latent", "value"] = "act",
) -> torch.Tensor:
    """``policies[gait[i]].<method>(obs[i])`` for every row i (at least one), one call per gait present: the
    actions, latents or values of worlds that each follow their own gait's policy."""
    out = None
    for g in torch.unique(gait).tolist():
        rows = (gait == g).nonzero().squeeze(1)
        values = getattr(policies[g], method)(obs[rows])
        if out is None:
            out = torch.empty((len(gait), *values.shape[1:]), dtype=values.dtype, device=values.device)
        out[rows] = values
    if out is None:
        raise ValueError("per_gait needs at least one row")
    return out
