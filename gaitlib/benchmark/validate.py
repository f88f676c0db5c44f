"""Validation by schema of the benchmark's results, a sweep's ``OUT/results.json`` (:func:`check_results`); a library's
route table is checked where it is read (:func:`gaitlib.strategies.routes.check_routes`).

Beyond types and ranges, the counts must agree with one another (successes, touches and switches within the
transitions counted, every cell of the sweep's number of samples, a touch counted where a longest touch is), every
pair must be named by the file's gaits and every strategy known (:func:`gaitlib.strategies.strategy_names`). A
refusal is one line naming the file and the field.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from itertools import pairwise
from pathlib import Path

from gaitlib.checks import (
    GAIT_NAME,
    SHA256,
    Invalid,
    check_content,
    items,
    number,
    plain,
    record,
    span,
    table,
    text,
)
from gaitlib.defaults import Falls
from gaitlib.errors import GaitlibError

__all__ = ["BACKENDS", "SWITCH_STEP_S", "check_results"]

BACKENDS = ("mujoco", "newton")
"""Backends a group may have run on (``auto`` is resolved before a group runs)."""

SWITCH_STEP_S = 0.1
"""Slack per switch on the times a file counts, s: waits and touches are whole control steps (1/30 s), so a wait
forced at the deadline may exceed it by half a step."""

_PUSH_N = number(0, 2000, unit="N")
_SEED = number(0, 2**32 - 1, whole=True)
_WORLDS = number(1, 65536, whole=True)
_SAMPLES = number(1, 1e6, whole=True)
_COUNT = number(0, whole=True)
_SECONDS = number(0, 600, unit="s")
_PAIR = text(pattern="[^-, ]+-[^-, ]+", what="a pair of gaits 'm-n'")
_PROTOCOL = {"warmup_s": _SECONDS, "source_extra_s": _SECONDS, "horizon_s": number(0, 600, low_open=True, unit="s"),
             "deadline_s": _SECONDS}


def _settings(strategies: Sequence[str]) -> Callable[[object, str], None]:
    return record(
        {
            "strategies": items(text(tuple(strategies)), low=1, unique=True),
            "magnitudes": items(_PUSH_N, low=1, high=1000, unique=True),
            "samples": _SAMPLES, "pairs": items(items(GAIT_NAME, length=2), low=1, unique=True),
            "num_worlds": _WORLDS, "seed": _SEED, "falls": text(tuple(Falls)), **_PROTOCOL,
            "push_lead_s": _SECONDS, "push_duration_s": span(0, 600, unit="s"),
            "push_interval_s": span(0, 600, unit="s"),
        },
        {
            "switching": text(pattern="[0-9a-f]{64}", what="a SHA-256 (64 hex digits)", nullable=True),
            "routes": table(_PAIR, items(GAIT_NAME, low=2)),
            "robot": text(), "robot_sha256": SHA256,
            "action_delay": number(0, 10, whole=True), "motor_strength": number(0, 10, low_open=True),
        },
        extra=plain(),
    )


def check_results(results: Mapping, *, path: Path, strategies: Sequence[str],
                  group_key: Callable[[str, float], str]) -> None:
    """Refuse, in one line, benchmark results (as :func:`~gaitlib.atomic.read_json` returns them) that are not of
    the format: types and ranges, pairs or routes not of the measured gaits, a group under another key than its
    strategy and magnitude, of a strategy or magnitude the settings do not name, without a cell of each pair, or
    with counts that cannot be (more successes, touches or switches than transitions, another number of
    transitions than the settings' samples, more forced switches than switches, waits beyond the deadline)."""
    cell = record({"samples": _COUNT, "successes": _COUNT, "forced": _COUNT, "wait_s": number(0, unit="s"),
                   "switched": _COUNT, "source_falls": _COUNT, "touched": _COUNT,
                   "longest_touch_s": number(0, unit="s")})
    group = record({"strategy": text(tuple(strategies)), "magnitude_n": _PUSH_N, "backend": text(BACKENDS),
                    "elapsed_s": number(0, unit="s"), "cells": table(_PAIR, cell, low=1)},
                   {"guard": record({"catches": _COUNT, "by_pair": table(_PAIR, _COUNT)}, extra=plain())})
    schema = record({"format": text(), "format_version": number(whole=True), "settings": _settings(strategies),
                     "library_identities": table(GAIT_NAME, SHA256, low=1), "groups": table(text(), group)})
    check_content(results, schema, error=GaitlibError, prefix=f"{path} is damaged: ")
    settings, gaits = results["settings"], results["library_identities"]
    try:
        legs = _legs(settings, gaits, group_key)
        _check_groups(results["groups"], settings, legs, group_key)
    except Invalid as refused:
        raise GaitlibError(f"{path} is damaged: {refused}") from None


def _legs(settings: Mapping, gaits: Mapping, group_key: Callable[[str, float], str]) -> dict[str, int]:
    """Pair -> the switches one of its transitions makes (its route's legs), each pair checked against the gaits."""
    keys = [group_key("", m) for m in settings["magnitudes"]]
    if len(set(keys)) != len(keys):
        raise Invalid("settings.magnitudes", "names one magnitude twice (to the millinewton)")
    legs = {}
    for i, (m, n) in enumerate(settings["pairs"]):
        for gait in (m, n):
            if gait not in gaits:
                raise Invalid(f"settings.pairs[{i}]", f"names {gait}, which library_identities does not list")
        if m == n:
            raise Invalid(f"settings.pairs[{i}]", f"switches {m} to itself")
        legs[f"{m}-{n}"] = 1
    for pair, path in settings.get("routes", {}).items():
        if pair not in legs or f"{path[0]}-{path[-1]}" != pair or any(a == b for a, b in pairwise(path)):
            raise Invalid(f"settings.routes.{pair}", "does not lead from one gait to another of a measured pair")
        unknown = [g for g in path if g not in gaits]
        if unknown:
            raise Invalid(f"settings.routes.{pair}", f"names {unknown[0]}, which library_identities does not list")
        legs[pair] = len(path) - 1
    return legs


def _check_groups(groups: Mapping, settings: Mapping, legs: Mapping[str, int],
                  group_key: Callable[[str, float], str]) -> None:
    magnitudes = {group_key("", m) for m in settings["magnitudes"]}
    samples, deadline, horizon = settings["samples"], settings["deadline_s"], settings["horizon_s"]
    for key, group in groups.items():
        where = f"groups.{key}"
        if key != group_key(group["strategy"], group["magnitude_n"]):
            raise Invalid(where, f"holds {group['strategy']} at {group['magnitude_n']:g} N, not what its key says")
        if group["strategy"] not in settings["strategies"]:
            raise Invalid(f"{where}.strategy", f"{group['strategy']} is not one of settings.strategies")
        if group_key("", group["magnitude_n"]) not in magnitudes:
            raise Invalid(f"{where}.magnitude_n", f"{group['magnitude_n']:g} N is not one of settings.magnitudes")
        cells = group["cells"]
        if set(cells) != set(legs):
            odd = sorted(set(cells) ^ set(legs))[0]
            raise Invalid(f"{where}.cells", f"{'holds' if odd in cells else 'lacks'} the pair {odd} (the measured "
                          f"pairs are settings.pairs)")
        for pair, c in cells.items():
            at = f"{where}.cells.{pair}"
            n = c["samples"]
            if n != samples:
                raise Invalid(f"{at}.samples", f"is {n}, settings.samples {samples}")
            for name, most, of in (("successes", n, "transitions"), ("touched", n, "transitions"),
                                   ("switched", n * legs[pair], "switches its transitions can make"),
                                   ("forced", c["switched"], "switches"), ("successes", c["switched"], "switches")):
                if c[name] > most:
                    raise Invalid(f"{at}.{name}", f"is {c[name]}, more than the {most} {of}")
            if c["wait_s"] > c["switched"] * (deadline + SWITCH_STEP_S):
                raise Invalid(f"{at}.wait_s", f"is {c['wait_s']:g} s, more than {c['switched']} switches can wait "
                              f"(deadline {deadline:g} s)")
            if c["longest_touch_s"] > deadline + horizon + 2 * SWITCH_STEP_S:
                raise Invalid(f"{at}.longest_touch_s", f"is {c['longest_touch_s']:g} s, longer than a transition "
                              f"is watched ({deadline:g} + {horizon:g} s)")
            if (c["touched"] == 0) != (c["longest_touch_s"] == 0):
                raise Invalid(f"{at}.touched", f"is {c['touched']} with a longest touch of {c['longest_touch_s']:g} s")
