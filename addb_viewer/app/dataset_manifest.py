"""A Reprocess in the review app keeps a dataset run's manifest current (no viser).

``addb process DATASET_DIR`` skips a subject whose ``manifest.json`` key (its input files, the
code, the settings and a digest of the review record's flags:
:mod:`solver.dataset.manifest`) still matches. The review app's Reprocess rewrites the
subject's trials with the reviewer's flags, but not the manifest, so the next dataset run (and
the workbench's "Process changed subjects") processed the subject again for flags it had just
been fitted with. After a Reprocess this module records, in the manifest, the flags the run
took and the trials' new summary rows (the figures of ``dataset_summary.json`` and the
queue) — only when nothing else of the key changed since the dataset run (inputs, code,
settings); otherwise the manifest is left as it is and the dataset run processes the subject.

A Reprocess fits the dynamics again from the kinematics the dataset run wrote (the same
inputs give the same kinematics) and agrees with a full run within the fit's convergence
tolerance (tests/dynamics: the Reprocess test of issue 29), so the output stands for the run
the manifest describes.
"""

from __future__ import annotations

import os
from typing import Any

from solver.dataset.manifest import (
    PROCESSED_STATUSES,
    KeyUnreadable,
    read_manifest,
    subject_key_now,
    subject_status,
    write_manifest,
)
from solver.dataset.summary import subject_rows


def _without_review(key: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in key.items() if k != "annotations"}


def mark_reprocessed(subject_dir: str | os.PathLike[str], out_dir: str | os.PathLike[str], review: str | None) -> bool:
    """Record in ``out_dir``'s dataset manifest that its output was made with the review
    flags whose digest is ``review`` (:func:`addb_viewer.review_masks.review_digest`, taken
    when the Reprocess started), with the trials' summary rows read again from the output.

    Returns
    -------
    bool
        Whether the manifest was rewritten: False without a manifest (not a dataset run's
        output), for a failed subject, or when the subject's inputs, the code or the settings
        changed since the run (the dataset run must process it again).
    """
    stored = read_manifest(out_dir)
    if stored is None or stored.get("status") not in PROCESSED_STATUSES:
        return False
    key = stored["key"]
    try:
        now = subject_key_now(subject_dir, out_dir, key.get("settings") or {}, lambda _subject, _out: review)
    except KeyUnreadable:  # a file of the subject cannot be read now: the dataset run names it
        return False
    if _without_review(now) != _without_review(key):
        return False
    rows = subject_rows(out_dir)
    masses = [r.get("mass_kg") for r in rows if r.get("status") == "ok"]
    manifest = {
        **stored,
        "key": now,
        "trials": rows,
        "status": subject_status(rows),
        "fitted_mass_kg": masses[0] if masses else stored.get("fitted_mass_kg"),
        "reprocessed_in_review_app": True,
    }
    write_manifest(out_dir, manifest)
    return True
