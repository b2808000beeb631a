"""End-to-end ``addb process`` timing on the shared subjects (run on demand).

    .venv/bin/python tests/benchmarks/bench_process.py [--repeat N] [--src DIR] [SUBJECT ...]

Runs the command in a fresh process per subject (as a user would), ``--repeat`` times each
(default 3; the table shows the median and the range of the wall times), and prints the
frames processed (every trial's frames, as in the trials' results.json), frames per
wall-clock second, the per-stage times of the median run from subject.json / results.json
and the quality metrics. ``--src DIR`` runs another source tree's ``solver`` package (e.g.
an export of an earlier commit) with this venv, for before/after figures on one machine.
Target (issue): 200 frames per core-second.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SUBJECTS = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "subjects"


def _run(name: str, out: Path, src: str | None) -> float:
    env = dict(os.environ)
    cmd = [str(Path(sys.executable).parent / "addb"), "process", str(SUBJECTS / name), "--out", str(out)]
    cwd = None
    if src:  # the other tree's `solver` first on the path; run outside the repo so '' does not shadow it
        env["PYTHONPATH"] = os.pathsep.join([src, env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
        cwd = tempfile.gettempdir()
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True, env=env, cwd=cwd)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("subjects", nargs="*", default=["rajagopal2016_walk", "rajagopal2016_run", "opencap_uhlrich2023"])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--src", default=None, help="source tree whose solver package to run")
    args = ap.parse_args()
    print(
        "| subject | frames | wall (s): median [min-max] | frames/s | kinematics (s) | dynamics (s): preprocess / CoM fit / fit / ID "
        "| trial: measured frames, marker RMS (cm), linear residual (N, BW), angular residual (N·m, BW·h) |"
    )
    print("| --- | ---: | ---: | ---: | ---: | --- | --- |")
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.subjects:
            walls = []
            for i in range(args.repeat):
                walls.append((_run(name, Path(tmp) / f"{name}_{i}", args.src), i))
            wall, i_med = sorted(walls)[len(walls) // 2]
            out = Path(tmp) / f"{name}_{i_med}"
            subj = json.loads((out / "subject.json").read_text())
            dyn = subj.get("dynamics_seconds") or {}
            trials, frames = [], 0
            for res in sorted(out.glob("*/results.json")):
                r = json.loads(res.read_text())
                frames += int(r.get("n_frames", 0))
                if "linear_residual_rms_N" in r:
                    trials.append(
                        f"{res.parent.name}: {r['n_observed_frames']}/{r['n_frames']}, {r['marker_rms_m'] * 100:.2f}, "
                        f"{r['linear_residual_rms_N']:.1f} ({r['linear_residual_rms_BW']:.3f}), "
                        f"{r['angular_residual_rms_Nm']:.1f} ({r['angular_residual_rms_BWh']:.3f})"
                    )
            stages = subj["stage_seconds"]
            dyn_s = " / ".join(f"{dyn.get(k, 0):.1f}" for k in ("preprocess", "com_fit", "dynamics_fit", "inverse_dynamics"))
            ws = [w for w, _ in walls]
            print(
                f"| {name} | {frames} | {statistics.median(ws):.1f} [{min(ws):.1f}-{max(ws):.1f}] | {frames / wall:.0f} "
                f"| {stages['kinematics']:.1f} | {dyn_s} | {'; '.join(trials)} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
