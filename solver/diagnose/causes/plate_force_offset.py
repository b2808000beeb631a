"""``plate_force_offset``: a plate reads F + offset, the zero drift of its force channels.

Extension: plate p's force minus a constant vector acting at the plate's centre
(:attr:`solver.diagnose.data.RawPlates.centre`: its corners' centre in a C3D file, the
median loaded centre of pressure otherwise), where the plate refers its moment, not at the
moving centre of pressure (:func:`solver.corrections.offset_plate`). The residual changes
by +o in force and (c - p) x o in moment about the pelvis p where the plate is loaded; where
it is idle its readings (which must be zero) change by -o. One alternative per plate.
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
from solver.diagnose.profile import skew


class PlateForceOffset(ForceCorrection):
    """A plate's zero drift (module docstring)."""

    name = "plate_force_offset"
    label = "plate force offset"
    channel = "residuals"
    main_parameter = "offset_N"
    min_effect = 10.0  # N
    max_effect = 300.0  # N
    # the converged motion takes up a drift on the plate's loaded frames (walk draw 3004: 3
    # of 5 folds improved there, 5 of 5 on the marker-only motion; docs/diagnose/RESULTS.md)
    chosen_on_marker_motion = True

    def alternatives(self, ctx: Context, full: Any) -> list[Alternative]:
        """One alternative per plate: the offset (3,), N, ground frame."""
        d = ctx.data
        idle = d.plates.on(d.time)[2]
        out: list[Alternative] = []
        eye = np.broadcast_to(np.eye(3), (d.n_frames, 3, 3))
        for i, name in enumerate(d.plates.names):
            # residual change for an offset o: force +o, moment +(c - p) x o (not where idle);
            # idle readings change by -o
            wrench = np.concatenate([eye, skew(d.plates.centre[i] - d.pelvis)], axis=1)  # (T, 6, 3)
            wrench = np.where(idle[i][:, None, None], 0.0, wrench)
            g = profiled(ctx, wrench, plate_idle(ctx, i, np.where(idle[i][:, None, None], -eye, 0.0)))

            centre = d.plates.centre[i].tolist()

            def physical(theta: FloatArray, name: str = name, centre: list[float] = centre) -> dict[str, Any]:
                return {"value": theta.tolist(), "plate": name, "offset_N": [float(v) for v in theta], "centre_m": centre}

            out.append(LinearAlternative(self.name, name, ctx.ref_rows, g, physical, ("offset_x_N", "offset_y_N", "offset_z_N")))
        return out

    def effect_size(self, parameters: dict[str, Any]) -> float:
        """|offset|, N."""
        return float(np.linalg.norm(parameters["offset_N"]))

    def extension(self, parameters: dict[str, Any], inputs: EntryInputs) -> dict[str, Any]:
        """``{"cause", "trial", "plate", "offset_N", "centre_m"}``."""
        p = parameters
        return {"cause": self.name, "trial": inputs.trial, "plate": p["plate"], "offset_N": p["offset_N"], "centre_m": p["centre_m"]}

    def describe(self, parameters: dict[str, Any], uncertainty: dict[str, Any] | None) -> str:
        """``plate p: offset [x, y, z] N ± [...] N``."""
        u = (uncertainty or {}).get(self.main_parameter)
        return f"plate {parameters['plate']}: offset {np.round(parameters['offset_N'], 1).tolist()} N{plus_minus(u, 1, 'N', 1)}"


CAUSE = PlateForceOffset()
