"""Consistency of the model's maths: spline derivatives, chain rule, Jacobians, dynamics identities."""

from __future__ import annotations

import numpy as np
import pytest

from solver.model.functions import CubicSpline, Linear, Multiplier, Polynomial
from solver.model.skeleton import ExternalWrench
from tests.model.conftest import MODELS, SHARED, skeleton

RNG = np.random.default_rng(42)
MODEL_PATHS = [
    str(MODELS / "Rajagopal2016.osim"),
    str(MODELS / "LaiUhlrich2022.osim"),
    str(SHARED / "oracles" / "opensim_scaled_walk.osim"),
]


def test_fmm_spline_reproduces_a_cubic_exactly_and_extrapolates_linearly() -> None:
    # The Forsythe-Malcolm-Moler end conditions make the spline exact for cubics.
    x = np.array([0.0, 0.3, 0.5, 1.1, 1.4, 2.0])
    cubic = Polynomial((0.7, -1.3, 0.2, 0.05))
    spline = CubicSpline(x, cubic.value(x), kind="fmm")
    t = np.linspace(0, 2, 101)
    np.testing.assert_allclose(spline.value(t), cubic.value(t), atol=1e-12)
    np.testing.assert_allclose(spline.derivative(t, 1), cubic.derivative(t, 1), atol=1e-11)
    np.testing.assert_allclose(spline.derivative(t, 2), cubic.derivative(t, 2), atol=1e-10)
    slope = cubic.derivative(np.array(2.0), 1)
    assert spline.value(np.array(2.5)) == pytest.approx(cubic.value(np.array(2.0)) + 0.5 * slope, abs=1e-12)
    assert spline.derivative(np.array(-1.0), 2) == 0.0


@pytest.mark.parametrize("kind", ["fmm", "natural"])
def test_spline_derivatives_match_finite_differences(kind: str) -> None:
    x = np.sort(RNG.uniform(0, 2, 9))
    spline = CubicSpline(x, RNG.normal(size=9), kind=kind)
    t, h = np.linspace(x[0] + 1e-3, x[-1] - 1e-3, 57), 1e-6
    np.testing.assert_allclose(spline.derivative(t, 1), (spline.value(t + h) - spline.value(t - h)) / (2 * h), atol=1e-6)
    np.testing.assert_allclose(
        spline.derivative(t, 2), (spline.derivative(t + h, 1) - spline.derivative(t - h, 1)) / (2 * h), atol=1e-5
    )
    if kind == "natural":
        assert spline.derivative(np.array(x[0]), 2) == pytest.approx(0.0, abs=1e-9)


def test_multiplier_scales_value_and_derivatives() -> None:
    f = Multiplier(Linear(2.0, 1.0), 0.5)
    assert f.value(np.array(3.0)) == pytest.approx(3.5)
    assert f.derivative(np.array(3.0)) == pytest.approx(1.0)


@pytest.mark.parametrize("path", MODEL_PATHS, ids=lambda p: p.split("/")[-1])
def test_function_bank_equals_each_function(path: str) -> None:
    # the bank evaluates splines sharing knots together (a multiplier folded into their
    # table: equal to round-off) and every polynomial of the model in one Horner sum (the
    # same sum as numpy.polyval's: equal to the bit, also inside a MultiplierFunction)
    from solver.model.coupling import FunctionBank

    sk = skeleton(path)
    functions = list(sk._dof_func) + [Multiplier(f, 0.93) for f in sk._dof_func]
    drivers = list(sk._dof_coord) * 2
    x = RNG.uniform(-1.5, 1.5, (40, sk.n))
    bank = FunctionBank(drivers, functions)
    got = bank.evaluate(x)
    for order in (0, 1):  # lower orders: the same arrays to the bit, nothing above
        fewer = bank.evaluate(x, order=order)
        for k in range(3):
            if k <= order:
                np.testing.assert_array_equal(fewer[k], got[k])
            else:
                assert fewer[k] is None
    for k, (c, fn) in enumerate(zip(drivers, functions)):
        inner = fn.inner if isinstance(fn, Multiplier) else fn
        for order, values in enumerate(got):
            own = (fn.value(x[:, c]) if order == 0 else fn.derivative(x[:, c], order)) * np.ones(40)
            if isinstance(inner, Polynomial):
                np.testing.assert_array_equal(values[:, k], own, err_msg=f"{fn} order {order}")
            else:
                np.testing.assert_allclose(values[:, k], own, rtol=1e-13, atol=1e-15, err_msg=f"{fn} order {order}")
    assert any(isinstance(fn, Polynomial) for fn in sk._dof_func) == path.endswith("LaiUhlrich2022.osim")


@pytest.mark.parametrize("path", MODEL_PATHS, ids=lambda p: p.split("/")[-1])
def test_function_bank_at_the_knots_and_past_the_ends(path: str) -> None:
    # the bank finds a spline's interval with one search over the knots, the last one nudged
    # up one unit in the last place: a value on the last knot is still in the last interval,
    # one just past it on the linear continuation; each as the spline itself has it
    sk = skeleton(path)
    bank = sk.cmap._dofs
    splines = [(k, c, fn) for k, (c, fn) in enumerate(zip(sk._dof_coord, sk._dof_func)) if isinstance(fn, CubicSpline)]
    assert splines, "the model's knee is driven by splines"
    for k, c, fn in splines:
        knots = fn.x
        xs = np.concatenate([knots, np.nextafter(knots, -np.inf), np.nextafter(knots, np.inf), [knots[0] - 0.3, knots[-1] + 0.3]])
        x = np.tile(sk.neutral(), (xs.size, 1))
        x[:, c] = xs
        got = bank.evaluate(x)
        for order, values in enumerate(got):
            own = fn.value(xs) if order == 0 else fn.derivative(xs, order)
            np.testing.assert_allclose(values[:, k], own, rtol=1e-13, atol=1e-15, err_msg=f"{fn} order {order}")


@pytest.mark.parametrize("path", MODEL_PATHS, ids=lambda p: p.split("/")[-1])
def test_expanded_velocities_are_the_time_derivative_of_positions(path: str) -> None:
    sk = skeleton(path)
    q, qd, qdd = RNG.uniform(-0.5, 0.5, sk.n), RNG.uniform(-1, 1, sk.n), RNG.uniform(-1, 1, sk.n)
    q[sk.coordinate_index("knee_angle_r")] = 0.8
    h = 1e-5

    def path_q(t: float) -> np.ndarray:
        return q + qd * t + 0.5 * qdd * t * t

    qp, vp, ap = sk.cmap.expand(q, qd, qdd)
    qp_p, vp_p, _ = sk.cmap.expand(path_q(h), qd + qdd * h, qdd)
    qp_m, vp_m, _ = sk.cmap.expand(path_q(-h), qd - qdd * h, qdd)
    np.testing.assert_allclose(vp, (qp_p - qp_m) / (2 * h), atol=1e-7)
    np.testing.assert_allclose(ap, (vp_p - vp_m) / (2 * h), atol=1e-5)
    np.testing.assert_allclose(qp, sk.cmap.expand(sk.cmap.complete(q))[0], atol=0)  # couplers applied


@pytest.mark.parametrize("path", MODEL_PATHS, ids=lambda p: p.split("/")[-1])
def test_marker_jacobian_matches_finite_differences(path: str) -> None:
    sk = skeleton(path)
    q = sk.cmap.complete(RNG.uniform(-0.5, 0.5, sk.n))
    q[sk.coordinate_index("knee_angle_l")] = 1.1
    idx = np.arange(len(sk.marker_names))
    pos, jac = sk.marker_jacobian(q, idx)
    np.testing.assert_allclose(pos, sk.marker_positions(q, idx)[0], atol=1e-12)
    h = 1e-6
    for c in np.flatnonzero(sk.is_independent):
        e = np.zeros(sk.n)
        e[c] = h
        fd = (sk.marker_positions(sk.cmap.complete(q + e), idx) - sk.marker_positions(sk.cmap.complete(q - e), idx))[0] / (2 * h)
        np.testing.assert_allclose(jac[:, :, c], fd, atol=1e-6, err_msg=sk.coordinate_names[c])
    assert not jac[:, :, ~sk.is_independent].any()


@pytest.mark.parametrize("path", MODEL_PATHS, ids=lambda p: p.split("/")[-1])
def test_positions_of_some_markers_equal_those_of_all(path: str) -> None:
    # asked for some markers, the batched kinematics computes only their joints' chains
    sk = skeleton(path)
    q = sk.cmap.complete(RNG.uniform(-0.5, 0.5, (5, sk.n)))
    every = sk.marker_positions(q)
    for body in ("tibia_l", "hand_r", sk.root_body):
        idx = np.array([i for i, b in enumerate(sk.marker_bodies) if b == body])
        if idx.size:
            np.testing.assert_array_equal(sk.marker_positions(q, idx[::-1]), every[:, idx[::-1]])
    np.testing.assert_array_equal(sk.marker_positions(q[0], [3, 0]), sk.marker_positions(q[0])[:, [3, 0]])


@pytest.mark.parametrize("path", MODEL_PATHS)
def test_batched_marker_jacobians_equal_the_per_frame_ones(path: str) -> None:
    sk = skeleton(path)
    q = sk.cmap.complete(RNG.uniform(-0.5, 0.5, (6, sk.n)))
    q[:, sk.coordinate_index("knee_angle_l")] = np.linspace(0.1, 1.6, 6)  # across the knee splines
    idx = np.arange(len(sk.marker_names))[::-2]  # a subset, out of order
    pos, jac = sk.marker_jacobians(q, idx)
    assert pos.shape == (6, idx.size, 3) and jac.shape == (6, idx.size, 3, sk.n)
    for k in range(6):
        p1, j1 = sk.marker_jacobian(q[k], idx)
        np.testing.assert_allclose(pos[k], p1, rtol=0, atol=1e-12)
        np.testing.assert_allclose(jac[k], j1, rtol=0, atol=1e-12)
    cols = np.flatnonzero(sk.is_independent & ~sk.locked)[::-1]  # a subset of columns, reordered
    pos_c, jac_c = sk.marker_jacobians(q, idx, cols)
    np.testing.assert_array_equal(pos_c, pos)
    np.testing.assert_array_equal(jac_c, jac[..., cols])


def test_gravity_torques_are_the_gradient_of_potential_energy() -> None:
    sk = skeleton(MODEL_PATHS[0])
    q = sk.cmap.complete(RNG.uniform(-0.4, 0.4, sk.n))
    zero = np.zeros((1, sk.n))
    tau = sk.inverse_dynamics(q[None], zero, zero).tau[0]
    g = np.array(sk.osim.gravity)
    h = 1e-6
    for c in np.flatnonzero(sk.is_independent):
        e = np.zeros(sk.n)
        e[c] = h
        dpe = -sk.total_mass * g @ (sk.center_of_mass(sk.cmap.complete(q + e))[0] - sk.center_of_mass(sk.cmap.complete(q - e))[0]) / (2 * h)
        assert tau[c] == pytest.approx(dpe, abs=1e-6), sk.coordinate_names[c]


def test_external_wrench_enters_as_minus_jacobian_transpose() -> None:
    sk = skeleton(MODEL_PATHS[0])
    q = sk.cmap.complete(RNG.uniform(-0.4, 0.4, sk.n))[None]
    zero = np.zeros_like(q)
    force, moment = np.array([[30.0, 700.0, -20.0]]), np.array([[0.0, 4.0, 0.0]])
    cop = sk.body_poses(q)[1][:, sk.body_index("calcn_r")] + np.array([0.1, -0.03, 0.02])
    free = sk.inverse_dynamics(q, zero, zero).tau
    loaded = sk.inverse_dynamics(q, zero, zero, [ExternalWrench("calcn_r", force, cop, moment)]).tau
    # virtual work: tau_ext = J_point^T F + J_rot^T M; check the force part with a point Jacobian
    h = 1e-6
    expected = np.zeros(sk.n)
    r_b, p_b = sk.body_poses(q)
    local = r_b[0, sk.body_index("calcn_r")].T @ (cop[0] - p_b[0, sk.body_index("calcn_r")])
    for c in np.flatnonzero(sk.is_independent):
        e = np.zeros(sk.n)
        e[c] = h
        rp, pp = sk.body_poses(sk.cmap.complete(q[0] + e))
        rm, pm = sk.body_poses(sk.cmap.complete(q[0] - e))
        b = sk.body_index("calcn_r")
        dp = (rp[0, b] @ local + pp[0, b] - rm[0, b] @ local - pm[0, b]) / (2 * h)
        dr = (rp[0, b] - rm[0, b]) / (2 * h) @ r_b[0, b].T
        omega = np.array([dr[2, 1], dr[0, 2], dr[1, 0]])
        expected[c] = dp @ force[0] + omega @ moment[0]
    np.testing.assert_allclose(free - loaded, expected[None], atol=1e-5)


def test_root_residual_is_the_total_external_wrench_balance() -> None:
    """Static pose, no contact: the root must carry the whole weight, m g upward."""
    sk = skeleton(MODEL_PATHS[0])
    q = sk.neutral()[None]
    zero = np.zeros_like(q)
    res = sk.inverse_dynamics(q, zero, zero)
    np.testing.assert_allclose(res.root_force[0], -sk.total_mass * np.array(sk.osim.gravity), atol=1e-9)
    com = sk.center_of_mass(q)[0]
    pelvis = sk.body_poses(q)[1][0, sk.body_index("pelvis")]
    expected_moment = np.cross(com - pelvis, -sk.total_mass * np.array(sk.osim.gravity))
    np.testing.assert_allclose(res.root_moment[0], expected_moment, atol=1e-9)
    np.testing.assert_allclose(res.tau[0, [sk.coordinate_index(c) for c in ("pelvis_tx", "pelvis_ty", "pelvis_tz")]],
                               res.root_force[0], atol=1e-9)
