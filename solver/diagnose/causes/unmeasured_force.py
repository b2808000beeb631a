"""``unmeasured_force``: on the frames U a force acts that no plate measures (a step off
the plates, a hand on a rail): they leave the residual terms (the paper's free
centre-of-mass accelerations there).

The frames U are found once per trial (:func:`solver.diagnose.candidates.unmeasured_frames`)
and are part of the shared context: every other cause is evaluated with U already out of
the residual terms, so its gain comes on top of U's and the two are no alternatives (its
channel is ``frames``). Its one alternative has no global parameters: each frame of U gets
its own free wrench (6 parameters a frame, charged in the score). Its effect is the number
of frames; it has no uncertainty, and its "no effect" check always passes.

Extension: the frames, as half-open runs of marker frames of the raw trial (``frames``,
``n_frames``; ``times_s`` for reading). They join the trial's unmeasured-force mask in the
next processing (:func:`solver.corrections.extension_masks`), and in the diagnosis' refit
they join the known unmeasured frames.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from solver.diagnose.candidates import Alternative, BoolArray, Context, FixedAlternative
from solver.diagnose.causes.base import Cause, EntryInputs, RefitSetup, residual_figures
from solver.diagnose.profile import Profile
from solver.dynamics.preprocess import true_runs

#: Note of the held-out figures.
NOTE = (
    "fixed kinematics, translation re-optimized; before: the unmeasured frames count in the "
    "residual terms, and the translation that best balances the missing support force moves "
    "the body off its markers (hence its marker RMS); after: those frames left out"
)


class UnmeasuredForce(Cause):
    """Frames whose force no plate measures (module docstring)."""

    name = "unmeasured_force"
    label = "unmeasured force"
    channel = "frames"
    main_parameter = "frames"
    min_effect = 3.0  # frames
    on_marker_motion = "evaluated"

    def alternatives(self, ctx: Context, full: Any) -> list[Alternative]:
        """One alternative when U has frames: U out of the residual terms. ``full`` (the
        profile with U evaluated) gives its reference."""
        d = ctx.data
        u = ctx.unmeasured
        if not u.any():
            return []
        residual = d.residual()
        ref = np.sum(full.project(full.raw_rows(residual, d.external()[2])) ** 2, axis=1)
        ext = ctx.ref_costs
        runs = true_runs(u)
        params = {
            "value": [],
            "frames": [[int(a), int(b)] for a, b in runs],
            "times_s": [[float(d.time[a]), float(d.time[b - 1])] for a, b in runs],
            "n_frames": int(u.sum()),
            "mean_force_N": [np.round(residual[a:b, :3].mean(axis=0), 1).tolist() for a, b in runs],
            "reasons": sorted({r for r in ctx.unmeasured_reasons if r}),
        }
        return [FixedAlternative(self.name, ext, ref, 6 * int(u.sum()), params, ctx.ref_rows)]

    def effect_size(self, parameters: dict[str, Any]) -> float:
        """The number of frames of U."""
        return float(parameters["n_frames"])

    def extension(self, parameters: dict[str, Any], inputs: EntryInputs) -> dict[str, Any]:
        """``{"cause", "trial", "n_frames", "frames", "times_s"}``: runs of marker frames of
        the raw trial (``n_frames`` of them)."""
        p = parameters
        frames = inputs.marker_frames(p["frames"])
        return {"cause": self.name, "trial": inputs.trial, "n_frames": int(inputs.marker_time.size), "frames": frames, "times_s": p["times_s"]}

    def refit(self, setup: RefitSetup, parameters: dict[str, Any], inputs: EntryInputs) -> RefitSetup:
        """The frames U join the known unmeasured frames."""
        return replace(setup, unmeasured_runs=[*setup.unmeasured_runs, *((int(a), int(b)) for a, b in parameters["frames"])])

    def describe(self, parameters: dict[str, Any], uncertainty: dict[str, Any] | None) -> str:
        """``n frames (a-b s, ...) look unmeasured``."""
        spans = ", ".join(f"{a:.2f}-{b:.2f} s" for a, b in parameters["times_s"])
        return f"{parameters['n_frames']} frames ({spans}) look unmeasured"

    def held_out_figures(self, ctx: Context, alt: Alternative, folds: np.ndarray, frames: BoolArray) -> dict[str, Any]:
        """:meth:`Cause.held_out_figures` (``folds`` ``(T,)``, ``frames`` ``(T,)``). Before: U
        counts in the residual terms (every frame not flagged evaluated); after: U left out.
        No fold fit: U has no global parameters."""
        d = ctx.data
        prof = Profile(d, ~d.flagged, ctx.sigmas)
        before_rows = prof.project(prof.raw_rows(d.residual(), d.external()[2]))
        after = np.array(ctx.ref_rows)
        for f in range(int(folds.max()) + 1):
            test = folds == f
            after[test] = alt.rows(alt.solve(~test))[test]
        # the walk's steps off the plates read 7.3 cm of marker RMS here: the translation
        # that balances a missing support force moves the whole body off its markers
        return {
            "before": residual_figures(ctx, before_rows, frames, ~d.flagged),
            "after": residual_figures(ctx, after, frames, ctx.evaluated),
            "note": NOTE,
        }


CAUSE = UnmeasuredForce()
