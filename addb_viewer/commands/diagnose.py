"""``addb diagnose SUBJECT_DIR --trial NAME [--json] [--apply]``: why a trial's residuals remain.

The subject is processed first when the trial has no output yet (with the reviewer's
flags, as the app does). The reviewer's flags of unmeasured force are the frames the
diagnosis knows to be unmeasured; every other frame is evaluated. They come from one file
(:func:`addb_viewer.review_masks.masks_from_file`, the conversion the app and ``addb
process`` use): the subject's review record where ``addb view`` keeps it
(:func:`addb_viewer.locations.annotations_path`; none there: no flags), or the file given
with ``--annotations`` (a record or an AddBiomechanics ``review.json``), which then
replaces the subject's record: that one is not read. An ``--annotations`` path with no
such file is refused before anything runs
(:func:`addb_viewer.commands.process.review_file`). Writes ``OUT/<trial>/diagnosis.json``
(read by the review app) and prints a report, or the JSON object with ``--json``.
``--apply`` saves the chosen extension in ``<subject>/addb_extensions.json`` so that the
next ``addb process`` uses it; a read-only subject folder is refused with ``--apply``
before the diagnosis runs.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
from collections.abc import Iterator
from pathlib import Path


@contextlib.contextmanager
def each_warning_once() -> Iterator[None]:
    """Show each warning once for the whole command, however many fits repeat it.

    ``addb diagnose`` runs the dynamics stage several times on one trial: the processing
    (when the trial has no output yet), the judged fit (:mod:`solver.diagnose.judged_fit`),
    and the refits with and without the chosen cause (:mod:`solver.diagnose.refit`). Each
    run warns about the same data again (a fitted mass far from ``massKg``, a plate loaded
    with no centre of pressure: :mod:`solver.dynamics.stage`), and Python's once-per-place
    rule does not hold them back: the refits call the stage from another place, and their
    numbers differ a little (the fitted mass of each fit). Here a warning whose text differs
    from one already shown only in its numbers is not shown again.
    """
    import re
    import warnings

    shown: set[tuple[type, str]] = set()
    show = warnings.showwarning

    def once(message, category, filename, lineno, file=None, line=None) -> None:
        key = (category, re.sub(r"[-+]?\d+(\.\d+)?", "#", str(message)))
        if key not in shown:
            shown.add(key)
            show(message, category, filename, lineno, file, line)

    with warnings.catch_warnings():
        warnings.showwarning = once
        yield


def _results(out: Path, trial: str) -> dict:
    """``OUT/<trial>/results.json`` as a dict (empty when it cannot be read: the diagnosis
    then reads the output as it always does, and fails there with its own error)."""
    try:
        results = json.loads((out / trial / "results.json").read_text())
    except (OSError, ValueError):
        return {}
    return results if isinstance(results, dict) else {}


def _nothing_to_diagnose(out: Path, trial: str) -> str | None:
    """Why the processed trial ``OUT/<trial>`` has nothing to diagnose, or None: it was written
    with its kinematics only (its ``dynamics_error``: a trial the dynamics stage could not
    take, :func:`solver.pipeline.process_subject`), or no frame with measured force entered
    its fit (``n_observed_frames`` 0: plates that never carry force, or every frame flagged),
    so that it has no residuals to explain."""
    results = _results(out, trial)
    failed = results.get("dynamics_error")
    if isinstance(failed, dict):
        return (f"trial {trial!r} was processed without dynamics: {failed.get('message')} "
                f"({failed.get('path') or 'its recordings'}); nothing to diagnose (process the subject again once that "
                "is mended)")  # fmt: skip
    if results.get("n_observed_frames") == 0:
        frames = results.get("n_frames")
        return (f"trial {trial!r} has no frame with measured force in its fit (all {frames} frames left out: plates "
                "that never carry force, or every frame flagged), so no residuals to explain; nothing to diagnose")  # fmt: skip
    return None


def run(args: argparse.Namespace) -> int:
    """``addb diagnose SUBJECT_DIR --trial NAME``: diagnose the trial (processing the subject first
    when it has no output), print the report or its JSON, write
    ``OUT/<trial>/diagnosis.json``; with ``--apply`` save the chosen cause's extension.

    Returns
    -------
    The exit code: 0 when the diagnosis was written (whether or not a cause stands out).

    Bad input raises, as in every subcommand (:mod:`addb_viewer.commands`).
    """
    from addb_viewer.commands.process import review_file
    from addb_viewer.locations import annotations_path, default_output_dir
    from addb_viewer.progress import ProgressBar
    from addb_viewer.review_masks import masks_from_file
    from solver.corrections import FILE_NAME, save_extension
    from solver.diagnose.core import DiagnoseOptions, diagnose_trial
    from solver.diagnose.report import to_json, to_text, write_report
    from solver.errors import DiagnosisError, DynamicsError, SubjectFolderError
    from solver.io.subject import folder_is_writable, load_subject, load_trial
    from solver.results import processed_trials

    subject = Path(args.subject)
    if not subject.is_dir():
        raise SubjectFolderError("no such subject folder", path=subject)
    info = load_subject(subject)
    files = info.trial(args.trial)  # SubjectFolderError naming the trials
    if info.disable_dynamics or load_trial(files).forces is None:
        raise DiagnosisError(f"trial {args.trial!r} has no force plates (or dynamics are disabled): nothing to diagnose", path=subject)
    if args.apply and not folder_is_writable(subject):  # before the diagnosis, not after it
        raise SubjectFolderError(
            f"--apply saves the extension in the subject folder ({FILE_NAME}), which is read-only; copy the subject "
            "to a folder you can write to and apply there (or leave out --apply)",
            path=subject,
        )
    out = Path(args.out) if args.out else default_output_dir(subject)
    # --annotations replaces the subject's record (which is then not read) and must exist
    record = review_file(args.annotations) if args.annotations else annotations_path(subject, out)
    masks = masks_from_file(record, subject, reviewer="addb diagnose", trials=(args.trial,),
                            given=bool(args.annotations)) if record.is_file() else {}  # fmt: skip
    progress = ProgressBar(sys.stderr)
    with each_warning_once():
        if args.trial not in processed_trials(out):
            from addb_viewer.commands.process import with_kept_kinematics
            from solver.pipeline import process_subject

            try:
                process_subject(subject, out, unmeasured_force=masks or None, progress=lambda m, f: progress(m, 0.8 * f))
            except DynamicsError as exc:
                raise with_kept_kinematics(exc, out) from None
        why = _nothing_to_diagnose(out, args.trial)
        if why is not None:
            raise DiagnosisError(why, path=out / args.trial / "results.json")
        diag = diagnose_trial(
            subject,
            args.trial,
            out,
            unmeasured_force=masks.get(args.trial),
            subject_flags=masks,
            options=DiagnoseOptions(refit=not args.no_refit),
            progress=lambda m, f: progress(m, 0.8 + 0.2 * f),
        )
    report = to_json(diag)
    write_report(diag, out, args.trial)
    applied = None
    if args.apply:
        if diag.extension is None:
            print("addb diagnose: no cause stands out; nothing to apply", file=sys.stderr)
        else:
            applied = save_extension(subject, diag.extension)
            report["applied"] = str(applied)
    if args.json:
        print(json.dumps(report))
    else:
        print(to_text(diag))
        print(f"\nwrote {out / args.trial / 'diagnosis.json'}")
        if applied is not None:
            print(f"saved the extension in {applied}; the next `addb process` of this subject uses it")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``diagnose`` subcommand's parser to ``sub`` (its ``handler``: :func:`run`)."""
    p = sub.add_parser(
        "diagnose",
        help="explain a trial's remaining residuals: test candidate causes, name one, measure the gain",
        description=(
            "Show where a processed trial's residual forces and moments concentrate, fit each "
            "candidate cause (unmeasured force, body mass, force/motion time offset, plate force "
            "offset, plate force gain, plate position, plate registration, segment mass "
            "distribution, marker offset) on "
            "training frames and score it on held-out frames, name the cause that stands out (or "
            "none), refit with and without it and report the gain. The subject is processed first if needed."
        ),
    )
    p.add_argument("subject", help="AddBiomechanics subject folder")
    p.add_argument("--trial", required=True, help="trial name")
    p.add_argument("--json", action="store_true", help="print the diagnosis as one JSON object")
    p.add_argument(
        "--apply", action="store_true",
        help="save the chosen extension in SUBJECT/addb_extensions.json for the next `addb process` "
             "(the subject folder must be writable: checked before the diagnosis runs)",
    )  # fmt: skip
    p.add_argument(
        "--out",
        help="processed output folder (default: <subject>/addb_out, or the user cache for read-only subjects)",
    )
    p.add_argument(
        "--annotations",
        help="the reviewer's unmeasured-force flags from this file instead of the subject's record: a review "
             "record or an AddBiomechanics review.json; it must exist, and the subject's own record is then "
             "not read (default: the subject's record where addb view keeps it, no flags when there is none)",
    )  # fmt: skip
    p.add_argument("--no-refit", action="store_true", help="skip the refit (fixed-kinematics figures only)")
    p.set_defaults(handler=run)
