"""Which pairs of a collection run (strl_pyg.collection.pairs)."""

from __future__ import annotations

import pytest

from strl_pyg.collection.pairs import (
    Pair,
    exhaustive_pairs,
    parse_pairs,
    read_pairs_file,
    sequential_pairs,
)

NAMES = ["a.jpg", "b.jpg", "sub/c.jpg", "d.jpg"]


def test_exhaustive_and_sequential_counts():
    assert exhaustive_pairs(4) == [Pair(0, 1), Pair(0, 2), Pair(0, 3), Pair(1, 2), Pair(1, 3),
                                   Pair(2, 3)]
    assert len(exhaustive_pairs(10)) == 45
    assert sequential_pairs(4, 2) == [Pair(0, 1), Pair(0, 2), Pair(1, 2), Pair(1, 3),
                                      Pair(2, 3)]
    assert len(sequential_pairs(10, 3)) == 9 + 8 + 7
    for bad in (0, -1, True, 1.5):
        with pytest.raises(ValueError, match="window >= 1"):
            sequential_pairs(4, bad)


def test_hloc_pairs_file(tmp_path):
    path = tmp_path / "pairs.txt"
    path.write_text("# hloc\na.jpg b.jpg\n\nsub/c.jpg d.jpg\nb.jpg a.jpg\nc.jpg a.jpg\n")
    # the repeated pair (b, a) is kept once; a bare file name finds 'sub/c.jpg'
    assert read_pairs_file(path, NAMES) == [Pair(0, 1), Pair(2, 3), Pair(2, 0)]


def test_superglue_pairs_carry_a_K_per_pair():
    K0 = "500 0 320 0 500 240 0 0 1"
    K1 = "600 0 300 0 610 200 0 0 1"
    T = " ".join(["1", "0", "0", "0"] * 4)
    (p,) = parse_pairs([f"a.jpg d.jpg 0 0 {K0} {K1} {T}"], NAMES)
    assert (p.i, p.j) == (0, 3)
    assert p.K0[0] == (500.0, 0.0, 320.0) and p.K1[1] == (0.0, 610.0, 200.0)


@pytest.mark.parametrize("line, match", [
    ("a.jpg", "got 1 fields"),
    ("a.jpg x.jpg", "got 'x.jpg', not among its 4 images"),
    ("a.jpg a.jpg", "two different images"),
    ("a.jpg b.jpg 90 0 " + "1 " * 34, "EXIF rotations 0"),
    ("a.jpg b.jpg 0 0 " + "x " * 34, "numbers after the names"),
    ("a.jpg b.jpg 0 0 " + "0 " * 34, "positive focal lengths"),
])
def test_bad_lines_are_one_line_errors(line, match):
    with pytest.raises(ValueError, match=match) as err:
        parse_pairs([line], NAMES, "'p.txt'")
    assert "\n" not in str(err.value) and "line 1" in str(err.value)


def test_empty_and_missing_files(tmp_path):
    with pytest.raises(ValueError, match="at least one pair"):
        parse_pairs(["# nothing"], NAMES)
    with pytest.raises(FileNotFoundError, match="pairs file"):
        read_pairs_file(tmp_path / "none.txt", NAMES)
