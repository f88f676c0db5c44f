"""Switching strategies behind one interface (:class:`Strategy`), a small registry, and what they are built from.

Built-in: ``random``, ``value``, ``tmt``, ``tmt-value`` (the baselines of the paper's Fig. 4), ``net`` (the
paper's transition-net rule) and ``net-lookahead`` (the calibrated net against what waiting is worth). A strategy
factory takes the :class:`SwitchResources` of a library (its TMT, transition-net and calibration, loaded only when a
strategy asks); :func:`register_strategy` adds one.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from gaitlib.defaults import COMPARED, DEFAULT_STRATEGY
from gaitlib.errors import TransitionDataError
from gaitlib.library import LibraryStatus, library_status
from gaitlib.library.store import Library
from gaitlib.registry import Registry
from gaitlib.strategies.base import PHASE_GRID, Decision, Strategy, SwitchQuery, phase_grid
from gaitlib.strategies.calibration import Calibration, load_calibration
from gaitlib.strategies.lookahead import LookaheadStrategy
from gaitlib.strategies.net import NET_THRESHOLD, NetStrategy
from gaitlib.strategies.random_switch import RandomStrategy
from gaitlib.strategies.tmt import TMTStrategy, TMTValueStrategy, TransitionTable, build_table, load_table, save_table
from gaitlib.strategies.value import ValueStrategy

__all__ = [
    "COMPARED",
    "DEFAULT_STRATEGY",
    "NET_THRESHOLD",
    "PHASE_GRID",
    "Decision",
    "Strategy",
    "SwitchQuery",
    "SwitchResources",
    "TransitionTable",
    "build_table",
    "get_strategy",
    "load_table",
    "phase_grid",
    "register_strategy",
    "save_table",
    "strategy_names",
]


@dataclass
class SwitchResources:
    """Where strategies get their data: a library and the gaits in use, with its TMT and transition-net loaded on
    demand and checked against the library's policies."""

    library: Library
    """The library (its TMT and transition-net, and the identities of its policies)."""
    gaits: tuple[str, ...]
    """Gaits of the environment the strategies will serve, in canonical order (indices in queries follow it)."""
    seed: int = 0
    """Seed of random choices."""
    pairs: tuple[tuple[str, str], ...] | None = None
    """The ordered pairs the strategies will switch (``None``: every pair of :attr:`gaits`); the switching models
    need to drive only these."""
    status: LibraryStatus | None = None
    """What state the library is in (:func:`~gaitlib.library.library_status`), when already read; read on first
    use otherwise (:meth:`library_status`)."""
    _cache: dict = field(default_factory=dict, repr=False)

    def library_status(self) -> LibraryStatus:
        """The library's status, read once."""
        if self.status is None:
            self.status = library_status(self.library)
        return self.status

    @property
    def table(self) -> TransitionTable:
        """The library's TMT (with typical values and calibrated thresholds)."""
        if "table" not in self._cache:
            self._check_coverage()
            table = load_table(self.library.tmt_path, identities=self.library.identities(self.gaits))
            self._check_gaits("TMT", table.gaits)
            self._cache["table"] = table
        return self._cache["table"]

    @property
    def calibration(self) -> Calibration:
        """The calibration of the library's transition-net (checked against the library's policies)."""
        if "calibration" not in self._cache:
            self._check_coverage()
            identities = self.library.identities(self.gaits)
            calibration = load_calibration(self.library.calibration_path, identities=identities)
            self._check_gaits("net calibration", calibration.gaits)
            self._cache["calibration"] = calibration
        return self._cache["calibration"]

    @property
    def net(self):
        """The library's transition-net (:class:`~gaitlib.transition_net.TransitionNet`, or the
        :class:`~gaitlib.transition_net.ComposedNet` of a library grown by ``gaitlib fit --extend``; eval mode)."""
        if "net" not in self._cache:
            from gaitlib.transition_net import load_net

            self._check_coverage()
            saved = load_net(self.library.net_path, identities=self.library.identities(self.gaits))
            self._check_gaits("transition-net", saved.net.spec.gaits)
            self._cache["net"] = saved.net
        return self._cache["net"]

    def _check_coverage(self) -> None:
        """Refuse, in one line with the commands that fix it, switching models that do not drive every pair of
        :attr:`gaits` (of :attr:`pairs`, when given) with the library's current policies
        (:mod:`gaitlib.library.status`; damaged or missing files are left to their own loaders' messages)."""
        if "covered" in self._cache:
            return
        self.library.check_switching()
        status = self.library_status()
        if status.bundle is not None:
            missing = status.uncovered(self.gaits)
            if self.pairs is not None:
                served = {f"{m}-{n}" for m, n in self.pairs}
                missing = [p for p in missing if p in served]
            refit = next((p for p in status.problems if p.about == "switching"), None)
            if (missing or set(status.bundle.gaits) != set(self.gaits)) and refit is not None:
                raise TransitionDataError(f"library {self.library.root}: {refit.line()}")
        self._cache["covered"] = True

    def _check_gaits(self, what: str, gaits: tuple[str, ...]) -> None:
        if tuple(gaits) != tuple(self.gaits):
            raise TransitionDataError(
                f"the {what} was fitted for gaits {list(gaits)}, not {list(self.gaits)}; fit it on data of exactly "
                f"these gaits (gaitlib library --library {self.library.root} lists the commands)"
            )


StrategyFactory = Callable[[SwitchResources], Strategy]
"""``factory(resources) -> Strategy``."""

_STRATEGIES: Registry[StrategyFactory] = Registry("strategy")
"""The strategies by name; :func:`register_strategy` adds one."""
_STRATEGIES.register("random", lambda r: RandomStrategy(seed=r.seed))
_STRATEGIES.register("value", lambda r: ValueStrategy(threshold=r.table.thresholds["value"]))
_STRATEGIES.register("tmt", lambda r: TMTStrategy(r.table))
_STRATEGIES.register("tmt-value", lambda r: TMTValueStrategy(r.table))
_STRATEGIES.register("net", lambda r: NetStrategy(r.net))
_STRATEGIES.register("net-lookahead", lambda r: LookaheadStrategy(r.net, r.calibration, r.table))


def register_strategy(name: str, factory: StrategyFactory) -> None:
    """Add (or replace) the strategy ``name``, built by ``factory(resources)``."""
    _STRATEGIES.register(name, factory)


def strategy_names() -> list[str]:
    """Registered strategy names, in registration order."""
    return _STRATEGIES.names()


def get_strategy(name: str, resources: SwitchResources) -> Strategy:
    """Build strategy ``name`` from ``resources``; :class:`UnknownNameError` for an unknown name."""
    return _STRATEGIES.get(name)(resources)
