"""Everything a meta-controller needs from a library, loaded once: policies, reference clips, strategies."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import torch

from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.errors import GaitlibError, UnknownNameError
from gaitlib.meta.controller import DEADLINE_S, MetaController
from gaitlib.sim import SimBackend
from gaitlib.strategies import SwitchResources, get_strategy
from gaitlib.training.library import LibraryEntry, entry_names, load_entry

__all__ = ["SwitchingSetup", "load_switching"]


@dataclass
class SwitchingSetup:
    """A library's gaits (in the order its transition data, TMT and net use) and its switching resources."""

    entries: list[LibraryEntry]
    """One loaded library entry per gait."""
    resources: SwitchResources
    """TMT and transition-net, loaded when a strategy asks for them."""

    @property
    def gaits(self) -> tuple[str, ...]:
        return self.resources.gaits

    def gait_index(self, name: str) -> int:
        """Index of gait ``name``; :class:`UnknownNameError` for a gait the library lacks."""
        if name not in self.gaits:
            raise UnknownNameError("gait", name, list(self.gaits))
        return self.gaits.index(name)

    def make_env(self, sim: SimBackend, cfg: EnvConfig | None = None, *, seed: int = 0) -> ImitationEnv:
        """An environment of every gait on ``sim``, with the policies' action settings (``cfg`` for the rest)."""
        first = self.entries[0]
        cfg = dataclasses.replace(
            cfg or EnvConfig(), action_scale=first.action_scale, action_clip=float(first.metadata["action"]["clip"])
        )
        return ImitationEnv(sim, [e.clip for e in self.entries], cfg, seed=seed)

    def controller(
        self, env: ImitationEnv, strategy: str, *, deadline_s: float = DEADLINE_S, seed: int = 0
    ) -> MetaController:
        """A meta-controller over ``env`` (made by :meth:`make_env`) switching with strategy ``strategy`` (``seed``:
        its random choices)."""
        chosen = get_strategy(strategy, dataclasses.replace(self.resources, seed=seed))
        typical = (
            torch.as_tensor(self.resources.table.typical_value, dtype=torch.float32) if chosen.needs_value else None
        )
        policies = [e.policy.to(env.device) for e in self.entries]
        return MetaController(env, policies, chosen, typical_value=typical, deadline_s=deadline_s)


def load_switching(library: Path) -> SwitchingSetup:
    """Load every entry of ``library`` (gaits in name order, as collections store them) for switching."""
    library = Path(library)
    names = entry_names(library)
    if len(names) < 2:
        raise GaitlibError(f"library {library} holds {len(names)} gait(s); switching needs at least two")
    entries = [load_entry(library, name) for name in names]
    scales = {(e.action_scale, float(e.metadata["action"]["clip"])) for e in entries}
    if len(scales) != 1:
        raise GaitlibError(f"library {library} mixes action scales/clips {sorted(scales)}; retrain its gaits alike")
    resources = SwitchResources(library=library, identities={e.name: e.identity for e in entries}, gaits=tuple(names))
    return SwitchingSetup(entries, resources)
