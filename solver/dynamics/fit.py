"""The dynamics fit: coordinates and body masses that trade marker error for root residuals.

For each trial, over all frames t (Werling et al. 2023, the AddBiomechanics dynamics pass,
solved here by Gauss-Newton on a banded system):

    min_Q  sum_t sum_m |p_m(q_t) - y_tm|² / s_m²                              markers, every frame
         + sum_{t observed} |F_res(t)|² / s_F² + |M_res(t)|² / s_M²            residuals, measured frames only
         + sum_t |q_{t+1} - 2 q_t + q_{t-1}|² / (h² s_a)²                       smoothness
                 (|qdd_t|² / s_a², the spline's accelerations, with direction "coefficients")

where F_res = pdot - m g - F_ext and M_res = kdot_G - sum_i (r_i - c) x f_i - tau_i are the
net force and the net moment about the centre of mass that the ground would have to add
to the measured external wrenches (the root residual wrench), pdot and kdot_G the rates
of linear and angular momentum (pinocchio's centroidal dynamics and their analytic
derivatives), velocities and accelerations the linear operators of
:mod:`solver.dynamics.spline` applied to Q. Frames with unmeasured force keep their marker
and smoothness terms only: the centre of mass accelerates freely there, and the motion
stays one continuous trajectory through them.

With ``FitSettings.direction = "coefficients"`` (:func:`converged_fit`) each Gauss-Newton
step is exact and banded: the unknowns are the coefficients a of the coordinates' natural quintic spline in
a local basis (q = E0 a, qd = E1 a, qdd = E2 a with E0, E1, E2 banded:
:class:`solver.dynamics.spline.CoefficientMaps`), so the normal matrix J^T J of the cost with
the spline's full (dense in q) derivative operators is block-banded in a and solved by a
banded Cholesky factorization (LAPACK ``dpbtrf``, :mod:`solver.dynamics.banded`). The
damping follows Levenberg-Marquardt's gain ratio (Nielsen 1999); a coordinate at a bound
that the gradient pushes out of its range is held there, and a step is clipped to the
bounds. The default direction, ``"band"``, truncates the derivative operators to ``band``
frames in q (its steps are not the cost's Gauss-Newton steps, and the fit stalls short of
the minimum); ``"exact"`` solves the exact system in q by preconditioned conjugate
gradients.

Rounds of coordinate steps (each stopped when the relative cost decrease falls below
``tolerance``, or the looser ``round_tolerance`` while the masses still move) alternate
with a linear least-squares solve of the body mass factors (the root generalized forces
are linear in the inertial parameters: pinocchio's joint torque regressor) with a prior
toward the mass distribution of the round's model (each solve's factors multiply the
earlier ones, so the prior moves with the fit: on the walk and the OpenCap subject the
factors move about 2 % a round, in the same direction every round, and the fit runs every
round); the alternation stops when a solve changes no factor by more than
``mass_tolerance`` (when set) after a round whose steps settled to ``tolerance``, or after
``rounds``. That alternation (``FitSettings.mass_fit = "rounds"``) has no fixed cost, so
the cap of ``rounds`` is what ends it on most subjects. The pipeline's default
(:func:`converged_fit`, ``mass_fit = "joint"``) instead solves the mass factors in every
step together with the coordinates, on one cost with a prior anchored at the starting
masses, and stops on a convergence test (:mod:`solver.dynamics.joint_fit`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray
from scipy.linalg import LinAlgError

from solver.dynamics.banded import BlockBands, banded_cholesky, banded_cholesky_back
from solver.dynamics.spline import CoefficientMaps, Derivatives
from solver.errors import DynamicsError
from solver.kinematics.ik import solver_bounds
from solver.model.skeleton import Skeleton

FloatArray = NDArray[np.float64]
#: Weight of a held coordinate's row in the coefficient system, relative to the normal matrix's diagonal.
HOLD = 1e4
#: Frames per chunk when the coefficient system is assembled (bounds its temporaries' memory).
ASSEMBLY_FRAMES = 256
IntArray = NDArray[np.intp]


@dataclass(frozen=True)
class FitSettings:
    """Weights (as standard deviations) and iteration limits of the dynamics fit.

    Attributes
    ----------
    marker_sigma
        s_m, m per marker coordinate.
    force_sigma
        s_F, N per residual force component.
    moment_sigma
        s_M, N·m per residual moment component.
    accel_sigma
        s_a, rad/s² (m/s²) per coordinate: a weak smoothness prior on the accelerations
        (central second differences; the spline's accelerations with ``"coefficients"``,
        whose normal matrix stays as narrow as a frame's window then).
    unobserved_force_sigma, unobserved_moment_sigma
        s_F and s_M on frames with unmeasured force: a weak pull of the free centre-of-mass
        accelerations there (the unmeasured force stays free to reach body weight).
    mass_fit
        How the body mass factors are fitted. ``"rounds"`` (default): the alternation of
        rounds of coordinate steps and mass solves (module docstring; :func:`fit_dynamics`).
        ``"joint"``: every step solves the coordinates and the mass factors together, on one
        cost whose mass prior is anchored at the starting masses, until the cost settles
        (:func:`solver.dynamics.joint_fit.fit_dynamics_joint`; :func:`converged_fit`).
    mass_sigma
        Prior deviation of each body's mass factor from 1 (relative). With ``"rounds"``, at
        each mass solve: the prior is centred on the masses of that round (the factor a
        solve returns multiplies them), not on the model's, so over rounds the factors can
        keep moving by a similar step. On the walk, the run and the OpenCap subject they do
        (1-5 % per solve), and ``rounds`` ends the alternation there, not ``mass_tolerance``
        (tests/benchmarks/RESULTS.md, block ``fit-rounds``, 4 rounds against 6). With
        ``"joint"``, relative to the masses the fit starts from, for the whole fit.
    rounds
        At most this many alternations of coordinate steps and mass solves.
    mass_tolerance
        Stop the alternation when a mass solve changes no body's mass factor by more than
        this (relative) after a round whose coordinate steps all stopped on ``tolerance``:
        the coordinates were fitted to the masses the solve returns. When the steps did not
        stop, the masses stand and another round of steps follows. Default 0: always
        ``rounds`` rounds (the older ``"band"`` fit); :func:`converged_fit` sets 0.01.
    iterations
        Gauss-Newton iterations per round.
    band
        ``"band"`` and ``"exact"`` only: frames kept on each side in the Jacobian of the
        derivative operators.
    tolerance
        Stop a round when the relative cost decrease is below this.
    round_tolerance
        The looser stop of the rounds after which the mass factors are solved again (None:
        ``tolerance``), when ``mass_tolerance`` is set: while the masses still move, the
        coordinates are fitted only as far as the next mass solve needs (an inexact
        alternation, as in inexact block-coordinate descent). Once a solve leaves every
        factor within ``mass_tolerance``, or at the last of ``rounds``, one round of steps
        to ``tolerance`` ends the fit, so the result is converged for the masses it returns;
        when the masses stand, each trial's steps go on from where they stopped (its damping
        kept), as if the round had not been cut. :func:`converged_fit` sets 1e-3 (block
        ``fit-round-tolerance`` of tests/benchmarks/RESULTS.md).
    derivative
        ``"spline"`` (OpenSim-consistent) or ``"central"``.
    direction
        How a Gauss-Newton step is found. ``"band"`` (default): the gradient and normal
        matrix of the Jacobian whose derivative operators are truncated to ``band`` frames,
        solved by banded Cholesky; the step is then not the Gauss-Newton step of the cost,
        and the fit stalls short of its minimum. ``"coefficients"``: exact, in a local basis
        of the natural splines, one banded Cholesky factorization per solve (module
        docstring); with :func:`converged_fit`, the pipeline's default, it reaches lower
        residuals *and* lower marker RMS than ``"band"`` on every subject measured, in fewer
        steps; the diagnosis judges every trial on it (:mod:`solver.diagnose.judged_fit`).
        ``"exact"``: the exact system in q by conjugate
        gradients preconditioned with the banded matrix (Nocedal & Wright 2006, §5.1 and
        §7.1); it converges slowly. Measured in tests/benchmarks/RESULTS.md, "Step
        direction of the dynamics fit".
    cg_iterations, cg_tolerance
        ``"exact"`` only: at most this many conjugate-gradient iterations per step, stopped
        when the residual falls below this fraction of the gradient.
    """

    marker_sigma: float = 0.01
    force_sigma: float = 2.0
    moment_sigma: float = 2.0
    accel_sigma: float = 500.0
    unobserved_force_sigma: float = 2000.0
    unobserved_moment_sigma: float = 2000.0
    mass_fit: str = "rounds"
    mass_sigma: float = 0.25
    rounds: int = 4
    iterations: int = 12
    mass_tolerance: float = 0.0
    band: int = 2
    tolerance: float = 1e-4
    round_tolerance: float | None = None
    derivative: str = "spline"
    direction: str = "band"
    cg_iterations: int = 20
    cg_tolerance: float = 0.05

    @property
    def converges(self) -> bool:
        """The fit runs until it settles (exact steps; the joint mass fit, or rounds stopped
        on the mass factors), so its end point does not depend on where it starts."""
        return self.direction == "coefficients" and (self.mass_fit == "joint" or self.mass_tolerance > 0)


def fit_name(st: FitSettings) -> str:
    """The ``addb process --fit`` name of a fit's settings (:data:`solver.pipeline.FIT_CHOICES`):
    ``"band"`` (``direction`` other than ``"coefficients"``), ``"rounds"`` (the alternation)
    or ``"converged"`` (the joint mass fit); names the fit for the diagnosis' report."""
    if st.direction != "coefficients":
        return "band"
    return "converged" if st.mass_fit == "joint" else "rounds"


#: Weights of :func:`converged_fit` that differ from ``FitSettings()``'s (sigmas: rad/s², N, N·m).
CONVERGED_WEIGHTS = {"accel_sigma": 120.0, "force_sigma": 4.0, "moment_sigma": 4.0}


#: Prior deviation of the joint mass fit's factors (:func:`converged_fit`). At 0.5 the fit
#: leaves the run's linear residual above the alternation's; at 1 its marker RMS and
#: residuals are at or below the alternation's on every trial of the walk, the run, the
#: OpenCap subject and the Camargo circuit (tests/benchmarks/RESULTS.md, block ``joint-fit``;
#: tests/dynamics/test_joint_fit.py).
JOINT_MASS_SIGMA = 1.0

#: Convergence test of the joint mass fit (:func:`converged_fit`): it stops when a step
#: lowers the cost by less than this fraction. Its steps hold the coordinates a step would
#: carry past a bound (:data:`solver.dynamics.joint_fit.PROJECTIONS`), and past this point
#: they still lower the Camargo circuit's cost by 3-8e-4 a step for 7 more steps (0.07 %
#: in all; 7.9 s for the whole process against 5.8 s) and the walk's by 0.1 % in 4, with
#: marker RMS and linear residuals unchanged to the digits the results show and the walk's
#: angular residual 3.8 N·m against 3.9 (2026-11-26).
JOINT_TOLERANCE = 1e-3

#: Convergence test of a round's coordinate steps in the alternation (:func:`alternating_fit`).
ROUND_STEP_TOLERANCE = 1e-4


def converged_fit(**changes: object) -> FitSettings:
    """Settings of a fit that runs to convergence, the pipeline's default:
    ``direction="coefficients"`` (exact banded Gauss-Newton steps), ``mass_fit="joint"``
    (coordinates and body mass factors solved together until the cost settles,
    :mod:`solver.dynamics.joint_fit`, with ``mass_sigma`` :data:`JOINT_MASS_SIGMA`) and the
    weights of :data:`CONVERGED_WEIGHTS`, other fields as given or default.
    :func:`alternating_fit` is the same with the alternation of rounds.

    The weights matter at the minimum, which the band fit never reaches. With ``FitSettings()``'s
    (accelerations 500 rad/s², residuals 2 N and 2 N·m) the alternation's minimum buys ~1 N
    residuals with the motion's accelerations (hip rotation 660 rad/s² RMS over 0.4 s of the
    walk, within a few degrees of angle the markers allow), and the walk's leg joint torques
    are 0.72 N·m/kg RMS from OpenSim's ID; the joint fit with them, 0.67 (2026-11-27). A
    tighter acceleration prior and looser residuals (accelerations 120 rad/s², residuals 4 N
    and 4 N·m) keep the torques at 0.16-0.18 N·m/kg (the band fit: 0.17), and give a marker
    RMS at or below the band fit's and lower residuals on every trial measured. The acceleration sigma sits below an edge where the fit has two minima:
    at 200 rad/s² the walk's torques were 0.5 N·m/kg from OpenSim's with every round run to
    ``tolerance`` (2026-11-24) and 0.16 with ``round_tolerance`` (the path decides which
    minimum it reaches); at 170 and below, 0.15 either way (tests/benchmarks/RESULTS.md,
    blocks ``joint-torques`` and ``converged-weights``;
    tests/dynamics/test_joint_torques_opensim.py).

    Raises
    ------
    TypeError
        A field FitSettings does not have.
    """
    return FitSettings(**{"direction": "coefficients", "mass_fit": "joint", "mass_sigma": JOINT_MASS_SIGMA, "tolerance": JOINT_TOLERANCE, **CONVERGED_WEIGHTS, **changes})  # type: ignore[arg-type]


def alternating_fit(**changes: object) -> FitSettings:
    """Settings of the converged fit's alternation (the pipeline's default until
    2026-11-26, and the fit the diagnosis is calibrated on, :mod:`solver.diagnose.judged_fit`):
    the exact steps and weights of :func:`converged_fit`, with ``mass_fit="rounds"``,
    ``mass_sigma=0.25``, ``tolerance`` :data:`ROUND_STEP_TOLERANCE` (a round's steps stop
    when one lowers the cost by less), ``mass_tolerance=0.01`` (rounds stop when the body mass factors
    settle; on the walk, the run and the OpenCap subject the cap of ``rounds`` comes first)
    and ``round_tolerance=1e-3`` (the rounds before the last stop early while the masses
    move; the last runs to ``tolerance``), other fields as given.

    Raises
    ------
    TypeError
        A field FitSettings does not have.
    """
    return converged_fit(**{"mass_fit": "rounds", "mass_sigma": 0.25, "mass_tolerance": 0.01, "round_tolerance": 1e-3, "tolerance": ROUND_STEP_TOLERANCE, **changes})


@dataclass(frozen=True)
class FitTrialInput:
    """One trial for the fit, on its common frames.

    Attributes
    ----------
    q
        ``(T, n)`` starting coordinates.
    markers
        ``(M,)`` model marker indices of the observations.
    observed_markers
        ``(T, M, 3)`` observed positions, NaN where missing.
    observed
        ``(T,)`` frames whose external force is measured (residual terms apply).
    force
        ``(T, 3)`` total external force, N, ground frame.
    moment
        ``(T, 3)`` total external moment about the ground origin, N·m.
    wrenches
        Per loaded body: (body name, ``(T, 6)`` [force, moment about the origin]) for the
        inverse-dynamics based mass solve.
    dt
        Frame interval, s.
    """

    q: FloatArray
    markers: IntArray
    observed_markers: FloatArray
    observed: NDArray[np.bool_]
    force: FloatArray
    moment: FloatArray
    wrenches: list[tuple[str, FloatArray]] = field(default_factory=list)
    dt: float = 0.01


@dataclass(frozen=True)
class FitOutput:
    """Fitted coordinates per trial and the mass factor of every body."""

    q: tuple[FloatArray, ...]
    mass_factors: dict[str, float]
    history: tuple[float, ...]


def _skew_batch(v: FloatArray) -> FloatArray:
    """``(T, 3)`` vectors -> ``(T, 3, 3)`` cross-product matrices (``[v]x w = v x w``)."""
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def _add_second_difference_normal(out: FloatArray, x: FloatArray, ws: float) -> FloatArray:
    """Add ``ws² L^T L x`` to ``out`` in place and return it, for ``(T, n)`` x and out, L the
    ``(T - 2, T)`` central second differences: the smoothness rows' normal product (their
    gradient at x, their Gauss-Newton product with a step x)."""
    sd = (x[2:] - 2 * x[1:-1] + x[:-2]) * ws**2
    out[:-2] += sd
    out[1:-1] -= 2 * sd
    out[2:] += sd
    return out


def _rows(idx: IntArray) -> IntArray | slice:
    """Row indices as a slice when they are consecutive (a view: no copy on ``+=``)."""
    if idx.size and idx[-1] - idx[0] == idx.size - 1 and np.all(np.diff(idx) == 1):
        return slice(int(idx[0]), int(idx[-1]) + 1)
    return idx


@lru_cache(maxsize=8)
def _coefficient_setup(t: int, dt: float, derivative: str) -> tuple[CoefficientMaps, tuple[IntArray, ...], int, FloatArray]:
    """What :meth:`_TrialProblem.coefficient_equations` needs of a trial's length ``t``,
    frame interval ``dt`` (s) and ``derivative`` method, made once for every round of the
    fit (each round builds its problems again for the new masses).

    Returns
    -------
    cmaps
        :meth:`Derivatives.coefficient_maps <solver.dynamics.spline.Derivatives.coefficient_maps>`.
    passes
        Frames in passes whose windows start at distinct coefficients (all frames at once
        for the quintic spline; the end frames of central differences share a window).
    nb
        Block bandwidth of the normal matrix.
    smooth_bands
        ``(nb + 1, nc)`` the bands of ``E2^T E2``, ``[o, i] = S[i, i + o]``: the smoothness
        rows are the spline's accelerations ``qdd = E2 a``, as wide as a window.

    The arrays are read-only (shared between problems).
    """
    cm = Derivatives(t, dt, derivative).coefficient_maps()
    first = np.searchsorted(cm.start, cm.start, side="left")
    rank = np.arange(t) - first
    passes = tuple(np.flatnonzero(rank == r) for r in range(int(rank.max()) + 1))
    smooth = (cm.e2.T @ cm.e2).tocsr()
    rows, cols = smooth.nonzero()
    width = max(cm.width, int(np.abs(cols - rows).max(initial=0)) + 1)
    smooth_bands = np.array([np.pad(smooth.diagonal(o), (0, o)) for o in range(width)])
    for a in (*passes, smooth_bands, cm.start, cm.weights):
        a.flags.writeable = False
    return cm, passes, width - 1, smooth_bands


class _TrialProblem:
    """Residuals and linearization of one trial for a fixed model."""

    def __init__(self, sk: Skeleton, data: FitTrialInput, st: FitSettings) -> None:
        self.sk, self.data, self.st = sk, data, st
        self.t = data.q.shape[0]
        self.free = np.flatnonzero(sk.is_independent & ~sk.locked)
        self.nf = self.free.size
        if st.direction not in ("band", "exact", "coefficients"):
            raise DynamicsError(f"unknown fit direction {st.direction!r} (use 'band', 'exact' or 'coefficients')")
        self.ops = Derivatives(self.t, data.dt, st.derivative)
        if st.direction == "coefficients":
            self._init_coefficients()
        else:
            self.b1, self.b2 = self.ops.band(st.band)  # (T, 2 band + 1): D[k, k + o]
        self.seen = np.isfinite(data.observed_markers).all(axis=2)
        self.y = np.nan_to_num(data.observed_markers)
        self.mass = sk.total_mass
        self.g = np.asarray(sk.osim.gravity, dtype=float)
        lo, hi = solver_bounds(sk)
        # the filtered starting motion may overshoot a bound slightly: never pull it back
        self.lo = np.minimum(lo, data.q.min(axis=0))
        self.hi = np.maximum(hi, data.q.max(axis=0))
        # residual weights per frame: measured frames as set; unmeasured frames much weaker,
        # the paper's regularization of the free centre-of-mass accelerations there (it also
        # keeps the fit from bending the first unmeasured frames to cancel the residual of
        # the last measured ones, which would spike the accelerations)
        w_obs = np.array([1 / st.force_sigma] * 3 + [1 / st.moment_sigma] * 3)
        w_unobs = np.array([1 / st.unobserved_force_sigma] * 3 + [1 / st.unobserved_moment_sigma] * 3)
        self.w_res = np.where(np.asarray(data.observed, dtype=bool)[:, None], w_obs, w_unobs)  # (T, 6)
        # (q, qp, vp, ap, hdot, com) of the last evaluated q: the step's accepted point is
        # linearized next, and its centroidal terms are the ones the line search computed
        self._state: tuple[FloatArray, ...] | None = None
        self._bands: BlockBands | None = None  # the normal matrix's storage, reused
        #: the joints whose pinocchio ``data.of`` (each subtree's momentum rate) every frame's
        #: linearization keeps, in this order, as ``subtree_rates`` ``(T, len, 6)`` (the joint
        #: mass fit's mass columns need them); empty: none kept
        self.subtree_joints: tuple[int, ...] = ()
        self.subtree_rates: FloatArray | None = None

    def _init_coefficients(self) -> None:
        """The pieces of :meth:`coefficient_equations` that do not change with q (shared by
        the problems of one trial length and frame interval: :func:`_coefficient_setup`)."""
        self.cmaps, self._passes, self._nb, self._smooth_bands = _coefficient_setup(self.t, self.data.dt, self.st.derivative)

    # -------------------------------------------------------------- residuals
    def kinematics(self, q: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        qd, qdd = self.ops(q)
        qp, vp, ap = self.sk.cmap.expand(q, qd, qdd)
        return qd, qdd, qp, vp, ap

    def momentum_rate(self, qp: FloatArray, vp: FloatArray, ap: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(T, 6) centroidal momentum rate [pdot, kdot_G] and (T, 3) centre of mass."""
        model, data = self.sk.model, self.sk.data
        hdot = np.empty((self.t, 6))
        com = np.empty((self.t, 3))
        for k in range(self.t):
            hdot[k] = pin.computeCentroidalMomentumTimeVariation(model, data, qp[k], vp[k], ap[k]).vector
            com[k] = data.com[0]
        return hdot, com

    def _dynamics_state(self, q: FloatArray) -> tuple[FloatArray, ...]:
        """``(qp, vp, ap, hdot, com)``: expanded (T, nv) positions, velocities, accelerations
        and :meth:`momentum_rate` at q, reused when q equals the last evaluated one."""
        last = self._state
        if last is not None and np.array_equal(last[0], q):
            return last[1:]
        _, _, qp, vp, ap = self.kinematics(q)
        hdot, com = self.momentum_rate(qp, vp, ap)
        self._state = (q.copy(), qp, vp, ap, hdot, com)
        return qp, vp, ap, hdot, com

    def residual_wrench(self, hdot: FloatArray, com: FloatArray) -> FloatArray:
        """(T, 6) root residual [force, moment about the centre of mass], ground frame."""
        f = hdot[:, :3] - self.mass * self.g - self.data.force
        m = hdot[:, 3:] - (self.data.moment - np.cross(com, self.data.force))
        return np.concatenate([f, m], axis=1)

    def cost(self, q: FloatArray) -> float:
        """Total cost (see the module docstring)."""
        st = self.st
        _, _, _, hdot, com = self._dynamics_state(q)
        pos = self.sk.marker_positions(q, self.data.markers)
        e = np.where(self.seen[..., None], pos - self.y, 0.0) / st.marker_sigma
        total = float(np.sum(e**2))
        # residual terms on every frame (weights per frame)
        r = self.residual_wrench(hdot, com) * self.w_res
        total += float(np.sum(r**2))
        if st.direction == "coefficients":  # the spline's accelerations (what the dynamics see)
            smooth = self.ops(q[:, self.free])[1] / st.accel_sigma
        else:  # central second differences
            smooth = (q[2:, self.free] - 2 * q[1:-1, self.free] + q[:-2, self.free]) / (self.data.dt**2 * st.accel_sigma)
        return total + float(np.sum(smooth**2))

    # -------------------------------------------------------------- linearization
    def _linearize(self, q: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        """The cost's pieces at q, per frame, on the free coordinates.

        Returns
        -------
        gm, g0
            ``(T, nf, nf)`` J_m^T J_m and ``(T, nf)`` J_m^T e of the marker terms (frame k
            depends on q_k only; unseen markers contribute nothing).
        res
            ``(T, 6)`` weighted root residual wrench.
        dq, dv, da
            ``(T, 6, nf)`` its derivatives with respect to the coordinates, velocities and
            accelerations of the same frame.
        """
        t, nf, free = self.t, self.nf, self.free
        qp, vp, ap, hdot_all, com_all = self._dynamics_state(q)
        model, data = self.sk.model, self.sk.data
        sm = self.st.marker_sigma
        pos, jac = self.sk.marker_jacobians(q, self.data.markers, free)  # (T, M, 3), (T, M, 3, nf)
        jac[~self.seen] = 0.0  # in place: the Jacobian is a fresh array
        jac /= sm
        jm = jac.reshape(t, -1, nf)
        rm = (np.where(self.seen[..., None], pos - self.y, 0.0) / sm).reshape(t, -1, 1)
        jmt = jm.transpose(0, 2, 1)
        gm = jmt @ jm
        g0 = (jmt @ rm)[:, :, 0]
        # every frame has a residual term (unmeasured frames with a weaker weight)
        res = self.residual_wrench(hdot_all, com_all) * self.w_res
        nv = self.sk.nv
        hq = np.empty((t, 6, nv))
        hv = np.empty((t, 6, nv))
        ha = np.empty((t, 6, nv))
        keep = self.subtree_joints
        of = np.empty((t, len(keep), 6)) if keep else None
        for k in range(t):
            _, hq[k], hv[k], ha[k] = pin.computeCentroidalDynamicsDerivatives(model, data, qp[k], vp[k], ap[k])
            if of is not None:  # each kept subtree's momentum rate, world frame, about the origin
                rates = data.of.tolist()  # one conversion: indexing data.of converts every time
                of[k] = [rates[j].vector for j in keep]
        self.subtree_rates = of
        # the external moment about the centre of mass moves with it: d/dq of c x F_ext, with
        # the centre-of-mass Jacobian J_c = A_g[:3] / m (d hdot / d a is the centroidal
        # momentum matrix A_g, whose linear rows are m J_c; Orin et al. 2013)
        jcom = ha[:, :3] / data.mass[0]
        hq[:, 3:] -= _skew_batch(self.data.force) @ jcom
        vals, dof, sel = self._coupling_free(q)
        w = self.w_res[:, :, None]
        dq, dv, da = (((h[:, :, dof] * vals[:, None, :]).reshape(-1, dof.size) @ sel).reshape(t, 6, nf) * w for h in (hq, hv, ha))
        return gm, g0, res, dq, dv, da

    def _smoothness(self, q: FloatArray) -> tuple[float, FloatArray]:
        """``(ws, (T, nf))``: the smoothness rows' weight 1 / (h² s_a) and the gradient of
        their half squared sum, on the free coordinates."""
        ws = 1.0 / (self.data.dt**2 * self.st.accel_sigma)
        return ws, _add_second_difference_normal(np.zeros((self.t, self.nf)), q[:, self.free], ws)

    def normal_equations(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Banded normal matrix and gradient for a step on the free coordinates.

        Marker Jacobians come from one batched forward kinematics over all frames; the
        centroidal derivatives are pinocchio's, one call per frame; the coupling Jacobian
        and the band products are batched over frames.

        Returns
        -------
        ab
            ``(u + 1, T nf)`` lower band storage (``ab[d, c] = H[c + d, c]``, row 0 the
            diagonal, u = (2 band + 1) nf - 1) for :func:`.banded.banded_cholesky`.
        grad
            ``(T nf,)`` gradient of half the cost: of the banded Jacobian with
            ``direction="band"``, exact with ``"exact"`` (which also keeps the per-frame
            Jacobians for :meth:`gauss_newton_product`).
        """
        st, t, nf = self.st, self.t, self.nf
        b = st.band
        nb = 2 * b  # block bandwidth of J^T J
        if self._bands is None:  # one buffer per trial problem (fresh zeroed pages cost more than a fill)
            self._bands = BlockBands(t, nb + 1, nf)
        else:
            self._bands.panel.fill(0.0)
        bands = self._bands
        blocks = bands.blocks  # blocks[i, o] = H(i, i + o)
        gm, grad, res, dq, dv, da = self._linearize(q)
        blocks[:, 0] += gm
        # residual terms: r_k depends on q_s through D1[k, s] dv + D2[k, s] da (+ dq at s = k);
        # jb[k, :, o + b] = d r_k / d q_{k+o}, zero past the ends
        idx = np.arange(t)
        jb = np.zeros((t, 6, 2 * b + 1, nf))
        for o in range(-b, b + 1):
            s = idx + o
            ok = (s >= 0) & (s < t)
            jb[ok, :, o + b] = (self.b1[ok, o + b][:, None, None] * dv[ok]
                                + self.b2[ok, o + b][:, None, None] * da[ok]
                                + (dq[ok] if o == 0 else 0.0))
        exact = st.direction == "exact"
        if exact:
            # the gradient with the full derivative operators: J^T r = dq^T r + D1^T (dv^T r) + D2^T (da^T r)
            grad += np.einsum("kri,kr->ki", dq, res) + self.ops.transpose(np.einsum("kri,kr->ki", dv, res), np.einsum("kri,kr->ki", da, res))
            self._lin = (gm, dq, dv, da)  # marker blocks J_m^T J_m, per-frame Jacobians
        else:
            gres = np.einsum("kroi,kr->koi", jb, res)  # (T, 2b + 1, nf): the banded Jacobian's gradient
        for o1 in range(-b, b + 1):
            # frames k with k + o1 inside the trial: k in [lo, hi), a contiguous range
            lo, hi = max(0, -o1), min(t, t - o1)
            if not exact:
                grad[lo + o1 : hi + o1] += gres[lo:hi, o1 + b]
            # blocks H(k + o1, k + o2) for every o2 >= o1 at once: the bands o2 - o1 = 0..b - o1
            # of block row k + o1 are contiguous panel columns (terms with k + o2 past the
            # end are zero, as jb is there)
            m = b - o1 + 1
            j1t = jb[lo:hi, :, o1 + b].transpose(0, 2, 1)  # (k, nf, 6)
            bands.panel[lo + o1 : hi + o1, :, : m * nf] += j1t @ jb[lo:hi, :, o1 + b :].reshape(hi - lo, 6, m * nf)
        # smoothness: central second differences, a scalar band per coordinate
        ws, gs = self._smoothness(q)
        grad += gs
        coef = np.array([1.0, -2.0, 1.0]) * ws
        diag = np.arange(nf)
        for a in range(3):
            for c in range(a, 3):
                blocks[a : a + t - 2, c - a][:, diag, diag] += coef[a] * coef[c]
        return bands.lower_band_storage(), grad.reshape(-1)

    def coefficient_equations(self, q: FloatArray) -> tuple[BlockBands, FloatArray, FloatArray, FloatArray]:
        """The exact Gauss-Newton system in the spline's coefficients (``direction="coefficients"``).

        With a the coefficients of the coordinates' natural spline in a local basis
        (q = E0 a, qd = E1 a, qdd = E2 a; :class:`.spline.CoefficientMaps`), each frame's
        rows depend on the ``width`` coefficients of its window only, so ``J_a^T J_a`` is
        block-banded: the Gauss-Newton step of the cost with the full (dense in q)
        derivative operators, found by one banded Cholesky factorization
        (tests/dynamics/test_fit_linear_algebra.py checks it against the Jacobian in q).

        Returns
        -------
        bands
            The normal matrix's upper block bands, ``nc`` block rows of ``nf`` (nc = T).
        g_c
            ``(nc, nf)`` gradient of half the cost with respect to a.
        g_q
            ``(T, nf)`` the same gradient with respect to q (exact; for the bounds).
        diag
            ``(nc, nf)`` the normal matrix's diagonal (for the damping).
        """
        cm, nf = self.cmaps, self.nf
        nc = cm.e0.shape[1]
        if self._bands is None:
            self._bands = BlockBands(nc, self._nb + 1, nf)
        else:
            self._bands.panel.fill(0.0)
        bands = self._bands
        gm, g0, res, dq, dv, da = self._linearize(q)
        g0 = g0 + np.einsum("kri,kr->ki", dq, res)
        g1, g2 = np.einsum("kri,kr->ki", dv, res), np.einsum("kri,kr->ki", da, res)
        ws = 1.0 / self.st.accel_sigma  # smoothness rows qdd / s_a: through E2 like the residuals' accelerations
        g2 += self.ops(q[:, self.free])[1] * ws**2
        g_c = cm.e0.T @ g0 + cm.e1.T @ g1 + cm.e2.T @ g2
        g_q = g0 + self.ops.transpose(g1, g2)
        w0, w1, w2 = cm.weights  # (T, W) each
        width = cm.width
        for frames in self._passes:  # frames whose windows start at distinct coefficients
            for lo in range(0, frames.size, ASSEMBLY_FRAMES):  # in chunks: the temporaries stay small
                f = frames[lo : lo + ASSEMBLY_FRAMES]
                s, wk, gk = cm.start[f], w0[f], gm[f]
                # xk[k, :, a] = d r_k / d a_{start_k + a}
                xk = (dq[f][:, :, None, :] * wk[:, None, :, None] + dv[f][:, :, None, :] * w1[f][:, None, :, None]
                      + da[f][:, :, None, :] * w2[f][:, None, :, None])  # fmt: skip
                for a in range(width):
                    m = width - a
                    # block row s + a, bands 0..m-1: residual rows x_a^T x_b, marker rows w_a w_b J_m^T J_m
                    add = xk[:, :, a].transpose(0, 2, 1) @ xk[:, :, a:].reshape(s.size, 6, m * nf)
                    add.reshape(s.size, nf, m, nf)[...] += (wk[:, a, None] * wk[:, a:])[:, None, :, None] * gk[:, :, None, :]
                    bands.panel[_rows(s + a), :, : m * nf] += add
        # the smoothness rows: the same scalar band matrix E2^T E2 / s_a² for every coordinate
        blocks = bands.blocks
        idx = np.arange(nf)
        for o, d in enumerate(self._smooth_bands * ws**2):
            blocks[: nc - o, o][:, idx, idx] += d[: nc - o, None]
        diag = np.einsum("kii->ki", blocks[:, 0]).copy()
        return bands, g_c, g_q, diag

    def _coupling_free(self, q: FloatArray) -> tuple[FloatArray, IntArray, FloatArray]:
        """The coupling Jacobian d q_pin / d q restricted to the free coordinates, sparse.

        Each expanded DoF depends on one coordinate, so ``C[t] = diag(vals[t]) @ sel`` on the
        DoFs ``dof`` that depend on a free coordinate, and ``X @ C[t]`` is
        ``(X[:, dof] * vals[t]) @ sel``: one gather and one 2-D product for all frames.

        Returns
        -------
        vals
            ``(T, D)`` d q_pin[dof] / d q[its coordinate].
        dof
            ``(D,)`` indices of those DoFs.
        sel
            ``(D, nf)`` 0/1: column of each DoF's free coordinate.
        """
        vals, cols = self.sk.cmap.jacobian_batch(q)  # (T, nv), (nv,)
        where = np.full(self.sk.n, -1)
        where[self.free] = np.arange(self.nf)
        dof = np.flatnonzero(where[cols] >= 0)
        sel = np.zeros((dof.size, self.nf))
        sel[np.arange(dof.size), where[cols[dof]]] = 1.0
        return vals[:, dof], dof, sel

    # -------------------------------------------------------------- steps
    def gauss_newton_product(self, v: FloatArray) -> FloatArray:
        """``J^T J v`` with the full derivative operators, at the last :meth:`normal_equations` point.

        Parameters
        ----------
        v
            ``(T, nf)`` a change of the free coordinates.

        Returns
        -------
        ``(T, nf)``: markers (per frame), residual wrench (r_k moves with q_k, and with every
        q_s through the velocity and acceleration operators) and smoothness terms.
        """
        jm2, dq, dv, da = self._lin
        v1, v2 = self.ops(v)
        u = np.einsum("kri,ki->kr", dq, v) + np.einsum("kri,ki->kr", dv, v1) + np.einsum("kri,ki->kr", da, v2)
        out = np.einsum("kij,kj->ki", jm2, v) + np.einsum("kri,kr->ki", dq, u)
        out += self.ops.transpose(np.einsum("kri,kr->ki", dv, u), np.einsum("kri,kr->ki", da, u))
        return _add_second_difference_normal(out, v, 1.0 / (self.data.dt**2 * self.st.accel_sigma))

    def _direction(self, chol: FloatArray, grad: FloatArray, keep: FloatArray, damping: FloatArray) -> FloatArray:
        """The damped Gauss-Newton step: ``(J^T J + mu D) delta = -grad`` on the coordinates
        ``keep`` (1.0; 0.0 where a bound holds it), by conjugate gradients preconditioned with
        the banded normal matrix's Cholesky factor (Nocedal & Wright 2006, Algorithm 5.3),
        to a residual of ``FitSettings.cg_tolerance`` of the gradient's."""
        nf = self.nf
        r = -grad.reshape(-1, nf) * keep
        x = np.zeros_like(r)
        z = banded_cholesky_back(chol, r.reshape(-1)).reshape(-1, nf) * keep
        p = z.copy()
        rz = float(np.vdot(r, z))
        stop = self.st.cg_tolerance * np.linalg.norm(r)
        for _ in range(self.st.cg_iterations):
            ap = (self.gauss_newton_product(p) + damping * p) * keep
            pap = float(np.vdot(p, ap))
            if pap <= 0:
                break
            alpha = rz / pap
            x += alpha * p
            r -= alpha * ap
            if np.linalg.norm(r) <= stop:
                break
            z = banded_cholesky_back(chol, r.reshape(-1)).reshape(-1, nf) * keep
            rz_new = float(np.vdot(r, z))
            p = z + (rz_new / rz) * p
            rz = rz_new
        return x

    def _hold(self, bands: BlockBands, grad: FloatArray, held: NDArray[np.bool_], diag: FloatArray, target: FloatArray | None = None) -> None:
        """Stiff rows ``E0[k] da = target`` (default 0) in the coefficient system for the
        ``(T, nf)`` coordinates ``held`` (at a bound, or carried past one by the step),
        weighted ``HOLD`` times the largest diagonal entry of the normal matrix ``diag``
        (``(nc, nf)``) in the frame's window; adds to ``bands`` and the gradient ``grad``
        (``(nc, nf)``) in place."""
        cm, nf = self.cmaps, self.nf
        blocks = bands.blocks
        idx = np.arange(nf)
        w0 = cm.weights[0]
        for frames in self._passes:
            frames = frames[held[frames].any(axis=1)]
            s = cm.start[frames]
            win = np.max([diag[s + a] for a in range(cm.width)], axis=0)  # (k, nf)
            h = held[frames] * HOLD * win
            for a in range(cm.width):
                if target is not None:
                    grad[s + a] -= w0[frames, a, None] * h * target[frames]
                for b in range(a, cm.width):
                    blocks[(s + a)[:, None], b - a, idx, idx] += (w0[frames, a] * w0[frames, b])[:, None] * h

    def held_at_bounds(self, q: FloatArray, g_q: FloatArray) -> NDArray[np.bool_]:
        """``(T, nf)``: the free coordinates of ``q`` at a bound that the gradient ``g_q``
        (``(T, nf)``, of the cost in q) pushes out, which a step holds there."""
        x = q[:, self.free]
        return ((x <= self.lo[self.free]) & (g_q > 0)) | ((x >= self.hi[self.free]) & (g_q < 0))

    def hold_past_bounds(
        self, q: FloatArray, delta: FloatArray, bands: BlockBands, grad: FloatArray, held: NDArray[np.bool_], diag: FloatArray, at_bound: bool = True
    ) -> bool:
        """Hold the free coordinates that the step ``delta`` (``(T, nf)``) carries from ``q``
        past a bound, in the coefficient system (``bands``, ``grad``, ``diag`` of
        :meth:`coefficient_equations`, in place; :meth:`_hold`): at the bound, or where they
        are (``at_bound=False``). They join ``held`` (in place); returns whether there were any."""
        x = q[:, self.free]
        lo, hi = self.lo[self.free], self.hi[self.free]
        over = ((x + delta < lo) | (x + delta > hi)) & ~held
        if not over.any():
            return False
        held |= over
        self._hold(bands, grad, over, diag, np.clip(x + delta, lo, hi) - x if at_bound else None)
        return True

    def _take(self, q: FloatArray, delta: FloatArray) -> FloatArray:
        """q with ``(T, nf)`` delta added to the free coordinates, clipped to the bounds,
        locked coordinates at their defaults and dependent ones completed."""
        q_new = q.copy()
        q_new[:, self.free] += delta
        q_new = np.clip(q_new, self.lo, self.hi)
        q_new[:, self.sk.locked] = self.sk.defaults[self.sk.locked]
        return self.sk.cmap.complete(q_new)

    def _coefficient_step(self, q: FloatArray, mu: float, cost0: float) -> tuple[FloatArray, float, float]:
        """One Levenberg-Marquardt step of ``direction="coefficients"``; returns (q, cost, mu).

        Solves the damped system ``(H + mu diag(H)) da = -g`` in the coefficients
        (:meth:`coefficient_equations`) with a coordinate at a bound that the gradient
        pushes out held there, and takes the step (clipped to the bounds) when it lowers
        the cost; mu then follows the ratio rho of the actual to the predicted decrease
        (Nielsen 1999: ``mu *= max(1/3, 1 - (2 rho - 1)^3)``). When the cost rose, mu grows
        4-fold, the coordinates the step carried past a bound are stopped at it, and the
        system is solved again (at most 6 solves).
        """
        nf = self.nf
        bands, grad, g_q, diag = self.coefficient_equations(q)
        held = self.held_at_bounds(q, g_q)
        grad = grad.copy()
        if held.any():
            self._hold(bands, grad, held, diag)
        damp = np.maximum(diag.reshape(-1), 1e-9)
        for _ in range(6):
            ab = bands.lower_band_storage()
            ab[0] += mu * damp
            try:
                chol = banded_cholesky(ab, overwrite=True)
            except LinAlgError:
                mu *= 10
                continue
            da = -banded_cholesky_back(chol, grad.reshape(-1))
            delta = self.cmaps.e0 @ da.reshape(-1, nf)
            q_new = self._take(q, delta)
            cost1 = self.cost(q_new)
            if cost1 < cost0:
                predicted = float(-grad.reshape(-1) @ da + mu * np.sum(damp * da**2))
                rho = (cost0 - cost1) / max(predicted, 1e-300)
                return q_new, cost1, max(mu * max(1 / 3, 1 - (2 * rho - 1) ** 3), 1e-12)
            self.hold_past_bounds(q, delta, bands, grad, held, diag)
            mu *= 4
        return q, cost0, mu

    def step(self, q: FloatArray, mu: float, cost0: float | None = None) -> tuple[FloatArray, float, float]:
        """One damped Gauss-Newton step with a backtracking line search; returns (q, cost, mu).

        The damping grows (and the system is solved again) only when no step length along
        the current direction lowers the cost.
        """
        cost0 = self.cost(q) if cost0 is None else cost0
        if self.st.direction == "coefficients":
            return self._coefficient_step(q, mu, cost0)
        nf = self.nf
        ab, grad = self.normal_equations(q)
        g2 = grad.reshape(-1, nf)
        held = self.held_at_bounds(q, g2)
        keep = (~held).astype(float)
        diag = np.maximum(ab[0].copy(), 1e-9)
        base = ab[0] + held.reshape(-1) * 1e12
        for _ in range(4):
            if ab is None:  # factored in place by the last attempt: the same matrix again
                ab = self._bands.lower_band_storage()
            ab[0] = base + mu * diag
            try:
                chol = banded_cholesky(ab, overwrite=True)  # in place: one band matrix in memory, not two
            except LinAlgError:
                mu *= 10
                continue
            finally:
                ab = None
            if self.st.direction == "exact":
                delta = self._direction(chol, grad, keep, (mu * diag).reshape(-1, nf))
            else:
                delta = -banded_cholesky_back(chol, grad * keep.reshape(-1)).reshape(-1, nf)
            for alpha in (1.0, 0.5, 0.25, 0.1):
                q_new = self._take(q, alpha * delta)
                cost1 = self.cost(q_new)
                if cost1 < cost0:
                    return q_new, cost1, (max(mu / 3, 1e-9) if alpha == 1.0 else mu)
            mu *= 10
        return q, cost0, mu


def mass_joints(sk: Skeleton) -> list[int]:
    """Pinocchio joints that carry mass: one mass factor each (the bodies welded to a joint share it)."""
    return [j for j in range(1, sk.model.njoints) if sk.model.inertias[j].mass > 0]


def bodies_of_joints(sk: Skeleton) -> dict[int, list[str]]:
    """Pinocchio joint index -> names of the bodies that move with it (a mass factor's bodies)."""
    out: dict[int, list[str]] = {}
    for b, j in zip(sk.body_names, sk.body_joint):
        out.setdefault(int(j), []).append(b)
    return out


def mass_regression(
    sk: Skeleton, q: FloatArray, qd: FloatArray, qdd: FloatArray, wrenches: list[tuple[str, FloatArray]], observed: NDArray[np.bool_]
) -> tuple[FloatArray, FloatArray, list[int]]:
    """Root generalized forces as a linear function of per-joint mass factors.

    Parameters
    ----------
    sk
        Skeleton of the model at its current masses (a factor k of 1 keeps a joint's).
    q, qd, qdd
        ``(T, n)`` coordinates (rad or m), their velocities (rad/s or m/s) and accelerations
        (rad/s² or m/s²).
    wrenches
        Per loaded body: (body name, ``(T, 6)`` [force N, moment about the ground origin
        N·m], ground frame), as :attr:`FitTrialInput.wrenches`.
    observed
        ``(T,)`` frames whose external force is measured: the K frames regressed.

    Returns
    -------
    a, b
        ``(6 K, J)`` and ``(6 K,)`` with tau_root = a @ k + b over the K observed frames:
        the six root coordinates' generalized forces (N·m rotational, N translational) for
        the ``(J,)`` mass factors k.
    joints
        Pinocchio joint index of each of the J factors (joints that carry mass).
    """
    from solver.model.skeleton import ExternalWrench

    model, data = sk.model, sk.data
    joints = mass_joints(sk)
    params = {j: model.inertias[j].toDynamicParameters() for j in joints}
    idx = np.flatnonzero(observed)
    qp, vp, ap = sk.cmap.expand(q[idx], qd[idx], qdd[idx])
    ext = [ExternalWrench(b, w[idx, :3], np.zeros((idx.size, 3)), w[idx, 3:]) for b, w in wrenches]
    tau_ext = sk.inverse_dynamics(q[idx], qd[idx], qdd[idx], ext).tau - sk.inverse_dynamics(q[idx], qd[idx], qdd[idx]).tau
    root = list(sk.root_transform_axes())
    # column c of p_mat holds joint c's inertial parameters at that joint's regressor columns
    p_mat = np.zeros((10 * (model.njoints - 1), len(joints)))
    for c, j in enumerate(joints):
        p_mat[10 * (j - 1) : 10 * j, c] = params[j]
    # C^T tau_pin on the root coordinates (C has one nonzero per expanded DoF): only the
    # expanded DoFs of the root coordinates are needed
    vals, cols = sk.cmap.jacobian_batch(q[idx])  # (K, nv), (nv,)
    root_dofs = [(i, int(dof)) for i, r in enumerate(root) for dof in np.flatnonzero(cols == r)]
    rows = [dof for _, dof in root_dofs]
    tau_pin = np.empty((idx.size, len(rows), len(joints)))  # those DoFs' forces of each factor
    for k in range(idx.size):
        tau_pin[k] = pin.computeJointTorqueRegressor(model, data, qp[k], vp[k], ap[k])[rows] @ p_mat
    a = np.zeros((idx.size, 6, len(joints)))
    for c, (i, dof) in enumerate(root_dofs):
        a[:, i] += vals[:, dof, None] * tau_pin[:, c]
    return a.reshape(-1, len(joints)), tau_ext[:, root].reshape(-1), joints


def fit_dynamics(
    build: object,
    trials: Sequence[FitTrialInput],
    settings: FitSettings | None = None,
    progress: object | None = None,
) -> FitOutput:
    """Run the fit (see the module docstring).

    Parameters
    ----------
    build
        Callable ``(mass_factors: dict[body, float]) -> Skeleton`` giving the model with
        each body's mass and inertia multiplied by its factor.
    trials
        The trials of the subject that have force data.
    settings
        Weights and limits.
    progress
        Optional callable (message, fraction).

    Raises
    ------
    DynamicsError
        ``settings.mass_fit`` is not ``"rounds"``, or a trial's problem cannot be set up.
    """
    st = settings or FitSettings()
    if st.mass_fit != "rounds":
        raise DynamicsError(f"fit_dynamics runs mass_fit='rounds', not {st.mass_fit!r} (the joint fit is solver.dynamics.joint_fit.fit_dynamics_joint)")
    factors = {}
    sk: Skeleton = build(factors)  # type: ignore[operator]
    qs = [np.array(tr.q, dtype=float) for tr in trials]
    history = []
    body_of_joint = bodies_of_joints(sk)
    final = False  # the masses settled: this round of steps, to ``tolerance``, is the last
    mus = [1e-6] * len(trials)  # each trial's damping where its last round stopped
    resume = False  # the masses stood: each trial's steps go on from where they stopped
    for rnd in range(st.rounds):
        final = final or rnd == st.rounds - 1
        tol = st.tolerance if final or st.round_tolerance is None else st.round_tolerance
        settled = True  # every trial's coordinate steps stopped on the tolerance
        for i, tr in enumerate(trials):
            prob = _TrialProblem(sk, tr, st)
            cost = prob.cost(qs[i])
            mu = mus[i] if resume else 1e-6
            for it in range(st.iterations):
                if progress:
                    progress(f"dynamics fit: round {rnd + 1}, trial {i + 1}, step {it + 1}", (rnd * st.iterations + it) / (st.rounds * st.iterations))  # type: ignore[operator]
                q_new, cost_new, mu = prob.step(qs[i], mu, cost)
                rel = (cost - cost_new) / max(cost, 1e-30)
                qs[i], cost = q_new, cost_new
                if rel < tol:
                    break
            else:
                settled = False
            history.append(cost)
            mus[i] = mu
            del prob  # the next trial's problem is built without this one's buffers in memory
        if final:
            break
        resume = False
        # mass factors: linear least squares on the root generalized forces of observed frames
        rows_a, rows_b = [], []
        joints: list[int] = []
        for i, tr in enumerate(trials):
            if not tr.observed.any():
                continue
            qd, qdd = Derivatives(qs[i].shape[0], tr.dt, st.derivative)(qs[i])
            a, b_vec, joints = mass_regression(sk, qs[i], qd, qdd, tr.wrenches, tr.observed)
            w = np.tile(np.array([1 / st.force_sigma] * 3 + [1 / st.moment_sigma] * 3), a.shape[0] // 6)
            rows_a.append(a * w[:, None])
            rows_b.append(b_vec * w)
        if not rows_a:
            break
        a_all = np.vstack(rows_a)
        b_all = np.concatenate(rows_b)
        # current factors are 1 for this skeleton; prior pulls new factors toward 1 scaled by mass share
        masses = np.array([sk.model.inertias[j].mass for j in joints])
        share = masses / masses.sum()
        prior_w = np.sqrt(a_all.shape[0] / 6 * share) / st.mass_sigma * np.sqrt(np.mean(np.sum(a_all**2, axis=0)) / max(a_all.shape[0], 1))
        lhs = np.vstack([a_all, np.diag(prior_w)])
        rhs = np.concatenate([-b_all, prior_w])
        k_new, *_ = np.linalg.lstsq(lhs, rhs, rcond=None)
        k_new = np.clip(k_new, 0.5, 2.0)
        if np.abs(k_new - 1.0).max() < st.mass_tolerance:
            if settled and tol <= st.tolerance:  # converged: the motion was fitted to the masses the solve returns
                break
            final = settled  # the steps stopped on round_tolerance: one round to tolerance ends the fit
            resume = True
            continue  # the masses stand; more coordinate steps, as if the round had gone on
        for j, k in zip(joints, k_new):
            for body in body_of_joint.get(j, []):
                factors[body] = factors.get(body, 1.0) * float(k)
        sk = build(factors)  # type: ignore[operator]
    return FitOutput(tuple(qs), dict(factors), tuple(history))
