"""``addb record SUBJECT_DIR --trial NAME -o FILE.rrd``: a Rerun recording, no viewer."""

from __future__ import annotations

import argparse
import os
from collections.abc import Sequence
from pathlib import Path


def refuse_output_folder(subject: str | os.PathLike[str], out: str | os.PathLike[str] | None, suggest: Sequence[str]) -> None:
    """Refuse an output folder of addb given where a recording command expects the subject folder.

    ``addb record`` and ``addb export`` (mcap, rrd) read the subject folder (review record,
    bone meshes) and process it first when its output folder holds no processed trial. An
    output folder (what ``addb process --out`` wrote: one of
    :data:`solver.outputs.OUTPUT_MARKERS`, no ``_subject.json``) in its place was reported
    as a subject folder without ``_subject.json``. An output folder that is also given as
    ``--out`` (or whose default output folder holds processed trials) is read as before.

    Parameters
    ----------
    subject
        The command's subject argument.
    out
        Its ``--out``; None: the subject's default output folder
        (:func:`addb_viewer.locations.default_output_dir`).
    suggest
        The command line to suggest, as arguments, with ``SUBJECT_DIR`` where the subject
        folder goes and without ``--out`` (:func:`solver.io.subject.output_folder_note` adds it).

    Raises
    ------
    SubjectFolderError
        ``subject`` is an output folder of addb and the command would have to process it;
        the message names the subject folder when it is the output's parent
        (``<subject>/addb_out``).
    """
    from addb_viewer.locations import default_output_dir
    from solver.errors import SubjectFolderError
    from solver.io.subject import output_folder_note
    from solver.results import processed_trials

    folder = Path(subject)
    if not folder.is_dir():
        return
    note = output_folder_note(folder, suggest)
    if note is None or processed_trials(out if out is not None else default_output_dir(folder)):
        return
    raise SubjectFolderError(note, path=folder)


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

    refuse_output_folder(args.subject, args.out, ["record", "SUBJECT_DIR", "--trial", args.trial, "-o", args.output])
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
