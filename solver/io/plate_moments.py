"""Which point a force file's moment columns are about, and the free moment at the CoP.

OpenSim's convention is that ``ground_torque_*`` is the *free moment*: the couple left
when the force acts at the centre of pressure. For a horizontal plate that couple is
vertical, because the CoP is where the horizontal moment vanishes. Lab exports do not
all follow it: some write the moment about the lab origin, some about each plate's own
origin (see the level-ground circuit and treadmill files in the shared data). With
``M`` the file's moment about a fixed point ``o``::

    free_moment = M - (cop - o) x force

This module tells the three cases apart from the data (the horizontal part of the
free moment must vanish on loaded frames) and converts. A conversion is reported with
a :class:`UserWarning` naming the plate and the point, never applied silently.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
Reference = Literal["auto", "cop", "origin"]

#: A horizontal moment at the CoP this large, divided by the force, is a CoP error in m.
#: Below it the columns are taken as free moments (2 cm: the noise of a plate CoP).
LEVER_TOLERANCE_M = 0.02
#: Frames with a vertical force above max(MIN_LOAD_N, LOAD_FRACTION * peak) decide.
MIN_LOAD_N = 20.0
LOAD_FRACTION = 0.2


@dataclass(frozen=True)
class MomentReference:
    """The point the moment columns of one plate refer to.

    Attributes
    ----------
    kind
        ``"cop"`` (already free moments), ``"origin"`` (lab origin) or ``"point"``
        (a fixed point found by least squares, usually the plate's own origin).
    point
        ``(3,)`` the point in the lab frame, m (zeros for ``"cop"`` and ``"origin"``).
    lever_m
        RMS horizontal moment at the CoP left after the conversion, divided by the RMS
        force, m: how well the choice explains the data (0 = exactly).
    """

    kind: str
    point: FloatArray
    lever_m: float


def _loaded(force: FloatArray, cop: FloatArray, moment: FloatArray, up: int) -> NDArray[np.bool_]:
    """Frames with finite data and a vertical force above the load threshold."""
    finite = np.isfinite(force).all(axis=1) & np.isfinite(cop).all(axis=1)
    finite &= np.isfinite(moment).all(axis=1)
    vertical = np.where(finite, force[:, up], -np.inf)
    peak = float(np.max(vertical)) if vertical.size else 0.0
    return finite & (vertical > max(MIN_LOAD_N, LOAD_FRACTION * peak))


def _lever(residual: FloatArray, force: FloatArray, up: int) -> float:
    horizontal = np.delete(residual, up, axis=1)
    f = float(np.sqrt(np.mean(np.sum(force**2, axis=1))))
    return float(np.sqrt(np.mean(np.sum(horizontal**2, axis=1)))) / f


def _fit_point(force: FloatArray, cop: FloatArray, moment: FloatArray, up: int) -> FloatArray:
    """Least-squares ``o`` with horizontal parts of ``M - (cop - o) x F`` = 0."""
    # (cop - o) x F = cop x F + F x o = cop x F + skew(F) @ o
    fx, fy, fz = force[:, 0], force[:, 1], force[:, 2]
    zero = np.zeros_like(fx)
    skew = np.stack(
        [
            np.stack([zero, -fz, fy], axis=1),
            np.stack([fz, zero, -fx], axis=1),
            np.stack([-fy, fx, zero], axis=1),
        ],
        axis=1,
    )  # (T, 3, 3)
    rhs = moment - np.cross(cop, force)
    rows = [a for a in range(3) if a != up]
    a_mat = skew[:, rows, :].reshape(-1, 3)
    b_vec = rhs[:, rows].reshape(-1)
    point, *_ = np.linalg.lstsq(a_mat, b_vec, rcond=None)
    return point  # finite input (see _loaded) keeps the SVD well defined


def detect_reference(
    force: FloatArray, cop: FloatArray, moment: FloatArray, *, up: int = 1
) -> MomentReference | None:
    """Decide what the moment columns of one plate are about.

    Parameters
    ----------
    force, cop, moment
        ``(T, 3)`` each: N, m, N·m in the lab frame.
    up
        Index of the vertical axis (1: OpenSim's Y).

    Returns
    -------
    MomentReference or None
        The first of CoP, lab origin, fitted fixed point whose free moment has a
        horizontal part below :data:`LEVER_TOLERANCE_M` times the force; None when
        none does (or no frame is loaded, in which case the columns are left as is by
        the caller).
    """
    loaded = _loaded(force, cop, moment, up)
    if loaded.sum() < 3:
        return MomentReference("cop", np.zeros(3), 0.0)
    f, c, m = force[loaded], cop[loaded], moment[loaded]
    with np.errstate(all="ignore"):  # absurd but finite values (1e308) give inf, not warnings
        lever = _lever(m, f, up)
        if lever <= LEVER_TOLERANCE_M:
            return MomentReference("cop", np.zeros(3), lever)
        lever = _lever(m - np.cross(c, f), f, up)
        if lever <= LEVER_TOLERANCE_M:
            return MomentReference("origin", np.zeros(3), lever)
        try:
            point = _fit_point(f, c, m, up)
        except np.linalg.LinAlgError:
            return None
        lever = _lever(m - np.cross(c - point, f), f, up)
    if np.all(np.isfinite(point)) and lever <= LEVER_TOLERANCE_M:
        return MomentReference("point", point, lever)
    return None


def free_moment(
    force: FloatArray, cop: FloatArray, moment: FloatArray, reference: MomentReference
) -> FloatArray:
    """``(T, 3)`` free moment at the CoP, N·m, from moments about ``reference``."""
    if reference.kind == "cop":
        return moment
    with np.errstate(all="ignore"):  # non-finite samples stay non-finite, silently
        return moment - np.cross(cop - reference.point, force)


def warn_conversion(plate: str, reference: MomentReference, source: str) -> None:
    """Report a moment-reference conversion (a UserWarning the app can show)."""
    where = (
        "the lab origin"
        if reference.kind == "origin"
        else "the point ({:.3f}, {:.3f}, {:.3f}) m".format(*reference.point)
    )
    warnings.warn(
        f"{source}: plate {plate}: the moment columns are moments about {where}, not free "
        f"moments at the centre of pressure; converted with M - (cop - o) x F "
        f"(remaining horizontal moment at the CoP: {reference.lever_m * 100:.1f} cm x force)",
        UserWarning,
        stacklevel=3,
    )
