"""``addb record SUBJECT_DIR --trial NAME -o FILE.rrd``: a Rerun recording, no viewer."""

from __future__ import annotations

import argparse


def run(args: argparse.Namespace) -> int:
    """``addb record SUBJECT_DIR --trial NAME -o FILE.rrd``: a Rerun recording of the trial, no
    viewer.

    Returns
    -------
    The exit code: 0 when the file was written.

    Bad input raises, as in every subcommand (:mod:`addb_viewer.commands`).
    """
    from addb_viewer.progress import ProgressBar
    from addb_viewer.recording.jobs import record_subject_trial

    path = record_subject_trial(
        args.subject,
        args.trial,
        args.output,
        fmt="rrd",
        out_dir=args.out,
        progress=ProgressBar(),
        geometry=args.geometry,
    )
    print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB); open it with: rerun {path}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``record`` subcommand's parser to ``sub`` (its ``handler``: :func:`run`)."""
    p = sub.add_parser(
        "record",
        help="write a Rerun recording (.rrd) of a processed trial: 3D scene, residuals, GRF, torques",
        description=(
            "Write a Rerun recording of one trial (markers, skeleton, GRF arrows, centre of mass, "
            "residuals, GRF, joint torques, marker RMS, flags; solver settings and review state) "
            "with a ready-made layout. The subject is processed first if it has no output yet."
        ),
    )
    p.add_argument("subject", help="AddBiomechanics subject folder")
    p.add_argument("--trial", required=True, help="trial name")
    p.add_argument("-o", "--output", required=True, help="the .rrd file to write")
    p.add_argument(
        "--out",
        help="processed output folder (default: <subject>/addb_out, or the user cache for read-only subjects)",
    )
    p.add_argument(
        "--geometry",
        metavar="DIR",
        help="folder of bone meshes (.vtp) to use when the subject has no Geometry folder "
        "(default: $ADDB_GEOMETRY, then the meshes bundled with addb)",
    )
    p.set_defaults(handler=run)
