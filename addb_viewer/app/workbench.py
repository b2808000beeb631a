"""The review workbench: ``addb view DATASET_DIR``, a queue over a whole dataset.

A "Dataset queue" window floating over the top of the 3D view shows the queue (:mod:`addb_viewer.app.queue`):
every subject and trial with its processing state, review state, pending proposals,
Hicks verdicts and marker RMS, sorted by what needs attention. "Open" switches the app
to the chosen subject and trial (:meth:`ReviewApp.open_subject`); "Next trial to review"
(button, and the hotkey R) opens the first trial in queue order that is not reviewed.

Subjects without an up-to-date output are processed in the background by the dataset
runner (:func:`solver.dataset.runner.process_dataset`, a Dask LocalCluster of
``workers`` processes, by default one core fewer than the machine has so that the
reviewer's own Reprocess keeps a core) while the reviewer works on others; the queue
shows them as "processing" and refreshes as each one finishes. The queue is also read
again every few seconds, so reviews saved from another page or machine show up.

Below the run's status line the window names the ``.b3d`` files of the dataset, which are
not subject folders and so are neither processed nor listed, and the symbolic links the
search did not follow because they lead back to a folder above them (the notes of
:func:`addb_viewer.app.queue.open_dataset`, found in the same search of the dataset folder
as the subjects), and, while a background run goes on, what it tells its user (its Dask
dashboard, a subject retried after its worker died).
"""

from __future__ import annotations

import dataclasses
import os
import threading
from pathlib import Path
from typing import Any

from addb_viewer.app.paths import ReviewPaths
from addb_viewer.app.queue import (
    FAILED,
    PROCESSED,
    PROCESSING,
    REVIEWED,
    QueueRow,
    QueueSubject,
    build_queue,
    next_to_review,
    open_dataset,
)
from solver.dataset.manifest import PROCESSED_STATUSES

#: Size of the queue's floating window, px (narrower on a narrower canvas), and its gap
#: from the canvas' top-left corner.
QUEUE_WIDTH_PX = 620
QUEUE_HEIGHT_PX = 300
QUEUE_GAP_PX = 10
#: The narrowest the queue's window is made to fit a canvas, px.
QUEUE_MIN_WIDTH_PX = 120
#: A queue window narrower than this shows the compact table (:func:`queue_markdown`), px.
COMPACT_BELOW_PX = 520
#: What "Next trial to review" says when no trial needs review.
ALL_REVIEWED = "Every processed trial is reviewed."
#: Rows shown in the queue table (the dropdown lists them all).
TABLE_ROWS = 25
#: Seconds between two readings of the queue from disk.
REFRESH_S = 5.0
#: Hotkey of "Next trial to review" (not a camera key; free in the review panel).
NEXT_HOTKEY = "R"


def row_label(row: QueueRow) -> str:
    """The dropdown label of a queue row: ``rel / trial`` or ``rel (state)``."""
    return f"{row.subject.rel} / {row.trial}" if row.trial else f"{row.subject.rel} ({row.processing})"


def queue_markdown(rows: list[QueueRow], *, limit: int = TABLE_ROWS, current: tuple[str, str | None] | None = None,
                   compact: bool = False) -> str:
    """The queue as a markdown table (first ``limit`` rows) with a one-line summary.

    ``compact`` (a window narrower than :data:`COMPACT_BELOW_PX`) leaves out the state and
    RMS columns: a state other than "processed" follows the row's name instead."""
    n_trials = sum(r.trial is not None for r in rows)
    done = sum(r.review == REVIEWED for r in rows if r.trial is not None)
    # processing and failed count subjects (a subject processed again keeps its trial rows),
    # reviewed counts trials
    waiting = len({r.subject.rel for r in rows if r.processing == PROCESSING})
    failed = len({r.subject.rel for r in rows if r.processing == FAILED})
    states = [f"{n} {what}" for n, what in ((waiting, "processing"), (failed, "failed")) if n]
    head = f"**{len({r.subject.rel for r in rows})} subjects" + (f" ({', '.join(states)})" if states else "")
    head += f", {n_trials} trials: {done} reviewed"
    columns = ("subject / trial", "review", "pending", "Hicks RMS") if compact else (
        "subject / trial", "state", "review", "pending", "Hicks RMS", "RMS cm")
    lines = [head + "**", "", "| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for row in rows[:limit]:
        name = _md(row_label(row) if row.trial else row.subject.rel)
        name = f"**▶ {name}**" if current == (row.subject.rel, row.trial) else name
        review = row.review + (f" ({row.reviewer})" if row.reviewer else "") if row.trial else "-"
        hicks = "-" if row.hicks_linear_ok is None else ("ok" if row.hicks_linear_ok and row.hicks_angular_ok is not False else "over")
        state = row.processing + (f": {row.detail}" if row.detail else "")
        rms = "-" if row.marker_rms_m is None else f"{100 * row.marker_rms_m:.2f}"
        pending = "-" if row.pending is None or row.processing != PROCESSED else str(row.pending)
        if compact:
            name += "" if row.processing == PROCESSED else f" ({_md(state[:60])})"
            lines.append(f"| {name} | {_md(review)} | {pending} | {hicks} |")
        else:
            lines.append(f"| {name} | {_md(state[:80])} | {_md(review)} | {pending} | {hicks} | {rms} |")
    if len(rows) > limit:
        lines.append(f"\n… and {len(rows) - limit} more in the list below.")
    return "\n".join(lines)


def _md(text: str) -> str:
    return text.replace("|", "\\|").replace("<", "&lt;")


class Workbench:
    """The dataset queue of a :class:`~addb_viewer.app.server.ReviewApp`.

    Parameters
    ----------
    app
        The review app (created with ``process_missing=False``).
    dataset_dir, out_dir
        The dataset (a tree of subject folders, or a dataset output tree) and its output
        tree (None: :func:`addb_viewer.app.queue.dataset_output_dir`).
    workers
        Worker processes of the background dataset run; 0: no background processing.
    """

    def __init__(self, app: Any, dataset_dir: str | Path, out_dir: str | Path | None = None, *, workers: int | None = None) -> None:
        self.app = app
        self._given = (dataset_dir, out_dir)  # as asked: the subject folders are read again from them
        opened = open_dataset(dataset_dir, out_dir)  # one search of the dataset folder: subjects and notes
        self.dataset_dir, self.out_dir, self.subjects = opened.dataset_dir, opened.out_dir, opened.subjects
        self.by_rel = {s.rel: s for s in self.subjects}
        self.running: dict[str, str] = {}
        self.progress_seen: list[tuple[str, float]] = []  # (subject, fraction) as reported
        self.rows: list[QueueRow] = []
        self.labels: dict[str, tuple[str, str | None]] = {}
        self.current: tuple[str, str | None] | None = None
        self._order: list[tuple[str, str | None]] = []  # the queue order when the trial on screen was opened
        self._visited: set[tuple[str, str | None]] = set()  # rows opened in this round of the queue (next_to_review)
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self.processing_done = threading.Event()
        self._planned = False  # whether the background run going has said which subjects it processes
        self._dataset_note: tuple[str | None, tuple[str, ...]] = (None, ())  # the .b3d files and loops left out (OpenedDataset.notes)
        self._run_notes: list[str] = []  # what the running background run told its user
        gui = app.server.gui
        # a window of its own floating over the top of the 3D view (the subject is framed
        # below it), movable and minimizable; not a tab beside the timeline, whose charts
        # would be drawn while hidden, at zero width
        self.panel = gui.add_panel()
        with self.panel.add_tab("Dataset queue"):
            # the controls first: on a narrow window the table wraps and scrolls below them
            self.choice = gui.add_dropdown("Open", ("(none)",), initial_value="(none)")
            self.next_button = gui.add_button("Next trial to review", hint=f"hotkey {NEXT_HOTKEY}")
            self.again_button = gui.add_button(
                "Process changed subjects",
                hint="run the background processing again: subjects whose inputs or review changed "
                "(a failed subject after its files were mended) are processed, the others skipped",
            )
            self.run_status = gui.add_markdown("")
            self.notes = gui.add_markdown("")
            self.table = gui.add_markdown("Reading the dataset…")
        self.panel.float(x=QUEUE_GAP_PX, y=QUEUE_GAP_PX, width=QUEUE_WIDTH_PX, height=QUEUE_HEIGHT_PX)
        self.width = float(QUEUE_WIDTH_PX)
        app.cameras.canvas_top_px = QUEUE_GAP_PX + QUEUE_HEIGHT_PX  # the camera frames the subject below the window
        self.command = gui.add_command("Next trial to review", description="open the next trial that needs review", hotkey=NEXT_HOTKEY)  # type: ignore[arg-type]
        guard = app._guard
        self.choice.on_update(guard("Open", lambda e: self._chosen(e.target.value)))
        self.next_button.on_click(guard("Next trial to review", lambda e: self.open_next()))
        self.again_button.on_click(guard("Process changed subjects", lambda e: self.process_again()))
        self.command.on_trigger(guard("Next trial to review", lambda e: self.open_next()))
        app.workbench = self
        self._dataset_note = opened.notes
        self._draw_notes()
        self.refresh()
        n = (os.cpu_count() or 2) - 1 if workers is None else workers
        self.workers = max(n, 0)
        if n > 0:
            threading.Thread(target=self._process, args=(max(n, 1),), name="addb-dataset", daemon=True).start()
        else:
            self.processing_done.set()
        threading.Thread(target=self._poll, name="addb-queue", daemon=True).start()

    def fit_to_canvas(self, canvas_width: float) -> None:
        """Make the queue's window no wider than ``canvas_width`` (the narrowest 3D canvas
        of the open pages, px) less its gaps, so it never covers the docked panels beside
        the canvas (the window is one for all pages)."""
        width = float(min(QUEUE_WIDTH_PX, max(QUEUE_MIN_WIDTH_PX, canvas_width - 2 * QUEUE_GAP_PX)))
        with self._lock:  # the table drawn for the new width before the width is published
            if abs(width - self.width) < 1.0:
                return
            if (self.width < COMPACT_BELOW_PX) != (width < COMPACT_BELOW_PX):
                self._draw_table(width)
            self.width = width
        self.panel.set_width(width)

    def _draw_table(self, width: float | None = None) -> None:
        """Show :attr:`rows` in the queue's table (compact in a window narrower than
        :data:`COMPACT_BELOW_PX`; ``width`` default :attr:`width`); call with ``_lock`` held."""
        width = self.width if width is None else width
        self.table.content = queue_markdown(self.rows, current=self.current, compact=width < COMPACT_BELOW_PX)

    # ------------------------------------------------------------------ queue
    def refresh(self) -> list[QueueRow]:
        """Read the queue again from disk and redraw it."""
        with self._lock:
            shown = getattr(self.app, "trial", None)
            if self.current is not None and shown is not None:
                # the subject's trial has loaded since it was opened, or the reviewer picked
                # another in the Playback folder's Trial list
                self.current = (self.current[0], shown.trial)
            rows = build_queue(self.subjects, dict(self.running))
            self.rows = rows
            self._forget_all_reviewed(rows)
            self.labels = {row_label(r): (r.subject.rel, r.trial) for r in rows}
            self._draw_table()
            options = ("(none)", *self.labels)
            value = next((k for k, v in self.labels.items() if v == self.current), "(none)")
            new_options = tuple(self.choice.options) != options
            if new_options or self.choice.value != value:
                with self.app._quiet_updates():
                    if new_options:
                        self.choice.options = options
                    self.choice.value = value  # also after R or a background open: the dropdown names the trial shown
            return rows

    def rediscover(self) -> None:
        """Read the dataset's subject folders again: a subject folder added (or removed)
        since the app started joins the queue (the background run finds it as it scans
        the dataset)."""
        opened = open_dataset(*self._given)
        with self._lock:
            self.subjects, self.by_rel = opened.subjects, {s.rel: s for s in opened.subjects}
            self._dataset_note = opened.notes
            self._draw_notes()

    def _draw_notes(self) -> None:
        """Show the dataset's note and the running background run's notes, each once."""
        with self._lock:
            note, run_notes = self._dataset_note
            shown = [note] if note else []
            shown += [n for n in dict.fromkeys(self._run_notes) if n not in run_notes]  # the files named once
            self.notes.content = "\n\n".join(_md(n) for n in shown)

    def _run_note(self, message: str) -> None:
        """A message of the background run for its user (``log`` of the dataset runner); shown
        until the run ends (its dashboard closes with it)."""
        with self._lock:
            self._run_notes.append(message)
            self._draw_notes()

    def _poll(self) -> None:
        while not self._stop.wait(REFRESH_S):
            try:
                self.refresh()
            except Exception as exc:  # noqa: BLE001 - shown in the page, the poll goes on
                self.run_status.content = f"queue not refreshed: {exc}"

    # ------------------------------------------------------------------ opening
    def open(self, rel: str, trial: str | None = None) -> None:
        """Show subject ``rel`` (its ``trial``, default the preferred one) in the app."""
        subject: QueueSubject = self.by_rel[rel]
        paths = ReviewPaths.for_subject(subject.subject_dir, subject.out_dir)
        self.current = (rel, trial)
        if trial is not None and self._shown(paths) and trial in self.app.trials:
            # another trial of the subject on screen: its review record (and the undo
            # history in it) stays open, a running Reprocess goes on; a trial that cannot be
            # read shows no trial (not the one before) and the error naming its file
            self.app.show_trial(trial)
        else:
            self.app.open_subject(paths, trial)
            if self.app.trial is None and subject.rel in self._failed:
                self.app.set_status(  # the path breaks anywhere: its line number stays in the panel
                    f"**{rel}** failed: <span style='overflow-wrap:anywhere'>{_md(self._failed[subject.rel])}</span>"
                )
        if self.app.trial is not None:
            self.current = (rel, self.app.trial.trial)
        self._visited.add(self.current)
        self._order = [(r.subject.rel, r.trial) for r in self.refresh()]  # as the reviewer sees it now

    def _shown(self, paths: ReviewPaths) -> bool:
        """Whether ``paths`` is the subject on screen (same subject and output folders)."""
        now = self.app.paths
        return (Path(now.subject_dir).resolve(), Path(now.out_dir).resolve()) == (
            Path(paths.subject_dir).resolve(), Path(paths.out_dir).resolve())  # fmt: skip

    @property
    def _failed(self) -> dict[str, str]:
        """The failed subjects' errors in full, by their place in the dataset (the queue's
        table shows the first 80 characters)."""
        return {r.subject.rel: r.detail for r in self.rows if r.processing == FAILED}

    def open_next(self) -> QueueRow | None:
        """Open the next trial that needs review (after the one shown); None when none."""
        row = next_to_review(self.refresh(), after=self.current, order=self._order, visited=self._visited)
        if row is None:
            self.run_status.content = ALL_REVIEWED
            return None
        if (row.subject.rel, row.trial) in self._visited:  # every row needing review opened: a new round
            self._visited.clear()
        self.open(row.subject.rel, row.trial)
        return row

    def _forget_all_reviewed(self, rows: list[QueueRow]) -> None:
        """Take back "Every processed trial is reviewed." once the queue has a trial to review
        again (a trial unticked, a subject processed since)."""
        if self.run_status.content == ALL_REVIEWED and next_to_review(rows, after=None) is not None:
            self.run_status.content = ""

    def _chosen(self, label: str) -> None:
        if label in self.labels and self.labels[label] != self.current:
            self.open(*self.labels[label])

    # ------------------------------------------------------------------ background processing
    def process_again(self) -> bool:
        """Run the background processing again (the "Process changed subjects" button): the
        dataset runner processes the subjects whose inputs or review changed since their
        output (a failed subject whose files were mended, a review edited here) and skips
        the others. Returns whether a run started; not while one runs, nor with no workers
        (``--workers 0``: the page says so)."""
        if self.workers <= 0:
            self.run_status.content = "This server processes nothing in the background (`--workers 0`)."
            return False
        with self._lock:
            if not self.processing_done.is_set():
                self.run_status.content = "Background processing is running already."
                return False
            if self.app.jobs.running:  # it could process the subject that run writes
                self.run_status.content = "A solver run of the subject on screen is in progress; press again once it ends."
                return False
            self._planned = False
            self.processing_done.clear()
        self.run_status.content = "Background processing: starting…"
        try:
            self.rediscover()  # subject folders added since
        except Exception as exc:  # noqa: BLE001 - the run reads the dataset itself and says what fails
            self.run_status.content = f"Background processing: starting (the queue's subject list not read again: {exc})…"
        threading.Thread(target=self._process, args=(self.workers,), name="addb-dataset", daemon=True).start()
        return True

    def _process(self, workers: int) -> None:
        from addb_viewer.review_masks import review_digest, subject_masks
        from solver.dataset.runner import DatasetOptions, process_dataset

        def event(kind: str, data: dict[str, Any]) -> None:
            if kind == "queued" and not set(data["rels"]) <= set(self.by_rel):
                self.rediscover()  # the run found subject folders the queue has not listed yet
            with self._lock:
                if kind == "queued":
                    self.running.update(dict.fromkeys(data["rels"], "queued"))
                    self._planned = True
                elif kind == "done":
                    self.running.pop(data["rel"], None)
                elif kind == "progress" and data.get("rel") in self.running:
                    self.running[data["rel"]] = f"{100 * data['fraction']:.0f} %: {data['message']}"
                    self.progress_seen.append((data["rel"], float(data["fraction"])))
                    # only that row's text changed: redraw from the rows in memory (no disk reads)
                    self.rows = [dataclasses.replace(r, detail=self.running[data["rel"]])
                                 if r.subject.rel == data["rel"] and r.processing == PROCESSING else r
                                 for r in self.rows]  # fmt: skip
                    self._draw_table()
                    return
            self.refresh()
            if kind == "done" and self.current is not None and self.current[0] == data["rel"]:
                if self.app.trial is None:
                    self.open(data["rel"])  # the subject on screen was waiting for its output
                elif data.get("status") in PROCESSED_STATUSES:  # its output was rewritten
                    self.app.panel.comparison.content = ""  # an earlier Reprocess's table: no longer the output
                    self.app.reload_shown(
                        f"{data['rel']} was processed again in the background (its inputs or its review changed): "
                        "the trial shown was reloaded with the new results."
                    )
                elif data.get("status") == "failed":  # the page still shows the output it had before
                    self.app.show_error(
                        f"{data['rel']} failed when processed again in the background; the trial shown is its "
                        "earlier output",
                        self._failed.get(data["rel"], "see the dataset queue"),
                    )

        try:
            dataset = self.dataset_dir
            run = process_dataset(
                dataset, self.out_dir, options=DatasetOptions(workers=workers), masks=subject_masks,
                review_digest=review_digest, events=event, stop=self._stop, log=self._run_note,
                progress=lambda m, f: setattr(self.run_status, "content", f"Background processing: {m}"),
            )  # fmt: skip
            # the counts, each kind apart (solver.dataset.runner.subject_counts): a run with
            # nothing to do said only "finished in 0 s", as the run before it, and a failed
            # subject was also counted as processed
            c = run.counts
            self.run_status.content = (
                f"Background processing finished in {run.seconds:.0f} s: {c['processed']} subject(s) processed, "
                f"{c['up_to_date']} up to date" + (f"; {c['failed']} failed" if c["failed"] else "")
                + (f"; {c['cancelled']} cancelled" if c["cancelled"] else "") + "."
            )  # fmt: skip
        except Exception as exc:  # noqa: BLE001 - shown in the page
            self.run_status.content = f"Background processing stopped: {exc}"
        finally:
            with self._lock:
                self.running.clear()
                self._run_notes = []  # about the run that ended: its dashboard is gone
                self._draw_notes()
            self.processing_done.set()
            if not self._stop.is_set():
                self.refresh()

    def background_state(self, out_dir: str | Path) -> str | None:
        """What this workbench's background run does to the subject whose output folder is
        ``out_dir``: None when no run is going (nor the tree's lock held by one); "starting"
        before the run has said which subjects it processes; "queued" when it processes this
        one (queued or running); "other" when it goes on without it. A run going holds the
        output tree's lock (:func:`solver.dataset.lock.output_tree_lock`) in this process, so
        the page's own solver runs (:mod:`addb_viewer.app.reprocess`) ask here instead."""
        target = Path(out_dir).resolve()
        with self._lock:
            if self.processing_done.is_set():
                return None
            if not self._planned:
                return "starting"
            rel = next((s.rel for s in self.subjects if Path(s.out_dir).resolve() == target), None)
            return "queued" if rel in self.running else "other"

    def stop(self) -> None:
        """Cancel the background run (subjects not finished keep their old output)."""
        self._stop.set()
        self.processing_done.wait(timeout=60)
