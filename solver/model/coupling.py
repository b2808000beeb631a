"""Exact coupling between OpenSim coordinates and the expanded pinocchio joints.

The pinocchio model has one 1-DoF joint per moving axis of every OpenSim joint, so the
walker knee (one coordinate driving two spline rotations and two spline translations)
becomes five pinocchio joints. Each expanded joint value is a function of one OpenSim
coordinate: q_pin[k] = f_k(x[c_k]), where x are the OpenSim coordinates after the
coordinate coupler constraints have been applied (x_dep = s * g(x_indep)).

Velocities and accelerations follow by the chain rule:

    v_pin[k] = f_k'(x) xdot,      a_pin[k] = f_k''(x) xdot^2 + f_k'(x) xddot,

and generalized forces are projected back with the coupling Jacobian C = dq_pin/dq:
tau = C^T tau_pin (principle of virtual work).

Evaluation is vectorized over any leading shape and grouped (identity, linear, cubic
splines sharing knots, polynomials, others) so that one frame costs a few numpy calls.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

from solver.model.functions import Constant, CubicSpline, Function, Linear, Multiplier, Polynomial

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]
F = TypeVar("F", bound=Function)


def _scaled(f: Function, kind: type[F]) -> tuple[F, float] | None:
    """(inner, scale) when f is a ``kind`` or a MultiplierFunction of one (scales multiplied)."""
    if isinstance(f, kind):
        return f, 1.0
    if isinstance(f, Multiplier):
        inner = _scaled(f.inner, kind)
        if inner is not None:
            return inner[0], inner[1] * f.scale
    return None


def _linear_of(f: Function) -> tuple[float, float] | None:
    """(slope, intercept) when f is linear or constant (possibly inside multipliers)."""
    if isinstance(f, Linear):
        return f.slope, f.intercept
    if isinstance(f, Constant):
        return 0.0, f.c
    if isinstance(f, Multiplier):
        inner = _linear_of(f.inner)
        if inner is not None:
            return inner[0] * f.scale, inner[1] * f.scale
    return None


@dataclass
class _PolynomialGroup:
    """Polynomials evaluated together by Horner's rule, column by column.

    ``coefficients[:, d]`` are ``(m + 1, k)``: the d-th derivative's coefficients of every
    polynomial, highest power first, zero-padded in front to the group's degree m (a leading
    zero leaves Horner's sum exactly as ``numpy.polyval`` has it, so the values are the same
    to the bit as those of :meth:`Polynomial.value` and :meth:`Polynomial.derivative`); one
    Horner pass over the ``(m + 1, 3, k)`` table gives the values and both derivatives.
    """

    outputs: IntArray  # (k,) output slots
    drivers: IntArray  # (k,) input slots
    scale: FloatArray  # (k,) multiplier of each polynomial
    coefficients: FloatArray  # (m + 1, 3, k)

    @staticmethod
    def of(items: list[tuple[int, int, Polynomial, float]]) -> _PolynomialGroup:
        degree = max(len(p.coefficients) for _, _, p, _ in items) - 1
        table = np.zeros((degree + 1, 3, len(items)))
        for order in range(3):
            for col, (_, _, p, _) in enumerate(items):
                c = np.polyder(np.asarray(p.coefficients, dtype=float), order)
                table[degree + 1 - c.size :, order, col] = c
        return _PolynomialGroup(
            outputs=np.array([it[0] for it in items], dtype=np.intp),
            drivers=np.array([it[1] for it in items], dtype=np.intp),
            scale=np.array([it[3] for it in items]),
            coefficients=table,
        )

    def evaluate(self, xv: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(..., k)`` inputs -> value, first and second derivative, each ``(..., k)``."""
        xs = xv[..., None, :]
        y = np.zeros(xv.shape[:-1] + self.coefficients.shape[1:])
        for row in self.coefficients:
            y = y * xs + row
        y *= self.scale
        return y[..., 0, :], y[..., 1, :], y[..., 2, :]


@dataclass
class _SplineGroup:
    """Cubic splines sharing one knot vector, evaluated together.

    ``table[i, k] = (anchor, y, b, c, d)`` so that f = y + t (b + t (c + t d)) with
    t = x - anchor, for slot i = 0 (below the first knot: the linear continuation),
    1..n-1 (the spline intervals) and n (above the last knot). The slot of x is
    ``searchsorted(bounds, x, "right")``, ``bounds`` the knots with the last one nudged up
    by one unit in the last place, so that x equal to it stays in the last interval.
    """

    outputs: IntArray  # (k,) output slots
    drivers: IntArray  # (k,) input slots
    bounds: FloatArray  # (n,)
    table: FloatArray  # (n + 1, k, 5)
    columns: IntArray  # (k,) 0..k-1, the table's column of each output


class FunctionBank:
    """Evaluate out[k] = f_k(x[driver_k]) and its derivatives for many functions at once.

    Parameters
    ----------
    drivers
        ``(K,)`` index into the input vector for each function.
    functions
        ``K`` scalar functions.
    """

    def __init__(self, drivers: list[int], functions: list[Function]) -> None:
        self.n_out = len(functions)
        lin_k, lin_c, lin_a, lin_b = [], [], [], []
        groups: dict[tuple[float, ...], list[tuple[int, int, CubicSpline, float]]] = {}
        polynomials: list[tuple[int, int, Polynomial, float]] = []
        self._others: list[tuple[int, int, Function]] = []
        for k, (c, f) in enumerate(zip(drivers, functions)):
            lin = _linear_of(f)
            spl = _scaled(f, CubicSpline)
            poly = _scaled(f, Polynomial)
            if lin is not None:
                lin_k.append(k)
                lin_c.append(c)
                lin_a.append(lin[0])
                lin_b.append(lin[1])
            elif spl is not None:
                groups.setdefault(tuple(spl[0].x), []).append((k, c, spl[0], spl[1]))
            elif poly is not None:
                polynomials.append((k, c, poly[0], poly[1]))
            else:
                self._others.append((k, c, f))
        self._lin_k = np.array(lin_k, dtype=np.intp)
        self._lin_c = np.array(lin_c, dtype=np.intp)
        self._lin_a = np.array(lin_a)
        self._lin_b = np.array(lin_b)
        self._groups = [self._make_group(items) for items in groups.values()]
        self._polynomials = _PolynomialGroup.of(polynomials) if polynomials else None

    @staticmethod
    def _make_group(items: list[tuple[int, int, CubicSpline, float]]) -> _SplineGroup:
        knots = items[0][2].x
        n, k = knots.size, len(items)
        table = np.zeros((n + 1, k, 5))
        for col, (_, _, spl, scale) in enumerate(items):
            table[1:n, col, 0] = knots[:-1]
            table[1:n, col, 1] = spl.y[:-1] * scale
            table[1:n, col, 2] = spl._b * scale
            table[1:n, col, 3] = spl._c * scale
            table[1:n, col, 4] = spl._d * scale
            table[0, col, :3] = knots[0], spl.y[0] * scale, spl._slope_start * scale
            table[n, col, :3] = knots[-1], spl.y[-1] * scale, spl._slope_end * scale
        return _SplineGroup(
            outputs=np.array([it[0] for it in items], dtype=np.intp),
            drivers=np.array([it[1] for it in items], dtype=np.intp),
            bounds=np.append(knots[:-1], np.nextafter(knots[-1], np.inf)),
            table=table,
            columns=np.arange(k, dtype=np.intp),
        )

    def evaluate(self, x: FloatArray, order: int = 2) -> tuple[FloatArray, FloatArray | None, FloatArray | None]:
        """Values, first and second derivatives.

        Parameters
        ----------
        x
            ``(..., N)`` input values.
        order
            Highest derivative wanted (0, 1 or 2); the ones above it are not computed.

        Returns
        -------
        f, df, ddf
            ``(..., K)`` each: f_k(x[driver_k]), f_k', f_k''; None above ``order``.
        """
        shape = x.shape[:-1] + (self.n_out,)
        # every output belongs to exactly one of the groups below, which fill it in
        f = np.empty(shape)
        df = np.empty(shape) if order >= 1 else None
        ddf = np.empty(shape) if order >= 2 else None
        if self._lin_k.size:
            f[..., self._lin_k] = self._lin_a * x[..., self._lin_c] + self._lin_b
            if df is not None:
                df[..., self._lin_k] = self._lin_a
            if ddf is not None:
                ddf[..., self._lin_k] = 0.0
        for g in self._groups:
            xv = x[..., g.drivers]  # (..., k)
            slot = np.searchsorted(g.bounds, xv, side="right")  # 0 below the knots, n above
            coef = g.table[slot, g.columns]  # (..., k, 5)
            t = xv - coef[..., 0]
            b, c, d = coef[..., 2], coef[..., 3], coef[..., 4]
            f[..., g.outputs] = coef[..., 1] + t * (b + t * (c + t * d))
            if df is not None:
                df[..., g.outputs] = b + t * (2 * c + 3 * t * d)
            if ddf is not None:
                ddf[..., g.outputs] = 2 * c + 6 * t * d
        if self._polynomials is not None:
            pg = self._polynomials
            pf, pdf, pddf = pg.evaluate(x[..., pg.drivers])
            f[..., pg.outputs] = pf
            if df is not None:
                df[..., pg.outputs] = pdf
            if ddf is not None:
                ddf[..., pg.outputs] = pddf
        for k, c, fn in self._others:
            xv = x[..., c]
            f[..., k] = fn.value(xv)
            if df is not None:
                df[..., k] = fn.derivative(xv, 1)
            if ddf is not None:
                ddf[..., k] = fn.derivative(xv, 2)
        return f, df, ddf


class CoordinateMap:
    """Map OpenSim coordinates q (n,) to expanded pinocchio joint values q_pin (nv,).

    Parameters
    ----------
    n_coordinates
        n, number of OpenSim coordinates (CoordinateSet order).
    dof_coordinate
        ``(nv,)`` OpenSim coordinate index driving each pinocchio DoF.
    dof_function
        ``nv`` functions f_k.
    couplers
        ``(dependent, independent, function, scale)`` index-based coupler constraints.
    """

    def __init__(
        self,
        n_coordinates: int,
        dof_coordinate: list[int],
        dof_function: list[Function],
        couplers: list[tuple[int, int, Function, float]],
    ) -> None:
        self.n = n_coordinates
        self.nv = len(dof_coordinate)
        self.dof_coordinate = np.array(dof_coordinate, dtype=np.intp)
        self._dofs = FunctionBank(dof_coordinate, dof_function)
        self.dependent = np.array([c[0] for c in couplers], dtype=np.intp)
        self.independent_of = np.array([c[1] for c in couplers], dtype=np.intp)
        self._couplers = FunctionBank(
            [c[1] for c in couplers], [Multiplier(c[2], c[3]) if c[3] != 1.0 else c[2] for c in couplers]
        )
        mask = np.ones(self.n, dtype=bool)
        mask[self.dependent] = False
        self.is_independent = mask
        # root[c]: the independent coordinate that finally drives coordinate c
        self.root = np.arange(self.n)
        self.root[self.dependent] = self.independent_of
        #: (nv,) the independent coordinate each DoF depends on (the couplers applied): the
        #: column of row k's one nonzero in the constrained coupling Jacobian
        self.dof_root = self.root[self.dof_coordinate]
        if np.any(~mask[self.independent_of]):
            raise ValueError("chained coupler constraints (a dependent driving another) are not supported")

    def complete(self, q: FloatArray) -> FloatArray:
        """``(..., n)`` coordinates ``q`` (rad or m) with every dependent coordinate replaced
        by its coupler value; the same shape."""
        x = np.array(q, dtype=float, copy=True)
        if self.dependent.size:
            g, _, _ = self._couplers.evaluate(q, order=0)
            x[..., self.dependent] = g
        return x

    def _coordinate_derivatives(
        self, q: FloatArray, qd: FloatArray | None, qdd: FloatArray | None, constrained: bool
    ) -> tuple[FloatArray, FloatArray | None, FloatArray | None, FloatArray]:
        """x, xdot, xddot of all coordinates and dx/dq_root (..., n)."""
        x = np.array(q, dtype=float, copy=True)
        xd = None if qd is None else np.array(qd, dtype=float, copy=True)
        xdd = None if qdd is None else np.array(qdd, dtype=float, copy=True)
        dxdroot = np.ones(q.shape)
        if constrained and self.dependent.size:
            g, dg, ddg = self._couplers.evaluate(q, order=1 if xdd is None else 2)
            x[..., self.dependent] = g
            dxdroot[..., self.dependent] = dg
            if xd is not None:
                qi_d = qd[..., self.independent_of]
                xd[..., self.dependent] = dg * qi_d
                if xdd is not None:
                    xdd[..., self.dependent] = ddg * qi_d**2 + dg * qdd[..., self.independent_of]
        return x, xd, xdd, dxdroot

    def expand(
        self,
        q: FloatArray,
        qd: FloatArray | None = None,
        qdd: FloatArray | None = None,
        *,
        constrained: bool = True,
    ) -> tuple[FloatArray, FloatArray | None, FloatArray | None]:
        """Expanded joint positions, velocities and accelerations.

        Parameters
        ----------
        q, qd, qdd
            ``(..., n)`` OpenSim coordinates (rad or m) and their first/second time
            derivatives; qd and qdd may be None.
        constrained
            True: dependent coordinates follow their coupler (their given values are
            ignored). False: every coordinate is treated as independent (OpenSim's
            "ignoring constraints" inverse dynamics).

        Returns
        -------
        q_pin, v_pin, a_pin
            ``(..., nv)`` each (None where the input was None).
        """
        x, xd, xdd, _ = self._coordinate_derivatives(q, qd, qdd, constrained)
        f, df, ddf = self._dofs.evaluate(x, order=0 if xd is None else (1 if xdd is None else 2))
        c = self.dof_coordinate
        v = None if xd is None else df * xd[..., c]
        a = None if xdd is None else ddf * xd[..., c] ** 2 + df * xdd[..., c]
        return f, v, a

    def jacobian(self, q: FloatArray, *, constrained: bool = True) -> FloatArray:
        """Coupling Jacobian C = d q_pin / d q, ``(nv, n)`` for one frame q (n,).

        With ``constrained`` the columns of dependent coordinates are zero and their
        effect is carried by the independent coordinate that drives them.
        """
        x, _, _, dxdroot = self._coordinate_derivatives(q, None, None, constrained)
        _, df, _ = self._dofs.evaluate(x, order=1)
        cmat = np.zeros((self.nv, self.n))
        cols = self.dof_root if constrained else self.dof_coordinate
        cmat[np.arange(self.nv), cols] = df * dxdroot[self.dof_coordinate]
        return cmat

    def expand_with_derivatives(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Constrained q_pin ``(nv,)`` of one frame and the nonzero entry of each row of the
        coupling Jacobian, ``(nv,)``: ``C[k, dof_root[k]]``, in one pass."""
        x, _, _, dxdroot = self._coordinate_derivatives(q, None, None, True)
        f, df, _ = self._dofs.evaluate(x, order=1)
        return f, df * dxdroot[self.dof_coordinate]

    def jacobian_batch(self, q: FloatArray, *, constrained: bool = True) -> tuple[FloatArray, IntArray]:
        """Sparse form of :meth:`jacobian` for many frames.

        Returns
        -------
        values
            ``(..., nv)``: dq_pin[k]/dq[cols[k]].
        cols
            ``(nv,)`` the coordinate each DoF depends on.
        """
        x, _, _, dxdroot = self._coordinate_derivatives(q, None, None, constrained)
        _, df, _ = self._dofs.evaluate(x, order=1)
        cols = self.dof_root if constrained else self.dof_coordinate
        return df * dxdroot[..., self.dof_coordinate], cols

    def project(self, q: FloatArray, tau_pin: FloatArray, *, constrained: bool = True) -> FloatArray:
        """Generalized forces on the OpenSim coordinates, tau = C^T tau_pin.

        Parameters
        ----------
        q
            ``(..., n)`` coordinates.
        tau_pin
            ``(..., nv)`` generalized forces of the expanded joints (N·m or N).

        Returns
        -------
        ``(..., n)`` N·m for rotational, N for translational coordinates; zero on
        dependent coordinates when ``constrained``.
        """
        vals, cols = self.jacobian_batch(q, constrained=constrained)
        onehot = np.zeros((self.nv, self.n))
        onehot[np.arange(self.nv), cols] = 1.0
        return (vals * tau_pin) @ onehot
