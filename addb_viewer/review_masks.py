"""The reviewer's unmeasured-force flags of a subject, as the solver takes them.

Used by ``addb process`` on a dataset (each subject's review record, where ``addb view``
keeps it: :func:`addb_viewer.locations.annotations_path`); :func:`review_digest` enters
each subject's manifest so that a changed review reprocesses the subject.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from addb_viewer.locations import annotations_path


def review_record(subject_dir: str, out_dir: str) -> Path | None:
    """The subject's review record file, or None when it has none."""
    path = annotations_path(subject_dir, out_dir)
    return path if path.is_file() else None


def review_digest(subject_dir: str, out_dir: str) -> str | None:
    """SHA-256 of the subject's unmeasured-force flags (trial -> frame runs and feet), or
    None when it has no record or no flag; what a dataset run's manifest keys on.

    Raises
    ------
    annotations.AnnotationError
        The record is damaged (names the file).
    """
    import hashlib
    import json

    from annotations import AnnotationStore

    path = review_record(subject_dir, out_dir)
    if path is None:
        return None
    with AnnotationStore.open(path, reviewer="addb process") as store:
        flags = {
            name: [[r.start, r.stop, r.foot] for r in store.review(name).unmeasured_force] for name in store.trials()
        }
    flags = {k: v for k, v in flags.items() if v}
    return hashlib.sha256(json.dumps(flags, sort_keys=True).encode()).hexdigest() if flags else None


def subject_masks(subject_dir: str, out_dir: str) -> dict[str, np.ndarray] | None:
    """Trial name -> ``(T,)`` bool mask of frames flagged with unmeasured force.

    ``T`` is the trial's frame count as the review record stores it, else as its marker
    file has it. Only trials with flags are listed; None when the subject has no record.

    Raises
    ------
    annotations.AnnotationError
        The record is damaged or does not fit the trial (names the file and trial).
    """
    from annotations import AnnotationStore
    from solver.io.subject import load_subject, load_trial

    path = review_record(subject_dir, out_dir)
    if path is None:
        return None
    subject = load_subject(subject_dir)
    masks: dict[str, np.ndarray] = {}
    with AnnotationStore.open(path, reviewer="addb process") as store:
        for name in store.trials():
            n = store.review(name).n_frames
            if not n:
                try:
                    n = load_trial(subject.trial(name)).markers.n_frames
                except KeyError:
                    continue  # a trial the subject no longer has
            mask = store.mask(name, n)
            if mask.any():
                masks[name] = mask
    return masks or None
