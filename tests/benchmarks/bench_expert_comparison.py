"""Our automatic scaling + IK against an expert's hand scaling + IK (run on demand).

    .venv/bin/python tests/benchmarks/bench_expert_comparison.py [--markdown FILE]

For each folder of shared/data/expert_comparison (Expert1, Expert2): we scale
``generic.osim`` to all the folder's trials (static included) and solve IK; the expert's
marker RMS is ``hand_scaled.osim`` posed with the expert's ``.mot``; both are evaluated
with our forward kinematics on the same markers (present in the trial and in both
models) over the frames of the expert's motion. Prints a table, optionally writes it.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from solver.io.mot import read_coordinates
from solver.io.trc import read_trc
from solver.kinematics.stage import run_kinematics
from solver.model.osim import read_osim
from solver.model.skeleton import Skeleton

ROOT = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "expert_comparison"


def expert_rms(folder: Path) -> list[dict]:
    """Run both methods on one expert folder; one row per trial with an expert motion."""
    generic = read_osim(folder / "generic.osim")
    expert_model = read_osim(folder / "hand_scaled.osim")
    expert_sk = Skeleton(expert_model)
    rotational = [c.name for c in expert_model.coordinates if c.motion_type == "rotational"]
    trcs = sorted(folder.glob("*.trc"))
    trials = [(p.stem, read_trc(p)) for p in trcs]
    t0 = time.perf_counter()
    ours = run_kinematics(generic, trials)
    seconds = time.perf_counter() - t0
    rows = []
    for name, markers in trials:
        mot = folder / f"{name}.mot"
        if not mot.exists():
            continue
        table = read_coordinates(mot, rotational=rotational)
        q = np.zeros((table.time.size, expert_sk.n))
        for j, c in enumerate(expert_sk.coordinate_names):
            q[:, j] = table.column(c) if c in table.column_names else expert_sk.defaults[j]
        q = expert_sk.cmap.complete(q)
        frames = np.array([int(np.argmin(np.abs(markers.time - t))) for t in table.time])
        ours_trial = ours.trial(name)
        common = [n for n in ours_trial.marker_names if n in expert_sk.marker_names]
        y = markers.positions[frames][:, [markers.names.index(n) for n in common]]
        exp_pos = expert_sk.marker_positions(q, expert_sk.marker_index(common))
        our_pos = ours_trial.modeled[frames][:, [ours_trial.marker_names.index(n) for n in common]]
        e_exp = np.linalg.norm(exp_pos - y, axis=2)
        e_our = np.linalg.norm(our_pos - y, axis=2)
        rows.append(
            {
                "expert": folder.name,
                "trial": name,
                "frames": int(frames.size),
                "markers": len(common),
                "expert_rms_cm": float(np.sqrt(np.nanmean(e_exp**2)) * 100),
                "ours_rms_cm": float(np.sqrt(np.nanmean(e_our**2)) * 100),
            }
        )
    for r in rows:
        r["seconds_all_trials"] = seconds
    return rows


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--markdown", type=Path, help="write the table as Markdown to this file")
    args = parser.parse_args()
    rows = []
    for folder in sorted(p for p in ROOT.iterdir() if p.is_dir()):
        rows += expert_rms(folder)
    lines = [
        "| expert | trial | frames | markers | expert RMS (cm) | ours RMS (cm) | ours lower |",
        "| --- | --- | ---: | ---: | ---: | ---: | --- |",
    ]
    for r in rows:
        better = "yes" if r["ours_rms_cm"] < r["expert_rms_cm"] else "NO"
        lines.append(
            f"| {r['expert']} | {r['trial']} | {r['frames']} | {r['markers']} | "
            f"{r['expert_rms_cm']:.2f} | {r['ours_rms_cm']:.2f} | {better} |"
        )
    n_better = sum(r["ours_rms_cm"] < r["expert_rms_cm"] for r in rows)
    lines.append("")
    lines.append(f"Ours lower on {n_better} of {len(rows)} trials.")
    for folder in sorted({r["expert"] for r in rows}):
        secs = next(r["seconds_all_trials"] for r in rows if r["expert"] == folder)
        lines.append(f"{folder}: scaling + IK of all its trials took {secs:.1f} s.")
    text = "\n".join(lines)
    print(text)
    if args.markdown:
        args.markdown.write_text(text + "\n")


if __name__ == "__main__":
    main()
