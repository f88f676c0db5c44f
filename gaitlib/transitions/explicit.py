"""The explicit state of a world: its recent proprioception without the actions, cut from the actor observation.

The explicit state (66) is the three newest proprioceptive frames of the actor observation (newest first), each
without its 12 previous actions: 12 joint angles (rad), projected gravity in the trunk frame (3, unit vector),
trunk angular velocity in the trunk frame (3, rad/s) and 4 foot contacts (0/1). These are the values the policy
sees (observation latency and noise included). It is the input of the "explicit" transition-net ablation.
"""

from __future__ import annotations

import torch

from gaitlib.envs import observations as obs_fn

__all__ = ["EXPLICIT_DIM", "EXPLICIT_LAYOUT", "explicit_state"]

EXPLICIT_DIM = obs_fn.HISTORY * obs_fn.SENSED.stop  # 66: each frame without its previous actions
"""Size of the explicit state."""
EXPLICIT_LAYOUT = {
    "frames": obs_fn.HISTORY,
    "order": "newest first",
    "frame": [f"{f.name}:{f.width}" for f in obs_fn.FRAME if f.name != "prev_action"],
    "source": "actor observation (observation latency and noise included), previous actions left out",
}
"""Description of :data:`EXPLICIT_DIM` stored with transition data."""


def explicit_state(actor_obs: torch.Tensor) -> torch.Tensor:
    """(N, 66) explicit state from the actor observation (N, 158) laid out as :mod:`gaitlib.envs.observations`."""
    frames = actor_obs[:, : obs_fn.STATE_DIM].reshape(-1, obs_fn.HISTORY, obs_fn.FRAME_DIM)
    return frames[:, :, obs_fn.SENSED].reshape(-1, EXPLICIT_DIM)
