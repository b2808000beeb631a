"""Velocities and accelerations as linear operators on coordinate samples.

Default: derivatives of the natural quintic spline interpolating the samples (third and
fourth derivatives zero at both ends). This is the operator OpenSim's
InverseDynamicsTool applies to a coordinates file (a degree-5 GCV spline without
smoothing), so OpenSim reproduces our generalized forces from our files (checked in
tests to well below 1 N·m). The paper's central differences are available as
``method="central"``; on coordinates filtered at 30 Hz and sampled at 100 Hz they damp
the 20-30 Hz content by up to a third, and OpenSim's ID then differs from ours by up to
~30 N.

The spline's derivative operators are dense (every sample moves every derivative a
little), but they factor into sparse pieces: with the B-spline coefficients c of the
spline (n + 4 of them), ``M c = [0, 0, q, 0, 0]`` (values at the samples, third and fourth
derivatives zero at both ends) and ``qd = E1 c``, ``qdd = E2 c``, where M, E1 and E2 hold
the B-splines' values and derivatives at the samples (de Boor, *A Practical Guide to
Splines*, 2001, ch. IX and XIII). :class:`Derivatives` applies D1 = E1 M^-1 P and
D2 = E2 M^-1 P and their transposes through one sparse LU factorization of M, in time and
memory linear in the number of samples; :func:`derivative_operators` forms the dense
matrices (tests and short trials).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy.sparse as sps
from numpy.typing import NDArray
from scipy.sparse.linalg import splu

from solver.errors import DynamicsError
from solver.scipy_imports import import_scipy

BSpline = import_scipy("scipy.interpolate").BSpline  # without scipy 1.17's docstring notes

FloatArray = NDArray[np.float64]

_DEGREE = 5
# |D[k, s]| of the quintic interpolating spline decays as 0.4306^|k - s| (the root of the
# degree-5 Euler-Frobenius polynomial inside the unit circle): past this many samples an
# entry is below 1e-22 of the largest, which :meth:`Derivatives.band` relies on.
_DECAY_SAMPLES = 60


def _check(n: int, method: str) -> None:
    if method not in ("spline", "central"):
        raise DynamicsError(f"unknown derivative method {method!r} (use 'spline' or 'central')")
    if method == "spline" and n < 6:
        raise DynamicsError(f"need at least 6 frames for quintic spline derivatives, got {n}")
    if method == "central" and n < 3:
        raise DynamicsError(f"need at least 3 frames for central differences, got {n}")


def _basis(x: FloatArray, knots: FloatArray, nu: int, chunk: int = 64) -> sps.csr_matrix:
    """``(x.size, n_coef)`` sparse nu-th derivatives of every B-spline of degree 5 at x.

    Evaluated a chunk of basis functions at a time, at the samples in their support only
    (linear in x.size)."""
    k = _DEGREE
    nc = knots.size - k - 1
    rows, cols, vals = [], [], []
    for j0 in range(0, nc, chunk):
        j1 = min(nc, j0 + chunk)
        sel = np.flatnonzero((x >= knots[j0]) & (x <= knots[j1 + k]))
        coef = np.zeros((nc, j1 - j0))
        coef[np.arange(j0, j1), np.arange(j1 - j0)] = 1.0
        v = BSpline(knots, coef, k)(x[sel], nu)
        r, c = np.nonzero(v)
        rows.append(sel[r])
        cols.append(c + j0)
        vals.append(v[r, c])
    return sps.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(x.size, nc))


@lru_cache(maxsize=16)
def _pieces(n: int, method: str) -> tuple[object, sps.csr_matrix, sps.csr_matrix, sps.csr_matrix, sps.csr_matrix]:
    """``(lu of M, E0, E1, E2, B)`` at dt = 1: E0..E2 the values and derivatives of the
    basis at the samples (``(n, nc)``), B the ``(4, nc)`` end conditions (rows of M);
    for central differences the basis is the samples themselves (E0 = I, no end rows)."""
    if method == "central":
        i = np.arange(1, n - 1)
        d1 = sps.lil_matrix((n, n))
        d2 = sps.lil_matrix((n, n))
        d1[i, i - 1], d1[i, i + 1] = -0.5, 0.5
        d2[i, i - 1], d2[i, i], d2[i, i + 1] = 1.0, -2.0, 1.0
        d1[0, :3] = [-1.5, 2.0, -0.5]
        d1[n - 1, n - 3 :] = [0.5, -2.0, 1.5]
        d2[0, :3] = d2[1, :3]
        d2[n - 1, n - 3 :] = d2[n - 2, n - 3 :]
        return None, sps.identity(n, format="csr"), d1.tocsr(), d2.tocsr(), sps.csr_matrix((0, n))
    k = _DEGREE
    x = np.arange(n, dtype=float)
    knots = np.r_[[0.0] * (k + 1), x[1:-1], [x[-1]] * (k + 1)]
    ends = [_basis(x[:1], knots, nu) for nu in (3, 4)] + [_basis(x[-1:], knots, nu) for nu in (3, 4)]
    e0 = _basis(x, knots, 0)
    m = sps.vstack([ends[0], ends[1], e0, ends[2], ends[3]]).tocsc()
    return splu(m), e0, _basis(x, knots, 1), _basis(x, knots, 2), sps.vstack(ends).tocsr()


def _natural_basis(ends: sps.csr_matrix) -> sps.csr_matrix:
    """``(nc, nc - r)`` Z whose columns span the coefficients with ``ends @ c = 0`` and are local.

    The r = 4 end conditions of the quintic spline act on the first and last five
    coefficients only (the B-splines whose third or fourth derivative is nonzero at an
    end), two each. They fix the two outermost coefficients at each end from the next
    three, ``[c0, c1] = -B[:, :2]^-1 B[:, 2:5] c[2:5]``; the other coefficients are the
    unknowns, so every sample still depends on five consecutive unknowns. With no end
    conditions (central differences) Z is the identity."""
    nc = ends.shape[1]
    if ends.shape[0] == 0:
        return sps.identity(nc, format="csr")
    dense = ends.toarray()
    head = -np.linalg.solve(dense[:2, :2], dense[:2, 2:5])  # (2, 3): c0, c1 from c2..c4
    tail = -np.linalg.solve(dense[2:, -2:], dense[2:, -5:-2])  # (2, 3): c[-2:] from c[-5:-2]
    z = sps.lil_matrix((nc, nc - 4))
    z[2:-2, :] = sps.identity(nc - 4)
    z[:2, :3] = head
    z[-2:, -3:] = tail
    return z.tocsr()


@dataclass(frozen=True)
class CoefficientMaps:
    """Coefficients of the natural spline as the unknowns: every map from them is sparse and banded.

    The natural quintic splines with knots at the n samples form an n-dimensional space
    (B-spline coefficients c, n + 4 of them, with the four end conditions ``B c = 0``).
    With a local basis of that space, c = Z a (:func:`_natural_basis`), the samples,
    velocities and accelerations are ``q = E0 a``, ``qd = E1 a``, ``qdd = E2 a``, and
    row k of E0, E1 and E2 is zero outside the ``width`` coefficients from ``start[k]`` on
    (5 for the quintic spline). So a cost of q, qd and qdd has a banded Gauss-Newton
    matrix in a, where its matrix in q is dense (de Boor 2001, ch. IX: the B-spline basis
    has local support). For central differences a = q, E0 = I.

    Attributes
    ----------
    e0, e1, e2
        ``(n, n)`` sparse: values, first (1/s) and second (1/s²) time derivatives.
    start
        ``(n,)`` first coefficient of each row's window (non-decreasing; strictly increasing
        for the quintic spline).
    width
        Coefficients in a row's window.
    weights
        ``(3, n, width)`` the rows of E0, E1, E2 inside their windows.
    """

    e0: sps.csr_matrix
    e1: sps.csr_matrix
    e2: sps.csr_matrix
    start: NDArray[np.intp]
    width: int
    weights: FloatArray


class Derivatives:
    """D1 and D2 of ``n`` samples ``dt`` apart as linear maps: ``qd = D1 q``, ``qdd = D2 q``.

    Linear in n in time and memory (module docstring); equal to the dense operators of
    :func:`derivative_operators` to round-off (about 1e-14 relative, tests/dynamics).

    Parameters
    ----------
    n
        Number of samples.
    dt
        Sample interval, s.
    method
        ``"spline"`` (default) or ``"central"``.

    Raises
    ------
    DynamicsError
        Too few samples or an unknown method.
    """

    def __init__(self, n: int, dt: float, method: str = "spline") -> None:
        n = int(n)
        _check(n, method)
        self.n, self.dt, self.method = n, float(dt), method
        self._lu, _, self._e1, self._e2, _ = _pieces(n, method)

    def __call__(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``(n, ...)`` samples -> their first and second time derivatives, same shape."""
        flat = np.asarray(q, dtype=float).reshape(self.n, -1)
        if self._lu is None:
            c = flat
        else:
            rhs = np.zeros((self.n + 4, flat.shape[1]))
            rhs[2:-2] = flat
            c = self._lu.solve(rhs)
        d1 = (self._e1 @ c) / self.dt
        d2 = (self._e2 @ c) / self.dt**2
        return d1.reshape(np.shape(q)), d2.reshape(np.shape(q))

    def transpose(self, w1: FloatArray, w2: FloatArray) -> FloatArray:
        """``D1^T w1 + D2^T w2`` for ``(n, ...)`` arrays w1, w2 (the adjoint, for gradients)."""
        shape = np.shape(w1)
        a = np.asarray(w1, dtype=float).reshape(self.n, -1)
        b = np.asarray(w2, dtype=float).reshape(self.n, -1)
        y = (self._e1.T @ a) / self.dt + (self._e2.T @ b) / self.dt**2
        if self._lu is not None:
            y = self._lu.solve(y, trans="T")[2:-2]
        return y.reshape(shape)

    def coefficient_maps(self) -> CoefficientMaps:
        """The sparse maps from a local basis of the natural splines (:class:`CoefficientMaps`), at this ``dt``."""
        _, e0, e1, e2, ends = _pieces(self.n, self.method)
        z = _natural_basis(ends)
        rows = [(e0 @ z).tocsr(), (e1 @ z / self.dt).tocsr(), (e2 @ z / self.dt**2).tocsr()]
        for e in rows:
            e.eliminate_zeros()
        lo = np.min([np.minimum.reduceat(e.indices, e.indptr[:-1]) for e in rows], axis=0)
        hi = np.max([np.maximum.reduceat(e.indices, e.indptr[:-1]) for e in rows], axis=0)
        width = int((hi - lo).max()) + 1
        lo = np.minimum(lo, z.shape[1] - width)  # windows inside the coefficients
        weights = np.zeros((3, self.n, width))
        for i, e in enumerate(rows):
            r = np.repeat(np.arange(self.n), np.diff(e.indptr))
            weights[i, r, e.indices - lo[r]] = e.data
        return CoefficientMaps(rows[0], rows[1], rows[2], lo.astype(np.intp), width, weights)

    def band(self, b: int) -> tuple[FloatArray, FloatArray]:
        """Entries of D1 and D2 within ``b`` samples of the diagonal.

        Returns
        -------
        ``(n, 2 b + 1)`` arrays B1, B2 with ``B[k, o + b] = D[k, k + o]`` (zero past the
        ends). Read off D applied to combs of unit samples ``2 b + 1 + 60`` apart (exact
        to 1e-22 relative, by the operators' decay)."""
        n = self.n
        period = min(n, 2 * b + 1 + _DECAY_SAMPLES)
        comb = np.zeros((n, period))
        comb[np.arange(n), np.arange(n) % period] = 1.0
        d1, d2 = self(comb)
        out1, out2 = np.zeros((n, 2 * b + 1)), np.zeros((n, 2 * b + 1))
        k = np.arange(n)
        for o in range(-b, b + 1):
            s = k + o
            ok = (s >= 0) & (s < n)
            out1[ok, o + b] = d1[k[ok], s[ok] % period]
            out2[ok, o + b] = d2[k[ok], s[ok] % period]
        return out1, out2


def derivative_operators(n: int, dt: float, method: str = "spline") -> tuple[FloatArray, FloatArray]:
    """``(n, n)`` dense matrices D1, D2 with qd = D1 @ q and qdd = D2 @ q for samples ``dt`` apart.

    Quadratic in n: for short trials and tests; :class:`Derivatives` applies the same maps
    in linear time.

    Raises
    ------
    DynamicsError
        Too few frames or an unknown method.
    """
    return Derivatives(n, dt, method)(np.eye(int(n)))


def differentiate(q: FloatArray, dt: float, method: str = "spline") -> tuple[FloatArray, FloatArray]:
    """``(T, ...)`` first and second time derivatives of samples ``q`` (see module doc).

    Raises
    ------
    DynamicsError
        Too few frames or an unknown method.
    """
    return Derivatives(np.shape(q)[0], dt, method)(q)
