"""The converged dynamics fit's weights: accuracy on every subject, and the walk's joint
torques against OpenSim's ID, for a grid of weights (run on demand).

    .venv/bin/python tests/benchmarks/bench_converged_weights.py [SUBJECT ...]

For each subject (default: the Rajagopal walk and run and OpenCap's subject of
../shared/data/subjects, and the Camargo circuit assembled by
``scripts/make_example_subject.py camargo2021_levelground``) one
``process_subject`` in this process per fit: ``--fit band`` (``FitSettings()``), the default
(:func:`solver.dynamics.fit.converged_fit`, weights :data:`~solver.dynamics.fit.CONVERGED_WEIGHTS`)
and :func:`converged_fit` with other sigmas of the acceleration prior (rad/s²) and of the
residual forces and moments (N, N·m). Prints one Markdown row per trial with force plates and
fit: wall time of the whole ``process_subject`` (s), measured frames, marker RMS (cm, three
decimals), linear and angular residual RMS; on the walk also the RMS difference of the leg
joint torques from ``../shared/oracles/opensim_id_walk.sto`` (N·m/kg,
:mod:`tests.dynamics.opensim_torques`).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

from solver.dynamics.fit import CONVERGED_WEIGHTS, FitSettings, converged_fit
from solver.dynamics.stage import DynamicsOptions
from solver.io.subject import load_subject
from solver.pipeline import ProcessOptions, process_subject
from solver.results import load_processed
from tests.benchmarks.example_subjects import subject_folder
from tests.dynamics.opensim_torques import ORACLE_ID, compare_with_opensim_id

#: (accel_sigma, force_sigma = moment_sigma) of the converged fits compared with the default.
GRID = ((500.0, 2.0), (150.0, 2.0), (100.0, 2.0), (200.0, 4.0), (170.0, 4.0), (100.0, 4.0), (100.0, 5.0))


def fits() -> dict[str, FitSettings]:
    """Label -> settings: band, the default, then :data:`GRID`."""
    out = {"band": FitSettings(), "default (converged, a={accel_sigma:g}, f=m={force_sigma:g})".format(**CONVERGED_WEIGHTS): converged_fit()}
    for a, f in GRID:
        out[f"converged, a={a:g}, f=m={f:g}"] = converged_fit(accel_sigma=a, force_sigma=f, moment_sigma=f)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("subjects", nargs="*", default=["rajagopal2016_walk", "rajagopal2016_run", "opencap_uhlrich2023", "camargo2021_levelground"])
    args = ap.parse_args()
    print("a: acceleration prior sigma (rad/s²); f, m: residual force and moment sigmas (N, N·m)")
    print("| subject / trial | fit | wall (s) | measured frames | marker RMS (cm) | linear residual RMS (N) | angular residual RMS (N·m) | leg torques from OpenSim's ID (N·m/kg) |")
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.subjects:
            subject = subject_folder(name, Path(tmp))
            for i, (label, fit) in enumerate(fits().items()):
                out = Path(tmp) / f"{name}_{i}"
                t0 = time.perf_counter()
                process_subject(subject, out, options=ProcessOptions(dynamics=DynamicsOptions(fit=fit)))
                wall = time.perf_counter() - t0
                for r in sorted(out.glob("*/results.json")):
                    m = json.loads(r.read_text())
                    if m.get("linear_residual_rms_N") is None:
                        continue
                    torque = ""
                    if name == "rajagopal2016_walk" and r.parent.name == "walk" and ORACLE_ID.is_file():
                        torque = f"{compare_with_opensim_id(load_processed(out, 'walk'), load_subject(subject).mass_kg).rms_difference:.3f}"
                    print(
                        f"| {name} / {r.parent.name} | {label} | {wall:.1f} | {m['n_observed_frames']} | {100 * m['marker_rms_m']:.3f} "
                        f"| {m['linear_residual_rms_N']:.1f} | {m['angular_residual_rms_Nm']:.1f} | {torque} |",
                        flush=True,
                    )


if __name__ == "__main__":
    main()
