"""``marker_offset``: a landmark marker sits s (body frame) from where the model puts it.

Channel: the marker's own error minus the frame's mean error, in its body frame, over the
marker sigma (each marker a channel of its own: markers do not compete with each other, and
those that stand out besides the chosen cause are listed as findings too,
:func:`solver.diagnose.selection.also_standing_out`). A shift s moves the model marker by
R s, of which the pose solved again leaves P_jj R s in the marker's error
(:func:`solver.diagnose.data.retained_displacement`), so the shift is fitted to the error
through Rᵀ P_jj R rather than through the identity. The reported shift m (``shift_m``) is
the whole misplacement relative to the model's landmark: the kinematics stage gave the
model marker an offset d (``fitted_offset_m``) and its scale fit moved the landmark itself
by L m toward the marker (L: :func:`solver.kinematics.fit.landmark_scale_response`, of the
diagnosed trial; ``landmark_shift_m`` = L m), so d + theta = (I - L) m. Without L the
walk's sacrum and elbow misplacements read 0.2-0.6 cm short (2026-11-25).
``visible_shift_m`` is the part the marker's error shows (mean Rᵀ P_jj R times the residual
shift), which is what is judged worth naming, and its significance is that of the shift
beyond the fitted offset (``residual_shift_m``).

Extension: the marker's recordings minus the lab-frame shift R(t) s of the residual shift
(``lab_shift_m``, one row per frame of the diagnosed trial). Until 2026-11-23 the whole
misplacement was applied, which counted the fitted offset twice (the walk's L.Shoulder,
named four rounds in a row).
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
    LinearAlternative,
)
from solver.diagnose.causes.base import Cause, EntryInputs, RefitSetup, plus_minus, residual_figures


class MarkerOffset(Cause):
    """A landmark marker placed off its landmark (module docstring)."""

    name = "marker_offset"
    label = "marker offset"
    channel = "markers"
    main_parameter = "shift_m"
    min_effect = 0.005  # m (residual part the marker's error shows)
    max_effect = 0.1  # m
    # A foot marker's error repeats with every stride (the skin over the foot; the rigid foot
    # segments cannot follow it). On folds dealt in turn each fold holds about one phase of
    # the stride, so a misplacement on top of that pattern fails the held-out folds; on folds
    # mixing the phases the walk's foot draws are named (docs/diagnose/RESULTS.md, "Why the
    # marker offsets' folds mix the phases").
    folds_mix_phases = True

    def alternatives(self, ctx: Context, full: Any) -> list[Alternative]:
        """One alternative per landmark marker seen on at least 10 frames: the residual
        shift (3,), m, body frame."""
        d = ctx.data
        mk = d.markers
        mean_err, _ = mk.mean_error()
        out: list[Alternative] = []
        s = ctx.sigmas.marker
        seen_all, landmark = mk.seen, mk.landmark
        for j, name in enumerate(mk.names):
            if not landmark[j]:
                continue
            seen = seen_all[:, j]
            if seen.sum() < 10:
                continue
            dev = np.where(seen[:, None], mk.error[:, j] - mean_err, 0.0)
            u = np.einsum("tji,tj->ti", mk.rotation[:, j], dev) / s  # body frame
            rot = mk.rotation[:, j]
            kept = np.einsum("tki,tkl,tlm->tim", rot, mk.retained[:, j], rot)  # body frame: R^T P_jj R
            g = np.where(seen[:, None, None], kept, 0.0) / s
            fitted = mk.fitted_offset[j]
            shown = kept[seen].mean(axis=0)
            absorbed = mk.scale_response[j]

            # the model marker moves by R s: error + R s -> in body frame u + s / sigma
            def physical(
                theta: FloatArray,
                name: str = name,
                fitted: FloatArray = fitted,
                body: str = mk.bodies[j],
                shown: FloatArray = shown,
                absorbed: FloatArray = absorbed,
            ) -> dict[str, Any]:
                # the model marker sits fitted + theta from the scaled landmark, which the
                # scale fit moved by L m toward the marker: (I - L) m = fitted + theta. The
                # value (whose jackknife error the t value divides theta by) stays
                # fitted + theta: a constant away from theta, so its error is theta's
                placed = fitted + theta
                total = np.linalg.solve(np.eye(3) - absorbed, placed)
                return {
                    "value": [float(v) for v in placed],
                    "marker": name,
                    "body": body,
                    "shift_m": [float(v) for v in total],
                    "residual_shift_m": [float(v) for v in theta],
                    "fitted_offset_m": [float(v) for v in fitted],
                    "landmark_shift_m": [float(v) for v in absorbed @ total],
                    "landmark_scale_response": [[float(v) for v in row] for row in absorbed],
                    "visible_shift_m": [float(v) for v in shown @ theta],
                }

            out.append(LinearAlternative(self.name, name, u, g, physical, ("shift_x_m", "shift_y_m", "shift_z_m")))
        return out

    def effect_size(self, parameters: dict[str, Any]) -> float:
        """The part of the shift the marker's own error shows (the pose takes up the rest), m."""
        return float(np.linalg.norm(parameters["visible_shift_m"]))

    def deviation(self, parameters: dict[str, Any]) -> FloatArray:
        """``(3,)`` the shift beyond the offset the kinematics stage already gave the model
        marker (``residual_shift_m``), m, in the marker's body frame.

        That is what the marker's own error shows and ``--apply`` corrects; the reported
        value adds that offset, a constant, so its jackknife error is the same. Judged by
        the whole shift, a marker the trial shows 1.3 cm from the model's marker (the walk's
        L.Shoulder once corrected, 2026-11-23) was 0.8 errors from "no effect" and blocked
        every other marker.
        """
        return np.atleast_1d(np.asarray(parameters["residual_shift_m"], dtype=float))

    def uncertainty_json(self, uncertainty: Any, parameters: dict[str, Any]) -> dict[str, Any]:
        """The jackknife standard error of ``shift_m``, m: that of the placed offset
        (``value``) carried through (I - L)⁻¹ with absolute coefficients (an upper bound:
        the folds' correlations between components are not kept)."""
        if uncertainty is None:
            return {self.main_parameter: None}
        absorbed = np.asarray(parameters.get("landmark_scale_response", np.zeros((3, 3))), dtype=float)
        carried = np.abs(np.linalg.inv(np.eye(3) - absorbed)) @ np.asarray(uncertainty, dtype=float)
        return {self.main_parameter: [float(v) for v in carried]}

    def lab_shift(self, parameters: dict[str, Any], inputs: EntryInputs) -> FloatArray:
        """``(T, 3)`` the residual shift in the lab frame at each frame of the diagnosed trial, m."""
        data = inputs.data
        j = data.markers.names.index(parameters["marker"])
        return np.einsum("tij,j->ti", data.markers.rotation[:, j], np.asarray(parameters["residual_shift_m"]))

    def extension(self, parameters: dict[str, Any], inputs: EntryInputs) -> dict[str, Any]:
        """``{"cause", "trial", "marker", "body", "shift_m" (beyond the fitted offset),
        "misplacement_m", "time_s", "lab_shift_m"}``."""
        # the model marker already carries the offset the kinematics stage fitted (from every
        # trial, the static one included): the recordings move by the rest. Until 2026-11-23
        # the whole shift was applied, which counted that offset twice: a marker's finding
        # applied again and again stayed named (the walk's L.Shoulder, four rounds)
        p = parameters
        lab = self.lab_shift(p, inputs)
        return {
            "cause": self.name,
            "trial": inputs.trial,
            "marker": p["marker"],
            "body": p["body"],
            "shift_m": p["residual_shift_m"],
            "misplacement_m": p["shift_m"],
            "time_s": inputs.data.time.tolist(),
            "lab_shift_m": np.round(lab, 6).tolist(),
        }

    def refit(self, setup: RefitSetup, parameters: dict[str, Any], inputs: EntryInputs) -> RefitSetup:
        """The observed marker moved back by the entry's lab shift."""
        # the correction ``--apply`` saves (the recordings minus the lab shift; until
        # 2026-11-23 the refit added it, which doubled the marker's error: the walk's marker
        # RMS rose from 1.30 to 1.51 cm in the refit with a shoulder marker's offset)
        data = inputs.data
        j = data.markers.names.index(parameters["marker"])
        observed = np.array(data.trial.observed if setup.observed is None else setup.observed)
        observed[:, j] -= np.asarray(self.extension(parameters, inputs)["lab_shift_m"])
        return replace(setup, observed=observed)

    def describe(self, parameters: dict[str, Any], uncertainty: dict[str, Any] | None) -> str:
        """``marker m on b: [...] cm from the model's landmark (... beyond what the kinematics fit placed) ± [...] cm``."""
        p, u = parameters, (uncertainty or {}).get(self.main_parameter)
        moved = p.get("landmark_shift_m")
        by_scaling = "" if moved is None else f"; the scale fit moved the landmark {np.round(np.asarray(moved) * 100, 2).tolist()} cm toward it"
        return (
            f"marker {p['marker']} on {p['body']}: {np.round(np.asarray(p['shift_m']) * 100, 2).tolist()} cm from the model's landmark "
            f"(body frame; {np.round(np.asarray(p['residual_shift_m']) * 100, 2).tolist()} cm beyond what the kinematics fit placed"
            f"{by_scaling}){plus_minus(u, 100, 'cm', 2)}"
        )

    def held_out_figures(self, ctx: Context, alt: Alternative, folds: np.ndarray, frames: BoolArray) -> dict[str, Any]:
        """:meth:`Cause.held_out_figures` (``folds`` ``(T,)``, ``frames`` ``(T,)``): the
        marker's error moved by the lab-frame shift ``(T, 3)``, m, of each fold's parameters
        (the ``(3,)`` body-frame shift, m); the residual rows stay the reference's."""
        d = ctx.data
        j = d.markers.names.index(alt.choice)
        lab = np.zeros((d.n_frames, 3))
        for f in range(int(folds.max()) + 1):
            test = folds == f
            theta = alt.solve(~test)
            lab[test] = np.einsum("tij,j->ti", d.markers.rotation[test, j], theta)
        return {
            "before": residual_figures(ctx, ctx.ref_rows, frames, ctx.evaluated),
            "after": residual_figures(ctx, np.array(ctx.ref_rows), frames, ctx.evaluated, (j, lab)),
            "note": "fixed kinematics, translation re-optimized; after: parameters fitted without the frame's fold",
        }


CAUSE = MarkerOffset()
