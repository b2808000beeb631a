"""Property tests of the record's frame-range conversions (frame indices -> ranges -> mask).
Runs of masks, resampling and joining are the solver's (tests/dynamics/test_masks.py)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from annotations import AnnotationError, frames_to_ranges, ranges_to_mask

masks = st.lists(st.booleans(), max_size=300).map(lambda xs: np.array(xs, dtype=bool))


@given(masks)
def test_flagged_frames_to_ranges_round_trip(mask: np.ndarray) -> None:
    ranges = frames_to_ranges(np.flatnonzero(mask))
    np.testing.assert_array_equal(ranges_to_mask(ranges, mask.size), mask)
    # sorted, non-empty, disjoint and non-adjacent (so the representation is unique)
    for (s0, e0), (s1, e1) in itertools.pairwise(ranges):
        assert s0 < e0 < s1 < e1
    assert sum(e - s for s, e in ranges) == int(mask.sum())


@given(st.lists(st.tuples(st.integers(0, 80), st.integers(0, 40)), max_size=12))
def test_ranges_to_mask_is_union_of_overlapping_ranges(pairs: list[tuple[int, int]]) -> None:
    ranges = [(s, s + n) for s, n in pairs]
    mask = ranges_to_mask(ranges, 130)
    expected = np.zeros(130, dtype=bool)
    for s, e in ranges:
        expected[s:e] = True
    np.testing.assert_array_equal(mask, expected)
    # canonical form is a fixed point
    canon = frames_to_ranges(np.flatnonzero(mask))
    assert frames_to_ranges(np.flatnonzero(ranges_to_mask(canon, 130))) == canon


@given(st.sets(st.integers(0, 500), max_size=60))
def test_frames_to_ranges_covers_exactly_the_frames(frames: set[int]) -> None:
    ranges = frames_to_ranges(frames)
    covered = {f for s, e in ranges for f in range(s, e)}
    assert covered == frames
    assert ranges == frames_to_ranges(np.flatnonzero(ranges_to_mask(ranges, 501)))


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: ranges_to_mask([(5, 3)], 10), "start <= stop"),
        (lambda: ranges_to_mask([(5, 11)], 10), "within"),
        (lambda: ranges_to_mask([(0, 1)], -1), "non-negative"),
        (lambda: frames_to_ranges([-1, 2]), ">= 0"),
    ],
)
def test_bad_inputs_raise_annotation_error(call, message: str) -> None:
    with pytest.raises(AnnotationError, match=message):
        call()
