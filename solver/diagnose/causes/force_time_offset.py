"""``force_time_offset``: the force recording is ``delay`` s late relative to the cameras
(the plates read at t + delay).

Extension: every plate read ``delay`` s later; not linear in the delay, so it is searched
on a 1 ms grid (:data:`DELAY_GRID`) and refined by a parabola
(:class:`solver.diagnose.candidates.GridAlternative`). Saved as ``delay_s``; the
correction moves the force samples to ``time - delay_s``. A delay leaves its evidence in
the force transients of every foot strike, which the dynamics fit leaves out or bends the
motion toward, so it may be named from the marker-only motion
(:func:`solver.diagnose.core.choice_on_marker_motion`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from solver.diagnose.candidates import Alternative, Context, FloatArray, GridAlternative
from solver.diagnose.causes.base import EntryInputs, ForceCorrection, plus_minus

#: Delays searched, s (forces late is positive).
DELAY_GRID = np.round(np.arange(-0.120, 0.1205, 0.001), 4)


class ForceTimeOffset(ForceCorrection):
    """Forces late (or early) relative to the markers (module docstring)."""

    name = "force_time_offset"
    label = "force/motion time offset"
    channel = "residuals"
    main_parameter = "delay_s"
    min_effect = 0.005  # s
    max_effect = 0.1  # s (the search grid ends at 0.12 s)
    chosen_on_marker_motion = True

    def alternatives(self, ctx: Context, full: Any) -> list[Alternative]:
        """One alternative: the delay, s, on :data:`DELAY_GRID`."""
        d = ctx.data
        grid = DELAY_GRID

        def raw(tau: float) -> FloatArray:
            _, total, idle_force = d.external(tau)
            return ctx.profile.raw_rows(d.inertial * (d.stated_mass / d.fitted_mass) - total, idle_force)

        rows = np.stack([raw(float(tau)) for tau in grid], axis=2)
        costs = np.sum(ctx.profile.project(rows) ** 2, axis=1)

        def physical(tau: float) -> dict[str, Any]:
            return {"value": tau, "delay_s": tau}

        return [GridAlternative(self.name, grid, costs, ctx.ref_costs, physical, lambda tau: ctx.profile.project(raw(tau)))]

    def effect_size(self, parameters: dict[str, Any]) -> float:
        """|delay|, s."""
        return abs(parameters["delay_s"])

    def extension(self, parameters: dict[str, Any], inputs: EntryInputs) -> dict[str, Any]:
        """``{"cause", "trial", "delay_s"}``."""
        return {"cause": self.name, "trial": inputs.trial, "delay_s": parameters["delay_s"]}

    def describe(self, parameters: dict[str, Any], uncertainty: dict[str, Any] | None) -> str:
        """``forces late by x ms ± u ms``."""
        u = (uncertainty or {}).get(self.main_parameter)
        return f"forces late by {1000 * parameters['delay_s']:+.1f} ms{plus_minus(u, 1000, 'ms', 1)}"


CAUSE = ForceTimeOffset()
