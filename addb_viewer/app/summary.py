"""Figures of one processed trial for the page: marker error, residuals, Hicks thresholds,
and the before/after table shown after a Reprocess.

Hicks thresholds (Hicks et al. 2015, "Is my model good enough?"): a residual force is
acceptable below 5 % of the peak external force, a residual moment below 1 % of the
centre-of-mass height times the peak external force. Here they are applied frame by
frame, with the peak of the summed plate forces as the external force (body weight when
the trial has no plates) and the median centre-of-mass height, on the frames with measured
force only: on a frame left out of the fit the residual is the force no plate measured.
These per-frame peak limits are not results.json's verdicts (``hicks_linear_ok``,
``hicks_angular_ok``: the residuals' RMS over the measured frames against 0.05 body weight
and 0.1 body weight x height, :mod:`solver.dynamics.metrics`), which the dataset queue shows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from solver.constants import GRAVITY as G  # standard gravity, m/s²
from solver.results import ProcessedTrial

HICKS_FORCE_FRACTION = 0.05
"""Residual force threshold as a fraction of the peak external force."""
HICKS_MOMENT_FRACTION = 0.01
"""Residual moment threshold as a fraction of COM height x peak external force."""


@dataclass(frozen=True)
class HicksThresholds:
    """Per-frame residual limits of a trial.

    Attributes
    ----------
    force_n
        Residual force limit, N.
    moment_nm
        Residual moment limit, N·m.
    """

    force_n: float
    moment_nm: float


def net_plate_force(trial: ProcessedTrial) -> NDArray[np.float64]:
    """``(T, 3)`` sum of all plates' ground reaction forces, N (NaN read as 0)."""
    total = np.zeros((trial.n_frames, 3))
    for p in trial.plates:
        total += np.nan_to_num(p.force)
    return total


def hicks_thresholds(trial: ProcessedTrial) -> HicksThresholds:
    """The trial's :class:`HicksThresholds` (see the module docstring)."""
    peak = float(np.max(np.linalg.norm(net_plate_force(trial), axis=1), initial=0.0))
    if peak <= 0.0:
        peak = trial.mass_kg * G
    com_y = trial.com[:, 1]
    height = float(np.nanmedian(com_y)) if np.isfinite(com_y).any() else 1.0
    return HicksThresholds(HICKS_FORCE_FRACTION * peak, HICKS_MOMENT_FRACTION * height * peak)


def hicks_exceeded(trial: ProcessedTrial) -> NDArray[np.bool_]:
    """``(T,)`` frames with measured force whose residual force or moment exceeds its Hicks
    threshold (all False without dynamics; never a frame left out of the fit, whose residual
    is the force no plate measured)."""
    th = hicks_thresholds(trial)
    with np.errstate(invalid="ignore"):
        f = np.linalg.norm(trial.residual_force, axis=1) > th.force_n
        m = np.linalg.norm(trial.residual_moment, axis=1) > th.moment_nm
    return (f | m) & ~np.asarray(trial.unobserved, bool)


def _rms(x: NDArray[np.float64]) -> float | None:
    v = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(v**2))) if v.size else None


def _max(x: NDArray[np.float64]) -> float | None:
    v = x[np.isfinite(x)]
    return float(v.max()) if v.size else None


def trial_summary(trial: ProcessedTrial) -> dict[str, float | int | None]:
    """The figures of the before/after table (None where not available).

    Returns
    -------
    dict
        ``marker_rms_cm``, ``marker_max_cm`` (over all markers and frames),
        ``residual_force_rms_n``, ``residual_force_max_n``, ``residual_moment_rms_nm``,
        ``residual_moment_max_nm``, ``hicks_frames`` (frames over a threshold): on the
        frames with measured force only, as results.json's residual metrics (on a frame
        left out of the fit the residual carries the force no plate measured);
        ``unobserved_frames`` (left out of the dynamic fit), ``measured_frames`` (frames
        with measured force, in the fit; None without dynamics), ``mass_kg``.
    """
    err = trial.marker_errors
    measured = ~np.asarray(trial.unobserved, bool)
    f = np.linalg.norm(trial.residual_force, axis=1)[measured]
    m = np.linalg.norm(trial.residual_moment, axis=1)[measured]
    rms = _rms(err.ravel())
    mx = _max(err.ravel())
    return {
        "marker_rms_cm": None if rms is None else 100 * rms,
        "marker_max_cm": None if mx is None else 100 * mx,
        "residual_force_rms_n": _rms(f),
        "residual_force_max_n": _max(f),
        "residual_moment_rms_nm": _rms(m),
        "residual_moment_max_nm": _max(m),
        "hicks_frames": int(hicks_exceeded(trial).sum()) if trial.has_dynamics else None,
        "unobserved_frames": int(np.count_nonzero(trial.unobserved)),
        "measured_frames": int(np.count_nonzero(measured)) if trial.has_dynamics else None,
        "mass_kg": float(trial.mass_kg),
    }


_ROWS = (
    ("marker_rms_cm", "marker RMS (cm)", 2),
    ("marker_max_cm", "marker max (cm)", 2),
    ("residual_force_rms_n", "residual force RMS, measured frames (N)", 1),
    ("residual_force_max_n", "residual force max, measured frames (N)", 1),
    ("residual_moment_rms_nm", "residual moment RMS, measured frames (N·m)", 1),
    ("residual_moment_max_nm", "residual moment max, measured frames (N·m)", 1),
    ("hicks_frames", "measured frames over a Hicks threshold", 0),
    ("unobserved_frames", "frames left out of dynamics", 0),
    ("measured_frames", "frames with measured force", 0),
    ("mass_kg", "mass (kg)", 2),
)


def _fmt(value: float | None, digits: int) -> str:
    if value is None:
        return "—"
    return f"{value:.{digits}f}" if digits else str(int(value))


def comparison_markdown(
    before: dict[str, float | int | None], after: dict[str, float | int | None]
) -> str:
    """A markdown table of two :func:`trial_summary` results with their change.

    "—" marks a figure that is not available (e.g. residuals before the dynamics stage).
    The change is the difference of the two figures as shown (rounded), so that it reads
    as their difference ("2.9 → 2.9" changes by 0.0, not by the -0.1 of the unrounded
    figures), signed when it is not zero.
    """
    lines = ["| | before | after | change |", "|---|---:|---:|---:|"]
    for key, label, digits in _ROWS:
        b, a = before.get(key), after.get(key)
        shown_b, shown_a = _fmt(b, digits), _fmt(a, digits)
        change = "—" if a is None or b is None else _change(float(shown_a) - float(shown_b), digits)
        lines.append(f"| {label} | {shown_b} | {shown_a} | {change} |")
    return "\n".join(lines)


def _change(delta: float, digits: int) -> str:
    """``delta`` with ``digits`` decimals, signed unless it rounds to zero ("0.00", never "-0.00")."""
    text = f"{delta:+.{digits}f}"
    return text[1:] if float(text) == 0.0 else text
