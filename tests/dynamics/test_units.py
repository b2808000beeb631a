"""Building blocks of the dynamics stage on hand-made cases with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from solver.dynamics.com_fit import ComTrial, fit_com
from solver.dynamics.preprocess import cop_from_wrench, lowpass, moment_about_origin
from solver.dynamics.spline import Derivatives, derivative_operators, differentiate
from solver.errors import DynamicsError

G = np.array([0.0, -9.80665, 0.0])


def test_spline_derivatives_are_exact_for_quintic_friendly_signals() -> None:
    t = np.arange(200) * 0.01
    x = np.sin(2 * np.pi * 1.5 * t)[:, None] * [1.0, 0.5]
    xd, xdd = differentiate(x, 0.01)
    inner = slice(10, -10)
    np.testing.assert_allclose(xd[inner], (2 * np.pi * 1.5 * np.cos(2 * np.pi * 1.5 * t))[inner, None] * [1.0, 0.5], atol=1e-4)
    np.testing.assert_allclose(xdd[inner], (-(2 * np.pi * 1.5) ** 2 * np.sin(2 * np.pi * 1.5 * t))[inner, None] * [1.0, 0.5], atol=2e-3)


def _spline_operators_by_definition(n: int) -> tuple[np.ndarray, np.ndarray]:
    """D1, D2 (dt = 1) straight from the definition: scipy's natural quintic interpolating
    spline through each unit sample (third and fourth derivatives zero at both ends)."""
    from scipy.interpolate import make_interp_spline

    t, zero = np.arange(n, dtype=float), np.zeros(n)
    spl = make_interp_spline(t, np.eye(n), k=5, bc_type=([(3, zero), (4, zero)], [(3, zero), (4, zero)]))
    return np.asarray(spl(t, 1)), np.asarray(spl(t, 2))


@pytest.mark.parametrize("n", [6, 7, 31, 400])
def test_linear_time_derivatives_equal_the_dense_spline_operators(n: int) -> None:
    """The sparse-factor operators (values, adjoint and near-diagonal band) equal the dense
    matrices of the natural quintic spline to round-off."""
    dt = 0.01
    d1, d2 = _spline_operators_by_definition(n)
    d1, d2 = d1 / dt, d2 / dt**2
    ops = Derivatives(n, dt)
    rng = np.random.default_rng(n)
    q, w1, w2 = (rng.normal(size=(n, 3)) for _ in range(3))
    qd, qdd = ops(q)
    np.testing.assert_allclose(qd, d1 @ q, rtol=0, atol=1e-12 * np.abs(d1 @ q).max())
    np.testing.assert_allclose(qdd, d2 @ q, rtol=0, atol=1e-12 * np.abs(d2 @ q).max())
    adj = d1.T @ w1 + d2.T @ w2
    np.testing.assert_allclose(ops.transpose(w1, w2), adj, rtol=0, atol=1e-12 * np.abs(adj).max())
    b1, b2 = ops.band(3)
    for k in (0, 1, n // 2, n - 1):
        for o in range(-3, 4):
            inside = 0 <= k + o < n
            assert b1[k, o + 3] == pytest.approx(d1[k, k + o] if inside else 0.0, rel=1e-12, abs=1e-12 * np.abs(d1).max())
            assert b2[k, o + 3] == pytest.approx(d2[k, k + o] if inside else 0.0, rel=1e-12, abs=1e-12 * np.abs(d2).max())


def test_derivatives_reject_too_few_frames_and_unknown_methods() -> None:
    with pytest.raises(DynamicsError, match="at least 6 frames"):
        Derivatives(5, 0.01)
    with pytest.raises(DynamicsError, match="unknown derivative method"):
        Derivatives(10, 0.01, "cubic")


def test_central_difference_operator_matches_the_formula() -> None:
    d1, d2 = derivative_operators(6, 0.5, "central")
    x = np.array([1.0, 4.0, 2.0, 7.0, 3.0, 0.0])
    assert (d1 @ x)[2] == pytest.approx((7.0 - 4.0) / 1.0)
    assert (d2 @ x)[3] == pytest.approx((3.0 - 14.0 + 2.0) / 0.25)


def test_lowpass_removes_high_frequency_and_keeps_low() -> None:
    t = np.arange(2000) / 1000.0
    slow, fast = np.sin(2 * np.pi * 2 * t), 0.5 * np.sin(2 * np.pi * 150 * t)
    out = lowpass((slow + fast)[:, None], 1000.0, 30.0)[:, 0]
    assert np.abs(out - slow)[200:-200].max() < 0.01
    with pytest.raises(DynamicsError, match="NaN"):
        lowpass(np.array([1.0, np.nan, 2.0, 3.0, 4.0]), 100.0, 30.0)


def test_cop_and_free_moment_round_trip_through_the_moment_about_the_origin() -> None:
    rng = np.random.default_rng(0)
    force = np.column_stack([rng.normal(0, 80, 50), rng.uniform(200, 900, 50), rng.normal(0, 80, 50)])
    cop = np.column_stack([rng.uniform(-1, 2, 50), np.full(50, 0.01), rng.uniform(-1, 1, 50)])
    free = np.column_stack([np.zeros(50), rng.normal(0, 5, 50), np.zeros(50)])
    cop2, free2 = cop_from_wrench(force, moment_about_origin(force, cop, free), 0.01, 10.0)
    np.testing.assert_allclose(cop2, cop, atol=1e-12)
    np.testing.assert_allclose(free2, free, atol=1e-10)


def _synthetic_com(mass: float, observed: np.ndarray, dt: float = 0.01) -> ComTrial:
    t = observed.size
    time = np.arange(t) * dt
    com = np.column_stack([1.2 * time, 0.95 + 0.03 * np.sin(2 * np.pi * 1.8 * time), 0.02 * np.sin(2 * np.pi * 0.9 * time)])
    acc = np.zeros_like(com)
    acc[1:-1] = (com[2:] - 2 * com[1:-1] + com[:-2]) / dt**2
    force = mass * (acc - G)
    force[~observed] = 0.0  # unmeasured: the plates read nothing there
    return ComTrial(com, force, observed, dt)


def test_com_fit_recovers_the_mass_with_unobserved_frames() -> None:
    observed = np.ones(150, dtype=bool)
    observed[:30] = False
    observed[100:120] = False
    trial = _synthetic_com(72.5, observed)
    fit = fit_com([trial], G, alpha=1e-6)
    assert fit.mass_kg == pytest.approx(72.5, rel=1e-3)
    assert fit.rms_shift[0] < 1e-3  # consistent already; alpha bends the unobserved spans slightly
    # where forces are measured the fitted path obeys them exactly
    acc = fit.acc[0]
    inner = np.flatnonzero(observed[1:-1]) + 1
    np.testing.assert_allclose(72.5 * (acc[inner] - G), trial.force[inner], rtol=2e-3, atol=0.5)


def test_com_fit_moves_a_noisy_path_onto_the_forces() -> None:
    rng = np.random.default_rng(3)
    observed = np.ones(200, dtype=bool)
    clean = _synthetic_com(80.0, observed)
    noisy = ComTrial(clean.com + rng.normal(0, 0.003, clean.com.shape), clean.force, observed, clean.dt)
    fit = fit_com([noisy], G)
    assert fit.mass_kg == pytest.approx(80.0, rel=0.01)
    assert np.sqrt(np.mean(np.sum((fit.com[0] - clean.com) ** 2, axis=1))) < 0.003


def test_com_fit_without_measured_frames_is_an_error() -> None:
    trial = _synthetic_com(70.0, np.zeros(50, dtype=bool))
    with pytest.raises(DynamicsError, match="no frame with measured force"):
        fit_com([trial], G)
