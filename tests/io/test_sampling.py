"""The frame interval and rate of a time column (solver.sampling), on every shared TRC file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from solver.io.trc import read_trc
from solver.sampling import frame_interval, frame_rate, nominal_interval, nominal_rate
from tests.conftest import SHARED_DATA as DATA

TRC_FILES = sorted(DATA.rglob("*.trc"))


@pytest.mark.parametrize("path", TRC_FILES, ids=lambda p: str(p.relative_to(DATA)))
def test_rate_of_a_time_column_is_its_header_rate_even_with_a_dropped_frame(path: Path) -> None:
    mk = read_trc(path)
    assert frame_rate(mk.time) == pytest.approx(mk.rate_hz, rel=1e-3)
    dropped = np.delete(np.asarray(mk.time), mk.time.size // 2)  # one frame lost in the middle
    assert frame_interval(dropped) == pytest.approx(1.0 / mk.rate_hz, rel=1e-3)


def test_fewer_than_two_frames_take_the_default_or_name_what_has_no_rate() -> None:
    time = read_trc(TRC_FILES[0]).time[:1]
    assert frame_rate(time, default=60.0) == 60.0
    assert frame_interval(time, default=0.01) == 0.01
    with pytest.raises(ValueError, match="trial walk: 1 frame"):
        frame_rate(time, what="trial walk")


@pytest.mark.parametrize("path", TRC_FILES, ids=lambda p: str(p.relative_to(DATA)))
def test_rate_of_a_time_column_is_the_nominal_rate_exactly(path: Path) -> None:
    """A time column of a whole-number rate gives that rate exactly (100.0 Hz, not
    99.99999999999991 Hz, in results.json and a .b3d header), and its interval the exact
    interval of that rate."""
    mk = read_trc(path)
    assert frame_rate(mk.time) == nominal_rate(mk.rate_hz) == round(mk.rate_hz), mk.rate_hz
    assert nominal_interval(frame_interval(mk.time)) == 1.0 / round(mk.rate_hz)


def test_a_rate_off_a_whole_number_is_kept_and_nonsense_passes_through() -> None:
    assert frame_rate(np.arange(1000) * 0.01) == 100.0  # median step 0.010000000000000009 s
    assert nominal_interval(0.010000000000000009) == 0.01
    assert nominal_rate(148.148) == 148.148 and nominal_rate(1999.9999999) == 2000.0
    assert nominal_rate(0.0) == 0.0 and np.isnan(nominal_rate(float("nan")))
    assert nominal_interval(-1.0) == -1.0
