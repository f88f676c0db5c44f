"""Checking and parsing of option values shared by the commands.

Every numeric option is declared with :func:`bounded`, which states its range in the help and refuses, while the
command line is parsed (before any work starts and before any file is created), a value that is not finite, not
whole where a count is asked, or out of range: one line ``gaitlib: error: --push-max must be a finite number in
[0, 2000] N, got nan`` and exit code 2. Ranges are sanity bounds, far beyond any useful run; what a count of
parallel worlds costs in memory is checked against the machine by :func:`check_worlds`.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

import typer

from gaitlib.defaults import DEFAULT_FALLS, Falls
from gaitlib.values import IMPULSE_NS, MAX_MAGNITUDES, Bounds, OptionError, parse_values

__all__ = [
    "CHUNK",
    "COUNT",
    "DELAY_STEPS",
    "EPISODE_SECONDS",
    "IMPULSE_NS",
    "MAX_MAGNITUDES",
    "MEASURE_SECONDS",
    "MOTOR_STRENGTH",
    "PUSH_N",
    "SEED",
    "TIME_IN_RUN",
    "WORKERS",
    "WORLDS",
    "WORLD_BYTES",
    "Bounds",
    "Number",
    "OptionError",
    "action_delay_option",
    "bounded",
    "check_worlds",
    "cluster_config",
    "parse_magnitudes",
    "parse_pairs",
    "parse_values",
    "ray_address_argument",
    "ray_option",
    "workers_option",
]

WORLD_BYTES = 1 << 20
"""Host memory one MuJoCo world costs, bytes: measured 0.68 MiB per world (peak RSS of the A1 backend with its
imitation environment, 2048 worlds against 256, stepped), rounded up to 1 MiB."""
PUSH_N = Bounds(low=0, high=2000, unit="N")
"""Push magnitudes: up to four times the largest push of the paper's sweep (500 N)."""
SEED = Bounds(low=0, high=2**32 - 1, whole=True)
"""Random seeds (numpy's seed sequences take non-negative 32-bit words)."""
WORLDS = Bounds(low=1, high=65536, whole=True)
"""Parallel worlds (and evaluation episodes, one world each); memory is checked by :func:`check_worlds`."""
COUNT = Bounds(low=1, high=1e6, whole=True)
"""Iterations, epochs, samples per benchmark cell, checkpoint spacing."""
EPISODE_SECONDS = Bounds(low=0, high=600, unit="s", low_open=True)
"""Simulated lengths of a run or an evaluation episode, s."""
TIME_IN_RUN = Bounds(low=0, high=600, unit="s")
"""Moments within a run, s from its start (0: at once)."""
DELAY_STEPS = Bounds(low=0, high=10, whole=True)
"""Action delays, control steps (10: a third of a second at 30 Hz)."""
MOTOR_STRENGTH = Bounds(low=0, high=10, low_open=True)
"""Multiples of the PD torque the motors deliver (1: as modelled)."""
MEASURE_SECONDS = Bounds(low=0, high=3600, unit="s", low_open=True)
"""Wall-clock time of a speed measurement, s."""
WORKERS = Bounds(low=1, high=4096, whole=True)
"""Ray workers of one job (each a process with its own simulator)."""
LEGS = Bounds(low=1, high=5, whole=True)
"""Switches a route may take (``gaitlib routes --max-legs``)."""
CHUNK = Bounds(low=1, high=1e7, whole=True)
"""Samples per chunk of a collection (its unit of work and of a commit)."""


def bounded(default, *names: str, help: str, bounds: Bounds):
    """A typer option ``names`` whose help ends with its range and whose value is read by :class:`Number` and
    checked by ``bounds`` at parse time."""

    def check(param: typer.CallbackParam, value):
        return bounds.check(param.opts[0], value)

    return typer.Option(default, *names, help=f"{help} {bounds.describe()}.", callback=check,
                        parser=Number(names[0], bounds), metavar="INTEGER" if bounds.whole else "FLOAT")


class Number:
    """The parser of option ``option``'s number as given: a whole number (``4294967295``, ``2e6``) as an ``int``
    where ``bounds`` take only whole numbers, any other as a ``float``. Text that is not a number, and a number out
    of ``bounds`` (``2.5`` for a count), is refused in gaitlib's one line (:class:`OptionError`), as the option's
    range is, not with click's usage message of several lines."""

    def __init__(self, option: str, bounds: Bounds) -> None:
        self.option, self.bounds = option, bounds

    def __call__(self, value):
        if not isinstance(value, str):  # a default, already a number
            return value
        option = self.option
        try:
            number: float = int(value)  # a whole number exactly, however large
        except ValueError:
            try:
                number = float(value)
            except ValueError:
                raise OptionError(f"{option} must be {self.bounds.kind()} in {self.bounds.describe()}, got "
                                  f"'{value}'") from None
        self.bounds.check(option, number, given=value)
        return int(number) if self.bounds.whole else float(number)


_FALLS_HELP = (
    "What is a fall: trunk (the default, the field's: the trunk too low, tilted past 90 degrees or on the ground, as "
    "legged_gym's and Isaac Lab's A1 tasks count one; a leg's touch ridden through is reported beside as a touch) or "
    "contact (gaitlib's strict definition: any non-foot body on the ground is a fall too)."
)


def action_delay_option():
    """``--action-delay``: a fixed delay of every action, control steps, instead of the policies' trained random
    one (``gaitlib run``, ``drive``, ``benchmark``)."""
    return bounded(None, "--action-delay", help="Control steps every action waits before it reaches the servos, "
                   "fixed (default: the policies' trained random delay);", bounds=DELAY_STEPS)


def falls_option(name: str = "--falls", *, help: str = _FALLS_HELP):
    """``--falls trunk|contact`` (or ``name``): what ends an episode or a transition as a fall, default ``trunk``
    (the field's). The one place a definition is validated: the command gets a :class:`~gaitlib.defaults.Falls`,
    and another value is refused in one line at parse time."""
    def check(param: typer.CallbackParam, value: str) -> Falls:
        if value not in tuple(Falls):
            raise OptionError(f"{name} takes {' or '.join(Falls)}, got '{value}'")
        return Falls(value)

    return typer.Option(DEFAULT_FALLS.value, name, callback=check, help=help)


def ray_option():
    """``--ray``: run the job's chunks on Ray workers, on a local Ray started for the run or, with the ADDRESS
    argument (:func:`ray_address_argument`), on a running cluster. Without Ray installed it is refused in one line
    at parse time."""

    def check(param: typer.CallbackParam, value: bool) -> bool:
        if value:
            from gaitlib.cluster import ClusterError, require_ray

            try:
                require_ray()
            except ClusterError as error:
                raise OptionError(str(error)) from None
        return value

    return typer.Option(
        False, "--ray", help="Run on Ray workers (needs Ray: the cluster extra of gaitlib).", callback=check
    )


def ray_address_argument():
    """``[ADDRESS]`` after ``--ray``: the Ray cluster to join (``auto``: the one this node belongs to). It is a
    positional argument so that ``--ray`` alone, ``--ray auto`` and ``--ray ray://head:10001`` all parse."""
    return typer.Argument(
        None, metavar="[ADDRESS]", show_default=False,
        help="With --ray: the cluster to join, auto (this node's) or ray://HOST:10001; none: a local Ray.",
    )


def workers_option():
    """``--workers N`` (with ``--ray``): Ray workers, each loading the library once and owning a simulator."""
    return bounded(
        None, "--workers", help="Ray workers, with --ray (default: one per CPU of the cluster, or per GPU);",
        bounds=WORKERS,
    )


def cluster_config(ray: bool, address: str | None, workers: int | None):
    """The :class:`~gaitlib.cluster.ClusterConfig` of ``--ray [ADDRESS]`` and ``--workers`` (``None``: no Ray); an
    address or ``--workers`` without ``--ray`` is refused."""
    if not ray:
        if address is not None:
            raise OptionError(f"unexpected argument '{address}' (a Ray address goes after --ray)")
        if workers is not None:
            raise OptionError("--workers needs --ray (without it the job runs in this process)")
        return None
    from gaitlib.cluster import ClusterConfig

    return ClusterConfig(address=address, workers=workers)


def check_worlds(option: str, worlds: int, *, backend: str) -> None:
    """Refuse ``worlds`` parallel MuJoCo worlds when their estimated memory (:data:`WORLD_BYTES` each) exceeds what
    the machine has available (other backends allocate on their device: only the range applies)."""
    from gaitlib.sim import resolve_backend_name

    if resolve_backend_name(backend) != "mujoco":
        return
    need, have = worlds * WORLD_BYTES, _available_bytes()
    if need > have:
        raise OptionError(
            f"{option} {worlds} needs about {need / 2**30:.1f} GiB ({WORLD_BYTES / 2**20:g} MiB per MuJoCo world) "
            f"but {have / 2**30:.1f} GiB is available; use fewer worlds"
        )


def _available_bytes() -> int:
    """Memory available to a new allocation, bytes (``MemAvailable``; the physical memory where it is unknown)."""
    try:
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")


def parse_pairs(text: str | None, gaits: list[str], *,
                identities: Mapping[str, str] | None = None) -> tuple[tuple[str, str], ...] | None:
    """``trot-stand,pace-stand`` -> ordered pairs; a bare gait name stands for every pair involving it, and
    ``fell:FILE`` for every pair in which a switch of the transition file FILE (a screen of the library's policies
    ``identities``, gait name -> identity) fell, by the default definition of a fall. A text that names no pair, or
    a pair with an empty side, is refused; so is a screen that does not read, or that names gaits outside
    ``gaits``."""
    if text is None:
        return None
    pairs: list[tuple[str, str]] = []
    for item in (part.strip() for part in text.split(",") if part.strip()):
        if item.startswith(SCREEN_PREFIX):
            pairs += _pairs_that_fell(item.removeprefix(SCREEN_PREFIX), gaits, identities=identities)
        elif "-" in item:
            m, n = (side.strip() for side in item.split("-", 1))
            if not (m and n):
                raise OptionError(f"--pairs '{text}': '{item}' is not a pair; give pairs like trot-stand")
            pairs.append((m, n))
        else:
            pairs += [(item, g) for g in gaits if g != item] + [(g, item) for g in gaits if g != item]
    if not pairs:
        raise OptionError(f"--pairs '{text}' names no pair; give pairs like trot-stand,pace-stand")
    return tuple(dict.fromkeys(pairs))


SCREEN_PREFIX = "fell:"
"""``--pairs fell:FILE``: the pairs in which a switch of the transition file FILE fell."""


def _pairs_that_fell(path: str, gaits: list[str], *,
                     identities: Mapping[str, str] | None) -> list[tuple[str, str]]:
    from gaitlib.errors import GaitlibError
    from gaitlib.transitions.combine import pairs_that_fell

    if identities is None:
        raise OptionError(f"--pairs {SCREEN_PREFIX}{path}: this command takes no screen; name the pairs")
    try:
        fell = pairs_that_fell(Path(path), current=identities, falls=DEFAULT_FALLS)
    except GaitlibError as error:
        raise OptionError(f"--pairs {SCREEN_PREFIX}{path}: {error}") from None
    outside = sorted({g for pair in fell for g in pair if g not in gaits})
    if outside:
        raise OptionError(f"--pairs {SCREEN_PREFIX}{path}: the screen holds gaits {', '.join(outside)}, "
                          "not in use here")
    return list(fell)


def parse_magnitudes(text: str) -> tuple[float, ...]:
    """``--magnitudes``: push magnitudes, N, each in :data:`PUSH_N` (see :func:`parse_values`)."""
    return parse_values(text, option="--magnitudes", bounds=PUSH_N, example="0:500:50")
