"""``body_mass``: the subject's mass is the stated mass plus ``dm``.

Extension: the inertial wrench (gravity + inertia of the processed motion) scaled to the
stated mass + dm, linear in dm: the residual changes by ``dm`` times the wrench per kg
(:attr:`solver.diagnose.data.DiagnosisData.inertial` over the fitted mass). Saved as a
change of the subject's mass (``mass_change_kg``), for every trial.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from solver.diagnose.candidates import Alternative, Context, FloatArray, LinearAlternative, profiled
from solver.diagnose.causes.base import Cause, EntryInputs, RefitSetup, plus_minus


class BodyMass(Cause):
    """A wrong stated body mass (module docstring)."""

    name = "body_mass"
    label = "body mass"
    channel = "residuals"
    main_parameter = "mass_change_kg"
    min_effect = 1.5  # kg
    max_effect = 30.0  # kg
    acts_on_forces = True

    def alternatives(self, ctx: Context, full: Any) -> list[Alternative]:
        """One alternative: dm, kg."""
        d = ctx.data
        col = (d.inertial / d.fitted_mass)[:, :, None]
        g = profiled(ctx, col)
        stated = d.stated_mass

        def physical(theta: FloatArray) -> dict[str, Any]:
            dm = float(theta[0])
            return {"value": dm, "mass_change_kg": dm, "stated_mass_kg": stated, "mass_kg": stated + dm}

        return [LinearAlternative(self.name, None, ctx.ref_rows, g, physical, ("mass_change_kg",))]

    def effect_size(self, parameters: dict[str, Any]) -> float:
        """|dm|, kg."""
        return abs(parameters["mass_change_kg"])

    def extension(self, parameters: dict[str, Any], inputs: EntryInputs) -> dict[str, Any]:
        """``{"cause", "trial": None, "mass_change_kg"}`` (every trial)."""
        return {"cause": self.name, "trial": None, "mass_change_kg": parameters["mass_change_kg"]}

    def refit(self, setup: RefitSetup, parameters: dict[str, Any], inputs: EntryInputs) -> RefitSetup:
        """The stated mass + dm."""
        return replace(setup, mass_kg=setup.mass_kg + parameters["mass_change_kg"])

    def describe(self, parameters: dict[str, Any], uncertainty: dict[str, Any] | None) -> str:
        """``mass change +x kg ± u kg (stated a kg -> b kg)``."""
        p, u = parameters, (uncertainty or {}).get(self.main_parameter)
        return f"mass change {p['mass_change_kg']:+.2f} kg{plus_minus(u, 1, 'kg', 2)} (stated {p['stated_mass_kg']:.2f} kg -> {p['mass_kg']:.2f} kg)"


CAUSE = BodyMass()
