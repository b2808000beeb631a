"""The review queue of a dataset: every subject and trial, its processing and review state,
sorted by what needs a reviewer's attention (no viser here: the page draws it).

A dataset is opened from either

* a dataset output tree (it holds ``dataset_summary.json``, written by
  ``addb process DATASET_DIR``): its subjects are those of the summary and their input
  folders are below the summary's ``dataset``; or
* a tree of subject folders (:func:`solver.dataset.discover.scan_dataset`): outputs go to
  ``<DATASET_DIR>/addb_out`` (mirroring the tree) when the folder is writable, else to the
  user's cache (:func:`dataset_output_dir`).

Per trial the row says: the processing state (not processed / processing with its
progress / failed with the error / processed / kinematics only / output lost, when a
trial's ``trial.npz`` or ``results.json`` is missing, empty or damaged), the review state
(unreviewed / in review / reviewed, and by whom) from the subject's review record
(:func:`addb_viewer.locations.annotations_path`), the frames the solver proposes as
unmeasured that the reviewer has neither flagged nor rejected (pending proposals), the
Hicks verdicts and the marker RMS. Everything is read from the small files of the output
tree (``manifest.json``, ``results.json``) and the review records, never from the trials'
arrays, so a queue of hundreds of subjects opens in well under a second.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np
from numpy.typing import NDArray

from addb_viewer.locations import annotations_path, cache_root
from solver.dataset.discover import DatasetScan, b3d_note, loop_note, scan_dataset
from solver.dataset.manifest import MANIFEST_NAME, read_manifest
from solver.dataset.summary import dynamics_error_message, proposed_ranges
from solver.errors import counted, listed
from solver.io.subject import folder_is_writable
from solver.outputs import SUMMARY_NAME, read_summary

#: Output folder of a dataset inside a writable dataset folder.
DATASET_OUTPUT_NAME = "addb_out"

#: Processing states, as shown.
NOT_PROCESSED, PROCESSING, FAILED, PROCESSED, KINEMATICS_ONLY = (
    "not processed", "processing", "failed", "processed", "kinematics only")  # fmt: skip
#: Processing state of a trial the manifest lists whose ``trial.npz`` or ``results.json`` is
#: missing, empty or damaged since the run: it cannot be opened (the row's detail says why).
OUTPUT_LOST = "output lost"
#: Review states, as shown (the last: the subject's review record cannot be read, so its
#: flags and review marks are unknown until it is mended; the app names the problem).
UNREVIEWED, IN_REVIEW, REVIEWED, RECORD_UNREADABLE = "unreviewed", "in review", "reviewed", "record unreadable"


@dataclass(frozen=True)
class QueueSubject:
    """One subject of the dataset: its key, input folder and output folder."""

    rel: str
    subject_dir: Path
    out_dir: Path


@dataclass(frozen=True)
class QueueRow:
    """One trial (or, for a subject without processed trials, the subject) in the queue.

    Attributes
    ----------
    subject
        The subject's :class:`QueueSubject`.
    trial
        Trial name; None for a subject row (not processed, processing or failed).
    processing
        :data:`NOT_PROCESSED`, :data:`PROCESSING`, :data:`FAILED`, :data:`PROCESSED`,
        :data:`KINEMATICS_ONLY` or :data:`OUTPUT_LOST`.
    detail
        The error of a failed subject, the progress message of a running one, for a
        trial kept with its kinematics because its dynamics failed, "dynamics failed: "
        and the error, for a trial whose output is lost, the file and what is wrong with
        it ("" else).
    review
        :data:`UNREVIEWED`, :data:`IN_REVIEW`, :data:`REVIEWED` or :data:`RECORD_UNREADABLE`.
    reviewer
        Who marked it reviewed (or, in review, everyone who edited it, the last editor first); None when nobody.
    pending
        Frames the solver proposes as unmeasured that are neither flagged nor rejected;
        None when unknown (an output without a manifest).
    frames, measured_frames
        Frames of the trial, and those with measured force (0 without dynamics).
    marker_rms_m
        Marker RMS error, m (None when unknown).
    hicks_linear_ok, hicks_angular_ok
        Hicks verdicts (None without dynamics).
    """

    subject: QueueSubject
    trial: str | None
    processing: str
    detail: str = ""
    review: str = UNREVIEWED
    reviewer: str | None = None
    pending: int | None = None
    frames: int = 0
    measured_frames: int = 0
    marker_rms_m: float | None = None
    hicks_linear_ok: bool | None = None
    hicks_angular_ok: bool | None = None

    @property
    def needs_review(self) -> bool:
        """Processed (dynamics or kinematics only), its output there, and not marked reviewed."""
        return self.trial is not None and self.processing != OUTPUT_LOST and self.review != REVIEWED

    @property
    def attention(self) -> tuple[Any, ...]:
        """Sort key: what a reviewer should look at first comes first.

        Order: trials whose review record cannot be read, processed trials with pending
        proposals or a failed Hicks threshold, trials in review, other unreviewed trials,
        failed subjects and trials whose output is lost, running ones, unprocessed ones,
        reviewed trials; within a group more pending frames first, then by name.
        """
        hicks_bad = self.hicks_linear_ok is False or self.hicks_angular_ok is False
        if self.processing == OUTPUT_LOST:
            group = 3
        elif self.trial is not None and self.review == RECORD_UNREADABLE:
            group = -1
        elif self.trial is not None and self.review != REVIEWED and ((self.pending or 0) > 0 or hicks_bad):
            group = 0
        elif self.trial is not None and self.review == IN_REVIEW:
            group = 1
        elif self.trial is not None and self.review == UNREVIEWED:
            group = 2
        else:
            group = {FAILED: 3, PROCESSING: 4, NOT_PROCESSED: 5}.get(self.processing, 6)
        return (group, -(self.pending or 0), self.subject.rel, self.trial or "")


def dataset_output_dir(dataset_dir: str | Path) -> Path:
    """Default output tree of a dataset folder: ``<dataset>/addb_out`` when writable, else
    ``$XDG_CACHE_HOME/addb/<name>-<hash>`` (as for single subjects)."""
    root = Path(dataset_dir).resolve()
    if folder_is_writable(root):
        return root / DATASET_OUTPUT_NAME
    return cache_root() / f"{root.name}-{hashlib.sha1(str(root).encode()).hexdigest()[:8]}"


def is_dataset(path: str | Path) -> bool:
    """True for a dataset output tree or a folder holding subject folders (not itself one)."""
    p = Path(path)
    if (p / SUMMARY_NAME).is_file():
        return True
    if not p.is_dir() or (p / "_subject.json").is_file():
        return False
    return bool(scan_dataset(p).subjects)


@dataclass(frozen=True)
class OpenedDataset:
    """A dataset as the workbench opens it (:func:`open_dataset`): one search of its folder."""

    dataset_dir: Path
    out_dir: Path
    subjects: tuple[QueueSubject, ...]
    #: The short note on what the queue leaves out, and the dataset run's messages about the
    #: same files and links (:func:`_notes`).
    notes: tuple[str | None, tuple[str, ...]]


def open_dataset(path: str | Path, out_dir: str | Path | None = None) -> OpenedDataset:
    """The dataset folder, the output tree, the subjects of ``path`` (see module doc) and what
    the queue leaves out, from one search of the dataset folder.

    Raises
    ------
    DatasetError
        A tree without any subject folder.
    FileFormatError
        An output tree whose summary is damaged (:func:`solver.outputs.read_summary`).
    """
    p = Path(path).resolve()
    if (p / SUMMARY_NAME).is_file():
        summary = read_summary(p)
        dataset = Path(summary["dataset"])
        rels = [s["rel"] for s in summary["subjects"]]
        subjects = tuple(QueueSubject(r, dataset.joinpath(*PurePosixPath(r).parts), p.joinpath(*PurePosixPath(r).parts)) for r in rels)
        scan = scan_dataset(dataset, exclude=(p,)) if dataset.is_dir() else None  # gone: an output tree moved without it
        return OpenedDataset(dataset, p, subjects, _notes(scan))
    out = Path(out_dir).resolve() if out_dir is not None else dataset_output_dir(p)
    scan = scan_dataset(p, exclude=(out,))
    return OpenedDataset(p, out, tuple(QueueSubject(s.rel, s.path, s.out_dir(out)) for s in scan.require_subjects(p)), _notes(scan))


def dataset_subjects(path: str | Path, out_dir: str | Path | None = None) -> tuple[Path, Path, tuple[QueueSubject, ...]]:
    """The dataset folder, the output tree and the subjects of ``path`` (:func:`open_dataset`
    without its notes).

    Raises
    ------
    DatasetError
        A tree without any subject folder.
    """
    opened = open_dataset(path, out_dir)
    return opened.dataset_dir, opened.out_dir, opened.subjects


def _notes(scan: DatasetScan | None) -> tuple[str | None, tuple[str, ...]]:
    """What below the dataset folder the queue leaves out, for the reviewer, from the search
    of the dataset folder (None: the folder is gone, an output tree moved without it).

    The ``.b3d`` files outside subject folders are not subject folders: the dataset run
    does not process them and the queue does not list them. Symbolic links leading back to a
    folder above them (a loop) are not followed: a subject folder reached only through one
    is not in the queue.

    Returns
    -------
    note, run_notes
        A short note naming them (and the commands that take the files: ``addb convert``,
        ``addb view FOLDER``), None when there are none or no search; and the messages the
        dataset run gives its user about the same files and links
        (:func:`solver.dataset.discover.b3d_note`, :func:`~solver.dataset.discover.loop_note`),
        so that a page showing both shows each once.
    """
    if scan is None:
        return None, ()
    parts = []
    if files := scan.b3d_files:
        parts.append(
            f"Not in the queue: {listed(files, 3)}, {counted(len(files), '.b3d file')} "
            "(no subject folder): `addb convert FILE.b3d --out SUBJECT_DIR` makes a subject folder of one, "
            "`addb view FOLDER` reviews a folder of them."
        )
    if scan.loops:
        parts.append(
            f"Not searched: {listed(list(scan.loops), 3)}, {counted(len(scan.loops), 'symbolic link')} leading back "
            "to a folder above (a loop)."
        )
    run_notes = tuple(n for n in (b3d_note(scan), loop_note(scan)) if n is not None)
    return (" ".join(parts) or None), run_notes


def _review_state(snapshot: Any | None) -> tuple[str, str | None]:
    """(review state, who): who marked the trial reviewed (and who edited it since, if
    anyone: "alice, edited since by bob"), else everyone who edited it, the last editor
    first ("bob, alice")."""
    if snapshot is None:
        return UNREVIEWED, None
    edits = [r.provenance for r in (*snapshot.unmeasured_force, *snapshot.excluded)]
    edits += [n.provenance for n in snapshot.notes] + [a.provenance for a in snapshot.activities]
    edits = [e for e in edits if e is not None and e.source not in ("imported",)]
    if snapshot.reviewed:
        prov = snapshot.reviewed_provenance
        if prov is None:
            return REVIEWED, None
        later = sorted((e for e in edits if e.timestamp > prov.timestamp and e.reviewer != prov.reviewer),
                       key=lambda e: e.timestamp)  # fmt: skip
        if later:  # the mark may no longer hold: say so beside it, with everyone else who edited since
            return REVIEWED, f"{prov.reviewer}, edited since by {', '.join(dict.fromkeys(e.reviewer for e in later))}"
        return REVIEWED, prov.reviewer
    if edits or snapshot.reviewed_provenance is not None:
        if not edits:
            return IN_REVIEW, snapshot.reviewed_provenance.reviewer
        # everyone who edited it, the last editor first ("bob, alice"): a team sees who to ask
        latest = sorted(edits, key=lambda e: e.timestamp, reverse=True)
        return IN_REVIEW, ", ".join(dict.fromkeys(e.reviewer for e in latest))
    return UNREVIEWED, None


def _pending(row: Mapping[str, Any], snapshot: Any | None) -> int | None:
    if "proposed_ranges" not in row:
        return None
    n = int(row["frames"])
    proposed = np.zeros(n, bool)
    for a, b in row["proposed_ranges"]:
        proposed[a:b] = True
    if snapshot is None:
        return int(proposed.sum())
    from addb_viewer.app.flags import build_view

    return int(build_view(snapshot, proposed).pending.sum())


def _snapshots(subject: QueueSubject) -> dict[str, Any] | None:
    """Trial -> review snapshot of the subject's record ({} when it has none; None when it
    cannot be read: damaged, or from a newer addb)."""
    from annotations import AnnotationError, AnnotationStore

    path = annotations_path(subject.subject_dir, subject.out_dir)
    if not path.is_file():
        return {}
    try:
        with AnnotationStore.open(path, reviewer="addb queue") as store:
            return store.snapshot()
    except (AnnotationError, OSError):
        return None


def _results_row(res: Path) -> dict[str, Any] | None:
    """A queue row's figures from one trial's ``results.json`` (None when unreadable or
    the trial has no ``trial.npz``)."""
    if not (res.parent / "trial.npz").is_file():
        return None
    try:
        m = json.loads(res.read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(m, dict):
        return None
    dyn = "n_observed_frames" in m
    return {
        "trial": res.parent.name, "status": "ok" if dyn else "kinematics_only", "frames": m.get("n_frames", 0),
        "measured_frames": m.get("n_observed_frames", 0), "marker_rms_m": m.get("marker_rms_m"),
        "hicks_linear_ok": m.get("hicks_linear_ok"), "hicks_angular_ok": m.get("hicks_angular_ok"),
        "dynamics_error": dynamics_error_message(m),
    }  # fmt: skip


def output_problem(trial_dir: Path, check_json: bool = True) -> str | None:
    """What is wrong with a processed trial's output folder ``trial_dir`` (``OUT/<trial>``),
    None when it can be opened: its ``trial.npz`` or ``results.json`` missing or empty (the
    rule of :func:`solver.dataset.manifest.lost_trials`), or (``check_json``) its
    ``results.json`` not a JSON object. The text names the file (its name first, for the
    queue's narrow state column; its full path last), what is wrong and the fix."""
    for name in ("trial.npz", "results.json"):
        f = trial_dir / name
        if not f.is_file():
            return f"{name} is missing: process the subject again ({f})"
        if f.stat().st_size == 0:
            return f"{name} is empty: process the subject again ({f})"
    if not check_json:
        return None
    res = trial_dir / "results.json"
    try:
        ok = isinstance(json.loads(res.read_text()), dict)
        why = "not a JSON object"
    except ValueError as exc:
        ok, why = False, f"not valid JSON ({getattr(exc, 'msg', exc)}, line {getattr(exc, 'lineno', '?')})"
    except OSError as exc:
        ok, why = False, f"cannot be read ({exc.strerror or exc})"
    return None if ok else f"results.json is damaged, {why}: process the subject again ({res})"


def _lost_row(trial: str, problem: str) -> dict[str, Any]:
    """A manifest row for a trial whose output is lost: no figures (they would be stale)."""
    return {"trial": trial, "status": OUTPUT_LOST, "frames": 0, "measured_frames": 0, "marker_rms_m": None,
            "hicks_linear_ok": None, "hicks_angular_ok": None, "output_problem": problem}  # fmt: skip


def _proposed(npz: Path) -> NDArray[np.bool_] | None:
    """``(T,)`` the frames a trial's fit proposes as unmeasured, from its ``trial.npz`` (None
    when it cannot be read or has none)."""
    try:
        with np.load(npz) as z:
            return np.asarray(z["proposed"], dtype=bool).reshape(-1)
    except (OSError, KeyError, ValueError):
        return None


#: The figures of a manifest's trial row that a later Reprocess (which rewrites the trial's
#: results.json and trial.npz, not the dataset run's manifest) replaces; its proposals too.
_REPROCESSED = ("status", "measured_frames", "marker_rms_m", "hicks_linear_ok", "hicks_angular_ok", "dynamics_error")


def _rows_of_output(subject: QueueSubject) -> tuple[str, str, list[dict[str, Any]]]:
    """(processing state, detail, trial rows) from a subject's output folder: the dataset
    run's manifest, with the figures of each trial whose results.json is newer (the review
    app's Reprocess) taken from there, and its proposals from the trial.npz beside it; a
    trial whose output is missing, empty or damaged since (:func:`output_problem`) gets a
    row with status :data:`OUTPUT_LOST`, no figures and the problem. Without a manifest,
    the results.json files."""
    manifest = read_manifest(subject.out_dir)
    if manifest is not None:
        if manifest.get("status") == "failed":
            err = manifest.get("error") or {}
            where = ":".join(str(x) for x in (err.get("path"), err.get("line")) if x is not None)
            return FAILED, f"{err.get('type')}: {err.get('message')}" + (f" ({where})" if where else ""), []
        rows = [dict(r) for r in manifest.get("trials") or []]
        written = (subject.out_dir / MANIFEST_NAME).stat().st_mtime_ns
        for i, r in enumerate(rows):
            res = subject.out_dir / str(r.get("trial")) / "results.json"
            newer = res.is_file() and res.stat().st_mtime_ns > written  # Reprocessed, or damaged, since the run
            # the rule of lost_trials (stat only), and a results.json changed since the run that is no JSON object
            if (problem := output_problem(res.parent, check_json=newer)) is not None:
                rows[i] = _lost_row(str(r.get("trial")), problem)
            elif newer and (new := _results_row(res)) is not None:
                r.update({k: new[k] for k in _REPROCESSED})
                if (proposed := _proposed(res.parent / "trial.npz")) is not None:  # its fit's proposals
                    r["frames"], r["proposed_ranges"] = len(proposed), proposed_ranges(proposed)
        return PROCESSED, "", rows
    folders = sorted({f.parent for pattern in ("*/results.json", "*/trial.npz") for f in subject.out_dir.glob(pattern)})
    rows = []
    for d in folders:  # a results.json read only once: its reason looked for when it cannot be
        problem = output_problem(d, check_json=False)
        row = _results_row(d / "results.json") if problem is None else None
        if row is None:
            row = _lost_row(d.name, problem or output_problem(d) or f"results.json is damaged: process the subject again ({d / 'results.json'})")
        rows.append(row)
    return (PROCESSED if rows else NOT_PROCESSED), "", rows


def build_queue(subjects: tuple[QueueSubject, ...], running: Mapping[str, str] | None = None) -> list[QueueRow]:
    """The queue rows of ``subjects``, sorted by :attr:`QueueRow.attention`.

    Parameters
    ----------
    subjects
        From :func:`dataset_subjects`.
    running
        Subject rel -> progress message, for subjects being processed now.
    """
    running = running or {}
    out: list[QueueRow] = []
    for subject in subjects:
        state, detail, rows = _rows_of_output(subject)
        if subject.rel in running and (state != PROCESSED or not rows):
            out.append(QueueRow(subject, None, PROCESSING, running[subject.rel]))
            continue
        if not rows:
            out.append(QueueRow(subject, None, state, detail))
            continue
        snaps = _snapshots(subject)
        for r in rows:
            snap = snaps.get(r["trial"]) if snaps is not None else None
            review, reviewer = _review_state(snap) if snaps is not None else (RECORD_UNREADABLE, None)
            # a subject processed again keeps its trials, reviews and figures (its earlier
            # output stays until the new one is in place), marked as processing
            processing = PROCESSING if subject.rel in running else PROCESSED if r["status"] == "ok" else KINEMATICS_ONLY
            failed = r.get("dynamics_error")
            detail = running.get(subject.rel) or (f"dynamics failed: {failed}" if failed else "")
            if r["status"] == OUTPUT_LOST and subject.rel not in running:  # being processed again: "processing"
                processing, detail = OUTPUT_LOST, r["output_problem"]
            out.append(QueueRow(
                subject, r["trial"], processing, detail, review, reviewer,
                _pending(r, snap) if snaps is not None else None, int(r.get("frames") or 0), int(r.get("measured_frames") or 0),
                r.get("marker_rms_m"), r.get("hicks_linear_ok"), r.get("hicks_angular_ok"),
            ))  # fmt: skip
    return sorted(out, key=lambda row: row.attention)


def next_to_review(
    rows: list[QueueRow],
    after: tuple[str, str | None] | None = None,
    order: list[tuple[str, str | None]] | None = None,
    visited: set[tuple[str, str | None]] | frozenset[tuple[str, str | None]] = frozenset(),
) -> QueueRow | None:
    """The next row that needs review after ``after`` (rel, trial) in queue order, wrapping
    around to the first; the first such row when ``after`` is no row (None, or a subject
    whose trial is not known yet). Repeated, it visits every row that needs review, and
    never returns ``after`` itself.

    ``order`` is the queue's order as the reviewer saw it when ``after`` was opened (keys
    ``(rel, trial)``; default: the order of ``rows``). Editing the trial on screen moves it
    in the queue (accepting its proposals sends it down), so "after" it is read in that
    order: the rows it had below it come next, not those it passed on its way down. Rows not
    in ``order`` (new since) come after it, in queue order.

    ``visited`` holds the rows opened since the reviewer started going round the queue:
    they are passed over while another row needs review, so a row that took a place above
    the one shown (a subject processed since, sorted high) is reached before any row is
    opened a second time (the explorer's report: R went round to the top again, skipping a
    trial processed meanwhile). The caller starts a new round (empties ``visited``) once
    the row returned is one of them."""
    by_key = {(r.subject.rel, r.trial): r for r in rows}
    keys = [k for k in (order or []) if k in by_key]
    keys += [k for k in by_key if k not in set(keys)]
    start = keys.index(after) + 1 if after in keys else 0
    waiting = [k for k in keys[start:] + keys[:start] if by_key[k].needs_review and k != after]
    fresh = [k for k in waiting if k not in visited]
    pick = fresh or waiting
    return by_key[pick[0]] if pick else None
