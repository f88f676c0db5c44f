"""The transition-net: an MLP that scores how likely a switch m -> n at destination phase phi_n succeeds.

Inputs (:mod:`gaitlib.transition_net.features`) are standardized with the training set's mean and standard
deviation (kept as buffers, so they travel with the weights); hidden layers 128-64-32, each followed by ReLU and
dropout 0.4; one output logit. Training uses the logit with ``BCEWithLogitsLoss``; :meth:`TransitionNet.probability`
is the sigmoid of it, in eval mode (dropout off).
"""

from __future__ import annotations

import torch

from gaitlib.transition_net.features import FeatureSpec, build_features

__all__ = ["TransitionNet"]


class TransitionNet(torch.nn.Module):
    """Feed-forward success classifier over :class:`FeatureSpec` inputs."""

    def __init__(self, spec: FeatureSpec, *, hidden: tuple[int, ...] = (128, 64, 32), dropout: float = 0.4) -> None:
        super().__init__()
        self.spec = spec
        self.hidden = tuple(hidden)
        self.dropout = dropout
        layers: list[torch.nn.Module] = []
        width = spec.dim
        for size in hidden:
            layers += [torch.nn.Linear(width, size), torch.nn.ReLU(), torch.nn.Dropout(dropout)]
            width = size
        layers.append(torch.nn.Linear(width, 1))
        self.mlp = torch.nn.Sequential(*layers)
        self.register_buffer("feature_mean", torch.zeros(spec.dim))
        self.register_buffer("feature_std", torch.ones(spec.dim))

    def set_normalization(self, features: torch.Tensor) -> None:
        """Standardize inputs with the mean and standard deviation of ``features`` (n, dim) (floor 1e-3)."""
        self.feature_mean.copy_(features.mean(0))
        self.feature_std.copy_(features.std(0, unbiased=False).clamp(min=1e-3))

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        """(N,) success logits of raw (unstandardized) inputs (N, dim)."""
        return self.mlp((features - self.feature_mean) / self.feature_std).squeeze(-1)

    @torch.inference_mode()
    def probability(self, features: torch.Tensor) -> torch.Tensor:
        """(N,) success probability in [0, 1] of inputs (N, dim); switches the module to eval mode."""
        self.eval()
        return torch.sigmoid(self(features))

    def score(self, **inputs: torch.Tensor) -> torch.Tensor:
        """(N,) success probability from named inputs (see :func:`~gaitlib.transition_net.features.build_features`:
        ``source``, ``dest``, ``phase_dest`` and ``latent``, ``phase_source`` or ``explicit``)."""
        return self.probability(build_features(self.spec, **inputs).to(self.feature_mean.device))
