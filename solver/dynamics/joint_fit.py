"""The dynamics fit with the body masses solved jointly with the coordinates (the pipeline's).

:func:`solver.dynamics.fit.fit_dynamics` alternates rounds of coordinate steps with a
least-squares solve of the body mass factors whose prior is centred on each round's masses.
That alternation has no fixed cost, so it has no end point: run on, the mass factors of the
distal segments keep drifting (the walk's left toes 0.49 of their mass after 24 rounds,
2026-11-26), and the cap of 4 rounds is what stops it on the walk, the run and the OpenCap
subject (tests/benchmarks/RESULTS.md, block ``fit-rounds``).

:func:`fit_dynamics_joint` minimizes one cost, fixed for the whole fit: the trials' costs of
:mod:`solver.dynamics.fit` (markers, root residual wrench, accelerations) plus a prior
``sum_j w_j² (f_j - 1)²`` on the mass factor f_j of each mass-carrying pinocchio joint,
relative to the masses the fit starts from. Each Levenberg-Marquardt step solves the spline
coefficients of every trial and the relative changes s of the factors at once: each trial's
banded normal matrix in the coefficients is bordered by J dense columns, the derivatives of
its weighted residual wrench with respect to s (:meth:`_BorderedProblem.mass_rows`), and
the bordered system is solved by its Schur complement (each trial's banded Cholesky
factor L, J + 1 forward substitutions W = L^-1 [B, g], the J x J system S = C - W^T W, one
back-substitution for the coordinates' step; Triggs et al. 2000, "Bundle adjustment - a
modern synthesis", §6.1, the same reduction with cameras and points). The
total mass, set by the centre-of-mass fit, is held: each step keeps ``sum_j m_j s_j = 0``
(a Lagrange multiplier on the J x J system). A step that would carry coordinates past
their bounds is solved again with them held at the bound before its cost is evaluated
(:data:`PROJECTIONS`). The fit stops when a step lowers the cost by less than
``FitSettings.tolerance`` (relative; :data:`~solver.dynamics.fit.JOINT_TOLERANCE` for the
pipeline): a convergence test on one cost, met in 4 steps on the walk, the run and the
OpenCap subject and 7 on the Camargo circuit (tests/benchmarks/RESULTS.md, block
``joint-fit``). Restarted from its answer, the fit still lowers the cost by a fraction of a
per cent (tests/dynamics/test_joint_fit.py): the coordinates held at a bound change from
step to step, and the Gauss-Newton model drops the second derivative of the nonlinear
joint functions (the knee splines).

The root residual wrench is linear in each joint's inertia. With F_j and N_j the rate of
linear momentum of joint j's bodies and of their angular momentum about the ground origin
(pinocchio's ``data.of`` of the joint's subtree minus its children's, world frame), m_j
their mass, c_j their centre of mass, c and M the whole body's, pdot its rate of linear
momentum and F_ext the external force, scaling joint j's mass and inertia by 1 + s_j gives

    d F_res / d s_j = F_j - m_j g
    d M_res / d s_j = N_j - c x F_j - (m_j (c_j - c) / M) x (pdot - F_ext)

for F_res = pdot - M g - F_ext and M_res = kdot_G - (M_ext - c x F_ext), kdot_G = N - c x pdot
(tests/dynamics/test_joint_fit.py checks them by finite differences).

``addb process`` runs it (``FitSettings.mass_fit = "joint"``,
:func:`~solver.dynamics.fit.converged_fit`); the diagnosis still judges every trial on the
alternation it is calibrated on (:mod:`solver.diagnose.judged_fit`). Measured against the
alternation in tests/benchmarks/RESULTS.md, block ``joint-fit``
(``tests/benchmarks/bench_joint_fit.py``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np
from scipy.linalg import LinAlgError

from solver.dynamics.banded import banded_back_solve, banded_cholesky, banded_forward_solve
from solver.dynamics.fit import (
    FitOutput,
    FitSettings,
    FitTrialInput,
    _TrialProblem,
    bodies_of_joints,
    converged_fit,
    mass_joints,
)
from solver.errors import DynamicsError
from solver.model.skeleton import Skeleton

FloatArray = np.ndarray
#: Solves of one step (the damping grows 4-fold after each that raises the cost).
TRIES = 10
#: Solves of one step, besides :data:`TRIES`, that hold at the bound the coordinates the
#: step would carry past one before its cost is evaluated (same damping). Clipped to the
#: bound after the step instead, those frames' kinks raised the cost up to 12-fold (the
#: walk's first step), each rejection raised the damping, and the coordinates held at a
#: bound grew by a few frames a step: the OpenCap subject's fit took 12 steps, crawling
#: 2-3e-4 a step with gain ratios near 1, and 4 with one such solve (2026-11-26; more than
#: one changed nothing there and cost the Camargo circuit a factorization a step).
PROJECTIONS = 1
#: After a step that needed more damping than the last, the damping stays at least that
#: high for the next steps, the floor halving at each (a step at a third of it, Nielsen's
#: rule after a good step, raised the cost on the walk and the OpenCap subject at every step).
FLOOR_DECAY = 0.5
#: Steps at the start that move the coordinates only. The first step leaves the filtered
#: IK motion for one near the markers and the residuals, lowering the cost 3-10 fold; mass
#: changes solved at the IK motion, with that step, led the Camargo circuit's fit to a
#: minimum with a linear residual 0.9 % above the alternation's (0.631 against 0.626 N),
#: and with one step of coordinates first it is below it (0.621), as on the other subjects
#: (2026-11-26; two such steps left the walk's marker RMS and the run's linear residual
#: above the alternation's).
COORDINATES_FIRST = 1
#: Each mass factor stays within these (relative to the masses the fit starts from).
FACTOR_BOUNDS = (0.5, 2.0)


def _mass_step(schur: FloatArray, rhs: FloatArray, constraint: FloatArray, f: FloatArray) -> FloatArray:
    """``(J,)`` relative changes s of the mass factors ``f`` minimizing the reduced model
    ``s^T S s / 2 - rhs^T s`` subject to ``constraint^T s = 0`` (the total mass) and
    ``f (1 + s)`` within :data:`FACTOR_BOUNDS`: the KKT system of the equality, solved again
    with each factor the solve carried past a bound fixed at it (an active set that only
    grows; at most J solves). A factor clipped after the solve instead would break the total
    mass, which the model's build then restores by scaling every body."""
    nj = f.size
    lo, hi = FACTOR_BOUNDS
    fixed = np.zeros(nj, dtype=bool)
    target = np.zeros(nj)
    for _ in range(nj + 1):
        idx = np.flatnonzero(fixed)
        n = nj + 1 + idx.size
        kkt = np.zeros((n, n))
        kkt[:nj, :nj] = schur
        kkt[:nj, nj] = kkt[nj, :nj] = constraint
        kkt[idx, nj + 1 + np.arange(idx.size)] = kkt[nj + 1 + np.arange(idx.size), idx] = 1.0
        ds = np.linalg.solve(kkt, np.concatenate([rhs, [0.0], target[idx]]))[:nj]
        f_new = f * (1.0 + ds)
        out = ~fixed & ((f_new < lo) | (f_new > hi))
        if not out.any():
            return ds
        fixed |= out
        target[out] = np.clip(f_new[out], lo, hi) / f[out] - 1.0
    return ds  # pragma: no cover - every factor fixed: the last solve stands


class _BorderedProblem(_TrialProblem):
    """A trial's problem with the mass border of its Gauss-Newton system
    (``direction="coefficients"`` only)."""

    def __init__(self, sk: Skeleton, data: FitTrialInput, st: FitSettings, joints: list[int]) -> None:
        super().__init__(sk, data, st)
        self.joints = joints
        model = sk.model
        self._m = np.array([model.inertias[j].mass for j in joints])
        self._lever = np.array([model.inertias[j].lever for j in joints])  # (J, 3), joint frame
        self.rows: FloatArray | None = None  # (T, 6, J) weighted d res / d s at the last linearization
        self.res: FloatArray | None = None  # (T, 6) weighted residual wrench there
        self.border: FloatArray | None = None  # (nc, nf, J) J_a^T rows
        parents = model.parents
        # the rates mass_rows reads: each mass joint's subtree and its children's
        mass_joints = set(joints)
        self.subtree_joints = tuple(sorted(mass_joints | {c for c in range(1, model.njoints) if parents[c] in mass_joints}))

    def mass_rows(self, q: FloatArray, ofs: FloatArray) -> FloatArray:
        """``(T, 6, J)`` derivatives of the unweighted root residual wrench [force, moment
        about the centre of mass] (N, N·m; ground frame) with respect to s_j, the relative
        change of the mass and inertia of joint ``joints[j]`` (module docstring).

        ``ofs``: ``(T, len(subtree_joints), 6)`` pinocchio's ``data.of`` at q of every frame
        for the joints ``subtree_joints`` (each subtree's momentum rate, world frame, about the
        origin), as the linearization keeps them (``subtree_rates``)."""
        _, _, _, hdot, com = self._dynamics_state(q)
        model = self.sk.model
        at = {j: i for i, j in enumerate(self.subtree_joints)}
        own = ofs[:, [at[j] for j in self.joints]]  # (T, J, 6), a copy
        place = {j: i for i, j in enumerate(self.joints)}
        for c in reversed(self.subtree_joints):  # a subtree's own rate: minus its children's
            if (p := model.parents[c]) in place:
                own[:, place[p]] -= ofs[:, at[c]]
        joints = self.joints
        rot, pos = self.sk._joint_poses_soa(q)
        c_j = np.einsum("jikt,jk->tji", rot[joints], self._lever) + pos[joints].transpose(2, 0, 1)  # (T, J, 3)
        f_j, n_j = own[:, :, :3], own[:, :, 3:]
        d_f = f_j - self._m[None, :, None] * self.g
        dc = self._m[None, :, None] * (c_j - com[:, None, :]) / self.mass
        lin = hdot[:, :3] - self.data.force  # pdot - F_ext
        d_m = n_j - np.cross(com[:, None, :], f_j) - np.cross(dc, lin[:, None, :])
        return np.concatenate([d_f, d_m], axis=2).transpose(0, 2, 1)

    def _linearize(self, q: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        out = super()._linearize(q)
        _, _, res, dq, dv, da = out
        self.rows = self.mass_rows(q, self.subtree_rates) * self.w_res[:, :, None]
        self.res = res
        cm, nj = self.cmaps, len(self.joints)
        # J_a^T rows: each frame's rows depend on the coefficients through E0, E1, E2 (the
        # same maps as the gradient's), so the border is E0^T P0 + E1^T P1 + E2^T P2 with
        # P[k] = (d r_k / d x_k)^T rows_k for x the positions, velocities, accelerations
        parts = [np.einsum("krf,krj->kfj", d, self.rows).reshape(self.t, -1) for d in (dq, dv, da)]
        self.border = (cm.e0.T @ parts[0] + cm.e1.T @ parts[1] + cm.e2.T @ parts[2]).reshape(-1, self.nf, nj)
        return out


def fit_dynamics_joint(
    build: Callable[[Mapping[str, float]], Skeleton],
    trials: Sequence[FitTrialInput],
    settings: FitSettings | None = None,
    progress: Callable[[str, float], None] | None = None,
) -> FitOutput:
    """Fit the coordinates of every trial and the body mass factors together (module docstring).

    Parameters
    ----------
    build
        ``(mass_factors: dict[body, float]) -> Skeleton``: the model with each body's mass
        and inertia multiplied by its factor, all rescaled to the model's total mass (as
        :func:`solver.dynamics.stage.run_dynamics` builds it).
    trials
        The trials with force data.
    settings
        Weights, ``mass_sigma`` (the prior's deviation of a factor from 1, relative),
        ``tolerance`` (the convergence test) and ``rounds x iterations`` (the most steps);
        ``direction`` must be ``"coefficients"``. Default :func:`~solver.dynamics.fit.converged_fit`.
    progress
        Optional callable (message, fraction).

    Returns
    -------
    FitOutput
        ``(T, n)`` coordinates per trial, the factor of every body (relative to ``build({})``'s
        masses), and the total cost after each accepted step (the first entry at the start).

    The prior weights are set once, at the first step, on the scale of the data as the
    alternation sets its own: ``w_j² = share_j mean_i(|G_i|²) / (6 mass_sigma²)``, G the
    columns of the weighted residual rows' derivatives with respect to s and share_j the
    joint's share of the mass. The first :data:`COORDINATES_FIRST` steps move the coordinates
    only. A factor that a step would carry past :data:`FACTOR_BOUNDS` is held at the bound
    (:func:`_mass_step`), and so are the coordinates a step would carry past theirs, solved
    again before the step's cost is evaluated (:data:`PROJECTIONS`). A step that raises the cost is solved again with 4 times the
    damping, the coordinates it carried past a bound held at the bound (where they are,
    after a second such solve), and the damping of the next steps stays at least that high
    (:data:`FLOOR_DECAY`); after :data:`TRIES` such solves the fit ends where it is.

    Raises
    ------
    DynamicsError
        ``settings.direction`` is not ``"coefficients"``, or ``settings.mass_fit`` is not
        ``"joint"``.
    """
    st = settings or converged_fit()
    if st.direction != "coefficients":
        raise DynamicsError(f"the joint mass fit needs direction='coefficients', not {st.direction!r}")
    if st.mass_fit != "joint":
        raise DynamicsError(f"fit_dynamics_joint runs mass_fit='joint', not {st.mass_fit!r} (the alternation is solver.dynamics.fit.fit_dynamics)")
    sk = build({})
    joints = mass_joints(sk)
    m0 = np.array([sk.model.inertias[j].mass for j in joints])
    bodies = bodies_of_joints(sk)

    def factors_of(f: FloatArray) -> dict[str, float]:
        return {b: float(fj) for j, fj in zip(joints, f) for b in bodies.get(j, [])}

    def problems(sk: Skeleton) -> list[_BorderedProblem]:
        return [_BorderedProblem(sk, tr, st, joints) for tr in trials]

    nj = len(joints)
    f = np.ones(nj)
    qs = [np.array(tr.q, dtype=float) for tr in trials]
    probs = problems(sk)
    w2 = np.zeros(nj)  # prior weights squared, set at the first step
    cost = sum(p.cost(q) for p, q in zip(probs, qs))
    history = [cost]
    mu, floor = 1e-6, 0.0
    steps = st.rounds * st.iterations
    # the per-trial work is done in helpers, so that no loop variable keeps a trial's normal
    # matrix or factor (64 MB each for 2,000 frames) alive while the next one is made
    for it in range(steps):
        if progress:
            progress(f"dynamics fit: step {it + 1}", it / steps)
        systems = None  # the last step's normal matrices go before new ones are made
        systems, c_ss, g_s = _linearized(probs, qs, nj)
        if it == 0:
            w2 = (m0 / m0.sum()) * np.mean(np.diag(c_ss)) / (6.0 * st.mass_sigma**2)
        c_ss += np.diag(w2 * f**2)
        g_s += w2 * f * (f - 1.0)  # the prior's residuals w (f (1 + s) - 1): half-cost gradient at s = 0
        damp_s = np.maximum(np.diag(c_ss).copy(), 1e-9)
        constraint = m0 * f  # sum_j m_j s_j = 0: the total mass stays
        step, raised = None, False
        untargeted = [s[3].copy() for s in systems]  # each gradient before the targets of held coordinates
        tries, projections = 0, PROJECTIONS
        while tries < TRIES:
            solved = None  # the last try's factors go before new ones are made
            try:
                solved, schur, rhs = _reduced(systems, mu, nj)
            except LinAlgError:
                mu *= 10
                tries += 1
                continue
            schur += c_ss + mu * np.diag(damp_s)
            rhs -= g_s
            ds = _mass_step(schur, rhs, constraint, f) if it >= COORDINATES_FIRST else np.zeros(nj)
            deltas, predicted = _coordinate_steps(systems, solved, untargeted, ds, mu)
            if projections and not raised and _hold_past_bounds(systems, deltas, untargeted, raised):
                projections -= 1
                continue
            tries += 1
            f_new = np.clip(f * (1.0 + ds), *FACTOR_BOUNDS)  # within rounding of the bounds already
            probs_new = problems(build(factors_of(f_new)))
            q_new = [pn._take(s[1], d) for s, pn, d in zip(systems, probs_new, deltas)]
            predicted += float(-g_s @ ds + mu * np.sum(damp_s * ds**2))
            cost_new = sum(pn.cost(qn) for pn, qn in zip(probs_new, q_new)) + float(np.sum(w2 * (f_new - 1.0) ** 2))
            if cost_new < cost:
                rho = (cost - cost_new) / max(predicted, 1e-300)
                if raised:
                    floor = max(floor, mu)
                mu = max(mu * max(1 / 3, 1 - (2 * rho - 1) ** 3), 1e-12, floor)
                floor *= FLOOR_DECAY
                step = (cost - cost_new) / max(cost, 1e-30)
                f, probs, qs, cost = f_new, probs_new, q_new, cost_new
                history.append(cost)
                break
            _hold_past_bounds(systems, deltas, untargeted, raised)
            mu *= 4
            raised = True
        if step is None or step < st.tolerance:
            break
    return FitOutput(tuple(qs), factors_of(f), tuple(history))


#: One trial's linearized system: (problem, q, normal-matrix bands, gradient, held, diagonal, border).
_System = tuple


def _linearized(probs: Sequence[_BorderedProblem], qs: Sequence[FloatArray], nj: int) -> tuple[list[_System], FloatArray, FloatArray]:
    """Every trial's coefficient system at its q (coordinates at a bound that the gradient
    pushes out held there), and the trials' ``(J, J)`` mass block C and ``(J,)`` mass gradient."""
    systems = []
    c_ss = np.zeros((nj, nj))
    g_s = np.zeros(nj)
    for p, q in zip(probs, qs):
        bands, grad, g_q, diag = p.coefficient_equations(q)
        held = p.held_at_bounds(q, g_q)
        grad = grad.copy()
        if held.any():
            p._hold(bands, grad, held, diag)
        c_ss += np.einsum("krj,kri->ji", p.rows, p.rows)
        g_s += np.einsum("krj,kr->j", p.rows, p.res)
        systems.append((p, q, bands, grad, held, diag, p.border.reshape(-1, nj)))
    return systems, c_ss, g_s


def _reduced(systems: Sequence[_System], mu: float, nj: int) -> tuple[list[tuple[FloatArray, ...]], FloatArray, FloatArray]:
    """The Schur complement of every trial's damped coefficient block, A = L L^T: per trial
    ``(L, W, v, damping)`` with W = L^-1 B and v = L^-1 g, and the sums ``-W^T W`` and
    ``W^T v`` (the mass block and right-hand side then add C + mu D and -g_s).

    Raises
    ------
    LinAlgError
        A damped block is not positive definite (more damping is needed).
    """
    solved = []
    schur = np.zeros((nj, nj))
    rhs = np.zeros(nj)
    for _, _, bands, grad, _, diag, border in systems:
        ab = bands.lower_band_storage()  # a fresh copy: the bands stay for another try
        damp = np.maximum(diag.reshape(-1), 1e-9)
        ab[0] += mu * damp
        chol = banded_cholesky(ab, overwrite=True)
        wv = banded_forward_solve(chol, np.column_stack([border, grad.reshape(-1)]))  # in row chunks that stay in cache
        w_b, v = wv[:, :nj], wv[:, nj]
        schur -= w_b.T @ w_b
        rhs += w_b.T @ v
        solved.append((chol, w_b, v, damp))
    return solved, schur, rhs


def _coordinate_steps(
    systems: Sequence[_System], solved: Sequence[tuple[FloatArray, ...]], untargeted: Sequence[FloatArray], ds: FloatArray, mu: float
) -> tuple[list[FloatArray], float]:
    """For the mass step ``ds``, each trial's coordinate step da = -L^-T (v + W ds): the
    ``(T, nf)`` steps of the free coordinates, and the model's predicted decrease of the
    trials' terms (Nielsen's ``-g da + mu da^T D da``, with each trial's gradient from before
    the targets of its held coordinates, ``untargeted``: with them, the hold rows' stiff pull
    made the prediction up to 1e8 for a decrease of 10, which the gain ratio then read as a
    poor model; the hold rows' own work is left out)."""
    deltas, predicted = [], 0.0
    for (p, _, _, _, _, _, _), (chol, w_b, v, damp), grad in zip(systems, solved, untargeted):
        da = -banded_back_solve(chol, v + w_b @ ds)
        predicted += float(-grad.reshape(-1) @ da + mu * np.sum(damp * da**2))
        deltas.append(p.cmaps.e0 @ da.reshape(-1, p.nf))
    return deltas, predicted


def _hold_past_bounds(systems: Sequence[_System], deltas: Sequence[FloatArray], untargeted: Sequence[FloatArray], raised: bool) -> bool:
    """Before a step's cost is evaluated (:data:`PROJECTIONS`) or after a rejected step:
    hold the coordinates it carried past a bound, in place in each trial's system, for the
    next solve; returns whether there were any.

    They are held at the bound, as a single trial's step holds them (held where they were
    instead, the Camargo circuit's fit with the masses frozen stalled above the
    alternation's cost, 19297.6 against 19295.5, and left its linear residual 2 % higher);
    after a second rejected solve (``raised``), every held coordinate is held where it is
    (the targets dropped: ``untargeted`` keeps each gradient from before them; with them,
    more damping still moved those coordinates to their bounds, and the OpenCap subject's
    fit stalled after 3 steps; 2026-11-26)."""
    found = False
    for (p, q, bands, grad, held, diag, _), delta, plain in zip(systems, deltas, untargeted):
        found |= p.hold_past_bounds(q, delta, bands, grad, held, diag, at_bound=not raised)
        if raised:
            grad[:] = plain
    return found
