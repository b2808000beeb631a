"""``plate_force_gain``: a plate's wrench is its true wrench times a gain.

Extension: plate p's wrench divided by the gain. Linear in k = 1 - 1/gain: the corrected
wrench is (1 - k) W_p, so the residual changes by k W_p (and the plate's idle readings by
-k times themselves). One alternative per plate; "no effect" is a gain of 1.

A gain may be named from the marker-only motion whitened with its own noise
(``chosen_on_own_noise``, :func:`solver.diagnose.core.choice_on_marker_motion`). The dynamics
fit absorbs a treadmill belt's gain: the fitted motion bends toward the scaled force, and the
stage's mass fit takes up the rest, so on the run a hidden gain of 0.93-0.95 left the fitted
motion's estimate within 0.4 % of 1, or named a body-mass change. The marker-only motion
owes nothing to the forces and recovers the gain exactly (the residual changes by
(1 - g) W_p), but its moment rows carry the inertial noise of a motion no force shaped (on
the run about 16 times the fitted motion's 2 N·m), and whitened with the fitted motion's
sigmas a body-mass change, which scales that inertial moment, outscores the gain. Whitened
with the marker-only motion's own noise (:func:`solver.diagnose.profile.own_noise_sigmas`) the
force rows, where a gain and a mass change differ (a mass change acts in the flight phases
too), decide.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from solver.diagnose.candidates import (
    Alternative,
    Context,
    FloatArray,
    LinearAlternative,
    plate_idle,
    profiled,
)
from solver.diagnose.causes.base import EntryInputs, ForceCorrection, plus_minus


class PlateForceGain(ForceCorrection):
    """A plate's calibration gain (module docstring)."""

    name = "plate_force_gain"
    label = "plate force gain"
    channel = "residuals"
    main_parameter = "gain"
    min_effect = 0.015  # relative
    max_effect = 0.3  # relative
    chosen_on_own_noise = True

    def alternatives(self, ctx: Context, full: Any) -> list[Alternative]:
        """One alternative per plate: the gain."""
        d = ctx.data
        per, _, idle_force = d.external()
        out: list[Alternative] = []
        for i, name in enumerate(d.plates.names):
            g = profiled(ctx, per[i][:, :, None], plate_idle(ctx, i, -idle_force[i][:, :, None]))

            def physical(theta: FloatArray, name: str = name) -> dict[str, Any]:
                gain = 1.0 / (1.0 - float(theta[0])) if theta[0] < 0.99 else float("inf")
                return {"value": gain, "plate": name, "gain": gain}

            out.append(LinearAlternative(self.name, name, ctx.ref_rows, g, physical, ("gain",)))
        return out

    def effect_size(self, parameters: dict[str, Any]) -> float:
        """|gain - 1|."""
        return abs(parameters["gain"] - 1.0)

    def deviation(self, parameters: dict[str, Any]) -> FloatArray:
        """``(1,)`` gain - 1, dimensionless (no effect: a gain of 1)."""
        return np.atleast_1d(np.asarray(parameters["value"], dtype=float)) - 1.0

    def extension(self, parameters: dict[str, Any], inputs: EntryInputs) -> dict[str, Any]:
        """``{"cause", "trial", "plate", "gain"}``."""
        return {"cause": self.name, "trial": inputs.trial, "plate": parameters["plate"], "gain": parameters["gain"]}

    def describe(self, parameters: dict[str, Any], uncertainty: dict[str, Any] | None) -> str:
        """``plate p: gain g ± u``."""
        u = (uncertainty or {}).get(self.main_parameter)
        return f"plate {parameters['plate']}: gain {parameters['gain']:.4f}{plus_minus(u, 1, '', 4)}"


CAUSE = PlateForceGain()
