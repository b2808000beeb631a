"""What every candidate cause shares: the context of one trial and the alternatives' interface.

A cause (:mod:`solver.diagnose.causes`, one module each) is a model extension whose
parameters are fitted by least squares; :meth:`solver.diagnose.causes.base.Cause.alternatives`
builds its *alternatives* (the cause plus the plate or marker it concerns) from the shared
:class:`Context`. Every alternative exposes the same small interface, used by
:mod:`.selection` for cross-validation:

* ``solve(mask)`` -> parameter vector fitted on the frames in ``mask``;
* ``frame_costs(theta)`` -> ``(T,)`` cost of each frame under the extension;
* ``ref_costs`` -> ``(T,)`` cost of each frame under the reference (same channels);
* ``n_params`` and ``physical(theta)`` -> the parameters in their units.

Three kinds: :class:`LinearAlternative` (rows affine in the parameters;
:class:`MotionAlternative` on the whole-motion profile's rows), :class:`GridAlternative`
(one parameter searched on a grid) and :class:`FixedAlternative` (no global parameters).
Costs are in the currency of :mod:`.profile` (squared residuals over the dynamics fit's
standard deviations, translation profiled out), except a :class:`MotionAlternative`'s,
whose rows have the whole motion profiled out (:mod:`.motion_profile`).

The frames U (:func:`unmeasured_frames`) are part of the context: every cause is evaluated
with them out of the residual terms.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import NDArray

from solver.diagnose.data import DiagnosisData
from solver.diagnose.motion_profile import MotionProfile
from solver.diagnose.profile import ROWS, Profile, Sigmas
from solver.dynamics.preprocess import true_runs

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass
class Context:
    """What every candidate of one trial shares.

    Attributes
    ----------
    data
        The prepared trial.
    sigmas
        Channel standard deviations.
    evaluated
        ``(T,)`` frames whose residual terms count (not flagged, not in U, not left out
        of the solver's dynamic fit without U explaining it).
    profile
        Translation profile over ``evaluated``.
    ref_rows
        ``(T, 9)`` profiled reference rows.
    unmeasured
        ``(T,)`` the frames U of ``unmeasured_force`` (see :func:`unmeasured_frames`).
    """

    data: DiagnosisData
    sigmas: Sigmas
    evaluated: BoolArray
    profile: Profile
    ref_rows: FloatArray
    unmeasured: BoolArray
    unmeasured_reasons: list[str] = field(default_factory=list)

    @property
    def ref_costs(self) -> FloatArray:
        """``(T,)`` reference cost of each frame."""
        return np.sum(self.ref_rows**2, axis=1)

    @cached_property
    def motion_profile(self) -> MotionProfile:
        """The whole-motion profile over :attr:`evaluated` (built on first use: 1-3 s)."""
        return MotionProfile(self.data, self.evaluated, self.sigmas)


class LinearAlternative:
    """An alternative whose rows are affine in its parameters: rows = rho0 + G theta.

    Parameters
    ----------
    cause, choice
        Cause name and the plate or marker (None when the cause has no choice).
    rho0
        ``(T, R)`` reference rows of the channels the cause acts on (profiled).
    g
        ``(T, R, k)`` change of those rows per unit parameter (profiled).
    physical
        theta -> dict of parameters in their units.
    names
        Names of the k parameters (for the uncertainty report).
    basis
        Optional ``(k, j)`` basis: theta = basis @ beta (e.g. total mass kept).
    prior
        Optional ``(m, k)`` rows added to every fit (a ridge prior in cost units).
    acts_on
        Optional ``(T,)`` frames the cause can change (e.g. where its plate bears load):
        its relative gain is measured against the reference cost of those frames only
        (:attr:`solver.diagnose.selection.Evaluation.relative_gain`). None: every frame.
    """

    def __init__(
        self,
        cause: str,
        choice: str | None,
        rho0: FloatArray,
        g: FloatArray,
        physical: Callable[[FloatArray], dict[str, Any]],
        names: tuple[str, ...],
        basis: FloatArray | None = None,
        prior: FloatArray | None = None,
        acts_on: BoolArray | None = None,
    ) -> None:
        self.cause, self.choice = cause, choice
        self.acts_on = acts_on
        self.rho0, self.g = rho0, g if basis is None else np.einsum("trk,kj->trj", g, basis)
        self.basis = basis
        self.prior = None if prior is None else (prior if basis is None else prior @ basis)
        self._physical = physical
        self.names = names
        self.n_params = self.g.shape[2]
        self.ref_costs = np.sum(rho0**2, axis=1)

    def solve(self, mask: BoolArray) -> FloatArray:
        """``(k,)`` least-squares parameters theta on the frames in ``mask`` ``(T,)`` (k =
        :attr:`n_params`; in the coordinates of ``basis`` when one was given), in the units
        the columns of ``g`` are per."""
        g = self.g[mask].reshape(-1, self.n_params)
        r = self.rho0[mask].reshape(-1)
        if not g.size or not np.any(g):
            return np.zeros(self.n_params)
        if self.prior is not None:
            g = np.vstack([g, self.prior * np.sqrt(mask.mean())])
            r = np.concatenate([r, np.zeros(self.prior.shape[0])])
        beta, *_ = np.linalg.lstsq(g, -r, rcond=None)
        return beta

    def frame_costs(self, theta: FloatArray) -> FloatArray:
        """``(T,)`` cost of each frame with parameters ``theta``."""
        return np.sum((self.rho0 + self.g @ theta) ** 2, axis=1)

    def rows(self, theta: FloatArray) -> FloatArray:
        """``(T, R)`` the cause's profiled rows with parameters ``theta``."""
        return self.rho0 + self.g @ theta

    def physical(self, theta: FloatArray) -> dict[str, Any]:
        """Parameters in their units from ``theta`` ``(k,)`` (in the coordinates of ``basis``
        when one was given; taken back to the cause's own parameters first)."""
        full = theta if self.basis is None else self.basis @ theta
        return self._physical(full)

    def vector(self, theta: FloatArray) -> FloatArray:
        """``(n,)`` the reported parameter vector, :meth:`physical`'s ``value`` in its units
        (n = 1 for a scalar value), from ``theta`` ``(k,)`` (for the spread across folds)."""
        out = self.physical(theta)
        return np.atleast_1d(np.asarray(out["value"], dtype=float))


class GridAlternative:
    """A 1-parameter alternative searched on a grid (``force_time_offset``).

    Parameters
    ----------
    cause
        Cause name.
    grid
        ``(J,)`` parameter values.
    costs
        ``(T, J)`` cost of each frame at each grid value.
    ref_costs
        ``(T,)`` reference cost of each frame.
    physical
        value -> dict of parameters in their units.
    """

    n_params = 1
    choice = None
    acts_on = None
    names = ("delay_s",)

    def __init__(
        self,
        cause: str,
        grid: FloatArray,
        costs: FloatArray,
        ref_costs: FloatArray,
        physical: Callable[[float], dict[str, Any]],
        rows_at: Callable[[float], FloatArray],
    ) -> None:
        self.cause, self.grid, self.costs, self.ref_costs = cause, grid, costs, ref_costs
        self._physical = physical
        self.rows_at = rows_at

    def rows(self, theta: FloatArray) -> FloatArray:
        """``(T, R)`` profiled rows at the parameter value ``theta[0]``."""
        return self.rows_at(float(theta[0]))

    def solve(self, mask: BoolArray) -> FloatArray:
        """``(1,)`` the grid minimum of the cost summed over the frames in ``mask`` ``(T,)``,
        refined by a parabola through its neighbours, in the grid's units (s for the delay)."""
        total = self.costs[mask].sum(axis=0)
        j = int(np.argmin(total))
        if 0 < j < self.grid.size - 1:
            c0, c1, c2 = total[j - 1], total[j], total[j + 1]
            den = c0 - 2 * c1 + c2
            step = 0.5 * (c0 - c2) / den if den > 0 else 0.0
            return np.array([self.grid[j] + np.clip(step, -1, 1) * (self.grid[1] - self.grid[0])])
        return np.array([self.grid[j]])

    def frame_costs(self, theta: FloatArray) -> FloatArray:
        """``(T,)`` cost of each frame at the parameter value ``theta[0]`` (``theta`` ``(1,)``),
        interpolated linearly between grid values."""
        x = float(np.clip(theta[0], self.grid[0], self.grid[-1]))
        j = int(np.clip(np.searchsorted(self.grid, x) - 1, 0, self.grid.size - 2))
        w = (x - self.grid[j]) / (self.grid[j + 1] - self.grid[j])
        return (1 - w) * self.costs[:, j] + w * self.costs[:, j + 1]

    def physical(self, theta: FloatArray) -> dict[str, Any]:
        """Parameters in their units from ``theta`` ``(1,)``, the grid's parameter."""
        return self._physical(float(theta[0]))

    def vector(self, theta: FloatArray) -> FloatArray:
        """``(1,)`` the reported parameter vector, :meth:`physical`'s ``value`` (the grid's
        parameter in its units, s for the delay), from ``theta`` ``(1,)``."""
        return np.atleast_1d(np.asarray(self.physical(theta)["value"], dtype=float))


class FixedAlternative:
    """An alternative without fitted global parameters (``unmeasured_force``): its frames'
    own free wrenches; ``n_params`` counts them (6 per frame)."""

    choice = None
    names = ()
    acts_on = None

    def __init__(self, cause: str, costs: FloatArray, ref_costs: FloatArray, n_params: int, params: dict[str, Any], rows: FloatArray) -> None:
        self.cause, self._costs, self.ref_costs, self.n_params = cause, costs, ref_costs, n_params
        self._params = params
        self._rows = rows

    def rows(self, theta: FloatArray) -> FloatArray:
        """``(T, R)`` profiled rows with U out of the residual terms."""
        return self._rows

    def solve(self, mask: BoolArray) -> FloatArray:
        """Nothing to fit globally: ``(0,)`` whatever the frames in ``mask`` ``(T,)``."""
        return np.zeros(0)

    def frame_costs(self, theta: FloatArray) -> FloatArray:
        """``(T,)`` cost of each frame with U's residual terms removed."""
        return self._costs

    def physical(self, theta: FloatArray) -> dict[str, Any]:
        """The frames of U and the unmeasured force on them (``theta`` ``(0,)``, unused)."""
        return dict(self._params)

    def vector(self, theta: FloatArray) -> FloatArray:
        """No vector parameter: ``(0,)`` (``theta`` ``(0,)``, unused)."""
        return np.zeros(0)


Alternative = LinearAlternative | GridAlternative | FixedAlternative


# --------------------------------------------------------------------------- helpers


def residual_rows(ctx: Context, wrench: FloatArray, idle: FloatArray | None = None) -> FloatArray:
    """Columns of a change -> ``(T, R, k)`` unprofiled rows (marker rows zero).

    ``wrench`` ``(T, 6, k)`` is the change of the root residual; ``idle`` ``(P, T, 3, k)``
    the change of the idle plate readings (N), if any.
    """
    t, _, k = wrench.shape
    rows = np.zeros((t, ctx.profile.n_rows, k))
    w = ctx.evaluated[:, None, None]
    rows[:, 3:6] = np.where(w, wrench[:, :3] / ctx.sigmas.force, 0.0)
    rows[:, 6:9] = np.where(w, wrench[:, 3:] / ctx.sigmas.moment, 0.0)
    if idle is not None:
        rows[:, ROWS:] = np.transpose(idle, (1, 0, 2, 3)).reshape(t, -1, k) / ctx.sigmas.force
    return rows


def profiled(ctx: Context, wrench: FloatArray, idle: FloatArray | None = None) -> FloatArray:
    """:func:`residual_rows` with the translation profiled out: ``(T, R, k)`` columns of an
    alternative (the change of the rows per unit parameter)."""
    return ctx.profile.project(residual_rows(ctx, wrench, idle))


def plate_idle(ctx: Context, plate: int, cols: FloatArray) -> FloatArray:
    """``(P, T, 3, k)`` idle-row change: ``cols`` ``(T, 3, k)`` for ``plate``, zero for the others."""
    t, _, k = cols.shape
    out = np.zeros((len(ctx.data.plates.names), t, 3, k))
    out[plate] = cols
    return out


class MotionAlternative(LinearAlternative):
    """A linear alternative on the whole-motion profile's rows
    (:class:`solver.diagnose.motion_profile.MotionProfile`): its held-out figures are read
    from those rows (:meth:`figures`)."""

    def __init__(self, *args: Any, profile: MotionProfile, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.profile = profile

    def figures(self, rows: FloatArray, frames: BoolArray) -> dict[str, float]:
        """Marker RMS (m), linear (N) and angular (N·m) residual RMS of ``rows`` ``(T, R)``
        over ``frames`` (residuals: on the evaluated ones among them)."""
        p, s = self.profile, self.profile.sigmas
        m = len(p.data.markers.names)
        seen = p.data.markers.seen[frames]
        err = rows[frames, 6 : 6 + 3 * m].reshape(-1, m, 3) * s.marker
        res = frames & p.evaluated
        f, mo = rows[res, :3] * s.force, rows[res, 3:6] * s.moment
        return {
            "marker_rms_m": float(np.sqrt(np.mean(np.sum(err[seen] ** 2, axis=1)))) if seen.any() else float("nan"),
            "linear_residual_rms_N": float(np.sqrt(np.mean(np.sum(f**2, axis=1)))) if res.any() else float("nan"),
            "angular_residual_rms_Nm": float(np.sqrt(np.mean(np.sum(mo**2, axis=1)))) if res.any() else float("nan"),
            "frames": int(frames.sum()),
        }


#: ``unmeasured_force`` frames: the residual force (a missing support force) exceeds
#: SUPPORT_BW body weights while a foot is in kinematic contact with no plate force under
#: it, for at least SUPPORT_FRAMES frames (then that whole contact counts, its lightly
#: loaded start and end too); or exceeds LARGE_BW for LARGE_SECONDS anyway
#: (another unmeasured contact: sustained, unlike the transients of a time offset between
#: forces and motion at each foot strike). Runs grow while the missing support force
#: exceeds GROW_BW (a step's load builds up and fades), then by PAD_FRAMES on each side that
#: does not end on flagged frames (an applied extension's frames were padded already).
SUPPORT_BW = 0.25
SUPPORT_FRAMES = 8
LARGE_BW = 0.4
LARGE_SECONDS = 0.2
PAD_FRAMES = 3
GROW_BW = 0.1


def unmeasured_frames(data: DiagnosisData) -> tuple[BoolArray, list[str]]:
    """The frames U of ``unmeasured_force``, ``(T,)``, and the reason of each frame (T
    strings, "" outside U).

    Uses the residual at the *fitted* mass (so that a wrong stated mass does not count as
    a missing force) and the kinematic contact of :func:`solver.dynamics.contact.assign_contacts`.
    """
    t = data.n_frames
    support = np.linalg.norm(data.residual(mass=data.fitted_mass)[:, :3], axis=1) / data.bw
    reasons = [""] * t
    mask = np.zeros(t, dtype=bool)
    off_plate = np.zeros(t, dtype=bool)
    feet_off: list[list[str]] = [[] for _ in range(t)]
    if data.foot_contact is not None and data.foot_loaded is not None:
        for k, foot in enumerate(data.feet):
            off = data.foot_contact[k] & ~data.foot_loaded[k]
            off_plate |= off
            for j in np.flatnonzero(off):
                feet_off[j].append(foot)
    contacts = true_runs(off_plate)
    for a, b in true_runs((support > SUPPORT_BW) & off_plate):
        if b - a >= SUPPORT_FRAMES:
            # the whole contact is unmeasured, also its lightly loaded start and end
            lo, hi = next((x, y) for x, y in contacts if x <= a and b <= y)
            mask[lo:hi] = True
            for j in range(lo, hi):
                reasons[j] = f"{' and '.join(feet_off[j])} in contact with no plate force, {support[j]:.2f} BW missing"
    long = int(np.ceil(LARGE_SECONDS / data.dt))
    for a, b in true_runs(support > LARGE_BW):
        if b - a >= long:
            for j in range(a, b):
                if not mask[j]:
                    reasons[j] = f"{support[j]:.2f} BW of support force missing"
            mask[a:b] = True
    flagged = data.flagged
    for a, b in true_runs(mask):
        # the support force builds up and fades: grow while it is still missing, then pad;
        # a side that ends on flagged frames was padded when they were flagged (an applied
        # unmeasured_force extension), so padding it again would only eat further frames
        while a > 0 and support[a - 1] > GROW_BW:
            a -= 1
        while b < t and support[b] > GROW_BW:
            b += 1
        lo = a if flagged[a] else max(a - PAD_FRAMES, 0)
        hi = b if flagged[b - 1] else min(b + PAD_FRAMES, t)
        for j in range(lo, hi):
            if not mask[j]:
                mask[j] = True
                reasons[j] = "next to unmeasured frames"
    mask &= ~flagged
    return mask, [r if m else "" for r, m in zip(reasons, mask)]
