"""A trained gait policy in deployment form: observation normalizer + actor MLP, and the critic beside it.

Built on rsl-rl's ``MLPModel`` so that weights trained by rsl-rl load as they are; exposes what switching needs:
the deterministic action, the actor's last hidden layer (the latent psi) and the critic value.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import torch
from rsl_rl.models import MLPModel
from tensordict import TensorDict

from gaitlib.envs import observations as obs_fn

__all__ = ["GaitPolicy", "build_models", "per_gait"]

OBS_GROUPS = {"actor": ["policy"], "critic": ["policy", "privileged"]}


def _dummy_obs(observation: obs_fn.ObservationConfig) -> TensorDict:
    return TensorDict(
        {
            "policy": torch.zeros(1, observation.actor_dim),
            "privileged": torch.zeros(1, observation.privileged_dim),
        },
        batch_size=[1],
    )


def build_models(
    *,
    actor_hidden: tuple[int, ...],
    critic_hidden: tuple[int, ...],
    activation: str,
    num_actions: int,
    observation: obs_fn.ObservationConfig,
) -> tuple[MLPModel, MLPModel]:
    """Fresh (untrained) actor and critic of the given sizes, laid out as in :func:`rsl_rl_config`, for actor
    observations of the options ``observation``."""
    obs = _dummy_obs(observation)
    actor = MLPModel(
        obs,
        OBS_GROUPS,
        "actor",
        num_actions,
        hidden_dims=list(actor_hidden),
        activation=activation,
        obs_normalization=True,
        distribution_cfg={"class_name": "rsl_rl.modules.distribution.GaussianDistribution"},
    )
    critic = MLPModel(
        obs, OBS_GROUPS, "critic", 1, hidden_dims=list(critic_hidden), activation=activation, obs_normalization=True
    )
    return actor, critic


class GaitPolicy(torch.nn.Module):
    """Deterministic actor, latent and value of one trained gait (inputs: the environment's observation dict)."""

    def __init__(self, actor: MLPModel, critic: MLPModel) -> None:
        super().__init__()
        self.actor = actor.eval()
        self.critic = critic.eval()
        layers = list(actor.mlp)
        self._hidden = torch.nn.Sequential(*layers[:-1])  # shares the actor's modules
        self._head = layers[-1]

    @property
    def latent_dim(self) -> int:
        """Size of the actor's last hidden layer."""
        return self._head.in_features

    @torch.inference_mode()
    def act(self, obs: TensorDict) -> torch.Tensor:
        """(N, 12) deterministic action (the Gaussian's mean), action units."""
        return self.actor(obs)

    @torch.inference_mode()
    def latent(self, obs: TensorDict) -> torch.Tensor:
        """(N, latent_dim) the actor's last hidden layer activations (psi in the paper)."""
        return self._hidden(self.actor.get_latent(obs))

    @torch.inference_mode()
    def act_and_latent(self, obs: TensorDict) -> tuple[torch.Tensor, torch.Tensor]:
        """Action (N, 12) and latent (N, latent_dim) in one forward pass."""
        hidden = self._hidden(self.actor.get_latent(obs))
        return self._head(hidden), hidden

    @torch.inference_mode()
    def value(self, obs: TensorDict) -> torch.Tensor:
        """(N,) critic value."""
        return self.critic(obs).squeeze(-1)


def per_gait(
    policies: Sequence[GaitPolicy],
    gait: torch.Tensor,
    obs: TensorDict,
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
