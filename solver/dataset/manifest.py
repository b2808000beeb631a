"""What a subject's output was made from, so that a rerun skips unchanged subjects.

Every subject output of a dataset run carries ``manifest.json``::

    {"key": {"schema": 1, "addb_version": "0.1.0", "code": "<sha256 of the processing modules' source>",
             "inputs": {"_subject.json": "<sha256>", "trials/walk/markers.trc": "<sha256>", ...},
             "settings": {...}, "annotations": "<sha256 of the reviewer's flags>" | null},
     "status": "ok" | "kinematics_only" | "failed", "error": {...} (failed only),
     "subject": {...}, "trials": [...]}          (the summary rows, solver.dataset.summary)

A rerun compares the stored ``key`` with the one computed from the inputs now: equal
keys mean the output is up to date. A subject whose data failed keeps its failure the
same way (its manifest has ``"status": "failed"`` and the error), so an unchanged broken
subject is reported again without being run again; a subject whose worker died has no
such record and runs again. The inputs are every file of the subject folder
except hidden files, addb's output folder, bone meshes (``Geometry/``, they do not change
the solution) and the review record, whose unmeasured-force flags enter as ``annotations``
instead (a digest given by the caller: the solver package does not read review records).
The ``code`` is a digest of the source of the solver modules processing runs
(:func:`solver.provenance.code_digest`, :func:`solver.provenance.processing_modules`): the
version number does not change with every commit, so a rerun after an update of that code
(a ``git pull`` of an editable install) processes the subjects again; an update of other
modules (the .b3d export, the diagnosis, this package) does not.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from solver.files import links_back
from solver.outputs import MANIFEST_NAME, write_json
from solver.provenance import addb_version, code_digest

SCHEMA = 1

#: Folder names inside a subject folder that are not inputs of the solution.
NOT_INPUTS = frozenset({"addb_out", "Geometry", "__pycache__"})

#: Review record names inside a subject folder (entered as ``annotations``, not inputs).
REVIEW_RECORDS = frozenset({"annotations.json"})

#: The manifest statuses of a processed subject: its output is in place (with dynamics, or
#: kinematics only).
PROCESSED_STATUSES = frozenset({"ok", "kinematics_only"})

#: The manifest statuses of a subject whose run finished: its output (:data:`PROCESSED_STATUSES`)
#: or the failure it records (``"failed"``). A manifest with any other status (a damaged
#: record) stands for no finished run.
FINAL_STATUSES = PROCESSED_STATUSES | {"failed"}


class KeyUnreadable(Exception):
    """The key of a subject's files now cannot be made (:func:`subject_key_now`): a file
    cannot be read, or the review record is damaged. The message says which, for the
    subject's failure record or a user; ``error_type`` names the error underneath
    (``"OSError"``, or the review reader's error class)."""

    def __init__(self, message: str, error_type: str) -> None:
        super().__init__(message)
        self.error_type = error_type


def file_sha256(path: str | Path) -> str:
    """Hex SHA-256 of a file's bytes (read in 1 MiB blocks)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def input_files(subject_dir: str | Path) -> dict[str, Path]:
    """The input files of a subject folder: relative posix path -> file (see module doc)."""
    base = Path(subject_dir).resolve()
    out: dict[str, Path] = {}
    for folder, dirs, files in os.walk(base, followlinks=True):
        here = Path(folder)
        dirs[:] = sorted(
            d for d in dirs
            if not d.startswith(".") and d not in NOT_INPUTS and not d.endswith(".annotations") and not links_back(here, d)
        )  # fmt: skip
        for name in sorted(files):
            if name.startswith(".") or (here == base and name in REVIEW_RECORDS):
                continue
            if name.endswith((".annotations.json", ".journal", ".lock")):
                continue
            out[(here / name).relative_to(base).as_posix()] = here / name
    return out


def manifest_key(subject_dir: str | Path, settings: dict[str, Any], review: str | None = None) -> dict[str, Any]:
    """The ``key`` of a subject's manifest, computed from its files now.

    Parameters
    ----------
    subject_dir
        The subject folder.
    settings
        The run's settings that change the solution (JSON-serializable).
    review
        A digest of the reviewer's flags the run applies (the review record's
        unmeasured-force frames, not its file: edits wait in a journal before they reach
        the file), or None when there are none.

    Raises
    ------
    OSError
        A file cannot be read (the caller records it as the subject's failure).
    """
    return {
        "schema": SCHEMA,
        "addb_version": addb_version(),
        "code": code_digest(),
        "inputs": {rel: file_sha256(p) for rel, p in input_files(subject_dir).items()},
        "settings": json.loads(json.dumps(settings, sort_keys=True)),
        "annotations": review,
    }


def subject_key_now(
    subject_dir: str | Path,
    out_dir: str | Path,
    settings: dict[str, Any],
    review_digest: Callable[[str, str], str | None] | None,
) -> dict[str, Any]:
    """The key a dataset run computes for a subject before it decides to skip it: the
    subject's files now, the run's ``settings`` (:func:`run_settings`) and the digest of the
    reviewer's flags (``review_digest(subject_dir, out_dir)``, or None without a
    ``review_digest``). The one test of :func:`solver.dataset.runner.process_dataset` and of
    ``addb info DATASET_DIR`` (:mod:`solver.dataset.inventory`).

    Raises
    ------
    KeyUnreadable
        A file of the subject cannot be read, or its review record is damaged (the
        ``review_digest``'s error).
    """
    try:
        review = review_digest(str(subject_dir), str(out_dir)) if review_digest else None
    except Exception as exc:  # a damaged review record: the annotations package's error, unknown here
        raise KeyUnreadable(f"cannot read the review record: {exc}", type(exc).__name__) from exc
    try:
        return manifest_key(subject_dir, settings, review)
    except OSError as exc:
        raise KeyUnreadable(f"cannot read the subject's files: {exc}", "OSError") from exc


def run_settings(options: dict[str, Any]) -> dict[str, Any]:
    """The ``settings`` of the key a dataset run keys its subjects on, for the run's
    ``options`` (:attr:`solver.dataset.runner.DatasetOptions.settings`: ``{}`` for a plain
    ``addb process DATASET_DIR --out OUT``)."""
    return {"addb_process": "default", **options}


def key_changes(stored: dict[str, Any], now: dict[str, Any], most: int = 3) -> list[str]:
    """What differs between a manifest's stored ``key`` and the key of the subject now
    (:func:`manifest_key`), as phrases for a user: "addb's code changed", "the settings
    changed", "the review's flags changed", "trials/walk/markers.trc changed", "trials/run
    added", "trials/old removed" (input files named up to ``most`` of a kind, then a count);
    [] when the keys are equal (the output is up to date)."""
    out = []
    if any(stored.get(k) != now.get(k) for k in ("schema", "addb_version", "code")):
        out.append("addb's code changed")
    if stored.get("settings") != now.get("settings"):
        out.append(f"the settings changed ({_settings_changes(stored.get('settings') or {}, now.get('settings') or {})})")
    old, new = stored.get("inputs") or {}, now.get("inputs") or {}
    kinds = (
        ("changed", [f for f in new if f in old and old[f] != new[f]]),
        ("added", [f for f in new if f not in old]),
        ("removed", [f for f in old if f not in new]),
    )
    for kind, files in kinds:
        if files:
            named = ", ".join(files[:most]) + (f" and {len(files) - most} more files" if len(files) > most else "")
            out.append(f"{named} {kind}")
    if stored.get("annotations") != now.get("annotations"):
        out.append("the review's flags changed")
    return out


def _settings_changes(old: dict[str, Any], new: dict[str, Any]) -> str:
    """"fit: band then, default now" for each setting that differs (an absent one is the
    default: a plain run records none)."""
    keys = sorted(set(old) | set(new))
    return ", ".join(
        f"{k}: {old.get(k, 'default')} then, {new.get(k, 'default')} now" for k in keys if old.get(k) != new.get(k)
    )


def subject_status(rows: list[dict[str, Any]]) -> str:
    """A processed subject's manifest ``status`` from its trials' summary rows
    (:func:`solver.dataset.summary.subject_rows`).

    Returns
    -------
    str
        ``"ok"`` when a trial has dynamics (a row with status ``"ok"``), else
        ``"kinematics_only"``. A failed subject has no rows; its ``"failed"`` is set by
        whoever caught the failure.
    """
    return "ok" if any(r["status"] == "ok" for r in rows) else "kinematics_only"


def read_manifest(out_dir: str | Path) -> dict[str, Any] | None:
    """The manifest stored in a subject's output folder, or None (absent or unreadable)."""
    path = Path(out_dir) / MANIFEST_NAME
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) and isinstance(data.get("key"), dict) else None


def write_manifest(out_dir: str | Path, manifest: dict[str, Any]) -> None:
    """Put ``manifest`` into the subject's output folder ``out_dir`` (an existing folder) as
    :data:`MANIFEST_NAME`, written to a hidden temporary file and renamed into place, so that
    a reader (:func:`read_manifest`) or a crash meets the old manifest or the new, never half
    of one.

    Raises
    ------
    OSError
        The folder cannot be written (the temporary file may be left; the old manifest stays).
    """
    tmp = Path(out_dir) / f".{MANIFEST_NAME}.tmp"
    write_json(tmp, manifest)
    os.replace(tmp, Path(out_dir) / MANIFEST_NAME)


def finished_manifest(out_dir: str | Path) -> dict[str, Any] | None:
    """The stored manifest of a subject whose run finished (its status one of
    :data:`FINAL_STATUSES`), else None (none, unreadable, or damaged)."""
    stored = read_manifest(out_dir)
    return stored if stored is not None and stored.get("status") in FINAL_STATUSES else None


def lost_trials(out_dir: str | Path, stored: dict[str, Any]) -> list[str]:
    """The trials a finished manifest ``stored`` lists (its ``trials`` rows) whose output is
    no longer in the subject's output folder ``out_dir``: a trial folder without a non-empty
    ``trial.npz`` and ``results.json`` (deleted or emptied after the run). [] for a failure
    record, which lists no trial. A manifest with lost trials is not up to date
    (:func:`current_manifest`): a new run processes the subject again
    (docs/audits/2026-12-02-dataset.md, finding 7)."""
    base = Path(out_dir)
    lost = []
    for row in stored.get("trials") or []:
        name = str(row.get("trial") or "") if isinstance(row, dict) else ""
        folder = base / name
        kept = bool(name) and all((folder / f).is_file() and (folder / f).stat().st_size > 0 for f in ("trial.npz", "results.json"))
        if not kept:
            lost.append(name or "(unnamed)")
    return lost


def transient_failure(stored: dict[str, Any]) -> bool:
    """Whether the manifest ``stored`` records a transient failure: the output storage failed
    (disk full, I/O error; ``error["transient"]``, :func:`solver.dataset.task.storage_error`),
    not the subject's data. Such a record is never up to date (:func:`current_manifest`): a
    new run processes the subject again (docs/audits/2026-12-02-dataset.md, finding 3)."""
    error = stored.get("error")
    return stored.get("status") == "failed" and isinstance(error, dict) and bool(error.get("transient"))


def current_manifest(out_dir: str | Path, key: dict[str, Any]) -> dict[str, Any] | None:
    """The stored manifest when its run finished, its key equals ``key`` (the output, or the
    failure it records, is up to date with the inputs), none of its trials' output is
    lost (:func:`lost_trials`) and it records no transient failure (:func:`transient_failure`),
    else None."""
    stored = finished_manifest(out_dir)
    if stored is None or stored["key"] != key or lost_trials(out_dir, stored) or transient_failure(stored):
        return None
    return stored
