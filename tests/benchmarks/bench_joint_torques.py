"""The walk's leg joint torques against OpenSim's inverse dynamics, for each dynamics fit.

    .venv/bin/python tests/benchmarks/bench_joint_torques.py

Processes rajagopal2016_walk with ``addb process --fit band`` (the default) and ``--fit
converged`` (in this process) and compares each walk's joint torques with
``../shared/oracles/opensim_id_walk.sto`` (:mod:`tests.dynamics.opensim_torques`): per leg
coordinate the RMS difference, our RMS and OpenSim's RMS (N·m), and the RMS difference over
all of them per kg of the stated mass; with the RMS leg accelerations and the residuals.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

from solver.io.subject import load_subject
from solver.pipeline import options_for_fit, process_subject
from solver.results import load_processed
from tests.conftest import SHARED_DATA, writable_copy
from tests.dynamics.opensim_torques import LEG_COORDINATES, compare_with_opensim_id


def main() -> None:
    walk = SHARED_DATA / "subjects" / "rajagopal2016_walk"
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        subject = writable_copy(walk, Path(tmp) / "rajagopal2016_walk")
        mass = load_subject(subject).mass_kg
        for fit in ("band", "converged"):
            process_subject(subject, Path(tmp) / fit, options=options_for_fit(fit, ("walk",)))
            trial = load_processed(Path(tmp) / fit, "walk")
            legs = [trial.coordinate_names.index(c) for c in LEG_COORDINATES]
            measured = ~trial.unobserved
            rows[fit] = (compare_with_opensim_id(trial, mass), float(np.sqrt(np.mean(trial.qdd[measured][:, legs] ** 2))), trial.metrics)
    print(f"walk, {rows['band'][0].frames} frames inside OpenSim's ID; RMS difference of the leg joint torques from OpenSim's ID")
    print("| fit | RMS difference (N·m/kg) | leg accelerations RMS, measured frames (rad/s²) | linear residual RMS (N) | angular residual RMS (N·m) |")
    print("| --- | ---: | ---: | ---: | ---: |")
    for fit, (cmp, acc, m) in rows.items():
        print(f"| {fit} | {cmp.rms_difference:.3f} | {acc:.0f} | {m['linear_residual_rms_N']:.1f} | {m['angular_residual_rms_Nm']:.1f} |")
    print()
    print("| coordinate | band: RMS difference / our RMS (N·m) | converged: RMS difference / our RMS (N·m) | OpenSim's RMS (N·m) |")
    print("| --- | ---: | ---: | ---: |")
    for c in LEG_COORDINATES:
        b, v = rows["band"][0].per_coordinate[c], rows["converged"][0].per_coordinate[c]
        print(f"| {c} | {b[0]:.1f} / {b[1]:.1f} | {v[0]:.1f} / {v[1]:.1f} | {b[2]:.1f} |")


if __name__ == "__main__":
    main()
