"""A dataset folder before (or beside) its processing: ``addb info DATASET_DIR``.

What a dataset builder checks before a run of hours: how many subjects the dataset search
finds (:func:`solver.dataset.discover.scan_dataset`, the same search ``addb process`` makes),
their trials, frames and hours in the terms of the AddBiomechanics Dataset paper (Werling et
al.: subjects, trials, hours, hours with force plates), each subject's mass and height, the
subjects that cannot be read (named with their error, the others still listed), what the
search leaves out (``.b3d`` files, symbolic-link loops), and the state of the dataset's
output tree when it has one: what its run left, the subjects added since, and those whose
files, review or addb's code changed since, which a new run processes again (the others it
skips: the test of the run's manifests, :mod:`solver.dataset.manifest`).

Frames with *measured* force are known only after the dynamics stage (its choice of frames);
before it, the measure of force data is the trials recorded with force plates.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from solver.dataset.discover import DatasetScan, DatasetSubject, b3d_note, loop_note, scan_dataset
from solver.dataset.manifest import (
    KeyUnreadable,
    finished_manifest,
    key_changes,
    lost_trials,
    run_settings,
    subject_key_now,
    transient_failure,
)
from solver.errors import AddbError, counted, listed
from solver.io.summary import summarize
from solver.outputs import SUBJECT_RECORD, SUMMARY_NAME, read_summary


def _seconds(trial: dict[str, Any]) -> float:
    """A trial's recorded time (s): its frames over its rate (the paper counts frames x
    interval), else the span of its time column."""
    rate = trial.get("rate_hz")
    return trial["frames"] / rate if rate else float(trial.get("duration_s") or 0.0)


#: Subjects changed since the output tree's run named one per line by :func:`inventory_text`
#: (the others counted).
CHANGED_SHOWN = 10

#: What an output tree's subject folders hold, by the status its summary records (a subject
#: skipped as up to date counts by the status of the output it kept).
OUTPUT_STATES = {"ok": "processed", "kinematics_only": "kinematics only", "failed": "failed", "cancelled": "cancelled"}


def _output_states(entries: list[dict[str, Any]]) -> dict[str, int]:
    counts = dict.fromkeys(OUTPUT_STATES.values(), 0)
    for e in entries:
        status = e.get("result_status") if e.get("status") == "skipped" else e.get("status")
        counts[OUTPUT_STATES.get(status, "failed")] += 1
    return counts


def _subject_entry(rel: str, path: Path) -> dict[str, Any]:
    """One subject of the inventory: its figures, or its error (a subject that cannot be read
    does not hide the others)."""
    try:
        d = summarize(path)
    except (AddbError, OSError) as exc:
        return {"rel": rel, "error": str(exc)}
    trials = d["trials"]
    force = [t for t in trials if not t.get("kinematics_only")]
    return {
        "rel": rel,
        "name": d["name"],
        "mass_kg": d["mass_kg"],
        "height_m": d["height_m"],
        "disable_dynamics": d["disable_dynamics"],
        "trials": len(trials),
        "trials_with_force": len(force),
        "frames": sum(int(t["frames"]) for t in trials),
        "seconds": sum(_seconds(t) for t in trials),
        "seconds_with_force": sum(_seconds(t) for t in force),
        "notes": d.get("notes", []),
    }


def dataset_inventory(
    root: str | Path,
    output_tree: str | Path | None = None,
    *,
    scan: DatasetScan | None = None,
    progress: Callable[[str, float], None] | None = None,
    review_digest: Callable[[str, str], str | None] | None = None,
    settings: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The inventory of the dataset folder ``root``: every subject folder the dataset search
    finds, read as ``addb info SUBJECT_DIR`` reads it (:func:`solver.io.summary.summarize`:
    every trial file is read), and the totals.

    Parameters
    ----------
    root
        The dataset folder (subject folders at any depth).
    output_tree
        Its output tree, if one may exist (``addb view``'s default place, or ``--out`` of an
        earlier run); summarized when it holds a dataset run's summary.
    scan
        The search of ``root`` when the caller made it already (:func:`scan_dataset`).
    progress
        Called with (message, fraction of subjects read) before each subject and at the end:
        every trial file is read, which takes a while on a large dataset.
    review_digest
        ``(subject folder, output folder) -> digest`` of the reviewer's flags, as a dataset
        run takes it (:func:`addb_viewer.review_masks.review_digest`; the solver package
        reads no review record); None: the flags recorded by the run are taken as unchanged.
    settings
        The options of the new run the output tree is compared with
        (:attr:`solver.dataset.runner.DatasetOptions.settings`: ``{"fit": "band"}`` for
        ``addb process DATASET_DIR --out OUT --fit band``); None: a plain run's, ``{}``.

    Returns
    -------
    dict
        ``kind`` ``"dataset"``, ``path``; ``subjects``: one dict each, sorted by relative path
        (``rel``), with ``error`` (str) for a subject that cannot be read, else ``name``,
        ``mass_kg`` (kg), ``height_m`` (m, or None), ``disable_dynamics``, ``trials``,
        ``trials_with_force`` (trials with a force recording), ``frames``, ``seconds`` and
        ``seconds_with_force`` (s, frames over rate), ``notes`` (the readers' warnings);
        ``totals`` (``subjects``, ``unreadable``, ``trials``, ``trials_with_force``,
        ``frames``, ``hours``, ``hours_with_force``, over the readable subjects);
        ``left_out`` (the dataset run's messages on ``.b3d`` files and link loops);
        ``output`` (None without ``output_tree``, else its ``path``, ``found`` (it holds a
        dataset run's summary) and, when found, ``finished``, subject ``counts`` by what their
        folders hold (:data:`OUTPUT_STATES`), ``new``: subjects found now that the run did
        not list, ``changed``: those it listed that a new run (``addb process DATASET_DIR
        --out OUT`` with ``settings``) processes again, in its order, each as ``rel`` and
        ``changes`` (phrases of :func:`solver.dataset.manifest.key_changes`, or why there is
        no record to compare with), and ``unchanged``: how many it would skip).

    Raises
    ------
    DatasetError
        ``root`` is not a folder or holds no subject folder (the message says what it is
        instead: an output folder, a folder of ``.b3d`` files).
    FileFormatError
        The output tree's summary is damaged (:func:`solver.outputs.read_summary`).
    """
    scan = scan_dataset(root) if scan is None else scan
    found = scan.require_subjects(root)
    say = progress or (lambda message, fraction: None)
    subjects = []
    for k, s in enumerate(found):
        say(f"reading {s.rel}", k / len(found))
        subjects.append(_subject_entry(s.rel, s.path))
    say(f"read {len(found)} subjects", 1.0)
    readable = [s for s in subjects if "error" not in s]
    totals = {
        "subjects": len(subjects),
        "unreadable": len(subjects) - len(readable),
        "trials": sum(s["trials"] for s in readable),
        "trials_with_force": sum(s["trials_with_force"] for s in readable),
        "frames": sum(s["frames"] for s in readable),
        "hours": sum(s["seconds"] for s in readable) / 3600.0,
        "hours_with_force": sum(s["seconds_with_force"] for s in readable) / 3600.0,
    }
    left_out = [n for n in (b3d_note(scan), loop_note(scan)) if n is not None]
    output = _output_entry(output_tree, found, review_digest, run_settings(settings or {}))
    return {"kind": "dataset", "path": str(root), "subjects": subjects, "totals": totals, "left_out": left_out, "output": output}


def _output_entry(
    output_tree: str | Path | None,
    found: Sequence[DatasetSubject],
    review_digest: Callable[[str, str], str | None] | None,
    settings: dict[str, Any],
) -> dict[str, Any] | None:
    """The ``output`` entry of :func:`dataset_inventory` (see there) for the subject folders
    ``found`` and a new run's key ``settings`` (:func:`solver.dataset.manifest.run_settings`)."""
    if output_tree is None:
        return None
    if not (Path(output_tree) / SUMMARY_NAME).is_file():
        return {"path": str(output_tree), "found": False}
    summary = read_summary(output_tree)
    listed_rels = {s["rel"] for s in summary["subjects"]}
    changed = []
    for entry in found:
        if entry.rel in listed_rels and (why := _changes(entry, Path(output_tree), review_digest, settings)):
            changed.append({"rel": entry.rel, "changes": why})
    return {
        "path": str(output_tree),
        "found": True,
        "finished": summary.get("finished"),
        "counts": _output_states(summary["subjects"]),
        "new": [s.rel for s in found if s.rel not in listed_rels],
        "changed": changed,
        "unchanged": sum(1 for s in found if s.rel in listed_rels) - len(changed),
    }


def _subject_line(s: dict[str, Any]) -> list[str]:
    if "error" in s:
        return [f"  {s['rel']}: cannot be read: {s['error']}"]
    height = f"{s['height_m']:.4g} m" if s["height_m"] else "unknown height"
    force = f"{s['trials_with_force']} with force plates" if not s["disable_dynamics"] else "dynamics disabled"
    line = (
        f"  {s['rel']}: {s['mass_kg']:.4g} kg, {height}; {counted(s['trials'], 'trial', figure=True)} ({force}), "
        f"{s['frames']:,} frames, {s['seconds']:.1f} s"
    )
    return [line] + [f"    note: {n}" for n in s["notes"]]


def _changes(
    entry: DatasetSubject,
    tree: Path,
    review_digest: Callable[[str, str], str | None] | None,
    settings: dict[str, Any],
) -> list[str]:
    """Why a new dataset run into ``tree`` with the key ``settings`` would process the
    subject ``entry`` again, as phrases; [] when it would skip it (the run's own test:
    :func:`solver.dataset.manifest.subject_key_now` against the finished manifest)."""
    target = entry.out_dir(tree)
    stored = finished_manifest(target)
    if stored is None and (target / SUBJECT_RECORD).is_file():
        return [("its output holds no record of the inputs it was made from (written by addb kinematics, or by a "
                 "one-subject addb process with --trial, or with a review file not the subject's own)")]
    if stored is None:
        return ["no finished output (cancelled, or its worker died)"]
    lost = lost_trials(target, stored)
    if lost:
        return [f"its output of {listed(lost, 3)} is gone (trial.npz or results.json missing or empty)"]
    if transient_failure(stored):
        return [f"its last run failed on a storage error, not on its data: {stored['error'].get('message')}"]
    kept = stored["key"].get("annotations")
    try:
        now = subject_key_now(entry.path, target, settings, review_digest or (lambda subject, out: kept))
    except KeyUnreadable as exc:
        return [str(exc)]
    return key_changes(stored["key"], now)


def inventory_text(d: dict[str, Any], command_hint: str = "addb process DATASET_DIR --out OUT") -> str:
    """The inventory of :func:`dataset_inventory` as text: the totals, one line per subject
    (with the readers' notes below it), what the search left out and the output tree's state
    (or, where none was found, ``command_hint``: the command that makes one)."""
    t = d["totals"]
    unreadable = f", {t['unreadable']} of them unreadable" if t["unreadable"] else ""
    lines = [
        f"{d['path']}: dataset folder",
        (
            f"  {counted(t['subjects'], 'subject', figure=True)}{unreadable}; {counted(t['trials'], 'trial', figure=True)} "
            f"({t['trials_with_force']} with force plates), {t['frames']:,} frames, "
            f"{t['hours']:.4f} hours ({t['hours_with_force']:.4f} with force plates)"
        ),
    ]
    for s in d["subjects"]:
        lines += _subject_line(s)
    lines += [f"  left out: {n}" for n in d["left_out"]]
    out = d["output"]
    if out is None or not out["found"]:
        where = f"none at {out['path']}" if out is not None else "none given"
        lines.append(
            f"  output tree: {where}; {command_hint} processes every subject (then addb info OUT summarizes the run, "
            "and addb info DATASET_DIR --out OUT names the subjects a new run processes again)"
        )
    else:
        counts = ", ".join(f"{n} {status}" for status, n in out["counts"].items() if n)
        when = f" finished {out['finished']}" if out["finished"] else ""
        lines.append(f"  output tree: {out['path']} (a run{when}: {counts or 'no subject'}; addb info OUTPUT_TREE for its totals)")
        if out["new"]:
            lines.append(f"    not in that run: {listed(out['new'], 3)} (added since; a new run processes {_them(len(out['new']))})")
        if out["changed"]:
            n = len(out["changed"])
            lines.append(f"    changed since that run: {counted(n, 'subject', figure=True)} (a new run processes {_them(n)} again)")
            lines += [f"      {c['rel']}: {'; '.join(c['changes'])}" for c in out["changed"][:CHANGED_SHOWN]]
            if len(out["changed"]) > CHANGED_SHOWN:
                lines.append(f"      and {len(out['changed']) - CHANGED_SHOWN} more")
        lines.append(f"    up to date: {counted(out['unchanged'], 'subject', figure=True)} (a new run skips {_them(out['unchanged'])})")
    return "\n".join(lines)


def _them(n: int) -> str:
    return "it" if n == 1 else "them"
