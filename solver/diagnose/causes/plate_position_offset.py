"""``plate_position_offset``: one plate's centre of pressure reads a horizontal shift s
from where the force acts (the plate misplaced against the motion-capture frame, alone).

Extension: plate p's centre of pressure minus s = (sx, 0, sz) (y stays: the plate surface
is levelled); the residual moment changes by s x F_p. A shifted centre of pressure changes
nothing where the plate bears no load, so the shift's relative gain is measured against
the residual of the frames where it is loaded (> 2 % BW). One alternative per plate, and the
named plate must stand out from the other plates' shifts (``distinct_choice``: a centre of
mass misplaced in the model moves the moment under every foot alike, as a shift of either
plate would; a shift shared by every plate is ``plate_registration``). The dynamics fit
turns the body to balance a shifted centre of pressure under large forces, so the shift
may be named from the marker-only motion.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from solver.diagnose.candidates import Alternative, Context, FloatArray, LinearAlternative, profiled
from solver.diagnose.causes.base import EntryInputs, ForceCorrection, plus_minus
from solver.diagnose.data import LOADED_BW
from solver.diagnose.profile import skew


class PlatePositionOffset(ForceCorrection):
    """One plate's centre of pressure shifted (module docstring)."""

    name = "plate_position_offset"
    label = "plate position"
    channel = "residuals"
    main_parameter = "shift_m"
    min_effect = 0.005  # m
    max_effect = 0.1  # m
    chosen_on_marker_motion = True
    distinct_choice = True

    def alternatives(self, ctx: Context, full: Any) -> list[Alternative]:
        """One alternative per plate: the shift (sx, sz), m, ground frame."""
        d = ctx.data
        per = d.external()[0]
        out: list[Alternative] = []
        for i, name in enumerate(d.plates.names):
            f = per[i][:, :3]
            cols = -skew(f)[:, :, [0, 2]]  # s x F = -F x s, for s = (sx, 0, sz)
            wrench = np.concatenate([np.zeros((d.n_frames, 3, 2)), cols], axis=1)
            g = profiled(ctx, wrench)

            def physical(theta: FloatArray, name: str = name) -> dict[str, Any]:
                s = [float(theta[0]), 0.0, float(theta[1])]
                return {"value": s, "plate": name, "shift_m": s}

            # a shifted CoP changes nothing where the plate bears no load: the shift's gain is
            # measured against the residual of the frames it can explain
            loaded = f[:, 1] > LOADED_BW * d.bw
            out.append(LinearAlternative(self.name, name, ctx.ref_rows, g, physical, ("shift_x_m", "shift_z_m"), acts_on=loaded))
        return out

    def effect_size(self, parameters: dict[str, Any]) -> float:
        """|s|, m."""
        return float(np.linalg.norm(parameters["shift_m"]))

    def extension(self, parameters: dict[str, Any], inputs: EntryInputs) -> dict[str, Any]:
        """``{"cause", "trial", "plate", "shift_m"}``."""
        return {"cause": self.name, "trial": inputs.trial, "plate": parameters["plate"], "shift_m": parameters["shift_m"]}

    def describe(self, parameters: dict[str, Any], uncertainty: dict[str, Any] | None) -> str:
        """``plate p: centre of pressure shifted by [x, y, z] cm ± [...] cm``."""
        u = (uncertainty or {}).get(self.main_parameter)
        shift = np.round(np.asarray(parameters["shift_m"]) * 100, 2).tolist()
        return f"plate {parameters['plate']}: centre of pressure shifted by {shift} cm{plus_minus(u, 100, 'cm', 2)}"


CAUSE = PlatePositionOffset()
