"""Property tests of the mask <-> range conversions (what the solver takes <-> what is stored)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from annotations import (
    AnnotationError,
    frames_to_ranges,
    mask_to_ranges,
    ranges_to_mask,
    resample_mask,
)

masks = st.lists(st.booleans(), max_size=300).map(lambda xs: np.array(xs, dtype=bool))


@given(masks)
def test_mask_to_ranges_round_trip(mask: np.ndarray) -> None:
    ranges = mask_to_ranges(mask)
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
    canon = mask_to_ranges(mask)
    assert mask_to_ranges(ranges_to_mask(canon, 130)) == canon


@given(st.sets(st.integers(0, 500), max_size=60))
def test_frames_to_ranges_covers_exactly_the_frames(frames: set[int]) -> None:
    ranges = frames_to_ranges(frames)
    covered = {f for s, e in ranges for f in range(s, e)}
    assert covered == frames
    assert ranges == mask_to_ranges(ranges_to_mask(ranges, 501))


@given(
    masks,
    st.sampled_from([50.0, 100.0, 120.0, 200.0, 250.0, 2000.0]),
    st.sampled_from([50.0, 100.0, 120.0, 200.0, 250.0, 2000.0]),
)
@settings(max_examples=150)
def test_resample_mask_is_conservative(mask: np.ndarray, f_in: float, f_out: float) -> None:
    out = resample_mask(mask, from_hz=f_in, to_hz=f_out)
    assert out.dtype == np.bool_
    assert out.size == round(mask.size * f_out / f_in)
    # every flagged input instant (frame centre) lies in a flagged output frame
    for i in np.flatnonzero(mask):
        j = int(np.floor(i * f_out / f_in + 0.5))
        if j < out.size:
            assert out[j], (i, j)
    # an unflagged output frame overlaps no flagged input frame
    for j in np.flatnonzero(~out):
        lo, hi = (j - 0.5) / f_out, (j + 0.5) / f_out
        touching = [
            i for i in np.flatnonzero(mask) if (i - 0.5) / f_in < hi and (i + 0.5) / f_in > lo
        ]
        overlap = [
            i for i in touching if min(hi, (i + 0.5) / f_in) - max(lo, (i - 0.5) / f_in) > 1e-12
        ]
        assert not overlap, (j, overlap)


@given(masks)
def test_resample_mask_same_rate_is_identity(mask: np.ndarray) -> None:
    np.testing.assert_array_equal(resample_mask(mask, from_hz=100.0, to_hz=100.0), mask)


def test_resample_mask_example_100_to_200_hz() -> None:
    mask = np.array([0, 1, 1, 0, 0], dtype=bool)
    # input frames 1..2 cover [0.005, 0.025) s; 200 Hz frame j covers [(j - .5), (j + .5)) * 5 ms,
    # so frames 1..5 overlap it (frame 5, [0.0225, 0.0275) s, by 2.5 ms)
    np.testing.assert_array_equal(
        resample_mask(mask, from_hz=100, to_hz=200),
        np.array([0, 1, 1, 1, 1, 1, 0, 0, 0, 0], dtype=bool),
    )
    # and back: 200 Hz frames 2..4 (10..20 ms) -> 100 Hz frames 1..2
    np.testing.assert_array_equal(
        resample_mask(np.array([0, 0, 1, 1, 1, 0, 0, 0], dtype=bool), from_hz=200, to_hz=100),
        np.array([0, 1, 1, 0], dtype=bool),
    )


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: mask_to_ranges(np.zeros((3, 2), dtype=bool)), "shape"),
        (lambda: mask_to_ranges(np.array([0, 1, 2])), "boolean"),
        (lambda: ranges_to_mask([(5, 3)], 10), "start <= stop"),
        (lambda: ranges_to_mask([(5, 11)], 10), "within"),
        (lambda: ranges_to_mask([(0, 1)], -1), "non-negative"),
        (lambda: frames_to_ranges([-1, 2]), ">= 0"),
        (lambda: resample_mask(np.ones(3, bool), from_hz=0.0, to_hz=100.0), "> 0"),
    ],
)
def test_bad_inputs_raise_annotation_error(call, message: str) -> None:
    with pytest.raises(AnnotationError, match=message):
        call()
