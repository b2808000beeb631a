"""Quality metrics of a processed trial in the style of Hicks et al. (2015), "Is my model
good enough? Best practices for verification and validation of musculoskeletal models
and simulations of movement", J Biomech Eng 137(2).

Residuals are evaluated on frames with measured external force only (on the others the
root residual is the unmeasured force itself). Thresholds: linear residual RMS below
0.05 body weight, angular residual RMS below 0.1 body weight x height.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from solver.constants import GRAVITY  # re-exported: the g of body weight

FloatArray = NDArray[np.float64]

HICKS_LINEAR_BW = 0.05
HICKS_ANGULAR_BWH = 0.1


def residual_metrics(
    residual_force: FloatArray,
    residual_moment: FloatArray,
    modeled: FloatArray,
    observed_markers: FloatArray,
    observed: NDArray[np.bool_],
    mass_kg: float,
    height_m: float | None,
) -> dict[str, Any]:
    """Marker and residual metrics of one trial.

    Parameters
    ----------
    residual_force, residual_moment
        ``(T, 3)`` root residual force (N) and moment (N·m).
    modeled, observed_markers
        ``(T, M, 3)`` model and observed marker positions, m (NaN where missing).
    observed
        ``(T,)`` frames with measured external force.
    mass_kg, height_m
        Body mass and height (height None: BW·h figures are None).

    Returns
    -------
    dict with ``marker_rms_m``, ``marker_max_m``, ``linear_residual_rms_N``,
    ``linear_residual_mean_N``, ``angular_residual_rms_Nm``, ``linear_residual_rms_BW``,
    ``angular_residual_rms_BWh``, ``hicks_linear_threshold_N``, ``hicks_angular_threshold_Nm``
    (the thresholds in physical units, e.g. to mark frames above them), ``hicks_linear_ok``,
    ``hicks_angular_ok``,
    ``n_observed_frames``.
    """
    err = np.linalg.norm(modeled - observed_markers, axis=2)
    seen = np.isfinite(err)
    bw = mass_kg * GRAVITY
    f = np.linalg.norm(residual_force[observed], axis=1)
    m = np.linalg.norm(residual_moment[observed], axis=1)
    has = f.size > 0
    lin_rms = float(np.sqrt(np.mean(f**2))) if has else float("nan")
    ang_rms = float(np.sqrt(np.mean(m**2))) if has else float("nan")
    bwh = bw * height_m if height_m else None
    return {
        "marker_rms_m": float(np.sqrt(np.mean(err[seen] ** 2))) if seen.any() else float("nan"),
        "marker_max_m": float(err[seen].max()) if seen.any() else float("nan"),
        "n_observed_frames": int(observed.sum()),
        "linear_residual_rms_N": lin_rms,
        "linear_residual_mean_N": float(f.mean()) if has else float("nan"),
        "angular_residual_rms_Nm": ang_rms,
        "angular_residual_mean_Nm": float(m.mean()) if has else float("nan"),
        "linear_residual_rms_BW": lin_rms / bw,
        "angular_residual_rms_BWh": ang_rms / bwh if bwh else None,
        "hicks_linear_threshold_N": HICKS_LINEAR_BW * bw,
        "hicks_angular_threshold_Nm": HICKS_ANGULAR_BWH * bwh if bwh else None,
        "hicks_linear_ok": bool(lin_rms / bw < HICKS_LINEAR_BW) if has else None,
        "hicks_angular_ok": bool(ang_rms / bwh < HICKS_ANGULAR_BWH) if (has and bwh) else None,
    }
