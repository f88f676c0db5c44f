"""Everything a meta-controller needs from a library, loaded once: policies, reference clips, strategies
(:class:`SwitchingSetup`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import torch

from gaitlib.envs import EnvConfig, ImitationEnv
from gaitlib.errors import GaitlibError, UnknownNameError
from gaitlib.library import LibraryStatus, library_status
from gaitlib.library.store import Library, LibraryEntry
from gaitlib.meta.controller import DEADLINE_S, MetaController
from gaitlib.meta.guard import Guard
from gaitlib.sim import SimBackend
from gaitlib.strategies import SwitchResources, get_strategy

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

    def serving(self, pairs: Sequence[tuple[str, str]]) -> SwitchingSetup:
        """This setup for switching ``pairs`` only: its switching models need to drive these pairs alone (a net fitted
        on some pairs, as a budget's curve fits them). Not for a guard or routes, which switch among every gait."""
        resources = dataclasses.replace(self.resources, pairs=tuple(map(tuple, pairs)), _cache={})
        return SwitchingSetup(self.entries, resources)

    def gait_index(self, name: str) -> int:
        """Index of gait ``name``; :class:`UnknownNameError` for a gait the library lacks, one line with the
        commands that fix it for a gait the switching models were not fitted on."""
        if name not in self.gaits:
            library = self.resources.library
            if name not in library.gaits():
                raise UnknownNameError("gait", name, list(self.gaits))
            fixes = [p.line() for p in self.resources.library_status().problems if p.about == "switching"]
            raise GaitlibError(
                f"the switching models of {library.root} drive {', '.join(self.gaits)}, not {name}"
                + (f"; {fixes[0]}" if fixes else "")
            )
        return self.gaits.index(name)

    def make_env(
        self, sim: SimBackend, cfg: EnvConfig | None = None, *, seed: int = 0, action_delay: int | None = None
    ) -> ImitationEnv:
        """An environment of every gait on ``sim``, with the policies' action and observation settings and their
        trained action delay (``action_delay``: every action waits exactly this many control steps instead), and
        ``cfg`` for the rest."""
        cfg = self.resources.library.shared_policy_settings(self.gaits).env_config(cfg or EnvConfig())
        if action_delay is not None:
            delay = (action_delay, action_delay)
            randomization = dataclasses.replace(cfg.randomization, action_delay_steps=delay)
            cfg = dataclasses.replace(cfg, randomization=randomization)
        return ImitationEnv(sim, [e.clip for e in self.entries], cfg, seed=seed)

    def guard(self, *, margin: float | None = None) -> Guard:
        """The library's guard (its survival estimate and calibrated transition-net; ``margin``: instead of the
        one chosen with the estimate); one line, before any work, for a library without a survival estimate, a
        stale one, or a margin out of range."""
        from gaitlib.strategies.survival import check_guard, load_survival

        check_guard(margin=margin)
        estimate = load_survival(self.resources.library, self.gaits)
        every_pair = self.resources if self.resources.pairs is None else dataclasses.replace(
            self.resources, pairs=None, _cache={})  # a guard offers every gait: models of some pairs are refused
        return Guard(estimate, get_strategy("net-lookahead", every_pair), margin=margin)

    def controller(
        self, env: ImitationEnv, strategy: str, *, deadline_s: float = DEADLINE_S, seed: int = 0,
        guard: Guard | None = None,
    ) -> MetaController:
        """A meta-controller over ``env`` (made by :meth:`make_env`) switching with strategy ``strategy`` (``seed``:
        its random choices), guarded by ``guard`` (:meth:`guard`) when given."""
        chosen = get_strategy(strategy, dataclasses.replace(self.resources, seed=seed))
        typical = (
            torch.as_tensor(self.resources.table.typical_value, dtype=torch.float32) if chosen.needs_value else None
        )
        policies = [e.policy.to(env.device) for e in self.entries]
        catchers = tuple(g for g, e in enumerate(self.entries) if e.description.task == "catch")
        return MetaController(env, policies, chosen, typical_value=typical, deadline_s=deadline_s, guard=guard,
                              catchers=catchers)


def load_switching(library: Library | Path | None = None) -> SwitchingSetup:
    """Load every entry of ``library`` (a :class:`Library`, a folder, or ``None`` for the default library) for
    switching, gaits in the canonical order the transition data, TMT and net use."""
    lib = library if isinstance(library, Library) else Library(library)
    if not lib.root.is_dir():  # a file, or nothing: no library at all, not one of no gaits
        what = "is a file, not a library folder" if lib.root.exists() else "does not exist"
        raise GaitlibError(f"library {lib.root} {what}")
    names = lib.gaits()
    if len(names) < 2:
        raise GaitlibError(f"library {lib.root} holds {len(names)} gait(s); switching needs at least two")
    status = library_status(lib) if lib.switching_dir.is_dir() else None
    names = _driven(status, names)
    lib.shared_policy_settings(names)  # one environment drives them all: refuse mixed policy settings now
    return SwitchingSetup(lib.entries(names), SwitchResources(library=lib, gaits=names, status=status))


def _driven(status: LibraryStatus | None, names: tuple[str, ...]) -> tuple[str, ...]:
    """The gaits switching runs with: every gait of the library, or the gaits the switching models were fitted on
    when they are fewer (a gait added since, or a fit on some gaits only) and drive every pair among them with the
    library's current policies; a pair they do not cover is then refused by name (:meth:`SwitchingSetup.gait_index`)."""
    if status is None or status.bundle is None:
        return names
    fitted = tuple(g for g in names if g in status.bundle.gaits)
    return fitted if 2 <= len(fitted) < len(names) and not status.uncovered(fitted) else names
