"""The frame interval and rate of a time column (solver.sampling), on every shared TRC file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from solver.io.trc import read_trc
from solver.sampling import frame_interval, frame_rate
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
