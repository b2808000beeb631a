"""Joint torques of a processed walk against OpenSim's inverse dynamics of the same trial.

``../shared/oracles/opensim_id_walk.sto`` is OpenSim 4.6's InverseDynamicsTool on its own IK
of the rajagopal2016 walk (the study's scaled model, coordinates low-passed at 6 Hz). The
comparison is over the leg coordinates (hip flexion, adduction and rotation, knee, ankle;
both sides), on the processed trial's frames inside the ID's time range (the ID is
interpolated linearly to them), as the RMS difference per kg of the stated body mass.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from solver.dynamics.fit import CONVERGED_WEIGHTS, FitSettings
from solver.io.mot import read_table
from solver.results import ProcessedTrial

ORACLE_ID = Path(__file__).resolve().parents[2].parent / "shared" / "oracles" / "opensim_id_walk.sto"
#: ``FitSettings()``'s values of the weights :func:`solver.dynamics.fit.converged_fit` changes:
#: the converged fit run with them is the one whose torques are far from OpenSim's.
BAND_WEIGHTS = {f.name: f.default for f in fields(FitSettings) if f.name in CONVERGED_WEIGHTS}
LEG_COORDINATES = tuple(
    f"{c}_{side}" for side in ("r", "l") for c in ("hip_flexion", "hip_adduction", "hip_rotation", "knee_angle", "ankle_angle")
)


@dataclass(frozen=True)
class TorqueComparison:
    """Attributes: ``rms_difference`` (N·m/kg over every leg coordinate and frame),
    ``per_coordinate`` (coordinate -> (RMS difference, our RMS, OpenSim's RMS), N·m),
    ``frames`` (frames compared)."""

    rms_difference: float
    per_coordinate: dict[str, tuple[float, float, float]]
    frames: int


def compare_with_opensim_id(trial: ProcessedTrial, mass_kg: float, oracle: Path = ORACLE_ID) -> TorqueComparison:
    """Compare ``trial``'s joint torques (``tau``, N·m) with OpenSim's ID of the walk.

    Raises
    ------
    ValueError
        The trial shares no frame with the ID, or lacks a leg coordinate.
    """
    table = read_table(oracle)
    inside = (trial.time >= table.time[0]) & (trial.time <= table.time[-1])
    if not inside.any():
        raise ValueError(f"{oracle}: no frame of trial {trial.trial!r} in its time range")
    per = {}
    diffs = []
    for c in LEG_COORDINATES:
        ours = trial.tau[inside, trial.coordinate_names.index(c)]
        ref = np.interp(trial.time[inside], table.time, table.column(f"{c}_moment"))
        d = ours - ref
        diffs.append(d)
        per[c] = (float(np.sqrt(np.mean(d**2))), float(np.sqrt(np.mean(ours**2))), float(np.sqrt(np.mean(ref**2))))
    return TorqueComparison(float(np.sqrt(np.mean(np.square(diffs)))) / mass_kg, per, int(inside.sum()))
