"""The joint mass fit (:mod:`solver.dynamics.joint_fit`) on the Rajagopal walk: its mass
derivatives, its convergence test, and its result against the pipeline's alternation."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import solver.dynamics.stage as stage_module
from solver.dynamics.fit import FitOutput, fit_dynamics
from solver.dynamics.joint_fit import _BorderedProblem, fit_dynamics_joint, mass_joints
from solver.pipeline import process_subject

WALK = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "subjects" / "rajagopal2016_walk"
SIGMA = 0.5  # the anchored prior's deviation measured in tests/benchmarks/RESULTS.md, block joint-fit


@pytest.fixture(scope="module")
def walk(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    """The walk processed with the alternation and with the joint fit, and the fit's inputs."""
    tmp = tmp_path_factory.mktemp("joint_fit")
    seen: dict[str, object] = {}

    def capture(build, trials, settings, progress=None) -> FitOutput:  # type: ignore[no-untyped-def]
        seen.update(build=build, trials=trials, settings=settings)
        return fit_dynamics(build, trials, settings, progress)

    def joint(build, trials, settings, progress=None) -> FitOutput:  # type: ignore[no-untyped-def]
        out = fit_dynamics_joint(build, trials, replace(settings, mass_sigma=SIGMA), progress)
        seen["joint"] = out
        return out

    for name, fit in (("alternation", capture), ("joint", joint)):
        stage_module.fit_dynamics = fit  # type: ignore[assignment]
        try:
            process_subject(WALK, tmp / name)
        finally:
            stage_module.fit_dynamics = fit_dynamics
        seen[name + "_results"] = json.loads((tmp / name / "walk" / "results.json").read_text())
    return seen


def _residual(prob: _BorderedProblem, q: np.ndarray) -> np.ndarray:
    """``(T, 6)`` weighted root residual wrench of ``prob`` at ``q`` (a fresh evaluation)."""
    _, _, qp, vp, ap = prob.kinematics(q)
    return prob.residual_wrench(*prob.momentum_rate(qp, vp, ap)) * prob.w_res


def test_mass_rows_are_the_residual_derivatives_by_finite_differences(walk: dict[str, object]) -> None:
    """Scaling one joint's mass by 1 + eps, then every mass to the same total (what
    ``build`` does), changes the weighted residual wrench by the mass rows times the
    relative changes s: eps k + k - 1 for that joint, k - 1 for the others."""
    build, trial, st = walk["build"], walk["trials"][0], walk["settings"]  # type: ignore[index]
    sk = build({})  # type: ignore[operator]
    joints = mass_joints(sk)
    prob = _BorderedProblem(sk, trial, st, joints)
    q = trial.q
    rows = prob.mass_rows(q) * prob.w_res[:, :, None]
    r0 = _residual(prob, q)
    bodies = {j: [b for b, bj in zip(sk.body_names, sk.body_joint) if int(bj) == j] for j in joints}
    total = sk.total_mass
    eps = 1e-5
    for i in (0, 3, 7, len(joints) - 1):  # pelvis, a thigh, a foot, the last arm joint
        j = joints[i]
        sk2 = build({b: 1.0 + eps for b in bodies[j]})  # type: ignore[operator]
        k = total / (total + sk.model.inertias[j].mass * eps)
        s = np.full(len(joints), k - 1.0)
        s[i] = (1.0 + eps) * k - 1.0
        moved = _residual(_BorderedProblem(sk2, trial, st, joints), q) - r0
        predicted = np.einsum("krj,j->kr", rows, s)
        assert np.abs(moved).max() > 0
        np.testing.assert_allclose(predicted, moved, rtol=0, atol=1e-5 * np.abs(moved).max())


def test_the_border_is_the_gauss_newton_cross_term(walk: dict[str, object]) -> None:
    """``border^T da`` equals ``rows^T (J_a da)``, the change of the residual wrench along a
    change da of the spline coefficients by central differences, to 1e-3 of its size (the
    fit's Jacobian drops the second derivative of the nonlinear joint functions, the knee
    splines, as tests/dynamics/test_fit_linear_algebra.py says)."""
    build, trial, st = walk["build"], walk["trials"][0], walk["settings"]  # type: ignore[index]
    sk = build({})  # type: ignore[operator]
    prob = _BorderedProblem(sk, trial, st, mass_joints(sk))
    q = trial.q
    prob.coefficient_equations(q)
    rng = np.random.default_rng(5)
    da = rng.standard_normal(prob.border.shape[:2]) * 1e-6
    moved = []
    for sign in (1.0, -1.0):
        qq = q.copy()
        qq[:, prob.free] += sign * (prob.cmaps.e0 @ da)
        moved.append(_residual(prob, sk.cmap.complete(qq)))
    expected = np.einsum("krj,kr->j", prob.rows, (moved[0] - moved[1]) / 2)
    got = np.einsum("nfj,nf->j", prob.border, da)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-3 * np.abs(expected).max())


def test_the_joint_fit_ends_on_its_convergence_test_and_keeps_the_total_mass(walk: dict[str, object]) -> None:
    out: FitOutput = walk["joint"]  # type: ignore[assignment]
    st = walk["settings"]
    build = walk["build"]
    h = np.array(out.history)
    assert np.all(np.diff(h) < 0)  # every accepted step lowers the one cost
    assert len(h) - 1 < st.rounds * st.iterations  # type: ignore[attr-defined]
    assert (h[-2] - h[-1]) / h[-2] < st.tolerance  # type: ignore[attr-defined]
    before, after = build({}), build(out.mass_factors)  # type: ignore[operator]
    assert after.total_mass == pytest.approx(before.total_mass, rel=1e-12)
    # the build rescales to the total: the factors it is given already hold it
    masses = {b.name: b.mass for b in before.osim.bodies}
    assert sum(masses[b] * f for b, f in out.mass_factors.items()) + sum(m for b, m in masses.items() if b not in out.mass_factors) == pytest.approx(
        before.total_mass, rel=1e-9
    )
    assert all(0.5 <= f <= 2.0 for f in out.mass_factors.values())


def test_the_joint_fit_is_at_least_as_good_as_the_alternation_on_the_walk(walk: dict[str, object]) -> None:
    """Issue 29's bar for a fit that stops on a convergence test: marker RMS, linear and
    angular residual RMS no higher, measured frames as many (the pipeline's metrics, from
    results.json)."""
    a, j = walk["alternation_results"], walk["joint_results"]
    assert j["n_observed_frames"] == a["n_observed_frames"]  # type: ignore[index]
    for key in ("marker_rms_m", "linear_residual_rms_N", "angular_residual_rms_Nm"):
        assert j[key] <= a[key], key  # type: ignore[index]
