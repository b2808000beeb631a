"""``addb process SUBJECT_DIR --out OUT``: kinematics and dynamics, OpenSim-ready outputs."""

from __future__ import annotations

import argparse


def _masks(path: str, subject_dir: str) -> dict:
    """Unmeasured-force masks from an annotations file (ours) or an AddBiomechanics review."""
    import json
    from pathlib import Path

    import numpy as np

    from solver.io.subject import load_subject, load_trial

    p = Path(path)
    data = json.loads(p.read_text())
    if isinstance(data, dict) and "missing_grf_data" in data:  # AddBiomechanics review.json
        subject = load_subject(subject_dir)
        if len(subject.trials) != 1:
            raise SystemExit("addb process: an AddBiomechanics review.json covers one trial; use --trial with a subject of one trial")
        return {subject.trials[0].name: np.array(data["missing_grf_data"], dtype=bool)}
    from annotations import AnnotationStore

    subject = load_subject(subject_dir)
    masks = {}
    with AnnotationStore.open(p, reviewer="addb process") as store:
        for trial in subject.trials:
            if trial.name in store.trials():
                n = load_trial(trial).markers.n_frames
                masks[trial.name] = store.mask(trial.name, n, kind="unmeasured_force")
    return masks


def run(args: argparse.Namespace) -> int:
    from addb_viewer.progress import ProgressBar, table
    from solver.pipeline import ProcessOptions, process_subject

    opts = ProcessOptions(trials=tuple(args.trial) if args.trial else None)
    unmeasured = _masks(args.annotations, args.subject) if args.annotations else None
    result = process_subject(args.subject, args.out, options=opts, unmeasured=unmeasured, progress=ProgressBar())
    rows = []
    for t in result.kinematics.kinematics.trials:
        if opts.trials and t.name not in opts.trials:
            continue
        d = None
        if result.dynamics is not None:
            d = next((x for x in result.dynamics.trials if x.name == t.name), None)
        if d is None:
            rows.append([t.name, str(t.q.shape[0]), f"{t.marker_rms * 100:.2f}", "-", "-", "-", "-"])
        else:
            m = d.metrics
            ang = m["angular_residual_rms_BWh"]
            rows.append([
                t.name, f"{m['n_observed_frames']}/{d.time.size}", f"{m['marker_rms_m'] * 100:.2f}",
                f"{m['linear_residual_rms_N']:.1f} ({m['linear_residual_rms_BW']:.3f})",
                f"{m['angular_residual_rms_Nm']:.1f} ({ang:.3f})" if ang is not None else f"{m['angular_residual_rms_Nm']:.1f}",
                "yes" if m["hicks_linear_ok"] else "no", "yes" if m["hicks_angular_ok"] else ("no" if m["hicks_angular_ok"] is not None else "-"),
            ])
    print(table(rows, ["trial", "frames (measured/all)", "marker RMS (cm)", "linear residual N (BW)", "angular residual N·m (BW·h)", "Hicks lin", "Hicks ang"]))
    if result.dynamics is not None:
        print(f"fitted mass: {result.dynamics.mass_kg:.2f} kg")
    print(f"wrote {result.out_dir}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("process", help="scaling, inverse kinematics and the dynamics fit; writes OpenSim files")
    p.add_argument("subject", help="AddBiomechanics subject folder")
    p.add_argument("--out", required=True, help="output folder (replaced atomically)")
    p.add_argument("--trial", action="append", help="write only this trial (repeatable)")
    p.add_argument("--annotations", help="annotations file (frames with unmeasured force) or an AddBiomechanics review.json")
    p.set_defaults(handler=run)
