"""Chart data (addb_viewer.app.plots) and trial figures (addb_viewer.app.summary): finite
arrays, per-frame shading, the cursor line, per-foot GRF, Hicks thresholds, the
before/after table, and NaN dynamics shown as "not available"."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from addb_viewer.app.plots import PROPOSAL_BAND, chart_arrays, frame_grid, grf_lines, residual_lines
from addb_viewer.app.summary import (
    HICKS_FORCE_FRACTION,
    comparison_markdown,
    hicks_exceeded,
    hicks_thresholds,
    net_plate_force,
    trial_summary,
)
from solver.results import load_processed


@pytest.fixture
def walk(demo_processed):
    return load_processed(demo_processed, "walk")


def test_chart_arrays_are_finite_with_shades_and_a_cursor() -> None:
    t = np.arange(6) / 100.0
    y = np.array([0.0, 1.0, np.nan, 3.0, 4.0, 5.0])
    flagged = np.array([0, 1, 1, 0, 0, 0], bool)
    proposed = np.array([0, 0, 0, 0, 1, 0], bool)
    x, line, shade, prop, cursor = chart_arrays(t, [y], [flagged, proposed], 3, shade_floors=[0.0, PROPOSAL_BAND])
    n = 3 * 6 + 2
    assert all(a.shape == (n,) and np.isfinite(a).all() for a in (x, line, shade, prop, cursor))
    assert np.all(np.diff(x) >= 0)  # uPlot needs sorted x
    # three samples per frame, the cursor's two extra ones after frame 3's centre
    np.testing.assert_allclose(x[[1, 4, 7, 10]], t[:4])
    assert x[11] == x[12] == x[10] == pytest.approx(0.03)
    assert cursor[10] == -1 and cursor[11] == 2 and cursor[12] == -1 and (np.delete(cursor, 11) == -1).all()
    assert line[6:9].tolist() == [0.0, 0.0, 0.0]  # NaN drawn as 0
    assert shade[:3].tolist() == [0, 0, 0] and shade[3:9].tolist() == [1] * 6 and shade[9:].max() == 0
    assert prop.min() == PROPOSAL_BAND and prop[np.isclose(x, 0.04)].tolist() == [1.0]


def test_frame_grid_edges_do_not_overlap() -> None:
    """At 50 Hz (20 ms frames) each frame spans its centre +-10 ms, the edges pulled in by
    far less than a frame so that neighbours touch but do not overlap."""
    t = np.arange(4) / 50.0
    x = frame_grid(t)
    assert x.shape == (12,) and np.all(np.diff(x) > 0)
    np.testing.assert_array_equal(x[1::3], t)
    np.testing.assert_allclose(x[0::3], t - 0.01, atol=1e-4)
    np.testing.assert_allclose(x[2::3], t + 0.01, atol=1e-4)


def test_grf_lines_per_plate_until_assigned_then_per_foot(walk) -> None:
    lines = grf_lines(walk)
    assert [ln.label for ln in lines] == ["plate r (N)", "plate l (N)"]  # no assignment, no dynamics
    np.testing.assert_allclose(lines[0].values, np.nan_to_num(walk.plates[0].force[:, 1]))
    calcn_r = walk.body_names.index("calcn_r")
    calcn_l = walk.body_names.index("calcn_l")
    loaded = [np.linalg.norm(np.nan_to_num(p.force), axis=1) > 20 for p in walk.plates]
    plates = (
        dataclasses.replace(walk.plates[0], body=np.where(loaded[0], calcn_r, -1)),
        dataclasses.replace(walk.plates[1], body=np.where(loaded[1], calcn_l, -1)),
    )
    acc = np.zeros((walk.n_frames, 3))
    lines = grf_lines(dataclasses.replace(walk, plates=plates, com_acc=acc))
    labels = [ln.label for ln in lines]
    assert labels[:2] == ["left foot (N)", "right foot (N)"] and labels[-1].startswith("m(a+g)")
    total = sum(ln.values for ln in lines[:-1])
    np.testing.assert_allclose(total, net_plate_force(walk)[:, 1], atol=1e-9)
    np.testing.assert_allclose(lines[-1].values, walk.mass_kg * 9.80665)


def test_hicks_thresholds_and_exceeded_frames(walk) -> None:
    th = hicks_thresholds(walk)
    peak = np.linalg.norm(net_plate_force(walk), axis=1).max()
    assert th.force_n == pytest.approx(HICKS_FORCE_FRACTION * peak)
    assert not hicks_exceeded(walk).any()  # no dynamics: nothing exceeds
    res = np.zeros((walk.n_frames, 3))
    res[50:60, 0] = 2 * th.force_n
    dyn = dataclasses.replace(walk, residual_force=res, residual_moment=np.zeros_like(res))
    assert np.flatnonzero(hicks_exceeded(dyn)).tolist() == list(range(50, 60))
    left_out = np.zeros(walk.n_frames, bool)
    left_out[55:70] = True  # frames left out of the fit: their residual is the unmeasured force
    dyn = dataclasses.replace(dyn, unobserved=left_out)
    assert np.flatnonzero(hicks_exceeded(dyn)).tolist() == list(range(50, 55))
    assert all(not ln.values[np.isfinite(ln.values)].size for ln in residual_lines(walk))  # hidden


def test_summary_table_marks_missing_dynamics(walk) -> None:
    before = trial_summary(walk)
    assert before["residual_force_rms_n"] is None and before["hicks_frames"] is None
    assert before["marker_rms_cm"] == pytest.approx(100 * walk.metrics["marker_rms_m"], rel=1e-6)
    after = dict(before, residual_force_rms_n=12.5, marker_rms_cm=before["marker_rms_cm"] + 0.5)
    table = comparison_markdown(before, after)
    assert "| residual force RMS, measured frames (N) | — | 12.5 | — |" in table
    assert "| marker RMS (cm) |" in table and "+0.50" in table
    # the change is that of the figures as shown: 2.94 -> 2.86 shows 2.9 -> 2.9, change 0.0
    # (it read -0.1), 1.14 -> 1.16 shows 1.1 -> 1.2, +0.1 (it read +0.0), and a change that
    # rounds to zero has no sign (it read -0.00)
    b = dict(before, residual_force_max_n=2.94, residual_moment_rms_nm=1.14, marker_max_cm=1.001)
    a = dict(before, residual_force_max_n=2.86, residual_moment_rms_nm=1.16, marker_max_cm=0.999)
    table = comparison_markdown(b, a)
    assert "| residual force max, measured frames (N) | 2.9 | 2.9 | 0.0 |" in table
    assert "| residual moment RMS, measured frames (N·m) | 1.1 | 1.2 | +0.1 |" in table
    assert "| marker max (cm) | 1.00 | 1.00 | 0.00 |" in table
    assert "| frames left out of dynamics | " in table and "-0" not in table
