"""Rounds of the dynamics fit: what more rounds than the default would change (run on demand).

    .venv/bin/python tests/benchmarks/bench_fit_rounds.py [--rounds 4 6 8] [SUBJECT ...]

The dynamics fit alternates ``FitSettings.rounds`` rounds (default 4) of at most
``FitSettings.iterations`` Gauss-Newton steps of the coordinates with a linear solve of the
body mass factors, and stops early on a relative cost decrease under
``FitSettings.tolerance``. For each subject of ../shared/data/subjects (default: the
Rajagopal walk and run) and each round count, one
``process_subject(SUBJECT, OUT, options=ProcessOptions(dynamics=DynamicsOptions(fit=FitSettings(rounds=R))))``
in this process, into a temporary folder. Prints a Markdown table per trial with force
plates: wall time of the whole ``process_subject`` (s), the dynamics fit's own time (s),
measured frames, marker RMS (cm), linear residual RMS and mean (N) and angular residual
RMS (N·m), from the trial's results.json.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from solver.dynamics.fit import FitSettings
from solver.dynamics.stage import DynamicsOptions
from solver.pipeline import ProcessOptions, process_subject

SUBJECTS = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "subjects"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("subjects", nargs="*", default=["rajagopal2016_walk", "rajagopal2016_run"])
    ap.add_argument("--rounds", type=int, nargs="+", default=[4, 6, 8])
    args = ap.parse_args()
    print(
        "| subject / trial | rounds | wall (s) | dynamics fit (s) | measured frames | marker RMS (cm) "
        "| linear residual RMS (mean), N | angular residual RMS, N·m |"
    )
    print("| --- | ---: | ---: | ---: | ---: | ---: | --- | ---: |")
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.subjects:
            for rounds in args.rounds:
                out = Path(tmp) / f"{name}_{rounds}"
                options = ProcessOptions(dynamics=DynamicsOptions(fit=FitSettings(rounds=rounds)))
                t0 = time.perf_counter()
                process_subject(SUBJECTS / name, out, options=options)
                wall = time.perf_counter() - t0
                fit_s = (json.loads((out / "subject.json").read_text()).get("dynamics_seconds") or {}).get("dynamics_fit", float("nan"))
                for res in sorted(out.glob("*/results.json")):
                    r = json.loads(res.read_text())
                    if "linear_residual_rms_N" not in r:
                        continue
                    print(
                        f"| {name} / {res.parent.name} | {rounds} | {wall:.1f} | {fit_s:.1f} | {r['n_observed_frames']} "
                        f"| {r['marker_rms_m'] * 100:.3f} | {r['linear_residual_rms_N']:.2f} ({r['linear_residual_mean_N']:.2f}) "
                        f"| {r['angular_residual_rms_Nm']:.2f} |",
                        flush=True,
                    )


if __name__ == "__main__":
    main()
