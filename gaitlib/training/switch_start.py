"""Switch-start training: the handover states a run starts a share of its episodes from
(:mod:`gaitlib.envs.handover`), checked before any work, and the record of them its library entry keeps."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gaitlib.envs.handover import HandoverStates, load_states
from gaitlib.errors import GaitlibError

__all__ = ["handover_states"]


def handover_states(path: Path | None, share: float, *, gait: str) -> tuple[HandoverStates | None, dict | None]:
    """The states of ``path`` recorded while a gait other than ``gait`` ran, and the record of them the entry keeps;
    ``(None, None)`` for the paper's recipe (no states, share 0). Refuses in one line a share out of [0, 1], a
    share without states, states without a share, and states holding none of another gait."""
    if not 0.0 <= share <= 1.0:
        raise GaitlibError(f"--switch-start must be a share in [0, 1], got {share:g}")
    if path is None:
        if share > 0:
            raise GaitlibError("--switch-start needs --states FILE (gaitlib states records them)")
        return None, None
    if share == 0:
        raise GaitlibError("--states needs a --switch-start share above 0")
    states, sha256 = load_states(path)
    rows = states.rows(exclude=gait)
    if not len(rows):
        raise GaitlibError(f"{path} holds no state of a gait other than {gait}")
    used = states.select(rows)
    sources = sorted({used.gaits[i] for i in np.unique(used.source)})
    record = {
        "share": share,
        "states": str(path),
        "states_sha256": sha256,
        "from_gaits": sources,
        "from_identities": {g: used.identities[g] for g in sources},
        "states_used": len(used),
        "recorded_with": {k: used.settings.get(k) for k in ("push_max", "warmup_s", "spacing_s", "num_worlds")},
        "handed_over": "at a uniform destination phase, the reference anchored on the robot (as ImitationEnv.switch)",
    }
    if used.push_force is not None:  # recorded in single shoves (gaitlib states --shove-max), the push kept
        record["shoves"] = {k: used.settings.get(k) for k in ("shove_max_ns", "shove_s", "shove_steps", "calm_share")}
    return used, record
