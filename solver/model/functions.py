"""OpenSim's one-argument functions (the ``function`` of a TransformAxis or coupler).

Each function maps one coordinate value ``x`` to a joint displacement (rad or m) and
gives its first and second derivatives, vectorized over numpy arrays, so that joint
velocities and accelerations follow exactly by the chain rule.

Supported: ``Constant``, ``LinearFunction``, ``PolynomialFunction``, ``SimmSpline``,
``NaturalCubicSpline``, ``PiecewiseLinearFunction`` and ``MultiplierFunction``.

SimmSpline: OpenSim's SimmSpline is the cubic interpolating spline of Forsythe,
Malcolm and Moler (Computer Methods for Mathematical Computations, 1977, §4.4): the
end conditions make the spline's third derivative at each end equal to that of the
cubic through the four end knots. Outside the knot range it is continued linearly
with the end slope. With fewer than four knots the end conditions fall back as
documented in :func:`_fmm_second_derivatives`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


class Function:
    """Base class: a scalar function of one coordinate with two derivatives."""

    def value(self, x: ArrayLike) -> FloatArray:
        """f(x), same shape as ``x``."""
        raise NotImplementedError

    def derivative(self, x: ArrayLike, order: int = 1) -> FloatArray:
        """d^order f / dx^order at ``x`` (order 1 or 2), same shape as ``x``."""
        raise NotImplementedError

    def is_identity(self) -> bool:
        """True when f(x) = x (a LinearFunction with slope 1 and intercept 0)."""
        return False

    def is_constant(self) -> bool:
        """True when f does not depend on x."""
        return False


@dataclass(frozen=True)
class Constant(Function):
    """f(x) = ``c``."""

    c: float

    def value(self, x: ArrayLike) -> FloatArray:
        """``c`` at every ``x``, same shape as ``x``."""
        return np.full(np.shape(x), self.c, dtype=float)

    def derivative(self, x: ArrayLike, order: int = 1) -> FloatArray:
        """Zeros, same shape as ``x``."""
        return np.zeros(np.shape(x))

    def is_constant(self) -> bool:
        """True."""
        return True


@dataclass(frozen=True)
class Linear(Function):
    """f(x) = ``slope`` x + ``intercept`` (OpenSim ``LinearFunction``, coefficients [slope, intercept])."""

    slope: float
    intercept: float = 0.0

    def value(self, x: ArrayLike) -> FloatArray:
        """``slope`` x + ``intercept``, same shape as ``x``."""
        return self.slope * np.asarray(x, dtype=float) + self.intercept

    def derivative(self, x: ArrayLike, order: int = 1) -> FloatArray:
        """``slope`` (order 1) or 0 (order 2), same shape as ``x``."""
        return np.full(np.shape(x), self.slope if order == 1 else 0.0)

    def is_identity(self) -> bool:
        """True when ``slope`` is 1 and ``intercept`` 0."""
        return self.slope == 1.0 and self.intercept == 0.0


@dataclass(frozen=True)
class Polynomial(Function):
    """f(x) = sum_k c_k x^(n-k) with ``coefficients`` from the highest power down.

    This is the order of OpenSim's ``PolynomialFunction`` (and of ``numpy.polyval``).
    """

    coefficients: tuple[float, ...]

    def value(self, x: ArrayLike) -> FloatArray:
        """The polynomial at ``x`` (``numpy.polyval``), same shape as ``x``."""
        return np.polyval(np.asarray(self.coefficients), np.asarray(x, dtype=float))

    def derivative(self, x: ArrayLike, order: int = 1) -> FloatArray:
        """The ``order``-th derivative (``numpy.polyder``) at ``x``, same shape as ``x``."""
        c = np.polyder(np.asarray(self.coefficients, dtype=float), order)
        return np.polyval(c, np.asarray(x, dtype=float)) * np.ones(np.shape(x))


@dataclass(frozen=True)
class Multiplier(Function):
    """f(x) = ``scale`` * ``inner``(x) (OpenSim ``MultiplierFunction``, written by scaling)."""

    inner: Function
    scale: float

    def value(self, x: ArrayLike) -> FloatArray:
        """``scale`` times ``inner`` at ``x``, same shape as ``x``."""
        return self.scale * self.inner.value(x)

    def derivative(self, x: ArrayLike, order: int = 1) -> FloatArray:
        """``scale`` times ``inner``'s ``order``-th derivative at ``x``, same shape as ``x``."""
        return self.scale * self.inner.derivative(x, order)

    def is_constant(self) -> bool:
        """True when ``inner`` is constant."""
        return self.inner.is_constant()


def _fmm_second_derivatives(x: FloatArray, y: FloatArray) -> FloatArray:
    """Second derivatives at the knots of the Forsythe-Malcolm-Moler cubic spline.

    Interior knots satisfy the usual C2 continuity equations
    h[i-1] M[i-1] + 2 (h[i-1] + h[i]) M[i] + h[i] M[i+1] = 6 (s[i] - s[i-1]),
    with s the secant slopes. End conditions: the spline's third derivative on the
    first (last) interval, (M1 - M0)/h0, equals 6 times the third divided difference
    of the first (last) four knots. With three knots these differences are taken as
    zero (M0 = M1, M[n-1] = M[n-2]).
    """
    n = x.size
    h = np.diff(x)
    s = np.diff(y) / h
    a = np.zeros((n, n))  # tridiagonal except for the two end rows; n is a few dozen knots
    rhs = np.zeros(n)
    i = np.arange(1, n - 1)
    a[i, i - 1], a[i, i], a[i, i + 1] = h[:-1], 2.0 * (h[:-1] + h[1:]), h[1:]
    rhs[1:-1] = 6.0 * (s[1:] - s[:-1])
    if n >= 4:
        dd2 = np.diff(s) / (x[2:] - x[:-2])  # second divided differences
        d3_start = (dd2[1] - dd2[0]) / (x[3] - x[0])
        d3_end = (dd2[-1] - dd2[-2]) / (x[-1] - x[-4])
    else:
        d3_start = d3_end = 0.0
    # (M1 - M0) / h0 = 6 d3_start  ->  -M0 + M1 = 6 h0 d3_start, scaled by h0 for balance.
    a[0, 0], a[0, 1] = -h[0], h[0]
    rhs[0] = 6.0 * h[0] ** 2 * d3_start
    a[-1, -2], a[-1, -1] = -h[-1], h[-1]
    rhs[-1] = 6.0 * h[-1] ** 2 * d3_end
    return np.linalg.solve(a, rhs)


def _natural_second_derivatives(x: FloatArray, y: FloatArray) -> FloatArray:
    """Second derivatives of the natural cubic spline (M = 0 at both ends)."""
    n = x.size
    h = np.diff(x)
    s = np.diff(y) / h
    a = np.eye(n)
    rhs = np.zeros(n)
    i = np.arange(1, n - 1)
    a[i, i - 1], a[i, i], a[i, i + 1] = h[:-1], 2.0 * (h[:-1] + h[1:]), h[1:]
    rhs[1:-1] = 6.0 * (s[1:] - s[:-1])
    return np.linalg.solve(a, rhs)


class CubicSpline(Function):
    """Interpolating cubic spline through knots (x, y), continued linearly outside.

    Parameters
    ----------
    x, y
        ``(n,)`` knots, ``x`` strictly increasing, n >= 2 (n = 2 gives a line).
    kind
        ``"fmm"`` for OpenSim's SimmSpline, ``"natural"`` for NaturalCubicSpline.

    Raises
    ------
    ValueError
        If the knots are not strictly increasing or fewer than two.
    """

    def __init__(self, x: ArrayLike, y: ArrayLike, kind: str = "fmm") -> None:
        self.x = np.asarray(x, dtype=float)
        self.y = np.asarray(y, dtype=float)
        self.kind = kind
        if self.x.ndim != 1 or self.x.shape != self.y.shape or self.x.size < 2:
            raise ValueError(f"spline needs matching x and y of 2 or more knots, got {self.x.shape}")
        if np.any(np.diff(self.x) <= 0):
            raise ValueError("spline x knots must be strictly increasing")
        if self.x.size == 2:
            m = np.zeros(2)
        elif kind == "fmm":
            m = _fmm_second_derivatives(self.x, self.y)
        else:
            m = _natural_second_derivatives(self.x, self.y)
        h = np.diff(self.x)
        # Per interval: f = y_i + b_i t + c_i t^2 + d_i t^3, t = x - x_i
        self._b = np.diff(self.y) / h - h * (2.0 * m[:-1] + m[1:]) / 6.0
        self._c = m[:-1] / 2.0
        self._d = np.diff(m) / (6.0 * h)
        self._slope_start = self._b[0]
        self._slope_end = self._b[-1] + 2 * self._c[-1] * h[-1] + 3 * self._d[-1] * h[-1] ** 2

    def __repr__(self) -> str:
        return f"CubicSpline(kind={self.kind!r}, n={self.x.size})"

    def _locate(self, x: FloatArray) -> tuple[FloatArray, NDArray[np.intp]]:
        i = np.clip(np.searchsorted(self.x, x, side="right") - 1, 0, self.x.size - 2)
        return x - self.x[i], i

    def value(self, x: ArrayLike) -> FloatArray:
        """The spline at ``x``, continued linearly with the end slopes outside the knots;
        same shape as ``x``."""
        xa = np.asarray(x, dtype=float)
        t, i = self._locate(xa)
        f = self.y[i] + t * (self._b[i] + t * (self._c[i] + t * self._d[i]))
        f = np.where(xa < self.x[0], self.y[0] + (xa - self.x[0]) * self._slope_start, f)
        return np.where(xa > self.x[-1], self.y[-1] + (xa - self.x[-1]) * self._slope_end, f)

    def derivative(self, x: ArrayLike, order: int = 1) -> FloatArray:
        """The first or second derivative at ``x`` (outside the knots: the end slope, and
        0); same shape as ``x``."""
        xa = np.asarray(x, dtype=float)
        t, i = self._locate(xa)
        if order == 1:
            f = self._b[i] + t * (2 * self._c[i] + 3 * t * self._d[i])
            f = np.where(xa < self.x[0], self._slope_start, f)
            return np.where(xa > self.x[-1], self._slope_end, f)
        f = 2 * self._c[i] + 6 * t * self._d[i]
        return np.where((xa < self.x[0]) | (xa > self.x[-1]), 0.0, f)


class PiecewiseLinear(Function):
    """Linear interpolation through knots (OpenSim ``PiecewiseLinearFunction``), linear outside."""

    def __init__(self, x: ArrayLike, y: ArrayLike) -> None:
        self.x = np.asarray(x, dtype=float)
        self.y = np.asarray(y, dtype=float)
        if self.x.size < 2 or np.any(np.diff(self.x) <= 0) or self.x.shape != self.y.shape:
            raise ValueError("piecewise linear function needs 2+ strictly increasing knots")
        self._slopes = np.diff(self.y) / np.diff(self.x)

    def value(self, x: ArrayLike) -> FloatArray:
        """Linear interpolation at ``x``, extrapolated with the end segments' slopes;
        same shape as ``x``."""
        xa = np.asarray(x, dtype=float)
        i = np.clip(np.searchsorted(self.x, xa, side="right") - 1, 0, self.x.size - 2)
        return self.y[i] + (xa - self.x[i]) * self._slopes[i]

    def derivative(self, x: ArrayLike, order: int = 1) -> FloatArray:
        """The slope of the segment holding ``x`` (order 1), or 0 (order 2), same shape as
        ``x``; at an interior knot, the slope of the segment to its right."""
        xa = np.asarray(x, dtype=float)
        if order != 1:
            return np.zeros(xa.shape)
        i = np.clip(np.searchsorted(self.x, xa, side="right") - 1, 0, self.x.size - 2)
        return self._slopes[i]
