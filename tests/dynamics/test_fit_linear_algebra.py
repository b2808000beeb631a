"""The dynamics fit's linear algebra: band storage, the banded Cholesky solve, the normal equations."""

from __future__ import annotations

from dataclasses import replace
from functools import cache

import numpy as np
import pytest
from scipy.linalg import LinAlgError, solveh_banded

from solver.dynamics.banded import (
    banded_back_solve,
    banded_cholesky,
    banded_cholesky_solve,
    banded_forward_solve,
    lower_band_storage,
)
from solver.dynamics.fit import FitSettings, FitTrialInput, _TrialProblem
from solver.errors import DynamicsError
from solver.model.osim import read_osim
from solver.model.skeleton import Skeleton
from tests.conftest import SHARED_DATA

MODEL = SHARED_DATA / "models" / "Rajagopal2016.osim"


def _random_block_bands(t: int, nbp1: int, nf: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Upper block bands of a symmetric positive definite matrix, and the dense matrix."""
    blocks = rng.normal(size=(t, nbp1, nf, nf))
    n = t * nf
    h = np.zeros((n, n))
    for i in range(t):
        for o in range(nbp1):
            if i + o < t:
                h[i * nf : (i + 1) * nf, (i + o) * nf : (i + o + 1) * nf] = blocks[i, o]
    h = np.triu(h) + np.triu(h, 1).T  # symmetric, from the upper triangle only
    shift = np.abs(h).sum(axis=1).max() + 1.0  # diagonally dominant: positive definite
    h += shift * np.eye(n)
    for i in range(t):
        blocks[i, 0] += shift * np.eye(nf)
    return blocks, h


@pytest.mark.parametrize(("t", "nbp1", "nf"), [(9, 5, 3), (3, 5, 2), (6, 1, 4), (1, 3, 5)])
def test_lower_band_storage_holds_the_dense_matrix(t: int, nbp1: int, nf: int) -> None:
    rng = np.random.default_rng(t * 100 + nbp1 * 10 + nf)
    blocks, h = _random_block_bands(t, nbp1, nf, rng)
    blocks[:, 0] += np.tril(rng.normal(size=(t, nf, nf)), -1)  # the lower triangle is not read
    ab = lower_band_storage(blocks)
    u, n = nbp1 * nf - 1, t * nf
    assert ab.shape == (u + 1, n)
    expected = np.zeros((u + 1, n))
    for d in range(min(u + 1, n)):
        expected[d, : n - d] = np.diagonal(h, -d)
    np.testing.assert_array_equal(ab, expected)


def test_banded_cholesky_solve_equals_scipy_and_dense() -> None:
    rng = np.random.default_rng(7)
    blocks, h = _random_block_bands(40, 5, 6, rng)
    ab = lower_band_storage(blocks)
    rhs = rng.normal(size=h.shape[0])
    keep = ab.copy()
    x = banded_cholesky_solve(ab, rhs)
    np.testing.assert_array_equal(ab, keep)  # not overwritten
    np.testing.assert_array_equal(x, solveh_banded(ab, rhs, lower=True))
    np.testing.assert_allclose(x, np.linalg.solve(h, rhs), rtol=1e-12, atol=1e-14)


def test_banded_cholesky_solve_rejects_an_indefinite_matrix() -> None:
    ab = np.array([[1.0, -1.0, 1.0], [0.5, 0.0, 0.0]])
    with pytest.raises(LinAlgError):
        banded_cholesky_solve(ab, np.ones(3))


@pytest.mark.parametrize("chunk", [7, 30, 64, 240, 8192])
def test_banded_forward_solve_in_chunks_is_the_factors_inverse(chunk: int) -> None:
    """L^-1 B by row chunks (the joint fit's mass border): equal to the dense triangular
    solve to round-off for every chunk size (chunks shorter than, equal to and longer than
    the band; 240 rows: one chunk, the whole system), and bit for bit LAPACK's dtbtrs when
    the system is one chunk."""
    from scipy.linalg import solve_triangular
    from scipy.linalg.lapack import dtbtrs

    rng = np.random.default_rng(11)
    blocks, h = _random_block_bands(40, 5, 6, rng)  # N = 240 rows, band u = 29
    factor = banded_cholesky(lower_band_storage(blocks))
    ell = np.linalg.cholesky(h)
    rhs = rng.normal(size=(h.shape[0], 23))
    x = banded_forward_solve(factor, rhs, chunk=chunk)
    np.testing.assert_allclose(x, solve_triangular(ell, rhs, lower=True), rtol=1e-11, atol=1e-12)
    one = banded_forward_solve(factor, rhs[:, 0], chunk=chunk)
    assert one.shape == (240,)
    np.testing.assert_allclose(one, x[:, 0], rtol=1e-12, atol=1e-13)
    if chunk >= 240:
        np.testing.assert_array_equal(x, dtbtrs(factor, rhs, uplo="L")[0])


def test_banded_forward_solve_names_the_chunk_of_a_zero_pivot() -> None:
    rng = np.random.default_rng(3)
    blocks, _ = _random_block_bands(40, 5, 6, rng)
    factor = banded_cholesky(lower_band_storage(blocks)).copy(order="F")
    factor[0, 100] = 0.0  # a zero on the diagonal, in the chunk of rows 64..128
    with pytest.raises(LinAlgError, match=r"rows 64\.\.128"):
        banded_forward_solve(factor, np.ones((240, 3)), chunk=64)


def test_banded_back_solve_is_the_transposed_factors_inverse() -> None:
    """L^-T b (the joint fit's coordinate step) equals the dense transposed triangular solve
    to round-off, one right-hand side or several, and LAPACK's dtbtrs with trans="T" bit for
    bit; a zero on the factor's diagonal raises LinAlgError."""
    from scipy.linalg import solve_triangular
    from scipy.linalg.lapack import dtbtrs

    rng = np.random.default_rng(17)
    blocks, h = _random_block_bands(40, 5, 6, rng)
    factor = banded_cholesky(lower_band_storage(blocks))
    ell = np.linalg.cholesky(h)
    rhs = rng.normal(size=(h.shape[0], 4))
    x = banded_back_solve(factor, rhs)
    np.testing.assert_allclose(x, solve_triangular(ell.T, rhs, lower=False), rtol=1e-11, atol=1e-12)
    one = banded_back_solve(factor, rhs[:, 1])
    assert one.shape == (240,)
    np.testing.assert_array_equal(one, dtbtrs(factor, rhs[:, 1:2], uplo="L", trans="T")[0][:, 0])
    broken = factor.copy(order="F")
    broken[0, 100] = 0.0
    with pytest.raises(LinAlgError, match="dtbtrs failed"):
        banded_back_solve(broken, rhs[:, 0])


@cache
def _skeleton() -> Skeleton:
    return Skeleton(read_osim(MODEL))


def _synthetic_trial(sk: Skeleton, t: int) -> FitTrialInput:
    rng = np.random.default_rng(3)
    time = np.arange(t) * 0.01
    q = np.tile(sk.neutral(), (t, 1))
    free = np.flatnonzero(sk.is_independent & ~sk.locked)
    q[:, free] += 0.2 * np.sin(2 * np.pi * 1.3 * time[:, None] + rng.uniform(0, 6, free.size))
    q = sk.cmap.complete(q)
    markers = np.arange(0, len(sk.marker_names), 3)
    obs = sk.marker_positions(q, markers) + rng.normal(scale=0.005, size=(t, markers.size, 3))
    obs[2, 1] = np.nan  # a missing marker
    force = np.array([0.0, sk.total_mass * 9.8, 0.0]) + rng.normal(scale=40.0, size=(t, 3))
    moment = rng.normal(scale=30.0, size=(t, 3))
    observed = np.ones(t, dtype=bool)
    observed[t // 2 :] = False
    return FitTrialInput(q=q, markers=markers, observed_markers=obs, observed=observed, force=force, moment=moment)


def _residual_vector(prob: _TrialProblem, q: np.ndarray) -> np.ndarray:
    """Every weighted residual of the fit's cost (its squares sum to the cost)."""
    st, free = prob.st, prob.free
    pos = prob.sk.marker_positions(q, prob.data.markers)
    e = np.where(prob.seen[..., None], pos - prob.y, 0.0) / st.marker_sigma
    _, _, qp, vp, ap = prob.kinematics(q)
    r = prob.residual_wrench(*prob.momentum_rate(qp, vp, ap)) * prob.w_res
    if st.direction == "coefficients":  # the spline's accelerations
        smooth = prob.kinematics(q)[1][:, free] / st.accel_sigma
    else:
        smooth = (q[2:, free] - 2 * q[1:-1, free] + q[:-2, free]) / (prob.data.dt**2 * st.accel_sigma)
    return np.concatenate([e.ravel(), r.ravel(), smooth.ravel()])


def _jacobian_by_central_differences(prob: _TrialProblem, q: np.ndarray) -> np.ndarray:
    """``(residuals, T nf)`` Jacobian of :func:`_residual_vector` in the free coordinates."""
    t, nf = q.shape[0], prob.nf
    jac = np.zeros((_residual_vector(prob, q).size, t * nf))
    h = 1e-6
    for k in range(t):
        for i, c in enumerate(prob.free):
            qp_, qm_ = q.copy(), q.copy()
            qp_[k, c] += h
            qm_[k, c] -= h
            jac[:, k * nf + i] = (_residual_vector(prob, qp_) - _residual_vector(prob, qm_)) / (2 * h)
    return jac


def _linear_columns(prob: _TrialProblem, q: np.ndarray) -> np.ndarray:
    """``(T nf,)`` True for the free coordinates that drive no nonlinear joint function."""
    vals, cols = prob.sk.cmap.jacobian_batch(q[:1])
    bent, _ = prob.sk.cmap.jacobian_batch(q[:1] + 0.1)
    curved = set(cols[np.flatnonzero(vals[0] != bent[0])].tolist())
    return np.tile([c not in curved for c in prob.free], q.shape[0])


def test_normal_equations_are_the_gauss_newton_system_of_the_cost() -> None:
    """With the band covering the trial (no truncation) H = J^T J and grad = J^T r for the
    Jacobian J of the weighted residuals, here by central differences.

    Coordinates that drive nonlinear joint functions (the knee splines and patella couplers)
    are left out: the fit's Jacobian of the velocities and accelerations keeps only the
    coupling Jacobian's first derivative (v_pin = f'(x) xdot, whose f''(x) xdot term by x
    it drops), a Gauss-Newton approximation of the residual wrench on those columns."""
    sk = _skeleton()
    t = 7
    trial = _synthetic_trial(sk, t)
    prob = _TrialProblem(sk, trial, replace(FitSettings(), band=t, direction="band"))
    q = trial.q
    r0 = _residual_vector(prob, q)
    assert np.sum(r0**2) == pytest.approx(prob.cost(q), rel=1e-12)
    ab, grad = prob.normal_equations(q)
    nf = prob.nf
    jac = _jacobian_by_central_differences(prob, q)
    jtj = jac.T @ jac
    n = t * nf
    dense = np.zeros((n, n))
    for d in range(min(ab.shape[0], n)):
        idx = np.arange(n - d)
        dense[idx + d, idx] = ab[d, : n - d]
        dense[idx, idx + d] = ab[d, : n - d]
    linear = _linear_columns(prob, q)
    assert linear.sum() > t * nf // 2 and not linear.all()
    scale = np.abs(jtj).max()
    keep = np.ix_(linear, linear)
    np.testing.assert_allclose(dense[keep], jtj[keep], rtol=0, atol=1e-7 * scale)
    g_fd = jac.T @ r0
    np.testing.assert_allclose(grad[linear], g_fd[linear], rtol=0, atol=1e-7 * np.abs(g_fd).max())


def test_exact_direction_uses_the_gauss_newton_system_of_the_full_operators() -> None:
    """With ``direction="exact"`` and a band much narrower than the trial, the gradient is
    J^T r and :meth:`gauss_newton_product` is J^T J v for the whole Jacobian J (central
    differences; coordinates of nonlinear joint functions left out, as above), while the
    banded matrix stays the truncated one (the preconditioner)."""
    sk = _skeleton()
    t = 12
    trial = _synthetic_trial(sk, t)
    prob = _TrialProblem(sk, trial, replace(FitSettings(), band=1, direction="exact"))
    q = trial.q
    r0 = _residual_vector(prob, q)
    ab, grad = prob.normal_equations(q)
    nf = prob.nf
    jac = _jacobian_by_central_differences(prob, q)
    linear = _linear_columns(prob, q)
    g_fd = jac.T @ r0
    np.testing.assert_allclose(grad[linear], g_fd[linear], rtol=0, atol=1e-7 * np.abs(g_fd).max())
    v = np.where(linear, np.random.default_rng(5).normal(size=t * nf), 0.0)
    hv = prob.gauss_newton_product(v.reshape(t, nf)).reshape(-1)
    hv_fd = jac.T @ (jac @ v)
    np.testing.assert_allclose(hv[linear], hv_fd[linear], rtol=0, atol=1e-7 * np.abs(hv_fd).max())
    # the banded matrix leaves out what the truncation drops: far from the exact product
    dense = np.zeros((t * nf, t * nf))
    for d in range(min(ab.shape[0], t * nf)):
        idx = np.arange(t * nf - d)
        dense[idx + d, idx] = ab[d, : t * nf - d]
        dense[idx, idx + d] = ab[d, : t * nf - d]
    assert np.abs(dense @ v - hv_fd)[linear].max() > 1e-3 * np.abs(hv_fd).max()


def test_coefficient_direction_is_the_gauss_newton_system_of_the_cost() -> None:
    """With ``direction="coefficients"`` the banded system in the natural spline's local
    coefficients a (q = E0 a) is the Gauss-Newton system of the cost with the full
    derivative operators: with N = E0^-1 (the coefficients of unit samples), N^T H N = J^T J
    and N^T g = J^T r for the Jacobian J in q by central differences (coordinates of
    nonlinear joint functions left out, as above), and the gradient in q it returns is
    J^T r too (its smoothness rows are the spline's accelerations), and the cost is the sum
    of the squared residuals."""
    sk = _skeleton()
    t = 14
    trial = _synthetic_trial(sk, t)
    prob = _TrialProblem(sk, trial, replace(FitSettings(), direction="coefficients"))
    q = trial.q
    nf = prob.nf
    assert np.sum(_residual_vector(prob, q) ** 2) == pytest.approx(prob.cost(q), rel=1e-12)
    bands, g_c, g_q, _ = prob.coefficient_equations(q)
    ab = bands.lower_band_storage()
    n = g_c.size
    dense = np.zeros((n, n))
    for d in range(min(ab.shape[0], n)):
        idx = np.arange(n - d)
        dense[idx + d, idx] = ab[d, : n - d]
        dense[idx, idx + d] = ab[d, : n - d]
    e0 = prob.cmaps.e0.toarray()
    assert e0.shape == (t, t) and prob.cmaps.width == 5
    big_n = np.kron(np.linalg.inv(e0), np.eye(nf))
    jac = _jacobian_by_central_differences(prob, q)
    r0 = _residual_vector(prob, q)
    linear = _linear_columns(prob, q)
    jtj, g_fd = jac.T @ jac, jac.T @ r0
    keep = np.ix_(linear, linear)
    np.testing.assert_allclose((big_n.T @ dense @ big_n)[keep], jtj[keep], rtol=0, atol=1e-7 * np.abs(jtj).max())
    np.testing.assert_allclose((big_n.T @ g_c.reshape(-1))[linear], g_fd[linear], rtol=0, atol=1e-7 * np.abs(g_fd).max())
    np.testing.assert_allclose(g_q.reshape(-1)[linear], g_fd[linear], rtol=0, atol=1e-7 * np.abs(g_fd).max())


def test_an_unknown_fit_direction_is_refused() -> None:
    sk = _skeleton()
    with pytest.raises(DynamicsError, match="unknown fit direction 'newton'"):
        _TrialProblem(sk, _synthetic_trial(sk, 7), replace(FitSettings(), direction="newton"))
