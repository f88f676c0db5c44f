"""A loaded library entry (:class:`LibraryEntry`) and what the entries that drive one environment share
(:class:`PolicySettings`); :class:`~gaitlib.library.store.Library` loads and checks them."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from gaitlib.envs import EnvConfig
from gaitlib.envs import observations as obs_fn
from gaitlib.gaits import GaitDescription, ReferenceClip
from gaitlib.library.policy import GaitPolicy

__all__ = ["LibraryEntry", "PolicySettings"]


@dataclass
class LibraryEntry:
    """One trained gait, loaded."""

    name: str
    """Gait name (the folder name)."""
    metadata: dict
    """Everything in ``metadata.json``."""
    policy: GaitPolicy
    """Actor, latent and critic."""
    description: GaitDescription
    """The gait description the policy was trained to imitate."""
    clip: ReferenceClip
    """The reference clip built from :attr:`description`."""

    @property
    def identity(self) -> str:
        """SHA-256 of the weights file: what transition data and transition-nets refer to."""
        return self.metadata["sha256"]

    @property
    def action(self) -> dict:
        """Action settings: ``type``, ``scale`` and ``clip`` (metadata ``action``)."""
        return self.metadata["action"]

    @property
    def action_scale(self) -> float:
        """PD target = reference + action_scale * action, rad per action unit."""
        return float(self.action["scale"])

    @property
    def action_clip(self) -> float:
        """Actions are clipped to [-action_clip, action_clip] action units before use."""
        return float(self.action["clip"])

    @property
    def action_delay_steps(self) -> tuple[int, int]:
        """The range of action delays the policy was trained with, control steps (entries of gaitlib 0.1, which
        trained without a delay, record none: (0, 0))."""
        low, high = self.metadata["training"].get("randomization", {}).get("action_delay_steps", (0, 0))
        return int(low), int(high)

    @property
    def observation(self) -> obs_fn.ObservationConfig:
        """The options of the observations the policy reads (from the layout in its metadata)."""
        cfg = obs_fn.observation_config(self.metadata["observation"])
        assert cfg is not None  # _load_entry refuses any other layout
        return cfg


@dataclass(frozen=True)
class PolicySettings:
    """What the policies that drive one environment and fill one transition file must share."""

    latent_dim: int
    """Size of the actors' last hidden layer."""
    action: dict
    """``type``, ``scale`` (rad per action unit) and ``clip`` (action units)."""
    observation: obs_fn.ObservationConfig
    """Options of the actor observation."""
    action_delay_steps: tuple[int, int]
    """Range of the action delay the policies were trained with, control steps: they run with it."""

    def env_config(self, cfg: EnvConfig) -> EnvConfig:
        """``cfg`` with the policies' action and observation settings and their trained action delay."""
        return dataclasses.replace(
            cfg,
            action_scale=self.action["scale"],
            action_clip=self.action["clip"],
            observation=self.observation,
            randomization=dataclasses.replace(cfg.randomization, action_delay_steps=self.action_delay_steps),
        )
