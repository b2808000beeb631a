"""The whole-motion profile: residual and marker rows with every coordinate re-optimized.

The translation profile of :mod:`.profile` re-optimizes one thing, a translation of the
whole body, because that is how the dynamics fit absorbs most force errors. A wrong mass
distribution is absorbed differently: the fit bends every joint a little (a fraction of a
millimetre of marker error) so that the wrong masses balance the measured forces, and what
it leaves is nearly orthogonal to a translation (docs/diagnose/RESULTS.md, seventh
session). This profile linearizes the dynamics fit's own cost around the processed motion
q and re-optimizes a step dq of every free coordinate (independent, not locked) at every
frame. With h the frame interval, the rows of the step are

    residual  (r_t + dW_t/dq dq_t + dW_t/dqd (dq_{t+1} - dq_{t-1}) / 2h
                   + dW_t/dqdd (dq_{t+1} - 2 dq_t + dq_{t-1}) / h²) / s      evaluated t  (6)
    markers   (e_tj + J_tj dq_t) / s_m                                        seen j      (3 each)
    prior     (dq_{t+1} - 2 dq_t + dq_{t-1}) / (h² s_a)                       interior t  (n_free)

with r_t the root residual at the fitted mass (force, N; moment about the pelvis origin,
N·m; s = s_F or s_M), W_t the root wrench of gravity and inertia (finite differences of
:meth:`solver.model.skeleton.Skeleton.inverse_dynamics`; the pelvis origin held where it
is), e_tj the marker errors (model minus observed), J_tj the marker Jacobians and s_a the
fit's acceleration prior (:class:`solver.dynamics.fit.FitSettings`). For rows z = z0 + A dq
the profiled rows are ``P z0``, ``P = I - A (AᵀA)⁻¹ Aᵀ`` (a sparse solve; a tiny ridge
keeps AᵀA invertible). A parameter theta whose rows are G theta is then fitted to the
profiled rows, ``min |P z0 + P G theta|²``: the Gauss-Newton step in theta of a joint
refit of motion and theta that starts at the processed motion, with the motion's own step
eliminated (the Schur complement).

Rows are handed out per frame, ``(T, R)`` with R = 6 + 3 M + n_free (zero where a row does
not exist: frames not evaluated, markers not seen, the first and last frame's prior), so
that the cross-validation of :mod:`.selection` can hold frames out.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.linalg import splu

from solver.diagnose.data import DiagnosisData
from solver.diagnose.profile import Sigmas
from solver.model.osim import read_osim
from solver.model.skeleton import Skeleton

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Finite-difference step of the root wrench's derivatives (rad, m, and per s, s²).
FD_STEP = 1e-5


def _wrench_about_ground(sk: Skeleton, q: FloatArray, qd: FloatArray, qdd: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``(T, 6)`` gravity + inertia root wrench with its moment about the ground origin
    (so that moving the pelvis does not move the reference point), and ``(T, 3)`` the
    pelvis origin."""
    idr = sk.inverse_dynamics(q, qd, qdd)
    pos = sk.body_poses(q)[1][:, sk.body_names.index(sk.root_body)]
    return np.concatenate([idr.root_force, idr.root_moment + np.cross(pos, idr.root_force)], axis=1), pos


class MotionProfile:
    """Rows of one trial with the whole motion profiled out (see the module docstring).

    Parameters
    ----------
    data
        The prepared trial (its processed q, qd, qdd are the linearization point).
    evaluated
        ``(T,)`` frames whose residual rows count; the first and last frame never do
        (their central differences need both neighbours).
    sigmas
        Channel standard deviations.
    accel_sigma
        s_a, the fit's acceleration prior (rad/s² or m/s² per coordinate); default: the
        trial's ``settings['fit']['accel_sigma']``, else 500.

    Raises
    ------
    ValueError
        The trial has fewer than three frames.
    """

    def __init__(
        self,
        data: DiagnosisData,
        evaluated: BoolArray,
        sigmas: Sigmas,
        accel_sigma: float | None = None,
    ) -> None:
        trial = data.trial
        t_n = data.n_frames
        if t_n < 3:
            raise ValueError(f"trial {trial.trial}: the whole-motion profile needs at least 3 frames, got {t_n}")
        fit = (trial.settings or {}).get("fit", {}) or {}
        s_a = float(fit.get("accel_sigma", 500.0)) if accel_sigma is None else float(accel_sigma)
        # the model the trial was prepared with (the processed one, or a refit's)
        sk = Skeleton(data.model if data.model is not None else read_osim(trial.model_path))
        free = np.flatnonzero(sk.is_independent & ~sk.locked)
        nf = free.size
        h = data.dt
        q, qd, qdd = trial.q, trial.qd, trial.qdd
        w0, pelvis = _wrench_about_ground(sk, q, qd, qdd)
        jac = np.empty((3, t_n, 6, nf))  # d wrench / d (q, qd, qdd) of each free coordinate
        for c, k in enumerate(free):
            for which in range(3):
                args = [q.copy(), qd.copy(), qdd.copy()]
                args[which][:, k] += FD_STEP
                jac[which, :, :, c] = (_wrench_about_ground(sk, *args)[0] - w0) / FD_STEP
        # moments back about the pelvis origin, held fixed: dM_p = dM_g - p x dF
        jac[:, :, 3:, :] -= np.cross(pelvis[None, :, :, None], jac[:, :, :3, :], axisa=2, axisb=2, axisc=2)
        sig = np.array([sigmas.force] * 3 + [sigmas.moment] * 3)
        ev = np.asarray(evaluated, dtype=bool).copy()
        ev[[0, -1]] = False
        self.evaluated = ev
        n_markers = len(data.markers.names)
        self.n_rows = 6 + 3 * n_markers + nf
        self.t = t_n
        rows, cols, vals = [], [], []
        frame, slot = [], []  # per row of A: its frame and its slot among the frame's R rows
        r = 0
        for t in np.flatnonzero(ev):
            dq, dv, da = jac[0, t], jac[1, t], jac[2, t]
            for tt, coef in ((t - 1, -dv / (2 * h) + da / h**2), (t, dq - 2 * da / h**2), (t + 1, dv / (2 * h) + da / h**2)):
                rows.append(np.repeat(np.arange(r, r + 6), nf))
                cols.append(np.tile(tt * nf + np.arange(nf), 6))
                vals.append((coef / sig[:, None]).ravel())
            frame.append(np.full(6, t))
            slot.append(np.arange(6))
            r += 6
        markers = sk.marker_index(list(data.markers.names))
        seen = data.markers.seen
        for t in range(t_n):
            _, jm = sk.marker_jacobian(q[t], markers)
            idx = np.flatnonzero(seen[t])
            m = idx.size
            rows.append(np.repeat(np.arange(r, r + 3 * m), nf))
            cols.append(np.tile(t * nf + np.arange(nf), 3 * m))
            vals.append((jm[idx][:, :, free] / sigmas.marker).ravel())
            frame.append(np.full(3 * m, t))
            slot.append(6 + (3 * idx[:, None] + np.arange(3)).ravel())
            r += 3 * m
        base = 6 + 3 * n_markers
        for t in range(1, t_n - 1):
            for tt, coef in ((t - 1, 1.0), (t, -2.0), (t + 1, 1.0)):
                rows.append(r + np.arange(nf))
                cols.append(tt * nf + np.arange(nf))
                vals.append(np.full(nf, coef / (h**2 * s_a)))
            frame.append(np.full(nf, t))
            slot.append(base + np.arange(nf))
            r += nf
        self.a = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(r, t_n * nf))
        self._frame = np.concatenate(frame).astype(np.intp)
        self._slot = np.concatenate(slot).astype(np.intp)
        ata = (self.a.T @ self.a).tocsc()
        self._lu = splu(ata + sp.identity(t_n * nf, format="csc") * 1e-6 * float(ata.diagonal().mean()))
        self.sigmas, self.data = sigmas, data
        # the reference rows: residual at the fitted mass, marker errors, no prior
        residual = data.residual(mass=data.fitted_mass)
        z0 = np.zeros(r)
        n_res = 6 * int(ev.sum())
        z0[:n_res] = (residual[ev] / sig).ravel()
        err = data.markers.error
        marker_rows = np.zeros(r, dtype=bool)
        marker_rows[n_res : n_res + 3 * int(seen.sum())] = True
        mf, ms = self._frame[marker_rows], self._slot[marker_rows] - 6
        z0[marker_rows] = err[mf, ms // 3, ms % 3] / sigmas.marker
        self._n_residual_rows = n_res
        self._sig = sig
        self.z0 = z0

    # ---------------------------------------------------------------- rows
    def wrench_rows(self, wrench: FloatArray) -> FloatArray:
        """``(rows of A, k)`` unprofiled rows of a change ``wrench`` ``(T, 6, k)`` of the
        root residual (force N; moment about the pelvis origin N·m); markers unchanged."""
        k = wrench.shape[2]
        out = np.zeros((self.a.shape[0], k))
        out[: self._n_residual_rows] = (wrench[self.evaluated] / self._sig[None, :, None]).reshape(-1, k)
        return out

    def project(self, z: FloatArray) -> FloatArray:
        """Profile rows ``(rows of A,)`` or ``(rows of A, k)`` (in standard deviations): the
        best motion step removed; the same shape."""
        x = self._lu.solve(np.asarray(self.a.T @ z))
        return z - self.a @ x

    def per_frame(self, z: FloatArray) -> FloatArray:
        """Rows ``(rows of A,)`` or ``(rows of A, k)`` -> ``(T, R)`` or ``(T, R, k)``, zero
        where a row does not exist."""
        shape = (self.t, self.n_rows) + z.shape[1:]
        out = np.zeros(shape)
        out[self._frame, self._slot] = z
        return out
