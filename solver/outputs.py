"""The output folder of a processed subject, written so that OpenSim users can open it.

Layout (``<subject>`` is the subject folder's name)::

    OUT/<subject>_scaled.osim            scaled (and, after dynamics, mass-fitted) model
    OUT/<trial>/<trial>_ik.mot           coordinates, degrees for rotational coordinates
    OUT/<trial>/<trial>_id.sto           generalized forces (dynamics stage)
    OUT/<trial>/<trial>_grf.mot          plate wrenches as applied (dynamics stage)
    OUT/<trial>/<trial>_external_loads.xml
    OUT/<trial>/results.json             metrics of the trial
    OUT/subject.json                     subject-level results (scales, offsets, mass)

Everything is first written into a temporary sibling folder, which then replaces OUT in
two renames, so a crash or an error never leaves a half-written OUT behind. Since OUT is
replaced whole, :func:`check_output_folder` refuses an OUT that holds anything but an
earlier output of addb (or is the subject folder, or a folder above it).
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from solver.errors import FileFormatError, OutputFolderError, listed
from solver.files import as_created

CACHE_DIR = ".addb_cache"
"""Folder of the output folder holding caches of the stages (not a trial)."""

#: The subject's summary at the top of its output folder (scales, marker offsets, fit RMS,
#: the settings of each stage), written by :func:`solver.pipeline.write_subject_summary`.
SUBJECT_RECORD = "subject.json"

#: Keys of :data:`SUBJECT_RECORD` naming the run's inputs: the subject folder it read
#: (absolute), and the review record whose flags it took (absolute; null when it took no
#: flags; absent when the caller gave flags without naming their record). ``addb export``
#: reads them to find the subject's tags and the reviewer's flags.
SUBJECT_DIR_KEY = "subject_dir"
REVIEW_RECORD_KEY = "review_record"

#: A dataset run's record of one subject's inputs and outcome (:mod:`solver.dataset.manifest`).
MANIFEST_NAME = "manifest.json"

#: The summary a dataset run writes at the top of its output tree (:mod:`solver.dataset.runner`).
SUMMARY_NAME = "dataset_summary.json"

#: The lock file a dataset run holds at the top of its output tree from its start
#: (:func:`solver.dataset.lock.output_tree_lock`; hidden: the dataset search and the exports
#: skip it). With :data:`SUMMARY_NAME`, which a run writes at its end, it marks an output tree.
RUN_LOCK_NAME = ".addb_run.lock"

#: A trial's metrics in its output folder (``OUT/<trial>/results.json``, written by
#: :func:`solver.pipeline.process_subject` beside the trial's ``trial.npz``).
TRIAL_RESULTS = "results.json"

#: Entries of which one marks a folder as an output of addb: :data:`SUBJECT_RECORD` (every
#: subject output, kinematics only included), :data:`MANIFEST_NAME` (a dataset run's subject
#: folder, also when the subject failed) or :data:`CACHE_DIR` (a folder the diagnosis'
#: judged fit reprocesses from the kinematics cache alone).
OUTPUT_MARKERS = (SUBJECT_RECORD, MANIFEST_NAME, CACHE_DIR)


def output_marker(folder: str | Path) -> str | None:
    """The first of :data:`OUTPUT_MARKERS` that ``folder`` holds (it is an output of addb),
    or None (also when ``folder`` is not a folder). The one test of "is this an output
    folder of addb" that the output check, the dataset run and the recording commands share."""
    folder = Path(folder)
    if not folder.is_dir():
        return None
    return next((m for m in OUTPUT_MARKERS if (folder / m).exists()), None)


def is_output_tree(folder: str | Path) -> bool:
    """Whether ``folder`` is a dataset run's output tree: it holds :data:`SUMMARY_NAME` (a
    run ended there) or :data:`RUN_LOCK_NAME` (a run started there, maybe still running:
    dataset audit 2026-12-02, finding 4)."""
    folder = Path(folder)
    return (folder / SUMMARY_NAME).is_file() or (folder / RUN_LOCK_NAME).is_file()


def output_tree_above(folder: str | Path) -> Path | None:
    """The dataset run's output tree that ``folder`` lies inside: the nearest folder above it
    that :func:`is_output_tree` (not ``folder`` itself), or None."""
    for parent in Path(folder).resolve().parents:
        if is_output_tree(parent):
            return parent
    return None


def tree_part(folder: str | Path) -> tuple[Path, str] | None:
    """Where ``folder`` lies in a dataset run's output tree when it is a folder inside one that
    holds no output of its own (``OUT/labA``, a folder of subject outputs): ``(tree, rel)``,
    ``rel`` its path below the tree with ``/`` separators (``"labA"``). None for a path that is
    not a folder, the tree itself, a subject's output folder (:func:`output_marker`, or trial
    outputs directly in it), a trial's output folder (:data:`TRIAL_RESULTS`) and any folder
    outside an output tree (:func:`output_tree_above`). The one test behind ``addb info
    OUT/labA``, ``addb benchmark`` and ``addb export`` of it, and the note the other commands
    give (:func:`solver.io.subject.output_tree_part_note`)."""
    from solver.results import processed_trials

    p = Path(folder)
    if not p.is_dir() or output_marker(p) is not None or (p / TRIAL_RESULTS).is_file() or processed_trials(p):
        return None
    tree = output_tree_above(p)
    return None if tree is None else (tree, p.resolve().relative_to(tree).as_posix())


def summary_subjects(summary: dict, below: str | None = None) -> list[dict]:
    """The subject entries of a dataset run's summary (:func:`read_summary`), those below the
    folder ``below`` when given: its path below the output tree (``"labA"``: ``labA/s01`` and
    ``labA/x/s02``, not ``labAB/s03``; :func:`tree_part`)."""
    return [s for s in summary["subjects"] if below is None or s["rel"].startswith(f"{below}/")]


def read_summary(out_dir: str | Path) -> dict:
    """The summary a dataset run wrote at the top of its output tree ``out_dir``
    (:data:`SUMMARY_NAME`, :func:`solver.dataset.runner.process_dataset`), read once for every
    reader (``addb info``, ``addb benchmark``, the workbench's queue).

    Returns
    -------
    dict
        The summary as written: ``dataset`` (the dataset folder, str), ``subjects`` (a list of
        dicts, each with its ``rel`` path below the tree, ``status`` and ``trials``),
        ``totals`` and the run's time and workers.

    Raises
    ------
    FileNotFoundError
        ``out_dir`` holds no summary.
    FileFormatError
        The summary is not valid JSON (with its line) or not a dataset summary of addb (no
        ``subjects`` list of objects each with its ``rel`` path, no ``dataset`` folder).
    """
    path = Path(out_dir) / SUMMARY_NAME
    try:
        summary = json.loads(path.read_bytes().decode("utf-8", errors="replace"))
    except json.JSONDecodeError as exc:
        raise FileFormatError(f"not valid JSON: {exc.msg}", path=path, line=exc.lineno) from None
    subjects = summary.get("subjects") if isinstance(summary, dict) else None
    if (
        not isinstance(subjects, list)
        or not all(isinstance(s, dict) and isinstance(s.get("rel"), str) for s in subjects)
        or not isinstance(summary.get("dataset"), str)
    ):
        raise FileFormatError("expected a dataset summary of addb (its dataset folder and subjects, written by addb process DATASET_DIR)", path=path)
    return summary


def _clean(value: Any) -> Any:
    """JSON-safe copy: numpy scalars/arrays to Python, NaN/inf to None."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if isinstance(value, np.ndarray):
        return _clean(value.tolist())
    if isinstance(value, (np.floating, float)):
        f = float(value)
        return f if math.isfinite(f) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def write_json(path: Path, data: dict[str, Any]) -> None:
    """Write ``data`` as indented JSON (NaN written as null)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(_clean(data), indent=2) + "\n")


def check_output_folder(out_dir: str | Path, inputs: tuple[str | Path, ...] = ()) -> None:
    """Refuse an output folder whose replacement would delete what addb did not write.

    Parameters
    ----------
    out_dir
        The folder an output is about to replace (it need not exist).
    inputs
        Folders read to make the output (the subject folder): ``out_dir`` must be neither
        one of them nor a folder above one.

    Raises
    ------
    OutputFolderError
        Naming ``out_dir``: it is a file; it is an input folder or holds one; it holds
        entries and none of :data:`OUTPUT_MARKERS` (the first few entries are named).
    """
    out = Path(out_dir).resolve()
    for folder in inputs:
        src = Path(folder).resolve()
        if src == out or out in src.parents:
            what = "is" if src == out else "holds"
            raise OutputFolderError(
                f"the output folder {what} the input folder {src}, and writing the output replaces the whole "
                "output folder; expected a new folder, an empty one, or an earlier output of addb (e.g. --out "
                f"{src.parent / (src.name + '_out')})",
                path=out,
            )
    if out.exists() and not out.is_dir():
        raise OutputFolderError("exists and is not a folder; expected a folder for the output (new, empty, or an earlier output of addb)", path=out)
    if out.is_dir():
        entries = sorted(e.name for e in out.iterdir())
        if entries and output_marker(out) is None:
            raise OutputFolderError(
                f"holds {len(entries)} entries ({listed(entries, 5)}) and is not an output of addb (no "
                f"{' or '.join(OUTPUT_MARKERS)}); writing the output replaces the whole folder and would delete them. "
                "Expected a new folder, an empty one, or an earlier output of addb",
                path=out,
            )


@contextmanager
def staged_output(out_dir: str | Path, *, merge: bool = False) -> Iterator[Path]:
    """Yield a temporary folder; on success it replaces ``out_dir`` atomically.

    With ``merge`` and an existing ``out_dir``, each entry written (a trial folder, the
    model, subject.json) replaces its namesake inside ``out_dir`` by a rename, and the other
    entries stay (used to reprocess some trials of a subject). On an exception the
    temporary folder is removed and ``out_dir`` is left untouched.

    Raises
    ------
    OutputFolderError
        Before anything is written: ``out_dir`` is not a folder addb may replace
        (:func:`check_output_folder`).
    """
    check_output_folder(out_dir)
    out = Path(out_dir).resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-", dir=out.parent))
    as_created(tmp)  # it becomes OUT: readable by others as the umask allows, not mkdtemp's 0700
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if merge and out.is_dir():
        trash = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-", dir=out.parent))
        for entry in tmp.iterdir():
            target = out / entry.name
            if target.exists():
                os.replace(target, trash / entry.name)
            os.replace(entry, target)
        shutil.rmtree(trash, ignore_errors=True)
        shutil.rmtree(tmp, ignore_errors=True)
        return
    replace_folder(tmp, out, aside_prefix=f".{out.name}.old-")


def replace_folder(src: Path, dst: Path, *, aside_prefix: str) -> None:
    """Move folder ``src`` to ``dst`` in two renames: an existing ``dst`` is first moved
    into a new temporary folder ``<aside_prefix>*/previous`` beside it (deleted at the end),
    so ``dst`` is at every moment either the old or the new folder, or (between the two
    renames of a killed process) absent with the old one in ``previous``."""
    old = None
    if dst.exists():
        old = Path(tempfile.mkdtemp(prefix=aside_prefix, dir=dst.parent))
        os.replace(dst, old / "previous")
    os.replace(src, dst)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
