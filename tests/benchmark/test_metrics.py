"""The four benchmark metrics on hand-made cases with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from solver.benchmark.metrics import (
    FrameErrors,
    com_acc_errors,
    grf_errors,
    grm_errors,
    summarize,
    torque_errors,
)


def test_com_acc_error_is_the_mean_l2_norm() -> None:
    true = np.zeros((2, 3))
    pred = np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 1.0]])  # errors 5 and 1 m/s²
    errors = com_acc_errors(pred, true)
    np.testing.assert_allclose(errors, [5.0, 1.0])
    assert summarize(FrameErrors(errors, errors, errors, errors))["com_acc"] == pytest.approx(3.0)


def test_grf_error_is_per_foot_l2_divided_by_mass() -> None:
    true = np.zeros((1, 2, 3))
    true[0, 0] = [0.0, 800.0, 0.0]
    pred = true.copy()
    pred[0, 0, 1] += 60.0  # right foot off by 60 N
    pred[0, 1] = [0.0, 0.0, 80.0]  # left foot off by 80 N
    # mean over feet (60 + 80) / 2 = 70 N, over 70 kg = 1 N/kg
    assert grf_errors(pred, true, 70.0) == pytest.approx([1.0])


def test_grm_error_uses_the_same_norm_with_per_frame_masses() -> None:
    true = np.zeros((2, 2, 3))
    pred = np.zeros((2, 2, 3))
    pred[0, 0] = [6.0, 8.0, 0.0]  # 10 N·m on one foot, 0 on the other: mean 5
    pred[1, 1] = [0.0, 0.0, 20.0]  # 20 N·m: mean 10
    np.testing.assert_allclose(grm_errors(pred, true, np.array([50.0, 100.0])), [0.1, 0.1])


def test_torque_error_is_mean_absolute_per_kg() -> None:
    true = np.array([[10.0, -5.0, 0.0, 2.0]])
    pred = np.array([[12.0, -9.0, 0.0, 0.0]])  # |errors| 2, 4, 0, 2 -> mean 2 N·m
    assert torque_errors(pred, true, 4.0) == pytest.approx([0.5])


def test_shapes_must_match() -> None:
    with pytest.raises(ValueError, match="shape"):
        com_acc_errors(np.zeros((3, 3)), np.zeros((2, 3)))


def test_pooled_summary_weighs_every_frame_the_same() -> None:
    a = FrameErrors(np.array([1.0]), np.array([1.0]), np.array([1.0]), np.array([1.0]))
    b = FrameErrors(np.array([4.0, 4.0, 4.0]), np.zeros(3), np.zeros(3), np.zeros(3))
    s = summarize(FrameErrors.concatenate([a, b]))
    assert s["com_acc"] == pytest.approx(13.0 / 4) and s["grf"] == pytest.approx(0.25)
    assert np.isnan(summarize(FrameErrors.concatenate([]))["torque"])
