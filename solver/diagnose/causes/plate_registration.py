"""``plate_registration``: the force plates as a whole are misregistered against the
motion-capture frame: one translation s = (sx, 0, sz) in the floor plane and one rotation
φ about the vertical, shared by every plate.

A misregistration moves every plate's reading rigidly about the pivot o, the plates' common
centre (the mean of their centres, :attr:`solver.diagnose.data.RawPlates.centre`: corners'
centres in a C3D file, median loaded centres of pressure otherwise): what the lab reports is

    c_read = o + R(φ) (c - o) + s,   F_read = R(φ) F,   free moment unchanged (vertical axis)

with R(φ) the rotation about the vertical (y) axis. The pivot is the plates' common centre
rather than the lab origin so that s and φ are nearly uncorrelated (plates lie a metre or
more from the origin, where a rotation about the origin is mostly a translation), and it is
saved with the entry (``centre_m``), so the correction is exact wherever it was estimated.

Linear model (first order in φ; per plate p, wrench about the pelvis origin P, where the
plate is not idle): the residual changes by

    force   φ ŷ×F_p
    moment  s×F_p + φ [ŷ×(M_p + (P - o)×F_p) - (P - o)×(ŷ×F_p)]

summed over the plates (M_p: the plate's moment about P; the bracket is the rotation of the
plate's wrench about o written about P), and an idle plate's readings by -φ ŷ×f. The relative
gain is measured on the frames where some plate bears load (> 2 % BW).

``value`` (the vector of the uncertainty, the t value and the effect size) is
(sx, sz, ρφ), all in metres: ρ is the RMS horizontal distance of the loaded centres of
pressure from the pivot, so ρφ is the typical displacement the rotation gives a centre of
pressure. A rotation that is not there comes back near zero (the one rotation costs one
more log T in the score than a translation alone).

A shift of one plate alone is ``plate_position_offset``: it moves the moment of that
plate's stances only, which a shared translation cannot (on the other plates' stances it
would predict a change that is not there). The two overlap (``overlaps``): on one plate's
stances they explain the same residual, so neither keeps all of its held-out gain when both
are fitted together; the better-scoring one stands out from the other when it keeps at
least a fifth of it, a part the other cannot explain, or a tenth while the other keeps
nothing on top of it (:func:`solver.diagnose.selection._stands_out`). A turn of more than
3 degrees is implausible (:data:`MAX_TURN_RAD`): such estimates came from a turn fitted to one
belt's shift. Under the large forces of running the dynamics
fit turns the body to balance a shifted centre of pressure, so this cause, like a plate's
shift, may be named from the marker-only motion. The effect noted on the treadmill run:
both belts' centres of pressure read 1.6 cm forward and 0.5 cm sideways on the marker-only motion, too
little of the cost to be named (docs/diagnose/findings_runs_run.md, round 2).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from solver.diagnose.candidates import (
    Alternative,
    BoolArray,
    Context,
    FloatArray,
    LinearAlternative,
    profiled,
)
from solver.diagnose.causes import plate_position_offset
from solver.diagnose.causes.base import EntryInputs, ForceCorrection, plus_minus
from solver.diagnose.data import LOADED_BW, DiagnosisData
from solver.diagnose.profile import skew
from solver.dynamics.preprocess import cop_from_wrench

#: The vertical axis of the ground frame (OpenSim: y up).
UP = np.array([0.0, 1.0, 0.0])

#: Largest plausible turn of the plates against the motion-capture frame, rad (3 degrees:
#: 2.6 cm at half a metre from the plates' centre, an error a lab's calibration does not
#: leave). A larger estimated turn means the rotation fits something else: on the treadmill
#: run, where both belts' centres of pressure lie within 0.2 m of their common centre, a
#: hidden 1-4 cm shift of one belt was fitted with turns of 3.2-8.9 degrees in 6 of 10 draws
#: (2026-11-24), while 20 hidden registrations of 0.5-2 degrees came back at 0.2-2.5 degrees
#: (the run's own estimate, 0.6 degrees, included).
MAX_TURN_RAD = float(np.radians(3.0))


def columns(d: DiagnosisData) -> tuple[FloatArray, FloatArray, BoolArray, FloatArray, float, dict[str, list[float]]]:
    """The linear model of the module docstring on one prepared trial.

    Returns
    -------
    wrench
        ``(T, 6, 3)`` change of the root residual (force N, moment about the pelvis origin
        N·m) per unit (sx m, sz m, φ rad); equally the change of the plates' total wrench
        that the misregistration makes (what they read minus what they measure).
    idle
        ``(P, T, 3, 3)`` change of each idle plate's readings, N.
    loaded
        ``(T,)`` frames where some plate bears load (> LOADED_BW body weights).
    pivot
        ``(3,)`` the plates' common centre o, m.
    radius
        ρ: RMS horizontal distance of the loaded centres of pressure from o, m (1 when none).
    centroids
        Plate name -> ``(3,)`` mean of its loaded centres of pressure, m (plates loaded on some
        frame).
    """
    per, _, idle_force = d.external()  # (P, T, 6) about the pelvis, zero where idle; (P, T, 3)
    pivot = d.plates.centre.mean(axis=0)
    arm = d.pelvis - pivot  # (T, 3): P - o
    t = d.n_frames
    up = np.broadcast_to(UP, (t, 3))
    wrench = np.zeros((t, 6, 3))
    idle = np.zeros((len(d.plates.names), t, 3, 3))
    loaded = np.zeros(t, dtype=bool)
    reach: list[FloatArray] = []
    centroids: dict[str, list[float]] = {}
    for i, name in enumerate(d.plates.names):
        f, m = per[i][:, :3], per[i][:, 3:]
        turned = np.cross(up, f)  # ŷ×F
        wrench[:, 3:, 0:2] += -skew(f)[:, :, [0, 2]]  # s×F = -F×s, s = (sx, 0, sz)
        wrench[:, :3, 2] += turned
        wrench[:, 3:, 2] += np.cross(up, m + np.cross(arm, f)) - np.cross(arm, turned)
        idle[i, :, :, 2] = -np.cross(up, idle_force[i])
        on = f[:, 1] > LOADED_BW * d.bw
        loaded |= on
        if on.any():
            m_o = m + np.cross(d.pelvis, f)
            cop, _ = cop_from_wrench(f, m_o, float(d.plates.centre[i][1]), LOADED_BW * d.bw)
            reach.append((cop[on] - pivot)[:, [0, 2]])
            centroids[name] = [float(v) for v in cop[on].mean(axis=0)]
    both = np.concatenate(reach) if reach else np.zeros((0, 2))
    radius = float(np.sqrt(np.mean(np.sum(both**2, axis=1)))) if both.size else 1.0
    return wrench, idle, loaded, pivot, radius, centroids


class PlateRegistration(ForceCorrection):
    """Every plate misregistered alike against the motion-capture frame (module docstring)."""

    name = "plate_registration"
    label = "plate registration"
    channel = "residuals"
    main_parameter = "shift_m"
    min_effect = 0.005  # m (displacement of the centres of pressure, as a plate's shift)
    max_effect = 0.1  # m
    chosen_on_marker_motion = True
    # an error of the force recording shows on the motion the markers alone decide as well; a
    # mass misplaced in the model leaves a registration-like residue only on the motion the
    # dynamics fit bent to the forces (walk draws hiding 5.0-6.9 kg moved out of the legs:
    # 11-15 % of its channels' cost removed on the fitted motion, 0.7-1.9 % added on the
    # marker-only one; hidden registrations removed up to 39 % there; tests/benchmarks/RESULTS.md,
    # "A change of the rule's structure", 2026-11-27)
    confirmed_on_marker_motion = True
    overlaps = (plate_position_offset.CAUSE,)

    def alternatives(self, ctx: Context, full: Any) -> list[Alternative]:
        """One alternative: (sx, sz) m and φ rad about the plates' common centre."""
        d = ctx.data
        if not d.plates.names:
            return []
        wrench, idle, loaded, pivot, radius, centroids = columns(d)
        g = profiled(ctx, wrench, idle)
        centre = [float(v) for v in pivot]

        def physical(theta: FloatArray) -> dict[str, Any]:
            sx, sz, phi = (float(v) for v in theta)
            return {
                "value": [sx, sz, radius * phi],
                "shift_m": [sx, 0.0, sz],
                "rotation_rad": phi,
                "rotation_deg": float(np.degrees(phi)),
                "centre_m": centre,
                "radius_m": radius,
                "plates_m": centroids,
            }

        return [LinearAlternative(self.name, None, ctx.ref_rows, g, physical, ("shift_x_m", "shift_z_m", "rotation_rad"), acts_on=loaded)]

    def plausible(self, parameters: dict[str, Any]) -> bool:
        """A turn of at most :data:`MAX_TURN_RAD`."""
        return abs(parameters["rotation_rad"]) <= MAX_TURN_RAD

    def effect_size(self, parameters: dict[str, Any]) -> float:
        """|(sx, sz, ρφ)|, m: about the RMS displacement of the loaded centres of pressure."""
        p = parameters
        return float(np.linalg.norm([p["shift_m"][0], p["shift_m"][2], p["radius_m"] * p["rotation_rad"]]))

    def extension(self, parameters: dict[str, Any], inputs: EntryInputs) -> dict[str, Any]:
        """``{"cause", "trial", "shift_m", "rotation_rad", "centre_m"}``
        (:func:`solver.corrections.register_plates` undoes it)."""
        p = parameters
        return {"cause": self.name, "trial": inputs.trial, "shift_m": p["shift_m"], "rotation_rad": p["rotation_rad"], "centre_m": p["centre_m"]}

    def uncertainty_json(self, uncertainty: Any, parameters: dict[str, Any]) -> dict[str, Any]:
        """``{"shift_m": [se_x, 0, se_z], "rotation_rad": se_φ}`` (from the jackknife error of
        (sx, sz, ρφ))."""
        u = np.atleast_1d(np.asarray(uncertainty, dtype=float))
        return {"shift_m": [float(u[0]), 0.0, float(u[1])], "rotation_rad": float(u[2] / parameters["radius_m"])}

    def describe(self, parameters: dict[str, Any], uncertainty: dict[str, Any] | None) -> str:
        """``every plate: centre of pressure shifted by [...] cm ± [...] cm, turned by a° ± b°
        about (x, z) m``."""
        p, u = parameters, uncertainty or {}
        shift = np.round(np.asarray(p["shift_m"]) * 100, 2).tolist()
        turn_u = u.get("rotation_rad")
        turned = f"{np.degrees(p['rotation_rad']):+.2f}°" + ("" if turn_u is None else f" ± {np.degrees(turn_u):.2f}°")
        return (
            f"every plate: centre of pressure shifted by {shift} cm{plus_minus(u.get('shift_m'), 100, 'cm', 2)}, turned by {turned} "
            f"about ({p['centre_m'][0]:.2f}, {p['centre_m'][2]:.2f}) m"
        )


CAUSE = PlateRegistration()
