"""``addb convert FILE.b3d --out SUBJECT_DIR``: an AddBiomechanics binary subject -> a subject folder.

The folder is one ``addb process`` solves (:func:`solver.io.b3d_convert.b3d_to_subject`);
the file's missing-GRF labels become the subject's review record (``annotations.json``,
provenance ``imported``): frames with a reason other than ``notMissingGRF`` are flagged
``unmeasured_force``, and each run of one reason carries a note naming it.

The record holds the flags on the frames the review app shows and edits, the trial's
processed frames (100 Hz over the span the markers and the plates share,
:func:`addb_viewer.review_masks.processed_frames`), put there from the file's frames by the
one resampling rule (:func:`solver.masks.resample_mask`). Until 2026-11-24 they were stored
on the file's frames: for a file at another rate than 100 Hz the app then read them, and
wrote the reviewer's own flags, on the wrong frames. A trial without force plates keeps the
file's frames (it has no processed frames to flag).

A conversion over an earlier one (``--force``) replaces what the earlier conversion imported,
not the reviewers' work: the imported flags and notes (provenance ``imported``) are those of
the new file, and the flags and notes a reviewer made are kept, also on trials the new file
no longer has. Until 2026-11-30 the file's labels were written over every flag of the trial
(a reviewer's flags cleared) and its notes added again beside the earlier ones.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from addb_viewer.commands import output_folder


def write_review_record(converted: Any, *, reviewer: str = "addb convert") -> Path:
    """Store a converted subject's missing-GRF labels as its review record.

    What an earlier conversion imported into the record is replaced (for the trials of
    ``converted``, and cleared for the trial folders it removed); the flags and notes of
    other provenance (the reviewers') are kept, a reviewer's flag taking precedence over the
    file's label on the same frame.

    Parameters
    ----------
    converted
        A :class:`solver.io.b3d_convert.ConvertedSubject`.
    reviewer
        Author recorded on the edits.

    Returns
    -------
    Path
        The review record (where :mod:`addb_viewer.locations` says the subject's record lives).

    Raises
    ------
    annotations.AnnotationError
        A flag or activity of the record lies past the end of a trial of the new file (the
        record does not belong to these trials).
    """
    import numpy as np

    from addb_viewer.locations import annotations_path, default_output_dir
    from addb_viewer.review_masks import processed_frames
    from annotations import AnnotationStore
    from solver.io.subject import load_subject, load_trial
    from solver.masks import resample_mask, true_runs
    from solver.sampling import frame_rate

    subject = load_subject(converted.path)
    path = annotations_path(converted.path, default_output_dir(converted.path))
    with AnnotationStore.open(path, reviewer=reviewer) as store:
        for t in converted.trials:
            reasons = np.asarray(t.missing_grf)
            file_time = np.asarray(load_trial(subject.trial(t.name)).markers.time)  # the file's frames, as written
            time = processed_frames(subject, t.name)
            if time is None:  # no dynamics: the file's own frames
                time = file_time
            rate = frame_rate(time, default=t.rate_hz)
            store.set_trial_info(t.name, n_frames=int(time.size), rate_hz=rate)
            missing = resample_mask(reasons != "notMissingGRF", file_time, time)
            _drop_imported(store, t.name)
            own = store.mask(t.name, int(time.size))  # what is left: the reviewers' flags
            # the reviewers' flags keep their foot and author; the file's labels fill the rest
            store.set_mask(t.name, missing | own, kind="unmeasured_force", source="imported", overwrite=False)
            for reason in sorted(set(t.missing_grf) - {"notMissingGRF"}):
                for start, stop in true_runs(resample_mask(reasons == reason, file_time, time)):
                    store.add_note(t.name, f"{IMPORTED_NOTE} ({reason})", start=start, stop=stop, source="imported")
        for name in converted.removed:  # trials the new file lacks: the earlier import goes with their folders
            _drop_imported(store, name)
    return path


#: Start of the text of the notes a conversion writes, one per run of one missing-GRF reason.
IMPORTED_NOTE = "AddBiomechanics: missing GRF"


def _drop_imported(store: Any, trial: str) -> None:
    """Clear what an earlier conversion imported into ``trial`` of the review record
    ``store``: its ``unmeasured_force`` flags of provenance ``imported`` and its notes
    (provenance ``imported``, text :data:`IMPORTED_NOTE`); the reviewers' flags and notes stay."""
    imported = [r for r in store.flag_runs(trial) if r.provenance.source == "imported"]
    if imported:
        store.set_unmeasured(trial, [f for r in imported for f in range(r.start, r.stop)], False, source="imported")
    for note in store.notes(trial):
        if note.provenance.source == "imported" and note.text.startswith(IMPORTED_NOTE):
            store.remove_note(trial, note.id)


def run(args: argparse.Namespace) -> int:
    """``addb convert FILE.b3d --out SUBJECT_DIR``: the .b3d file as a subject folder, its missing-
    GRF labels as the folder's review record; prints each trial's frames and labelled
    frames.

    Returns
    -------
    The exit code: 0 when the folder and record were written.

    Bad input raises, as in every subcommand (:mod:`addb_viewer.commands`).
    """
    from solver.errors import SubjectFolderError
    from solver.io.b3d_convert import b3d_to_subject
    from solver.io.subject import SUBJECT_JSON

    if not args.force and (Path(args.out) / SUBJECT_JSON).exists():
        raise SubjectFolderError(
            f"exists and already holds a subject ({SUBJECT_JSON}); add --force to write the converted subject "
            "over it, or give a new folder as --out",
            path=args.out,
        )
    converted = b3d_to_subject(args.file, args.out, pass_index=args.pass_index, overwrite=args.force)
    record = write_review_record(converted)
    for t in converted.trials:
        n_missing = int(t.missing_mask.sum())
        print(f"  {t.name}: {t.n_frames} frames at {t.rate_hz:g} Hz, {n_missing} frames with missing GRF")
    if converted.removed:
        print(f"  removed the trial folders of the earlier conversion that this file does not have: {', '.join(converted.removed)}")
    if converted.kept:
        print(
            f"  kept trial folders of the earlier conversion that this file does not have, as they hold other files "
            f"(addb process solves them with this subject; remove them if they do not belong to it): {', '.join(converted.kept)}"
        )
    kept = _reviewers_flags(record)
    if kept:
        listed = ", ".join(f"{trial} {n}" for trial, n in kept.items())
        print(f"  kept the reviewers' own flags and notes in the review record (flagged frames: {listed})")
    print(f"wrote {converted.path} (review record {record})")
    print(f"next: addb process {converted.path} --out OUT --annotations {record}")
    return 0


def _reviewers_flags(record: Path) -> dict[str, int]:
    """Trial -> frames flagged in the review record ``record`` by a reviewer (provenance
    other than ``imported``), for the trials that have any."""
    from annotations import AnnotationStore

    counts: dict[str, int] = {}
    with AnnotationStore.open(record, reviewer="addb convert") as store:
        for trial in store.trials():
            n = sum(r.stop - r.start for r in store.flag_runs(trial) if r.provenance.source != "imported")
            if n:
                counts[trial] = n
    return counts


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``convert`` subcommand's parser to ``sub`` (its ``handler``: :func:`run`)."""
    p = sub.add_parser(
        "convert",
        help="convert an AddBiomechanics .b3d file to a subject folder that addb process solves",
        description=(
            "Write the .b3d file's markers (markers.trc), raw force plates (grf.mot), subject (_subject.json) "
            "and embedded model (unscaled_generic.osim) as an AddBiomechanics subject folder, and its "
            "missing-GRF labels as the subject's review record (provenance: imported)."
        ),
    )
    p.add_argument("file", help="the .b3d file")
    p.add_argument("--out", required=True, type=output_folder, help="subject folder to write")
    p.add_argument("--pass", dest="pass_index", type=int, default=0, help="processing pass whose model to use (default 0)")
    p.add_argument(
        "--force",
        action="store_true",
        help=(
            "write over the subject already in --out (its model, _subject.json and the file's trials; trial folders an "
            "earlier conversion wrote that this file does not have are removed, other trial folders are kept; in the "
            "review record the file's labels replace the earlier conversion's, and the reviewers' flags and notes are kept)"
        ),
    )
    p.set_defaults(handler=run)
