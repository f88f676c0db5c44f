"""``gaitlib map``: the transition map of a file, checked against hand-counted samples."""

from __future__ import annotations

import json

import numpy as np
import pytest
from cli_runner import gaitlib_quick
from test_transitions import make_file, synthetic

from gaitlib.benchmark.maps import fall_time_quantile, transition_maps, write_map_json, write_map_plot
from gaitlib.transitions.records import TransitionBatch, TransitionData, TransitionFileInfo, TransitionHeader


def _data(source, dest, phase_source, phase_dest, success, contacts, fall_after) -> TransitionData:
    n = len(source)
    explicit = np.zeros((n, 66), dtype=np.float32)
    explicit[:, 18:22] = np.asarray(contacts) + 0.02  # newest frame's foot contacts, with a little noise
    batch = TransitionBatch(
        source=source, dest=dest, latent=np.zeros((n, 4)), phase_source=phase_source, phase_dest=phase_dest,
        explicit=explicit, value_source=np.zeros(n), value_dest=np.zeros(n), push_force=np.zeros(n),
        success=success, switch_time=np.ones(n), world=np.zeros(n), chunk=np.zeros(n), fall_after=fall_after,
    )
    header = TransitionHeader(gaits=("stand", "trot"), identities=("a", "b"), latent_dim=4, settings={})
    return TransitionData(TransitionFileInfo(header, n, [], None), batch)


SAMPLES = _data(
    source=[1, 1, 1, 1, 1, 0],
    dest=[0, 0, 0, 0, 0, 1],
    phase_source=[0.05, 0.1, 0.55, 0.6, 0.95, 0.3],
    phase_dest=[0.2, 0.7, 0.2, 0.2, 0.9, 0.5],
    success=[1, 1, 0, 0, 1, 1],
    contacts=[[1, 0, 0, 1], [1, 0, 0, 1], [0, 0, 0, 0], [0, 1, 1, 0], [1, 0, 0, 1], [1, 1, 1, 1]],
    fall_after=[np.inf, np.inf, 0.3, 1.2, np.inf, np.inf],
)


def test_the_map_counts_each_switch_in_its_bins() -> None:
    stand_trot, trot_stand = transition_maps(SAMPLES, bins=2)
    assert stand_trot.pair == "stand-trot" and stand_trot.overall.samples == 1
    assert trot_stand.pair == "trot-stand"
    assert (trot_stand.overall.samples, trot_stand.overall.successes) == (5, 3)
    # Source bins [0, 0.5) and [0.5, 1): rows 0, 1 (both up); rows 2, 3, 4 (one up). Destination likewise.
    assert trot_stand.grid_samples == [[1, 1], [2, 1]]
    assert trot_stand.grid_success == [[1.0, 1.0], [0.0, 1.0]]
    assert [r.samples for r in trot_stand.by_source_phase] == [2, 3]
    best, worst = trot_stand.best_worst_source_bins()
    assert (best.rate, worst.rate) == (1.0, pytest.approx(1 / 3))
    assert worst.ci95[0] < 1 / 3 < worst.ci95[1]
    assert {k: (r.samples, r.successes) for k, r in trot_stand.by_contacts.items()} == {
        "FR+RL": (3, 3), "none": (1, 0), "FL+RR": (1, 0),
    }
    assert trot_stand.fall_after_s == [pytest.approx(0.3), pytest.approx(1.2)]
    assert fall_time_quantile([stand_trot, trot_stand], 0.5) == pytest.approx(0.75)


def test_empty_bins_are_null_in_json_and_the_plot_is_written(tmp_path) -> None:
    maps = transition_maps(SAMPLES, bins=4)
    written = json.loads(write_map_json(maps, tmp_path / "map.json", source="x.h5", falls="trunk").read_text())
    assert written["source"] == "x.h5" and written["fall_after_s_q99"] == pytest.approx(1.191)
    assert written["pairs"][0]["grid_success"][0][0] is None  # stand-trot: one sample, in bin (1, 2)
    assert written["pairs"][0]["grid_success"][1][2] == 1.0
    assert write_map_plot(maps, tmp_path / "map.png").read_bytes()[:4] == b"\x89PNG"


def test_the_command_writes_the_map_of_a_file(tmp_path) -> None:
    path = tmp_path / "t.h5"
    make_file(path, synthetic(40))
    result = gaitlib_quick("map", str(path), "--bins", "5")
    assert result.returncode == 0, result.stderr
    assert "random switch" in result.stdout and "stand-trot" in result.stdout
    body = json.loads((tmp_path / "t-map" / "map.json").read_text())
    assert sum(p["overall"]["samples"] for p in body["pairs"]) == 40
    assert (tmp_path / "t-map" / "map.png").is_file()
