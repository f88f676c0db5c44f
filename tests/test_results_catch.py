"""The catch skill's tables from small evidence: the catch alone at the guard's moment (bold within each impulse's
goal, the gaits that miss it named with the points they miss by), and each entry shoved three ways on the same draws
(an entry new to the library and draws that differ are said so)."""

from __future__ import annotations

from pathlib import Path

from benchmarks.results.catch_skill import catch_alone, guard_with_catch
from tests.test_results_doc import _guarded_shove, _store


def _arm(falls: int, episodes: int = 1024) -> dict:
    return {"falls": falls, "episodes": episodes, "fall_rate": falls / episodes}


def test_the_catch_alone_from_small_evidence(tmp_path: Path) -> None:
    rows = [{"gait": "pace", "impulse_ns": 12.0, "stay": _arm(73), "catch": _arm(17)},
            {"gait": "stand", "impulse_ns": 12.0, "stay": _arm(29), "catch": _arm(3)},
            {"gait": "pace", "impulse_ns": 18.0, "stay": _arm(300), "catch": _arm(90)}]
    _store(tmp_path, "alone", {"catch": "catch", "delay_steps": 2, "episodes": 1024, "rows": rows})
    lines = catch_alone(tmp_path).splitlines()
    assert lines[2] == "| pace | 7.1% [5.7, 8.9] | 1.7% [1.0, 2.6] | 29.3% [26.6, 32.2] | **8.8% [7.2, 10.7]** |"
    assert lines[3] == "| stand | 2.8% [2.0, 4.0] | **0.3% [0.1, 0.9]** | - | - |"
    assert "at 12 N s 99.0% stay up: missed by pace by 0.7 points" in " ".join(lines)
    assert "at 18 N s 90.0% stay up: met by every gait" in " ".join(lines)
    assert catch_alone(tmp_path / "none").startswith("Not yet measured:")


def test_each_entry_shoved_three_ways_from_small_evidence(tmp_path: Path) -> None:
    unguarded = _guarded_shove(40, {"left": 30}, []) | {"guard": {"on": False}}
    other_draws = _guarded_shove(40, {"right": 30}, []) | {"guard": {"on": False}}
    caught = _guarded_shove(8, {"left": 8}, [2, 3])
    caught["guard"]["catches"] = [{"to": "catch", "delay_steps": 2}, {"to": "trot", "delay_steps": -1}]
    caught["guard"]["false_catches"] = 1
    _store(tmp_path, "shove-12-pace-catch", {"points": [caught], "unguarded_points": [unguarded]})
    _store(tmp_path, "shove-12-pace-grown", {"points": [_guarded_shove(50, {}, [])], "unguarded_points": [unguarded]})
    _store(tmp_path, "shove-12-walk-catch", {"points": [caught], "unguarded_points": [unguarded]})
    _store(tmp_path, "shove-12-walk-grown", {"points": [_guarded_shove(5, {}, [])],
                                             "unguarded_points": [other_draws]})
    _store(tmp_path, "shove-12-catch-catch", {"points": [caught], "unguarded_points": [unguarded]})
    _store(tmp_path, "shove-12-pace-imu-catch", {"points": [], "unguarded_points": []})  # another tag's: not read
    lines = guard_with_catch(tmp_path).splitlines()
    assert lines[2] == ("| pace | 12 N s | 3.9% [2.9, 5.3] | 4.9% [3.7, 6.4] | **0.8% [0.4, 1.5]** | left, 8 of 256 | "
                        "2 (1; 1) | met pooled; left missed by 2.1 points |")
    assert lines[3] == ("| walk | 12 N s | 3.9% [2.9, 5.3] | **0.5% [0.2, 1.1]** (other draws) | **0.8% [0.4, 1.5]** "
                        "| left, 8 of 256 | 2 (1; 1) | met pooled; left missed by 2.1 points |")
    assert lines[4].startswith("| catch | 12 N s | 3.9% [2.9, 5.3] | - (not in the library before) |")
    _store(tmp_path, "shove-18-pace-catch", {"points": [_guarded_shove(150, {"right": 150}, [], impulse=18.0)],
                                             "unguarded_points": [unguarded]})
    assert guard_with_catch(tmp_path).splitlines()[5].endswith("| missed by 4.6 points; right by 48.6 |")
    assert lines[5] == ""
    assert guard_with_catch(tmp_path / "none").startswith("Not yet measured:")
