"""A one-subject run into a dataset output tree leaves the manifest a dataset run would.

``addb process labA/s01 --out OUT/labA/s01`` replaces that subject's folder of a dataset
run's output tree (holding the tree's lock: :mod:`solver.dataset.lock`). Without a manifest
the next ``addb process DATASET_DIR --out OUT`` processed the subject again, though nothing
had changed. A whole run (every trial, no review file given) now writes the manifest a
dataset run writes (:func:`solver.dataset.task.run_subject`): its key is made the same way
(:func:`solver.dataset.manifest.manifest_key` with the run's settings and no review flags),
so the dataset run skips the subject while its files, addb's code, the fit and the review
record are as they were, and processes it again as soon as one of them differs (a review
record with flags for it, too: the one-subject run did not apply them).

A run of some trials (``--trial``) or with a review file (``--annotations``) is not what a
dataset run does, so it leaves no manifest; a ``--trial`` run merges into the folder, where
the earlier run's manifest would otherwise still describe the whole output, so that
manifest is removed (:func:`forget_subject_run`).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from solver.dataset.manifest import MANIFEST_NAME, manifest_key, run_settings, subject_status
from solver.dataset.summary import subject_rows
from solver.outputs import write_json


def subject_run_key(subject_dir: str | Path, settings: dict[str, Any]) -> dict[str, Any] | None:
    """The manifest key of a whole one-subject run with the dataset run ``settings``
    (:attr:`solver.dataset.runner.DatasetOptions.settings`, e.g. ``{"fit": "band"}``) and no
    review flags, from the subject's files now (taken before the run, as a dataset run
    does); None when a file cannot be read (the run then names it itself)."""
    try:
        return manifest_key(subject_dir, run_settings(settings), None)
    except OSError:
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
) -> dict[str, Any]:
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

    Returns
    -------
    dict
        The manifest written (as a dataset run's: ``key``, ``rel``, ``status``, ``trials``
        (summary rows read from the output), masses, ``seconds``, ``warnings``, and
        ``one_subject_run``: True).
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
    tmp = out / f".{MANIFEST_NAME}.tmp"
    write_json(tmp, manifest)
    os.replace(tmp, out / MANIFEST_NAME)
    return manifest


def forget_subject_run(out_dir: str | Path) -> bool:
    """Remove the manifest of ``out_dir`` after a run that rewrote part of the folder (some
    trials, or a review file a dataset run would not apply): it no longer describes the
    output, and without it the next dataset run processes the subject again. Returns whether
    one was removed."""
    try:
        os.remove(Path(out_dir) / MANIFEST_NAME)
    except FileNotFoundError:
        return False
    return True
