"""End-to-end ``addb process`` timing on the shared subjects (run on demand).

    .venv/bin/python tests/benchmarks/bench_process.py [SUBJECT ...]

Runs the command in a fresh process per subject (as a user would) and prints the wall time,
the per-stage times from subject.json / results.json and the quality metrics.
Target (rajagopal2016_walk): under 60 s on this 2-core machine.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SUBJECTS = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "subjects"


def main() -> None:
    names = sys.argv[1:] or ["rajagopal2016_walk", "rajagopal2016_run", "opencap_uhlrich2023"]
    addb = Path(sys.executable).parent / "addb"
    print("| subject | wall (s) | kinematics (s) | dynamics (s): preprocess / CoM fit / fit / ID | trial: measured frames, marker RMS (cm), linear residual (N, BW), angular residual (N·m, BW·h) |")
    print("| --- | ---: | ---: | --- | --- |")
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            out = Path(tmp) / name
            t0 = time.perf_counter()
            subprocess.run([str(addb), "process", str(SUBJECTS / name), "--out", str(out)], check=True, capture_output=True)
            wall = time.perf_counter() - t0
            subj = json.loads((out / "subject.json").read_text())
            dyn = subj.get("dynamics_seconds") or {}
            trials = []
            for res in sorted(out.glob("*/results.json")):
                r = json.loads(res.read_text())
                if "linear_residual_rms_N" in r:
                    trials.append(
                        f"{res.parent.name}: {r['n_observed_frames']}/{r['n_frames']}, {r['marker_rms_m'] * 100:.2f}, "
                        f"{r['linear_residual_rms_N']:.1f} ({r['linear_residual_rms_BW']:.3f}), "
                        f"{r['angular_residual_rms_Nm']:.1f} ({r['angular_residual_rms_BWh']:.3f})"
                    )
            stages = subj["stage_seconds"]
            dyn_s = " / ".join(f"{dyn.get(k, 0):.1f}" for k in ("preprocess", "com_fit", "dynamics_fit", "inverse_dynamics"))
            print(f"| {name} | {wall:.1f} | {stages['kinematics']:.1f} | {dyn_s} | {'; '.join(trials)} |")


if __name__ == "__main__":
    main()
