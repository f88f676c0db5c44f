"""Every file gaitlib reads is validated by schema, not only by its checksum: an edited route table, handover-states
file, entry metadata or benchmark result with its checksum kept valid is refused in one line naming the file and the
field, and the shipped libraries still load (tests/fuzz/byte_flips.py --edits fuzzes the same readers)."""

from __future__ import annotations

import contextlib
import json
import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from conftest import copy_library, write_foreign_json

from gaitlib.atomic import write_json
from gaitlib.benchmark.results import load_results
from gaitlib.envs.handover import load_states
from gaitlib.errors import GaitlibError
from gaitlib.library import Library, library_status
from gaitlib.library.store import LibraryError
from gaitlib.strategies.routes import ROUTES_FILE, load_routes
from gaitlib.transitions.states import StatesConfig, record_states


def refused(call, error: type[Exception], *parts: str) -> str:
    """The one-line message ``call()`` raises as ``error``, which must hold each of ``parts``."""
    with pytest.raises(error) as raised:
        call()
    message = str(raised.value)
    assert "\n" not in message, message
    for part in parts:
        assert part in message, message
    return message


@pytest.mark.parametrize("root", ["library", "library-paper"])
def test_the_shipped_libraries_pass_their_schemas(root) -> None:
    library = Library(root)
    status = library_status(library)
    assert [g.problem for g in status.gaits] == [None] * len(status.gaits) and not status.problems
    if (library.switching_dir / ROUTES_FILE).is_file():
        assert load_routes(library, library.gaits()).detours()


@contextlib.contextmanager
def edited(path: Path, change) -> Iterator[None]:
    """``path``'s JSON changed by ``change`` with a matching checksum while the block runs, then put back."""
    pristine = path.read_text()
    content = json.loads(pristine)
    content.pop("checksum")
    change(content)
    write_foreign_json(path, content)
    try:
        yield
    finally:
        path.write_text(pristine)


@pytest.fixture(scope="module")
def shipped_copy(tmp_path_factory) -> Library:
    return copy_library(Library(), tmp_path_factory.mktemp("shipped") / "library")


@pytest.fixture(scope="module")
def routed_copy(tmp_path_factory) -> Library:
    """A copy of a committed library with a route table: the switch-start library's (the shipped one holds none
    since it grew)."""
    return copy_library(Library(Library().root.parent / "library-switch-start"),
                        tmp_path_factory.mktemp("routed") / "library")


ROUTE_EDITS = {
    "a success count above its total": (lambda t: t["rates"].update({"trot-stand": [1001, 1000]}),
                                        "rates.trot-stand counts 1001 successes of 1000 transitions"),
    "a negative push": (lambda t: t.update(push_n=-50.0), "push_n must be a finite number in [0, 2000] N, got -50.0"),
    "an unknown strategy": (lambda t: t.update(strategy="teleport"), "strategy must be one of random,"),
    "an unknown gait": (lambda t: t["gaits"].__setitem__(-1, "zebra"), "rates.bound-walk is not a pair of the table"),
    "a nan count": (lambda t: t["rates"]["pace-trot"].__setitem__(0, float("nan")),
                    "rates.pace-trot[0] must be a whole number >= 0, got nan"),
    "a total other than measured": (lambda t: t["rates"].update({"walk-pace": [10, 20]}),
                                    "rates.walk-pace counts 20 transitions, measured_with.samples 1000"),
}


@pytest.mark.parametrize("edit", list(ROUTE_EDITS), ids=list(ROUTE_EDITS))
def test_an_impossible_route_table_is_refused_naming_the_field(routed_copy, edit) -> None:
    path = routed_copy.switching_dir / ROUTES_FILE
    change, message = ROUTE_EDITS[edit]
    with edited(path, change):
        refused(lambda: load_routes(Library(routed_copy.root), routed_copy.gaits()), GaitlibError,
                f"{path} is damaged: ", message)
    assert load_routes(Library(routed_copy.root), routed_copy.gaits())  # the pristine table still loads


@pytest.fixture(scope="module")
def states_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("states") / "states.npz"
    config = StatesConfig(per_gait=3, num_worlds=2, warmup_s=0.2, spacing_s=0.1, backend="mujoco")
    record_states(Library(), gaits=["stand", "trot"], config=config).save(path)
    return path


def _quat_zero(a, m):
    a["root_quat"][0] = 0.0


def _trunk_high(a, m):
    a["root_height"][1] = 50.0


def _narrow_frames(a, m):
    a["history"] = a["history"][..., :-1]


def _nan_velocity(a, m):
    a["joint_vel"][2, 5] = np.nan


def _source_out_of_range(a, m):
    a["source"][0] = 2


def _identities_of_other_gaits(a, m):
    m["identities"] = {"pace": m["identities"]["stand"], "trot": m["identities"]["trot"]}


STATE_EDITS = {
    "a zero quaternion": (_quat_zero, "root_quat of state 0 is not a unit quaternion (norm 0)"),
    "a trunk at 50 m": (_trunk_high, "root_height of state 1 lies outside [0, 2] m"),
    "frames of the wrong width": (_narrow_frames, "history must have shape (6, 3, 34)"),
    "a non-finite velocity": (_nan_velocity, "joint_vel of state 2 is not finite"),
    "a gait index not listed": (_source_out_of_range, "source of state 0 is gait index 2, the file lists 2 gaits"),
    "identities of other gaits": (_identities_of_other_gaits, "identities name pace, trot, the file's gaits are stand"),
}


@pytest.mark.parametrize("edit", list(STATE_EDITS), ids=list(STATE_EDITS))
def test_impossible_handover_states_are_refused_naming_the_field(states_file, tmp_path, edit) -> None:
    with np.load(states_file) as npz:
        meta, arrays = json.loads(str(npz["meta"])), {k: npz[k] for k in npz.files if k != "meta"}
    change, message = STATE_EDITS[edit]
    change(arrays, meta)
    path = tmp_path / "edited.npz"
    np.savez(path, meta=np.array(json.dumps(meta)), **arrays)
    refused(lambda: load_states(path), GaitlibError, f"{path} is damaged: ", message)
    assert len(load_states(states_file)[0]) == 6


METADATA_EDITS = {
    "a fall rate above 1": (lambda m: m["evaluation"].update(fall_rate=1.5),
                            "evaluation.fall_rate must be a finite number in [0, 1], got 1.5"),
    "episodes as a string": (lambda m: m["evaluation"].update(episodes="256"),
                             "evaluation.episodes must be a whole number in [1, 65536], got '256'"),
    "a trunk at 50 m": (lambda m: m["description"].update(body_height=50.0),
                        "description.body_height must be a finite number in (0, 2] m, got 50.0"),
    "a negative layer": (lambda m: m["networks"]["actor_hidden"].__setitem__(0, -256),
                         "networks.actor_hidden[0] must be a whole number in [1, 65536], got -256"),
    "a delay range upside down": (lambda m: m["training"]["randomization"].update(action_delay_steps=[1, 0]),
                                  "training.randomization.action_delay_steps must be a range [low, high]"),
    "a changed stiffness in the deployment block": (lambda m: m["deployment"]["control"].update(kp=61.0),
                                                    "deployment.control.kp is not what the entry's own"),
    # The reference table's thousands of numbers are checked in one loop; a refusal still names the one that differs.
    "a reference number off by 1e-5": (lambda m: _row(m, 100).__setitem__(3, _row(m, 100)[3] + 1e-5),
                                       "deployment.reference.rows[100][3] is not what the entry's own"),
    "a reference number as true": (lambda m: _row(m, 5).__setitem__(0, True),
                                   "deployment.reference.rows[5][0] is not what the entry's own"),
    "a reference number as text": (lambda m: _row(m, 5).__setitem__(0, str(_row(m, 5)[0])),
                                   "deployment.reference.rows[5][0] is not what the entry's own"),
    "a reference row cut short": (lambda m: _row(m, 7).pop(),
                                  "deployment.reference.rows[7] is not what the entry's own"),
    "a nan in the reference table": (lambda m: _row(m, 7).__setitem__(2, float("nan")),
                                     "deployment.reference.rows[7][2] must be a finite number, got nan"),
}


def _row(metadata: dict, k: int) -> list:
    """Row ``k`` of an entry's reference table, as its deployment block holds it."""
    return metadata["deployment"]["reference"]["rows"][k]


def test_a_reference_number_within_the_tables_rounding_is_accepted(shipped_copy) -> None:
    path = shipped_copy.root / "stand" / "metadata.json"
    with edited(path, lambda m: _row(m, 100).__setitem__(3, _row(m, 100)[3] + 1e-6)):
        assert Library(shipped_copy.root).entry("stand").identity


@pytest.mark.parametrize("edit", list(METADATA_EDITS), ids=list(METADATA_EDITS))
def test_impossible_entry_metadata_is_refused_naming_the_field(shipped_copy, edit) -> None:
    path = shipped_copy.root / "stand" / "metadata.json"
    change, message = METADATA_EDITS[edit]
    with edited(path, change):
        refused(lambda: Library(shipped_copy.root).entry("stand"), LibraryError,
                "library entry 'stand' has damaged metadata: ", message, str(path))
    assert Library(shipped_copy.root).entry("stand").identity


def _results() -> dict:
    """Benchmark results of one finished group (two gaits, both pairs), as a sweep writes them."""
    cell = {"samples": 10, "successes": 9, "forced": 1, "wait_s": 0.5, "switched": 10, "source_falls": 2,
            "touched": 3, "longest_touch_s": 0.2}
    return {
        "format": "gaitlib.benchmark", "format_version": 3,
        "settings": {"strategies": ["net"], "magnitudes": [0.0, 100.0], "samples": 10,
                     "pairs": [["stand", "trot"], ["trot", "stand"]], "num_worlds": 4, "seed": 0, "falls": "trunk",
                     "warmup_s": 1.0, "source_extra_s": 1.0, "horizon_s": 2.5, "deadline_s": 2.0,
                     "push_lead_s": 0.6, "push_duration_s": [0.1, 0.3], "push_interval_s": [0.2, 1.0],
                     "switching": "a" * 64},
        "library_identities": {"stand": "b" * 64, "trot": "c" * 64},
        "groups": {"net@100": {"strategy": "net", "magnitude_n": 100.0, "backend": "mujoco", "elapsed_s": 12.5,
                               "cells": {"stand-trot": dict(cell), "trot-stand": dict(cell)}}},
    }


def _cell(results: dict) -> dict:
    return results["groups"]["net@100"]["cells"]["trot-stand"]


RESULT_EDITS = {
    "a success count above its samples": (lambda r: _cell(r).update(successes=11),
                                          "groups.net@100.cells.trot-stand.successes is 11, more than the 10"),
    "a negative count": (lambda r: _cell(r).update(touched=-1),
                         "groups.net@100.cells.trot-stand.touched must be a whole number >= 0, got -1"),
    "more forced switches than switches": (lambda r: _cell(r).update(forced=11),
                                           "groups.net@100.cells.trot-stand.forced is 11, more than the 10 switches"),
    "an unknown strategy": (lambda r: r["groups"]["net@100"].update(strategy="teleport"),
                            "groups.net@100.strategy must be one of random,"),
    "a negative magnitude": (lambda r: r["settings"].update(magnitudes=[-100.0]),
                             "settings.magnitudes[0] must be a finite number in [0, 2000] N, got -100.0"),
    "an infinite wait": (lambda r: _cell(r).update(wait_s=float("inf")),
                         "groups.net@100.cells.trot-stand.wait_s must be a finite number >= 0 s, got inf"),
    "a pair of a gait not measured": (lambda r: r["settings"]["pairs"].append(["stand", "pace"]),
                                      "settings.pairs[2] names pace, which library_identities does not list"),
}


@pytest.mark.parametrize("edit", list(RESULT_EDITS), ids=list(RESULT_EDITS))
def test_impossible_benchmark_results_are_refused_naming_the_field(tmp_path, edit) -> None:
    write_json(tmp_path / "results.json", _results(), checksum=True)
    assert load_results(tmp_path)["groups"]["net@100"]["cells"]["trot-stand"]["successes"] == 9
    change, message = RESULT_EDITS[edit]
    results = _results()
    change(results)
    write_foreign_json(tmp_path / "results.json", results)
    refused(lambda: load_results(tmp_path), GaitlibError, f"{tmp_path / 'results.json'} is damaged: ", message)


def test_a_refusal_names_the_field_and_its_range() -> None:
    from gaitlib.checks import Invalid, items, number, record

    schema = record({"rates": items(number(0, 1000, whole=True), length=2)})
    with pytest.raises(Invalid, match=re.escape("rates[1] must be a whole number in [0, 1000], got 1000.5")):
        schema({"rates": [3, 1000.5]}, "")
    with pytest.raises(Invalid, match=re.escape("rates is missing")):
        schema({}, "")
