"""The benchmark's four metrics (Werling et al. 2024, §5), normalized by body mass.

For predictions ``p`` and ground truth ``g`` on the scored frames (``K`` frames, two feet):

* centre-of-mass acceleration error, m/s²: ``mean_k ‖p_com,k - g_com,k‖``;
* GRF error, N/kg: ``mean_{k,f} ‖p_F,k,f - g_F,k,f‖ / m`` over frames and both feet;
* GRM error, N·m/kg: the same for the ground reaction moment about each foot's origin;
* joint torque error, N·m/kg: ``mean_{k,j} |p_τ,k,j - g_τ,k,j| / m`` over frames and the
  scored coordinates (all but the six root coordinates, whose generalized forces are
  residuals, and the dependent coupled ones; see :func:`~.dataset.torque_columns`).

Norms are of 3-vectors in one frame for prediction and truth, so they do not depend on
which frame (ground or pelvis) both are expressed in. Each function returns the per-frame
errors; :func:`summarize` averages them over all frames pooled (every frame weighs the
same, whichever subject it comes from).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: Metric keys, in the table's column order, with their units.
METRICS = {
    "com_acc": "m/s²",
    "grm": "N·m/kg",
    "grf": "N/kg",
    "torque": "N·m/kg",
}

#: Column titles of the metrics.
TITLES = {
    "com_acc": "CoM acc. error (m/s²)",
    "grm": "GRM error (N·m/kg)",
    "grf": "GRF error (N/kg)",
    "torque": "joint torque error (N·m/kg)",
}


def _check(pred: FloatArray, true: FloatArray) -> tuple[FloatArray, FloatArray]:
    p = np.asarray(pred, dtype=float)
    g = np.asarray(true, dtype=float)
    if p.shape != g.shape:
        raise ValueError(f"prediction shape {p.shape} differs from ground truth shape {g.shape}")
    return p, g


def com_acc_errors(pred: FloatArray, true: FloatArray) -> FloatArray:
    """``(K,)`` L2 error of the centre-of-mass acceleration, m/s².

    Parameters
    ----------
    pred, true
        ``(K, 3)`` accelerations, m/s², one frame for both.
    """
    p, g = _check(pred, true)
    return np.linalg.norm(p - g, axis=-1)


def grf_errors(pred: FloatArray, true: FloatArray, mass_kg: float | FloatArray) -> FloatArray:
    """``(K,)`` mean over the feet of the L2 ground reaction force error per kg, N/kg.

    Parameters
    ----------
    pred, true
        ``(K, F, 3)`` force on each foot, N.
    mass_kg
        Body mass, kg: a scalar or ``(K,)`` (frames of several subjects).
    """
    p, g = _check(pred, true)
    return np.linalg.norm(p - g, axis=-1).mean(axis=-1) / np.asarray(mass_kg, dtype=float)


def grm_errors(pred: FloatArray, true: FloatArray, mass_kg: float | FloatArray) -> FloatArray:
    """``(K,)`` mean over the feet of the L2 ground reaction moment error per kg, N·m/kg.

    Parameters
    ----------
    pred, true
        ``(K, F, 3)`` moment about each foot body's origin, N·m.
    mass_kg
        Body mass, kg: a scalar or ``(K,)``.
    """
    return grf_errors(pred, true, mass_kg)


def torque_errors(pred: FloatArray, true: FloatArray, mass_kg: float | FloatArray) -> FloatArray:
    """``(K,)`` mean absolute joint torque error per kg over the scored coordinates, N·m/kg.

    Parameters
    ----------
    pred, true
        ``(K, J)`` generalized forces of the scored coordinates only (N·m; N for a
        translational coordinate).
    mass_kg
        Body mass, kg: a scalar or ``(K,)``.
    """
    p, g = _check(pred, true)
    return np.abs(p - g).mean(axis=-1) / np.asarray(mass_kg, dtype=float)


@dataclass(frozen=True)
class FrameErrors:
    """Per-frame errors of one method on a set of frames (see the module docstring).

    Attributes
    ----------
    com_acc, grm, grf, torque
        ``(K,)`` each, in m/s², N·m/kg, N/kg, N·m/kg.
    """

    com_acc: FloatArray
    grm: FloatArray
    grf: FloatArray
    torque: FloatArray

    @staticmethod
    def concatenate(parts: list[FrameErrors]) -> FrameErrors:
        """The frames of several parts, pooled."""
        if not parts:
            empty = np.zeros(0)
            return FrameErrors(empty, empty, empty, empty)
        return FrameErrors(*(np.concatenate([getattr(p, k) for p in parts]) for k in METRICS))


def summarize(errors: FrameErrors) -> dict[str, float]:
    """Mean of each metric over the frames: ``{"com_acc", "grm", "grf", "torque"}`` (NaN
    when there is no frame)."""
    out = {}
    for k in METRICS:
        v = getattr(errors, k)
        out[k] = float(v.mean()) if v.size else float("nan")
    return out
