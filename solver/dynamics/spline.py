"""Velocities and accelerations as linear operators on coordinate samples.

Default: derivatives of the natural quintic spline interpolating the samples (third and
fourth derivatives zero at both ends). This is the operator OpenSim's
InverseDynamicsTool applies to a coordinates file (a degree-5 GCV spline without
smoothing), so OpenSim reproduces our generalized forces from our files (checked in
tests to well below 1 N·m). The paper's central differences are available as
``method="central"``; on coordinates filtered at 30 Hz and sampled at 100 Hz they damp
the 20-30 Hz content by up to a third, and OpenSim's ID then differs from ours by up to
~30 N.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import make_interp_spline

from solver.errors import DynamicsError

FloatArray = NDArray[np.float64]


@lru_cache(maxsize=16)
def _operators(n: int, method: str) -> tuple[FloatArray, FloatArray]:
    """Unit-interval operators (dt = 1) for ``n`` samples; cached."""
    t = np.arange(n, dtype=float)
    eye = np.eye(n)
    if method == "central":
        d1 = np.zeros((n, n))
        d2 = np.zeros((n, n))
        i = np.arange(1, n - 1)
        d1[i, i - 1], d1[i, i + 1] = -0.5, 0.5
        d2[i, i - 1], d2[i, i], d2[i, i + 1] = 1.0, -2.0, 1.0
        d1[0, :3] = [-1.5, 2.0, -0.5]
        d1[-1, -3:] = [0.5, -2.0, 1.5]
        d2[0], d2[-1] = d2[1], d2[-2]
        return d1, d2
    if method != "spline":
        raise DynamicsError(f"unknown derivative method {method!r} (use 'spline' or 'central')")
    if n < 6:
        raise DynamicsError(f"need at least 6 frames for quintic spline derivatives, got {n}")
    zero = np.zeros(n)
    spl = make_interp_spline(t, eye, k=5, bc_type=([(3, zero), (4, zero)], [(3, zero), (4, zero)]))
    return np.asarray(spl(t, 1)), np.asarray(spl(t, 2))


def derivative_operators(n: int, dt: float, method: str = "spline") -> tuple[FloatArray, FloatArray]:
    """``(n, n)`` matrices D1, D2 with qd = D1 @ q and qdd = D2 @ q for samples ``dt`` apart.

    Raises
    ------
    DynamicsError
        Too few frames or an unknown method.
    """
    d1, d2 = _operators(int(n), method)
    return d1 / dt, d2 / dt**2


def differentiate(q: FloatArray, dt: float, method: str = "spline") -> tuple[FloatArray, FloatArray]:
    """``(T, ...)`` first and second time derivatives of samples ``q`` (see module doc)."""
    d1, d2 = derivative_operators(q.shape[0], dt, method)
    flat = q.reshape(q.shape[0], -1)
    return (d1 @ flat).reshape(q.shape), (d2 @ flat).reshape(q.shape)
