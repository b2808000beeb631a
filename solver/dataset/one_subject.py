"""A one-subject run into a dataset output tree leaves the manifest a dataset run would.

``addb process labA/s01 --out OUT/labA/s01`` replaces that subject's folder of a dataset
run's output tree (holding the tree's lock: :mod:`solver.dataset.lock`). Without a manifest
the next ``addb process DATASET_DIR --out OUT`` processed the subject again, though nothing
had changed. A whole run (every trial; no review file, or the subject's own review record,
the one a dataset run reads) writes the manifest a dataset run writes
(:func:`solver.dataset.task.run_subject`): its key is made the same way
(:func:`solver.dataset.manifest.subject_key_now` with the run's settings, and the digest of
the record's flags when the run applied it), so the dataset run skips the subject while its
files, addb's code, the fit and the review record are as they were, and processes it again
as soon as one of them differs (a review record with flags for it, too, after a run that
did not apply them).

A run of some trials (``--trial``), or with another review file, is not what a dataset run
does, so it leaves no manifest; a ``--trial`` run merges into the folder, where the earlier
run's manifest would otherwise still describe the whole output, so that manifest is removed
(:func:`forget_subject_run`).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from solver.dataset.manifest import (
    MANIFEST_NAME,
    KeyUnreadable,
    run_settings,
    subject_key_now,
    subject_status,
    write_manifest,
)
from solver.dataset.summary import subject_rows


def subject_run_key(
    subject_dir: str | Path,
    out_dir: str | Path,
    settings: dict[str, Any],
    review_digest: Callable[[str, str], str | None] | None = None,
) -> dict[str, Any] | None:
    """The manifest key of a whole one-subject run into ``out_dir`` with the dataset run
    ``settings`` (:attr:`solver.dataset.runner.DatasetOptions.settings`, e.g.
    ``{"fit": "band"}``), from the subject's files now (taken before the run, as a dataset
    run does: :func:`solver.dataset.manifest.subject_key_now`).

    ``review_digest`` is given when the run applies the subject's own review record, the
    one a dataset run reads (:func:`addb_viewer.review_masks.review_digest`); without it the
    key holds no review flags. Returns None when a file cannot be read or the record is
    damaged (the run then names it itself)."""
    try:
        return subject_key_now(subject_dir, out_dir, run_settings(settings), review_digest)
    except KeyUnreadable:
        return None


def record_subject_run(
    out_dir: str | Path,
    tree: str | Path,
    key: dict[str, Any],
    *,
    mass_kg: float,
    fitted_mass_kg: float | None,
    seconds: float,
    warnings: list[str],
) -> None:
    """Write the manifest of a whole one-subject run into ``out_dir``, a subject's folder
    of the output tree ``tree``, after the run has put its output in place.

    Parameters
    ----------
    out_dir
        The run's output folder (``OUT/labA/s01``).
    tree
        The output tree it lies in (:func:`solver.dataset.lock.subject_output_lock` yields it).
    key
        :func:`subject_run_key`, taken before the run.
    mass_kg, fitted_mass_kg
        The subject's given mass and the mass the dynamics fitted (None without dynamics), kg.
    seconds
        Wall time of the run, s.
    warnings
        The distinct messages of the warnings the run raised.

    The manifest is a dataset run's (``key``, ``rel``, ``status``, ``trials``: summary rows
    read from the output, masses, ``seconds``, ``warnings``), with ``one_subject_run``: True.

    Raises
    ------
    OSError
        The folder cannot be written (:func:`solver.dataset.manifest.write_manifest`).
    """
    out = Path(out_dir)
    rows = subject_rows(out)
    manifest = {
        "key": key,
        "rel": out.resolve().relative_to(Path(tree).resolve()).as_posix(),
        "status": subject_status(rows),
        "trials": rows,
        "mass_kg": mass_kg,
        "fitted_mass_kg": fitted_mass_kg,
        "seconds": seconds,
        "warnings": warnings,
        "one_subject_run": True,
    }
    write_manifest(out, manifest)


def forget_subject_run(out_dir: str | Path) -> None:
    """Remove the manifest of ``out_dir``, if it has one, after a run that rewrote part of
    the folder (some trials): it no longer describes the output, and without it the next
    dataset run processes the subject again."""
    with contextlib.suppress(FileNotFoundError):
        os.remove(Path(out_dir) / MANIFEST_NAME)
