"""The walk's leg joint torques against OpenSim's inverse dynamics, for each dynamics fit.

    .venv/bin/python tests/benchmarks/bench_joint_torques.py

Processes rajagopal2016_walk (in this process) with ``addb process``'s default fit (the
converged fit, :func:`solver.dynamics.fit.converged_fit`), with ``--fit band``, and with the
converged fit given the band fit's weights (``FitSettings()``'s sigmas in place of
:data:`solver.dynamics.fit.CONVERGED_WEIGHTS`), and compares each walk's joint torques with
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

from solver.dynamics.fit import CONVERGED_WEIGHTS, converged_fit
from solver.dynamics.stage import DynamicsOptions
from solver.io.subject import load_subject
from solver.pipeline import ProcessOptions, options_for_fit, process_subject
from solver.results import load_processed
from tests.conftest import SHARED_DATA, writable_copy
from tests.dynamics.opensim_torques import BAND_WEIGHTS, LEG_COORDINATES, compare_with_opensim_id

FITS = {
    "default (converged)": options_for_fit("default", ("walk",)),
    "band": options_for_fit("band", ("walk",)),
    "converged, band weights": ProcessOptions(trials=("walk",), dynamics=DynamicsOptions(fit=converged_fit(**BAND_WEIGHTS))),
}


def main() -> None:
    walk = SHARED_DATA / "subjects" / "rajagopal2016_walk"
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        subject = writable_copy(walk, Path(tmp) / "rajagopal2016_walk")
        mass = load_subject(subject).mass_kg
        for i, (fit, options) in enumerate(FITS.items()):
            out = Path(tmp) / f"out{i}"
            process_subject(subject, out, options=options)
            trial = load_processed(out, "walk")
            legs = [trial.coordinate_names.index(c) for c in LEG_COORDINATES]
            measured = ~trial.unobserved
            rows[fit] = (compare_with_opensim_id(trial, mass), float(np.sqrt(np.mean(trial.qdd[measured][:, legs] ** 2))), trial.metrics)
    first = next(iter(rows.values()))[0]
    print(f"walk, {first.frames} frames inside OpenSim's ID; RMS difference of the leg joint torques from OpenSim's ID")
    print(f"converged weights {CONVERGED_WEIGHTS}; band weights {BAND_WEIGHTS}")
    print("| fit | RMS difference (N·m/kg) | leg accelerations RMS, measured frames (rad/s²) | marker RMS (cm) | linear residual RMS (N) | angular residual RMS (N·m) |")
    print("| --- | ---: | ---: | ---: | ---: | ---: |")
    for fit, (cmp, acc, m) in rows.items():
        print(f"| {fit} | {cmp.rms_difference:.3f} | {acc:.0f} | {100 * m['marker_rms_m']:.2f} | {m['linear_residual_rms_N']:.1f} | {m['angular_residual_rms_Nm']:.1f} |")
    print()
    print("| coordinate | " + " | ".join(f"{fit}: RMS difference / our RMS (N·m)" for fit in rows) + " | OpenSim's RMS (N·m) |")
    print("| --- |" + " ---: |" * (len(rows) + 1))
    for c in LEG_COORDINATES:
        per = [cmp.per_coordinate[c] for cmp, _, _ in rows.values()]
        print(f"| {c} | " + " | ".join(f"{p[0]:.1f} / {p[1]:.1f}" for p in per) + f" | {per[0][2]:.1f} |")


if __name__ == "__main__":
    main()
