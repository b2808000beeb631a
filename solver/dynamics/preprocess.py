"""Resampling, zero-phase low-pass filtering and finite differences (the dynamics inputs).

As the AddBiomechanics dataset paper proposes (Werling et al. 2024, §4): every trial is
put on a common rate (100 Hz by default), the signals that enter accelerations are
low-pass filtered with a 3rd-order zero-phase Butterworth filter at 30 Hz; the paper's
accelerations are central differences of the filtered coordinates (:func:`derivatives`;
the dynamics stage's default takes them from the coordinates' natural quintic spline
instead, :mod:`solver.dynamics.spline`). The force plates are
filtered with the same filter (at their own rate, before resampling) so that forces and
accelerations keep the same bandwidth.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from solver.errors import DynamicsError
from solver.masks import true_runs  # noqa: F401 (re-exported: the one runs helper lives in solver.masks)
from solver.scipy_imports import import_scipy

FloatArray = NDArray[np.float64]


def lowpass(x: FloatArray, rate_hz: float, cutoff_hz: float, order: int = 3) -> FloatArray:
    """Zero-phase Butterworth low-pass along axis 0.

    Parameters
    ----------
    x
        ``(T, ...)`` samples at ``rate_hz``; NaN-free.
    rate_hz
        Sampling rate, Hz.
    cutoff_hz
        Cut-off frequency, Hz; at or above the Nyquist frequency the signal is returned as is.
    order
        Filter order (3 as in the paper); applied forward and backward (scipy ``sosfiltfilt``).

    Raises
    ------
    DynamicsError
        ``x`` holds NaN.
    """
    x = np.asarray(x, dtype=float)
    if not np.isfinite(x).all():
        raise DynamicsError("cannot filter a signal with missing (NaN) samples")
    nyquist = 0.5 * rate_hz
    if cutoff_hz >= nyquist or x.shape[0] < 4:
        return x.copy()
    signal = import_scipy("scipy.signal")  # ~0.5 s to import: only when filtering

    sos = signal.butter(order, cutoff_hz / nyquist, btype="low", output="sos")
    padlen = min(3 * (2 * len(sos) + 1), x.shape[0] - 1)
    return signal.sosfiltfilt(sos, x, axis=0, padlen=padlen)


def moment_about_origin(force: FloatArray, cop: FloatArray, free_moment: FloatArray) -> FloatArray:
    """``(T, 3)`` moment of a plate wrench about the ground origin: cop x F + free moment.
    Unloaded frames (NaN CoP) give the free moment alone."""
    return np.cross(np.nan_to_num(cop), force) + free_moment


def cop_from_wrench(
    force: FloatArray, moment_o: FloatArray, plane_y: float, min_force: float
) -> tuple[FloatArray, FloatArray]:
    """Centre of pressure on the horizontal plane y = ``plane_y`` and vertical free moment.

    Solves moment_o = cop x F + tau e_y with cop_y = plane_y for cop_x, cop_z and tau.

    Returns
    -------
    cop, free_moment
        ``(T, 3)`` each; CoP is NaN where the vertical force is below ``min_force``.
    """
    fx, fy, fz = force[:, 0], force[:, 1], force[:, 2]
    mx, mz = moment_o[:, 0], moment_o[:, 2]
    loaded = fy > min_force
    safe = np.where(loaded, fy, 1.0)
    # m_x = y f_z - z f_y ; m_z = x f_y - y f_x  (y = plane height)
    cx = (mz + plane_y * fx) / safe
    cz = (plane_y * fz - mx) / safe
    cop = np.stack([cx, np.full_like(cx, plane_y), cz], axis=1)
    cop[~loaded] = np.nan
    tau_y = moment_o[:, 1] - np.nan_to_num(cz * fx - cx * fz)
    free = np.zeros_like(force)
    free[:, 1] = np.where(loaded, tau_y, 0.0)
    return cop, free


def resample(time: FloatArray, x: FloatArray, new_time: FloatArray) -> FloatArray:
    """Linear interpolation of ``x`` ``(T, ...)`` from ``time`` onto ``new_time``; NaN
    outside the original span."""
    flat = np.asarray(x, dtype=float).reshape(x.shape[0], -1)
    out = np.empty((new_time.size, flat.shape[1]))
    for k in range(flat.shape[1]):
        out[:, k] = np.interp(new_time, time, flat[:, k], left=np.nan, right=np.nan)
    return out.reshape((new_time.size,) + x.shape[1:])


def nearest_frames(src_time: FloatArray, time: FloatArray) -> NDArray[np.intp]:
    """``(T,)`` index of the frame of ``src_time`` (sorted, at least 2 frames) nearest each of ``time``."""
    idx = np.clip(np.searchsorted(src_time, time), 1, src_time.size - 1)
    left = idx - 1
    return np.where(np.abs(src_time[left] - time) <= np.abs(src_time[idx] - time), left, idx)


def common_time(start: float, stop: float, rate_hz: float) -> FloatArray:
    """``(T,)`` frame times from ``start`` to ``stop`` s (inclusive when on the grid) at
    ``rate_hz`` Hz, s.

    Raises
    ------
    DynamicsError
        ``stop`` is before ``start`` (no overlap in time).
    """
    n = int(np.floor((stop - start) * rate_hz + 1e-9)) + 1
    if n < 1:
        raise DynamicsError(f"no overlap in time ({start:.3f} s to {stop:.3f} s)")
    return start + np.arange(n) / rate_hz


def derivatives(x: FloatArray, dt: float) -> tuple[FloatArray, FloatArray]:
    """First and second time derivatives by central differences (one-sided at the ends).

    Parameters
    ----------
    x
        ``(T, ...)`` samples, T >= 3.
    dt
        Sample interval, s.

    Returns
    -------
    xd, xdd
        ``(T, ...)`` each: (x[t+1] - x[t-1]) / 2dt and (x[t+1] - 2 x[t] + x[t-1]) / dt²
        inside; second-order one-sided formulas at both ends.

    Raises
    ------
    DynamicsError
        Fewer than 3 frames.
    """
    x = np.asarray(x, dtype=float)
    if x.shape[0] < 3:
        raise DynamicsError(f"need at least 3 frames for accelerations, got {x.shape[0]}")
    xd = np.empty_like(x)
    xdd = np.empty_like(x)
    xd[1:-1] = (x[2:] - x[:-2]) / (2 * dt)
    xdd[1:-1] = (x[2:] - 2 * x[1:-1] + x[:-2]) / dt**2
    xd[0] = (-3 * x[0] + 4 * x[1] - x[2]) / (2 * dt)
    xd[-1] = (3 * x[-1] - 4 * x[-2] + x[-3]) / (2 * dt)
    xdd[0], xdd[-1] = xdd[1], xdd[-2]
    return xd, xdd
