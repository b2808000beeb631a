"""``segment_mass_distribution``: the legs carry ``legs_kg`` more of the body mass, taken
from the rest of the body (pelvis and trunk with head and arms, each in proportion to its
mass); total kept.

Judged on the rows of the whole-motion profile
(:attr:`solver.diagnose.candidates.Context.motion_profile`), with every coordinate at every
frame re-optimized: the dynamics fit balances a wrong distribution by bending the whole
motion, which the translation profile cannot undo (on the fitted motion it found 0.2-0.5 kg
of a hidden 5-6 kg). The root residual is taken at the fitted mass (a wrong total is
``body_mass``'s). One direction only: with the three groups free, the walk's pelvis took
+21.6 kg (the pelvis' own inertial wrench is nearly that of a translation of the whole
body), while the legs against the rest of the body came back within 0.7-1.6 kg on eight
draws (docs/diagnose/RESULTS.md, seventh and eighth sessions). Each group's change is
reported (``mass_change_kg``); ``value`` is the legs' change.

Its channels carry every marker's error and the fit's acceleration prior, which no mass
changes: the relative-gain rule does not apply (``min_relative_gain`` 0; a hidden 4-9 %
redistribution removes 0.3-6 % of them), and it is named only when no cause on the other
channels stands out (:func:`solver.diagnose.selection.choose`). It is not evaluated on the
marker-only motion (the profile re-optimizes the motion anyway). Saved as each group's
``fraction`` of its mass; ``--apply`` writes the redistributed generic model beside the
extensions file (:data:`solver.corrections.CORRECTIONS`).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from solver.diagnose.candidates import (
    Alternative,
    BoolArray,
    Context,
    FloatArray,
    MotionAlternative,
)
from solver.diagnose.causes.base import Cause, EntryInputs, RefitSetup, plus_minus

#: Note of the held-out figures on the whole-motion profile's rows.
NOTE = "fixed processed motion, every coordinate re-optimized (linearized); after: parameters fitted without the frame's fold"


class SegmentMassDistribution(Cause):
    """Mass misplaced between the legs and the rest of the body (module docstring)."""

    name = "segment_mass_distribution"
    label = "segment mass distribution"
    channel = "motion"
    # its rows carry every marker's error, the feet's stride-locked error with them: folds
    # mixing the phases, as the marker offsets' (docs/diagnose/RESULTS.md, "Why the marker
    # offsets' folds mix the phases")
    folds_mix_phases = True
    main_parameter = "mass_change_kg"
    min_effect = 1.5  # kg moved to the legs (consistent synthetic trials: up to 0.8 kg, 1.1 kg on the run's of 2026-11-23)
    max_effect = 15.0  # kg moved
    min_relative_gain = 0.0
    on_marker_motion = "skipped"

    def alternatives(self, ctx: Context, full: Any) -> list[Alternative]:
        """One alternative (none without a legs group and another): the legs' change, kg."""
        d = ctx.data
        groups = [g for g in d.groups if d.group_mass[g] > 0]
        if "legs" not in groups or len(groups) < 2:
            return []
        mp = ctx.motion_profile
        masses = np.array([d.group_mass[g] for g in groups])
        cols = np.stack([d.groups[g] / d.group_mass[g] for g in groups], axis=2)  # (T, 6, G): wrench per kg
        g = mp.per_frame(mp.project(mp.wrench_rows(cols)))
        rho0 = mp.per_frame(mp.project(mp.z0))
        legs = np.array([grp == "legs" for grp in groups], dtype=float)
        rest = np.where(legs > 0, 0.0, masses)
        basis = (legs - rest / rest.sum())[:, None]  # theta (kg per group) = basis @ legs_kg

        def physical(theta: FloatArray) -> dict[str, Any]:
            moved = {grp: float(v) for grp, v in zip(groups, theta)}
            return {"value": moved["legs"], "mass_change_kg": moved, "group_mass_kg": dict(zip(groups, masses.tolist()))}

        return [MotionAlternative(self.name, None, rho0, g, physical, ("legs_kg",), basis, profile=mp)]

    def effect_size(self, parameters: dict[str, Any]) -> float:
        """Mass moved, kg (half the sum of the groups' absolute changes)."""
        return float(np.sum(np.abs(list(parameters["mass_change_kg"].values()))) / 2)

    def extension(self, parameters: dict[str, Any], inputs: EntryInputs) -> dict[str, Any]:
        """``{"cause", "trial": None, "mass_change_kg", "fraction"}`` (each group's change
        over its mass; every trial)."""
        p = parameters
        fractions = {g: p["mass_change_kg"][g] / p["group_mass_kg"][g] for g in p["mass_change_kg"]}
        return {"cause": self.name, "trial": None, "mass_change_kg": p["mass_change_kg"], "fraction": fractions}

    def refit(self, setup: RefitSetup, parameters: dict[str, Any], inputs: EntryInputs) -> RefitSetup:
        """The processed model with the groups' masses changed."""
        from solver.model.mass_groups import redistribute

        return replace(setup, model=redistribute(setup.model, parameters["mass_change_kg"]))

    def uncertainty_json(self, uncertainty: Any, parameters: dict[str, Any]) -> dict[str, Any]:
        """One parameter, the legs' change (the rest follows): ``{"mass_change_kg": {"legs": se}}``."""
        return {self.main_parameter: {"legs": uncertainty}}

    def describe(self, parameters: dict[str, Any], uncertainty: dict[str, Any] | None) -> str:
        """``mass moved: legs +x kg, trunk -y kg, ... (legs ± u kg)``."""
        u = (uncertainty or {}).get(self.main_parameter)
        legs = f" (legs{plus_minus(u.get('legs'), 1, 'kg', 2)})" if isinstance(u, dict) and u.get("legs") is not None else ""
        return "mass moved: " + ", ".join(f"{g} {v:+.2f} kg" for g, v in parameters["mass_change_kg"].items()) + legs

    def held_out_figures(self, ctx: Context, alt: Alternative, folds: np.ndarray, frames: BoolArray) -> dict[str, Any]:
        """:meth:`Cause.held_out_figures` (``folds`` ``(T,)``, ``frames`` ``(T,)``) from the
        whole-motion profile's rows (:meth:`MotionAlternative.figures`), each fold's ``(1,)``
        legs' change, kg, fitted without it."""
        assert isinstance(alt, MotionAlternative)
        after = np.array(alt.rho0)
        for f in range(int(folds.max()) + 1):
            test = folds == f
            after[test] = alt.rows(alt.solve(~test))[test]
        return {"before": alt.figures(alt.rho0, frames), "after": alt.figures(after, frames), "note": NOTE}


CAUSE = SegmentMassDistribution()
