"""``addb kinematics SUBJECT_DIR --out OUT``: scaling and inverse kinematics only
(``--model SCALED.osim``: inverse kinematics alone, with a model already scaled)."""

from __future__ import annotations

import argparse

from addb_viewer.commands import output_folder


def run(args: argparse.Namespace) -> int:
    """``addb kinematics SUBJECT_DIR --out OUT``: scaling and inverse kinematics (``--model``:
    inverse kinematics alone with a scaled model); prints each trial's marker RMS error.

    Returns
    -------
    The exit code: 0 when the outputs were written.

    Bad input raises, as in every subcommand (:mod:`addb_viewer.commands`).
    """
    from addb_viewer.progress import ProgressBar, table
    from solver.dataset.lock import subject_output_lock
    from solver.pipeline import ProcessOptions, process_kinematics

    opts = ProcessOptions(trials=tuple(args.trial) if args.trial else None)
    with subject_output_lock(args.out):  # not while a dataset run writes the tree --out lies in
        result = process_kinematics(args.subject, args.out, options=opts, progress=ProgressBar(), scaled_model=args.model)
    rows = [
        [t.name, str(t.q.shape[0]), f"{t.marker_rms * 100:.2f}", f"{t.marker_max * 100:.2f}", t.worst_marker]
        for t in result.kinematics.trials
        if not opts.trials or t.name in opts.trials
    ]
    print(table(rows, ["trial", "frames", "marker RMS (cm)", "max (cm)", "worst marker"]))
    print(f"wrote {args.out}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``kinematics`` subcommand's parser to ``sub`` (its ``handler``: :func:`run`)."""
    p = sub.add_parser("kinematics", help="scale the model and solve inverse kinematics for a subject")
    p.add_argument("subject", help="AddBiomechanics subject folder")
    p.add_argument("--out", required=True, type=output_folder, help="output folder: new, empty, or an earlier output of addb (replaced atomically)")
    p.add_argument("--trial", action="append", help="write only this trial (repeatable); all trials are used for scaling")
    p.add_argument(
        "--model",
        help="an .osim already scaled to the subject (e.g. the <subject>_scaled.osim of an earlier run): "
        "skip scaling and solve inverse kinematics only, as OpenSim's IK tool does (with --trial, only those trials are read)",
    )
    p.set_defaults(handler=run)
