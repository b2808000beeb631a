"""The diagnosis' currency: whitened residual rows with the body's translation profiled out.

Per frame t the reference model leaves nine numbers (the *rows* of the frame):

    marker   sqrt(n_t) (e_t + d_t) / s_m                                   (3)
    force    (r_F(t) + m dd_t) / s_F                     evaluated frames  (3)
    moment   (r_M(t) + m (c_t - p_t) x dd_t + d_t x F_t) / s_M    evaluated frames  (3)

with e_t the mean marker error (model minus observed) over the n_t markers seen, r_F and
r_M the root residual force and moment about the pelvis origin p_t (:mod:`.data`), c_t the
centre of mass, F_t the total plate force, m the stated mass and s_m, s_F, s_M the
dynamics fit's standard deviations as the judged trial was fitted with (1 cm per marker
coordinate, 4 N, 4 N·m on the alternation the diagnosis judges on; 2 N, 2 N·m when a trial's
settings name none).

``d`` ``(T, 3)`` is a translation of the whole body over time (``dd`` its second central
difference / h²). The pipeline absorbs much of any force error into the motion (its
centre-of-mass fit moves the root so that the centre of mass follows the measured forces);
a translation is the main way it does so, and it moves the model markers by ``d``, the
centre-of-mass acceleration by ``dd`` and the moment arms of the plates by ``-d``. The
diagnosis therefore scores every model with ``d`` re-optimized: for rows z = z0 + A d,
the profiled rows are ``P z0`` with ``P = I - A (A^T A)^-1 A^T`` (a sparse banded solve).
Costs are sums of squared profiled rows; a candidate cause changes z0 (linearly in its
parameters, or through a 1-D search for the force delay).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.linalg import splu

from solver.diagnose.data import DiagnosisData

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Profiled rows per frame: marker mean (3), residual force (3), residual moment (3).
ROWS = 9


@dataclass(frozen=True)
class Sigmas:
    """Standard deviations that turn each channel into cost units (the dynamics fit's).

    Attributes
    ----------
    marker
        m per marker coordinate.
    force
        N per residual force component.
    moment
        N·m per residual moment component.
    """

    marker: float = 0.01
    force: float = 2.0
    moment: float = 2.0

    @classmethod
    def of(cls, data: DiagnosisData) -> Sigmas:
        """The sigmas the trial was processed with (``settings['fit']``), else the defaults."""
        fit = (data.trial.settings or {}).get("fit", {}) or {}
        return cls(float(fit.get("marker_sigma", 0.01)), float(fit.get("force_sigma", 2.0)), float(fit.get("moment_sigma", 2.0)))


def own_noise_sigmas(ref_rows: FloatArray, evaluated: BoolArray, sigmas: Sigmas) -> Sigmas:
    """The sigmas that whiten a motion's residual rows with that motion's own noise.

    The force and moment sigmas are multiplied by the RMS of the motion's profiled force and
    moment rows over the ``evaluated`` frames, when that RMS is above 1; the marker sigma is
    kept. Used for the marker-only motion, whose residual no force shaped (on the treadmill
    run its profiled moment rows are far above those of the fitted motion, with the fitted
    motion's 4 N·m).

    Parameters
    ----------
    ref_rows
        ``(T, R)`` the motion's profiled reference rows, whitened with ``sigmas``
        (:attr:`solver.diagnose.candidates.Context.ref_rows`: :meth:`Profile.project` of
        :meth:`Profile.raw_rows` of its residual).
    evaluated
        ``(T,)`` the frames whose rows count.
    sigmas
        The sigmas ``ref_rows`` were whitened with.

    Returns
    -------
    Sigmas
        m, N and N·m, as ``sigmas``.
    """
    rows = np.asarray(ref_rows)[np.asarray(evaluated, dtype=bool)]
    if not len(rows):
        return sigmas
    force = float(np.sqrt(np.mean(rows[:, 3:6] ** 2)))
    moment = float(np.sqrt(np.mean(rows[:, 6:9] ** 2)))
    return Sigmas(sigmas.marker, sigmas.force * max(1.0, force), sigmas.moment * max(1.0, moment))


def _second_difference(t: int, dt: float) -> sp.csr_matrix:
    """``(T, T)`` central second difference / h² (ends copy their neighbour's row)."""
    main = np.full(t, -2.0)
    off = np.ones(t - 1)
    d2 = sp.diags([off, main, off], [-1, 0, 1], shape=(t, t), format="lil")
    if t >= 3:
        d2[0, :3] = [1.0, -2.0, 1.0]
        d2[t - 1, t - 3 :] = [1.0, -2.0, 1.0]
    return (d2.tocsr() / dt**2).tocsr()


def skew(v: FloatArray) -> FloatArray:
    """``(T, 3)`` vectors -> ``(T, 3, 3)`` cross-product matrices [v_t]x."""
    z = np.zeros(v.shape[0])
    return np.stack(
        [np.stack([z, -v[:, 2], v[:, 1]], axis=1), np.stack([v[:, 2], z, -v[:, 0]], axis=1), np.stack([-v[:, 1], v[:, 0], z], axis=1)],
        axis=1,
    )


def _cross_blocks(v: FloatArray) -> sp.csr_matrix:
    """Block diagonal ``(3T, 3T)`` of the cross-product matrices [v_t]x."""
    return sp.block_diag(list(skew(v)), format="csr")


class Profile:
    """The translation-profiled residual rows of one trial for one set of evaluated frames.

    Parameters
    ----------
    data
        The prepared trial.
    evaluated
        ``(T,)`` frames whose residual rows count (measured force).
    sigmas
        Channel standard deviations.
    """

    def __init__(self, data: DiagnosisData, evaluated: BoolArray, sigmas: Sigmas) -> None:
        self.data, self.sigmas = data, sigmas
        self.evaluated = np.asarray(evaluated, dtype=bool)
        t = data.n_frames
        self.t = t
        mean_err, count = data.markers.mean_error()
        self.mean_error, self.count = mean_err, count
        m = data.stated_mass
        total_force = data.external()[1][:, :3]
        w = self.evaluated.astype(float)
        d2 = sp.kron(_second_difference(t, data.dt), sp.identity(3), format="csr")
        wk = sp.diags(np.repeat(w, 3))
        a_marker = sp.diags(np.repeat(np.sqrt(count) / sigmas.marker, 3))
        a_force = wk @ d2 * (m / sigmas.force)
        lever = _cross_blocks(data.com - data.pelvis)
        a_moment = wk @ (m * lever @ d2 - _cross_blocks(total_force)) / sigmas.moment
        self.a = sp.vstack([a_marker, a_force, a_moment], format="csr")
        ata = (self.a.T @ self.a).tocsc()
        ata = ata + sp.identity(3 * t, format="csc") * 1e-9 * float(ata.diagonal().mean())
        self._lu = splu(ata)

    # ---------------------------------------------------------------- rows
    @property
    def n_rows(self) -> int:
        """Rows per frame: the nine profiled ones, then three per plate (idle readings)."""
        return ROWS + 3 * len(self.data.plates.names)

    def raw_rows(self, residual: FloatArray, idle_force: FloatArray, marker_shift: FloatArray | None = None) -> FloatArray:
        """``(T, n_rows)`` unprofiled rows.

        Parameters
        ----------
        residual
            ``(T, 6)`` root residual (its rows are zero on frames not evaluated).
        idle_force
            ``(P, T, 3)`` plate readings where the plates are idle (their true force is
            zero there), N; every frame counts.
        marker_shift
            ``(T, 3)`` added to the mean marker error, m.
        """
        s = self.sigmas
        e = self.mean_error if marker_shift is None else self.mean_error + marker_shift
        rows = np.empty((self.t, self.n_rows))
        rows[:, :3] = e * (np.sqrt(self.count) / s.marker)[:, None]
        w = self.evaluated[:, None]
        rows[:, 3:6] = np.where(w, residual[:, :3] / s.force, 0.0)
        rows[:, 6:9] = np.where(w, residual[:, 3:] / s.moment, 0.0)
        rows[:, ROWS:] = np.transpose(idle_force, (1, 0, 2)).reshape(self.t, -1) / s.force
        return rows

    def project(self, rows: FloatArray) -> FloatArray:
        """Profile rows ``(T, R)`` or ``(T, R, k)``: the best translation applied to the
        first nine; idle-reading rows do not depend on the motion and pass through."""
        flat = rows.reshape(self.t, rows.shape[1], -1)
        k = flat.shape[2]
        z = np.concatenate([flat[:, 0:3].reshape(-1, k), flat[:, 3:6].reshape(-1, k), flat[:, 6:9].reshape(-1, k)], axis=0)
        x = self._lu.solve(np.asarray(self.a.T @ z))
        z = z - self.a @ x
        n3 = 3 * self.t
        out = flat.copy()
        out[:, 0:3] = z[:n3].reshape(self.t, 3, k)
        out[:, 3:6] = z[n3 : 2 * n3].reshape(self.t, 3, k)
        out[:, 6:9] = z[2 * n3 :].reshape(self.t, 3, k)
        return out.reshape(rows.shape)

    def translation(self, rows: FloatArray) -> FloatArray:
        """``(T, 3)`` the best translation d for unprofiled rows ``(T, R)``, m."""
        z = np.concatenate([rows[:, 0:3].reshape(-1), rows[:, 3:6].reshape(-1), rows[:, 6:9].reshape(-1)])
        return -self._lu.solve(np.asarray(self.a.T @ z)).reshape(self.t, 3)
