"""``--pairs fell:FILE``: the pairs of a screen in which a switch fell, the growth's allocation by need
(``docs/transitions.md``, "Growing by extension")."""

from __future__ import annotations

import numpy as np
import pytest

from gaitlib.cli.options import parse_pairs
from gaitlib.defaults import DEFAULT_FALLS
from gaitlib.library import Library
from gaitlib.transitions import read
from gaitlib.values import OptionError


def _screen(switching_library):
    return switching_library.parent / "samples.h5"


def test_the_pairs_that_fell_are_those_with_a_failed_switch(switching_library):
    library = Library(switching_library)
    path = _screen(switching_library)
    data = read(path).labelled(DEFAULT_FALLS)
    s, gaits = data.samples, data.header.gaits
    expected = {(gaits[m], gaits[n]) for m, n in s.pairs()
                if not s.success[(s.source == m) & (s.dest == n)].astype(bool).all()}
    kept = {(gaits[m], gaits[n]) for m, n in s.pairs()} - expected
    assert expected, "the screen must hold a pair that fell for the test to mean anything"
    pairs = parse_pairs(f"fell:{path}", library.gaits(), identities=library.identities())
    assert set(pairs) == expected
    assert not kept & set(pairs)
    both = parse_pairs(f"fell:{path},stand-trot", library.gaits(), identities=library.identities())
    assert set(both) == expected | {("stand", "trot")} and len(both) == len(set(both))


def test_a_screen_of_other_policies_holds_no_pair(switching_library):
    library = Library(switching_library)
    foreign = dict.fromkeys(library.gaits(), "0" * 64)
    with pytest.raises(OptionError, match=r"fell:.*no sample .* current policies"):
        parse_pairs(f"fell:{_screen(switching_library)}", library.gaits(), identities=foreign)


def test_a_screen_is_refused_where_no_library_is_given_or_the_file_does_not_read(switching_library, tmp_path):
    library = Library(switching_library)
    with pytest.raises(OptionError, match="takes no screen"):
        parse_pairs(f"fell:{_screen(switching_library)}", library.gaits())
    junk = tmp_path / "junk.h5"
    junk.write_bytes(np.arange(64, dtype=np.uint8).tobytes())
    with pytest.raises(OptionError, match=r"fell:.*junk\.h5"):
        parse_pairs(f"fell:{junk}", library.gaits(), identities=library.identities())
    with pytest.raises(OptionError, match="fell:"):
        parse_pairs(f"fell:{tmp_path / 'missing.h5'}", library.gaits(), identities=library.identities())


def test_collect_takes_the_pairs_that_fell_in_a_screen(switching_library, tmp_path):
    from cli_runner import gaitlib_quick

    library = Library(switching_library)
    screen = _screen(switching_library)
    expected = parse_pairs(f"fell:{screen}", library.gaits(), identities=library.identities())
    out = tmp_path / "top-up.h5"
    done = gaitlib_quick("collect", "--library", str(library.root), "--pairs", f"fell:{screen}", "--samples", "8",
                         "--worlds", "8", "--horizon", "1.0", "--backend", "mujoco", "--seed", "3", "--out", str(out))
    assert done.returncode == 0, done.stderr
    data = read(out)
    gaits = data.header.gaits
    assert {(gaits[m], gaits[n]) for m, n in data.samples.pairs()} == set(expected)
    refused = gaitlib_quick("collect", "--library", str(library.root), "--pairs", f"fell:{tmp_path / 'none.h5'}",
                            "--samples", "8", "--out", str(tmp_path / "other.h5"))
    assert refused.returncode == 2 and "fell:" in refused.stderr and not (tmp_path / "other.h5").exists()
