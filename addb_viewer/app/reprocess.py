"""Solver runs started from the page (first processing of a subject, Reprocess of a trial)
and the "Record to Rerun" export, with their progress, cancel and results in the panel.

One run at a time. A Reprocess gives the solver the reviewer's flags of unmeasured force
(:func:`addb_viewer.review_masks.unmeasured_force`: the trials flagged or marked reviewed, at
their processed frames) and the trial's name; the solver reruns the dynamics stage only, on the
kinematics cached by the last full run (:func:`solver.pipeline.reprocess_dynamics`). That stage
fits the body mass and the segment masses over every trial with force plates, and the scaled
model it writes carries them, so the run rewrites the folder of every such trial
(:func:`dynamics_trials`), not only the edited one: a trial left as it was would hold joint
torques made with the old masses beside the new model. Each folder (plus the model and
subject.json) is replaced in the output folder when the run succeeds; the app then reloads
the trial at the same frame and shows the before/after table. A failed or cancelled run leaves the previous
result on screen and on disk, and says why in the page.
"""

from __future__ import annotations

import html
import json
import threading
import time
import zipfile
import zlib
from contextlib import ExitStack
from dataclasses import replace
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from addb_viewer.app.diagnosis import kept_reports, restore_reports
from addb_viewer.app.flags import FlagView, build_view, pending_replaced
from addb_viewer.app.jobs import JobResult, JobSpec, SolverJob, new_work_dir, prestart_solver
from addb_viewer.app.summary import comparison_markdown, trial_summary
from annotations import AnnotationError, AnnotationStore
from solver.errors import AddbError

#: How often a run waiting for the background run's plan asks again, s.
PLAN_POLL_S = 0.2


def apply_refusal(subject_dir: Path) -> str | None:
    """Why "Apply the named cause and reprocess" cannot save a correction in ``subject_dir``
    (markdown), None when it can: the correction goes into the subject folder
    (``addb_extensions.json``), so a read-only folder and the bundled demo (package data,
    :func:`addb_viewer.locations.uses_subject_folder`) are refused before anything runs."""
    from addb_viewer.locations import is_bundled_demo
    from solver.io.subject import folder_is_writable

    subject = Path(subject_dir).resolve()
    if is_bundled_demo(subject):
        return ("the bundled demo is package data and is not changed: copy its folder "
                f"({subject}) to a folder you can write to, open the copy and apply there")  # fmt: skip
    if not folder_is_writable(subject):
        return "the subject folder is read-only: copy the subject to a folder you can write to, open the copy and apply there"
    return None


class ReprocessHost(Protocol):
    """What the reprocessor needs from the app (:class:`~addb_viewer.app.server.ReviewApp`
    implements it); the reprocessor imports nothing of the server."""

    paths: Any
    store: AnnotationStore | None
    trial: Any
    view: Any  # the shown trial's FlagView (None without a review record)
    trials: list[str]
    panel: Any
    playback: Any
    geometry: Any
    ready: threading.Event

    def set_status(self, text: str) -> None:
        """Replace the status line at the top of the panel with ``text``."""
        ...
    def show_error(self, context: str, exc: BaseException | str) -> None:
        """Show ``exc`` in the page under the heading ``context`` (what was being done)."""
        ...
    def after_processing(self) -> None:
        """Take up the output folder once the first processing run has written it."""
        ...
    def load_trial(self, name: str, *, frame: int = 0) -> None:
        """Load ``OUT/<name>`` and show it from ``frame``."""
        ...

    def reload_shown(self, why: str) -> None:
        """Load the shown trial again from the output folder at the frame shown; say ``why``."""
        ...

    def clear_error(self) -> None:
        """Hide the page's error area."""
        ...

    def show_diagnosis(self, trial: str | None) -> None:
        """Show ``trial``'s diagnosis report when that trial is on screen (None: nothing)."""
        ...
    def set_trial_options(self, selected: str) -> None:
        """Fill the trial list with :attr:`trials` and select ``selected``."""
        ...

    def background_run(self) -> str | None:
        """What a dataset's background run does to the subject shown: None (none goes),
        "starting", "queued" (it processes this subject) or "other" (it holds the output tree
        and goes on without this subject)."""
        ...


def _recorded_masses(out_dir: str | Path) -> dict[str, Any]:
    """Trial name -> the ``mass_kg`` of its ``results.json``, for the output's trials whose
    results record one (the trials with dynamics), in name order; unreadable files left out."""
    masses = {}
    for path in sorted(Path(out_dir).glob("*/results.json")):
        try:
            results = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        if isinstance(results, dict) and "mass_kg" in results:
            masses[path.parent.name] = results["mass_kg"]
    return masses


def dynamics_trials(subject_dir: str | Path, out_dir: str | Path) -> list[str]:
    """The output's trials with dynamics (a ``mass_kg`` in their ``results.json``) that are
    still trials of the subject (a folder ``SUBJECT/trials/<name>``), sorted: those a
    Reprocess rewrites, since the dynamics stage fits the body mass and the segment masses
    over all of them and writes one scaled model for all (:mod:`addb_viewer.app.reprocess`)."""
    return [name for name in _recorded_masses(out_dir) if (Path(subject_dir) / "trials" / name).is_dir()]


def written_trials(subject_dir: str | Path, out_dir: str | Path, trial: str) -> tuple[str, ...]:
    """The trials a Reprocess of ``trial`` writes: ``trial`` first, then every other trial
    with dynamics (:func:`dynamics_trials`)."""
    return (trial, *[t for t in dynamics_trials(subject_dir, out_dir) if t != trial])


def other_mass_trials(out_dir: str | Path, trial: str, mass_kg: float) -> list[tuple[str, float]]:
    """The output's trials other than ``trial`` whose dynamics were made with another body
    mass than ``mass_kg`` (their ``results.json`` ``mass_kg``, rounded to 0.01 kg), as
    ``(name, mass)``. A Reprocess rewrites every trial with dynamics (:func:`dynamics_trials`),
    so this is empty after one, unless a trial's folder is left in the output while the
    subject no longer has that trial."""
    return [
        (name, float(mass))
        for name, mass in _recorded_masses(out_dir).items()
        if name != trial and isinstance(mass, int | float) and round(float(mass), 2) != round(float(mass_kg), 2)
    ]


def already_saved(subject_dir: str | Path, entry: dict) -> bool:
    """Whether the subject's ``addb_extensions.json`` holds ``entry`` already (every field of
    the diagnosis' entry equal; the file adds ``source`` and ``created``). An unreadable file
    counts as not holding it (saving then says why)."""
    from solver.corrections import read_extensions

    try:
        saved = read_extensions(subject_dir)
    except AddbError:
        return False
    return any(all(s.get(k) == v for k, v in entry.items()) for s in saved)


CONFIRM_AFTER_S = 1.0
"""Least time between the pending-proposal warning and the press that goes ahead, s."""


def output_view(store: AnnotationStore, out_dir: str | Path, trial: str) -> FlagView | None:
    """:class:`~addb_viewer.app.flags.FlagView` of ``trial`` as the store holds it, against
    the proposals of its processed output (``OUT/<trial>/trial.npz``, ``proposed``): the
    review state of a trial that is not on screen. None when that output cannot be read (no
    file, damaged, without the array), or the store refuses the trial
    (:class:`annotations.AnnotationError`)."""
    path = Path(out_dir) / trial / "trial.npz"
    try:
        with np.load(path, allow_pickle=False) as npz:
            proposed = np.asarray(npz["proposed"], dtype=bool)
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error):  # as load_processed's damaged file
        return None
    if proposed.ndim != 1:
        return None
    try:
        return build_view(store.review(trial), proposed)
    except AnnotationError:
        return None


def _pending_count(pending: list[tuple[str, int]]) -> str:
    """"11 proposed frames of walk" or "14 proposed frames (walk 11, run 3)"."""
    if len(pending) == 1:
        trial, n = pending[0]
        return f"{n} proposed frames of {trial} are"
    parts = ", ".join(f"{trial} {n}" for trial, n in pending)
    return f"{sum(n for _, n in pending)} proposed frames ({parts}) are"


def _pending_warning(name: str, pending: list[tuple[str, int]]) -> str:
    """The first press's warning of a Reprocess of ``name`` that would fit ``pending``
    (``(trial, frames)``) as measured frames (markdown)."""
    others = [trial for trial, _ in pending if trial != name]
    also = ""
    if others:
        also = (f" A Reprocess of {name} fits {', '.join(others)} again too (the body mass and the segment masses "
                "are fitted over every trial with force plates).")
    whose = "trial's" if len(pending) == 1 else "trials'"
    return (
        f"<span style='color:#c00'>**{_pending_count(pending)} still pending.**</span>{also} The "
        f"{whose} flags replace the solver's own choice, so Reprocess fits them as measured frames (with the "
        "plates' force, often none: marker and residual errors rise). Accept or reject them first (All "
        "proposals), or press Reprocess again to fit them as measured."
    )


class SecondThought:
    """A press that warns first and goes ahead when pressed again about the same thing
    (``key``, e.g. the trial and its pending frames) at least :data:`CONFIRM_AFTER_S` later:
    a double click is not a second thought. Reprocess and "Trial reviewed" with pending
    proposals use it."""

    def __init__(self) -> None:
        self.key: Any = None  # what the last warning named (None: no warning standing)
        self.at = 0.0  # time.monotonic() of that warning

    def confirmed(self, key: Any) -> bool:
        """Whether this press about ``key`` goes ahead; a first press (or one about
        something else) is remembered as warned and does not."""
        now = time.monotonic()
        if self.key == key and now - self.at >= CONFIRM_AFTER_S:
            self.key = None
            return True
        if self.key != key:
            self.key, self.at = key, now
        return False

    def forget(self) -> None:
        """No warning standing (nothing to warn about any more)."""
        self.key = None


class Reprocessor:
    """The solver-run controls of the review app (a :class:`ReprocessHost`)."""

    def __init__(self, app: ReprocessHost) -> None:
        self.app = app
        self.job: SolverJob | None = None
        self._lock = threading.Lock()
        self.last_result: JobResult | None = None
        self.finished = threading.Event()
        self.pending_warning = SecondThought()  # Reprocess with pending proposals: ((trial, pending frames), ...)
        self._review: str | None | bool = False  # the flags' digest when the running Reprocess started
        self._tree = ExitStack()  # the output tree held by the run going (_hold_output_tree)
        self._kept: dict[str, tuple[bytes, int]] = {}  # the diagnosis reports of the trials a Reprocess rewrites
        self._waiter: tuple[threading.Event, threading.Thread] | None = None  # a run waiting for the background plan
        prestart_solver(app.paths.jobs_dir)  # the first Reprocess finds the solver's imports done (jobs.py)

    @property
    def running(self) -> bool:
        """Whether a solver run is in progress, or waiting to start until the page's
        background run says which subjects it processes (:meth:`_wait_for_plan`)."""
        return self._waiter is not None or (self.job is not None and self.job.running)

    # ------------------------------------------------------------------ starting
    def process_subject(self) -> None:
        """Process the whole subject into the output folder (first start)."""
        paths = self.app.paths
        spec = JobSpec(paths.subject_dir, paths.out_dir, None, self._masks(), review_record=self._record())
        self._start(spec, new_work_dir(paths.jobs_dir, "process"), label="Processing the subject", trial=None)

    def reprocess(self, trial: str | None = None) -> None:
        """Run the solver on ``trial`` (default: the one shown) with the current flags.

        When some trial the run rewrites (:func:`written_trials`: the one shown, or any other
        with dynamics) has flags that replace the solver's proposals while some proposals
        are still pending (:func:`~addb_viewer.app.flags.pending_replaced`), the first press
        says so and starts nothing; pressed again with the same pending frames, at least
        :data:`CONFIRM_AFTER_S` later (a double click is not a second thought), it runs."""
        app = self.app
        selected = app.panel.trial.value if app.panel.trial.value in app.trials else None
        name = trial or (app.trial.trial if app.trial is not None else selected)
        if name is None:
            self._say("No trial to reprocess.")
            return
        # every trial with dynamics is rewritten, since the masses are fitted over all of them
        trials = written_trials(app.paths.subject_dir, app.paths.out_dir, name)
        pending = self._pending(trials)
        if pending and not self.pending_warning.confirmed(tuple(pending)):
            self._say(_pending_warning(name, pending))
            return
        self.pending_warning.forget()
        if self.running:  # before the reports of the running one's trials are read again
            self._say("A solver run is already in progress; cancel it first.")
            return
        work = new_work_dir(app.paths.jobs_dir, f"reprocess-{name}")
        # flags change the dynamics only: the child reuses the kinematics cached by the last
        # full run (a full run when that cache is missing or stale, e.g. after an extension)
        spec = JobSpec(app.paths.subject_dir, app.paths.out_dir, trials, self._masks(), dynamics_only=True,
                       review_record=self._record())
        self._review = self._review_digest()  # the flags this run takes, for a dataset run's manifest
        self._kept = kept_reports(app.paths.out_dir, trials)  # the solver rewrites those folders without them
        self._start(spec, work, label=f"Reprocessing {name}", trial=name)

    def diagnose(self, trial: str | None = None) -> None:
        """Run ``addb diagnose`` on ``trial`` (default: the one shown) with the reviewer's
        flags, in the background (progress and Cancel as for a Reprocess); the report
        appears in the Diagnosis folder when it ends."""
        app = self.app
        name = trial or (app.trial.trial if app.trial is not None else None)
        if name is None:
            self._say("No trial to diagnose.")
            return
        if app.trial is not None and app.trial.trial == name and not app.trial.has_dynamics:
            self._say(f"{name} has no dynamics (no force plates): nothing to diagnose.")
            return
        spec = JobSpec(app.paths.subject_dir, app.paths.out_dir, (name,), self._masks(), kind="diagnose")
        self._start(spec, new_work_dir(app.paths.jobs_dir, f"diagnose-{name}"), label=f"Diagnosing {name}",
                    trial=name, kind="diagnose")  # fmt: skip

    def apply_diagnosis(self, trial: str | None = None) -> dict | None:
        """Save the extension the trial's diagnosis chose (``addb diagnose --apply``) and
        reprocess the trial with it (the before/after table follows); returns the saved
        entry, None when the diagnosis named no cause."""
        from solver.corrections import save_extension

        app = self.app
        name = trial or (app.trial.trial if app.trial is not None else None)
        if name is None:
            self._say("No trial shown.")
            return None
        refused = apply_refusal(app.paths.subject_dir)
        if refused is not None:
            self._say(f"<span style='color:#c00'>**Not applied**</span>: {html.escape(refused, quote=False)}")
            return None
        path = app.paths.out_dir / name / "diagnosis.json"
        try:
            report = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            self._say("Run the diagnosis first (Diagnose this trial).")
            return None
        entry = report.get("extension")
        if not entry:
            self._say("The diagnosis named no cause: nothing to apply.")
            return None
        # nothing is saved unless the Reprocess that uses it can start: a correction saved
        # twice (a second press while the first run goes on) is applied twice by every
        # later processing
        if self.running:
            self._say("A solver run is already in progress; the correction was not saved (press again once it ends).")
            return None
        pending = self._pending(written_trials(app.paths.subject_dir, app.paths.out_dir, name))
        if pending:
            self._say(
                f"<span style='color:#c00'>**{_pending_count(pending)} still pending**</span>: accept or reject them first "
                "(All proposals); the correction was not saved."
            )
            return None
        if already_saved(app.paths.subject_dir, entry):
            self._say(f"`{entry['cause']}` is already saved for this subject; reprocessing {name} with it…")
            self.reprocess(name)
            return None
        try:
            saved = save_extension(app.paths.subject_dir, entry)
        except (AddbError, OSError) as exc:  # beside the button, not only at the top of the panel
            self._say(f"<span style='color:#c00'>**Not applied**</span>: {html.escape(str(exc), quote=False)}")
            raise
        self._say(f"Saved `{entry['cause']}` in {saved.name}; reprocessing {name} with it…")
        self.reprocess(name)
        return entry

    def _pending(self, trials: tuple[str, ...]) -> list[tuple[str, int]]:
        """``(trial, frames)`` for each of ``trials`` with pending proposals that a run fits as
        measured frames (:func:`~addb_viewer.app.flags.pending_replaced`): the shown trial's
        from the page's view, the others' from the store and their processed output
        (:func:`output_view`). Empty without a review record (the
        solver then keeps its own proposals)."""
        app = self.app
        if app.store is None:
            return []
        found = []
        for name in trials:
            shown = app.trial is not None and app.trial.trial == name
            view = app.view if shown else output_view(app.store, app.paths.out_dir, name)
            n = pending_replaced(view) if view is not None else 0
            if n:
                found.append((name, n))
        return found

    def _masks(self) -> dict[str, np.ndarray]:
        """The reviewer's ``unmeasured_force`` masks as the solver takes them
        (:func:`addb_viewer.review_masks.unmeasured_force`, the conversion ``addb process``
        and ``addb diagnose`` use too); {} with the error shown in the page when the flags
        do not fit the trials (the solver then keeps its own proposals)."""
        from addb_viewer.review_masks import unmeasured_force
        from solver.errors import AddbError

        store = self.app.store
        if store is None:
            return {}
        try:
            return unmeasured_force(store, self.app.paths.subject_dir)
        except (AnnotationError, AddbError) as exc:
            self.app.show_error("The reviewer's flags were not used", exc)
            return {}

    def _record(self) -> Path | None:
        """The review record the flags of :meth:`_masks` come from (recorded by the solver in
        the output's ``subject.json``); None when the record could not be opened."""
        return Path(self.app.paths.annotations) if self.app.store is not None else None

    def _review_digest(self) -> str | None | bool:
        """The digest of the review record's flags a dataset run keys on
        (:func:`addb_viewer.review_masks.review_digest`), False when the record cannot be
        read (no manifest is then touched)."""
        from addb_viewer.review_masks import review_digest

        try:
            return review_digest(str(self.app.paths.subject_dir), str(self.app.paths.out_dir))
        except (AnnotationError, OSError):
            return False

    def _start(self, spec: JobSpec, work: Any, *, label: str, trial: str | None, kind: str = "process",
               waited: tuple[threading.Event, threading.Thread] | None = None) -> None:  # fmt: skip
        """Start the solver run; ``waited``: the waiter (:meth:`_wait_for_plan`) that calls
        this, the run counting as in progress until it has started or been refused."""
        with self._lock:
            try:
                self._start_locked(spec, work, label=label, trial=trial, kind=kind, waited=waited)
            finally:
                if waited is not None and self._waiter is waited:
                    self._waiter = None

    def _start_locked(self, spec: JobSpec, work: Any, *, label: str, trial: str | None, kind: str,
                      waited: tuple[threading.Event, threading.Thread] | None) -> None:  # fmt: skip
        if waited is not None and waited[0].is_set():
            self._say(f"{label}: cancelled before it started.")
            return
        if waited is not None:  # it waited for the plan: the flags as they are now, not as when it was pressed
            spec = replace(spec, unmeasured_force=self._masks(), review_record=self._record())
            if kind == "process" and spec.dynamics_only:
                self._review = self._review_digest()
        if waited is None and self.running:
            self._say("A solver run is already in progress; cancel it first.")
            return
        state = self.app.background_run()
        if state == "starting":
            self._wait_for_plan(lambda w: self._start(spec, work, label=label, trial=trial, kind=kind, waited=w), label)
            return
        try:
            self._tree = self._hold_output_tree(state)
        except AddbError as exc:  # another run writes the output tree: nothing started, the panel as it was
            self._say(f"<span style='color:#c00'>**{html.escape(label)}: not started**</span>: {html.escape(str(exc), quote=False)}")
            return
        before = trial_summary(self.app.trial) if trial and self.app.trial is not None and self.app.trial.trial == trial else None
        p = self.app.panel
        p.progress.value = 0.0
        p.progress.visible = True
        p.cancel.disabled = False
        p.cancel.visible = True
        p.reprocess.disabled = True
        p.job_status.content = f"{label}: starting…"
        p.comparison.content = ""
        self.finished.clear()
        self.job = SolverJob(
            spec,
            work,
            on_progress=lambda m, f: self._progress(label, m, f),
            on_done=lambda r: self._done(r, label=label, trial=trial, before=before, work=work, kind=kind),
        )
        try:
            self.job.start()
        except BaseException:
            self._tree.close()
            raise

    def _wait_for_plan(self, start: Any, label: str) -> None:
        """Wait, in a thread, until this server's background run has said which subjects it
        processes (it hashes every subject's files first: seconds, or minutes on a large
        dataset), then ``start()`` the run pressed for (a Reprocess pressed in that window
        was refused and had to be pressed again). Meanwhile the run counts as in progress
        (:attr:`running`), the Reprocess button waits and Cancel (or opening another subject)
        drops it; it takes the reviewer's flags as they are when it starts (frames flagged
        while it waits enter it). ``start(waiter)`` runs in the thread. Called holding ``self._lock``."""
        stop = threading.Event()
        p = self.app.panel
        p.reprocess.disabled = True
        p.cancel.disabled = False
        p.cancel.visible = True
        p.job_status.content = f"{label}: waiting until the background processing says which subjects it processes…"

        def wait() -> None:
            while not stop.wait(PLAN_POLL_S) and self.app.background_run() == "starting":
                pass
            p.reprocess.disabled = False
            p.cancel.visible = False
            try:
                start(waiter)  # it says "cancelled" when Cancel was pressed meanwhile
            except Exception as exc:  # noqa: BLE001 - no button handler above this thread: shown in the page
                self.app.show_error(f"{label}: could not start", exc)

        waiter = (stop, threading.Thread(target=wait, name="addb-wait-for-plan", daemon=True))
        self._waiter = waiter
        waiter[1].start()

    def _hold_output_tree(self, state: str | None) -> ExitStack:
        """Hold, for a run about to start, the dataset output tree the subject's output folder
        lies in, as ``addb process SUBJECT --out OUT/labA/s01`` does
        (:func:`solver.dataset.lock.subject_output_lock`): the run does not write while another
        addb run writes the tree, nor does a dataset run start into it meanwhile. Under this
        server's own background run (``addb view DATASET_DIR``; ``state``, of
        :meth:`addb_viewer.app.workbench.Workbench.background_state`, not "starting"), whose
        lock is held in this process, the run joins that hold
        (:func:`solver.dataset.lock.join_tree_hold`) as long as that run does not process this
        subject: the tree stays held until both have ended (before, a background run that ended
        first freed the tree while the Reprocess still wrote). Returns what to close when the
        run ends (holding nothing outside a tree).

        Raises
        ------
        DatasetError
            Another run holds the tree (the message names it), or this server's background run
            processes this subject.
        """
        from solver.dataset.lock import join_tree_hold, subject_output_lock
        from solver.errors import DatasetError
        from solver.outputs import output_tree_above

        out_dir = self.app.paths.out_dir
        if state == "queued":
            raise DatasetError("the background processing has this subject queued (its inputs or review changed); "
                               "wait until it is processed (the queue says when)", path=out_dir)  # fmt: skip
        hold = ExitStack()
        try:
            if state is None or not hold.enter_context(join_tree_hold(output_tree_above(out_dir))):
                hold.enter_context(subject_output_lock(out_dir))  # (the background run has just ended)
        except BaseException:
            hold.close()
            raise
        return hold

    # ------------------------------------------------------------------ progress / end
    def _progress(self, label: str, message: str, fraction: float) -> None:
        p = self.app.panel
        p.progress.value = round(100.0 * fraction, 1)
        p.job_status.content = f"{label}: {message} ({100 * fraction:.0f} %)"
        if self.app.trial is None:
            self.app.set_status(f"{label}: {message} ({100 * fraction:.0f} %)")

    def _done(self, result: JobResult, *, label: str, trial: str | None, before: dict | None, work: Any,
              kind: str = "process") -> None:  # fmt: skip
        app, p = self.app, self.app.panel
        try:
            if result.status == "done" and kind == "diagnose":
                p.job_status.content = f"{label}: done in {result.seconds:.1f} s; the report is in Diagnosis."
                app.show_diagnosis(trial)
            elif result.status == "done":
                p.job_status.content = f"{label}: done in {result.seconds:.1f} s."
                if trial is None:
                    app.after_processing()
                else:
                    restore_reports(app.paths.out_dir, self._kept)
                    if kind == "process" and self._review is not False:  # a dataset run would not redo it
                        from addb_viewer.app.dataset_manifest import mark_reprocessed

                        mark_reprocessed(app.paths.subject_dir, app.paths.out_dir, self._review)
                    self._install(trial, before, work)
            elif result.status == "cancelled":
                p.job_status.content = f"{label}: cancelled; the previous result is kept."
                if trial is None:
                    app.set_status("Processing was cancelled. Reload the page's server to try again.")
            else:
                p.job_status.content = (
                    f"<span style='color:#c00'>**{label} failed**</span>; the previous result is kept."
                )
                app.show_error(f"{label} failed", result.message)
                if trial is None:
                    app.set_status("The subject could not be processed (see the error).")
        except Exception as exc:  # noqa: BLE001 - shown in the page
            app.show_error(f"{label}: could not use the result", exc)
        finally:
            self._tree.close()  # the output tree, held since the run started
            p.progress.visible = False
            p.cancel.disabled = True
            p.cancel.visible = False
            p.reprocess.disabled = False
            self.last_result = result
            if self.job is not None:
                self.job.cleanup()
            self.finished.set()
            if trial is None:
                app.ready.set()

    def _install(self, trial: str, before: dict | None, work: Any) -> None:
        app = self.app
        showing = app.trial is None or app.trial.trial == trial
        if trial not in app.trials:
            app.trials = sorted([*app.trials, trial])
            app.set_trial_options(trial if showing else app.trial.trial)
        if not showing:
            shown = app.trial.trial
            if shown in dynamics_trials(app.paths.subject_dir, app.paths.out_dir):
                # rewritten by the same run (its masses are fitted over every trial)
                app.reload_shown(f"{trial} was reprocessed, and {shown} (shown) rewritten with it and reloaded; "
                                 f"pick {trial} in the trial list to see it.")  # fmt: skip
            else:
                self._say(f"{trial} was reprocessed; pick it in the trial list to see it.")
            return
        frame = app.playback.frame if app.playback is not None else 0
        app.load_trial(trial, frame=frame)
        after = trial_summary(app.trial)
        app.panel.comparison.content = f"**Reprocess result: {trial}**\n\n" + comparison_markdown(before or {}, after)
        others = written_trials(app.paths.subject_dir, app.paths.out_dir, trial)[1:]
        if others:
            app.panel.comparison.content += (
                f"\n\nRewritten too, with the masses refitted over every trial with force plates: {', '.join(others)}."
            )
        stale = other_mass_trials(app.paths.out_dir, trial, after["mass_kg"])
        if stale:
            app.panel.comparison.content += (
                f"\n\n<span style='color:#c00'>**The fitted body mass is now {after['mass_kg']:.2f} kg**</span> "
                "(the mass fit uses every trial with its flags); "
                + ", ".join(f"{name} ({mass:.2f} kg)" for name, mass in stale)
                + " still hold results made with the old mass (their trials are no longer in the subject folder) "
                "and the scaled model is the new one."
            )

    def cancel(self, *, wait: bool = False) -> None:
        """Cancel the running solver, or the run waiting to start (no-op when none); ``wait``
        for its end."""
        waiter = self._waiter
        if waiter is not None:
            waiter[0].set()  # the waiter's start sees it (under the lock) and starts nothing
            if not wait:
                return
            waiter[1].join(10.0)  # then the job it may have started just before is cancelled too
        job = self.job
        if job is None:
            return
        job.cancel()
        if wait:
            job.wait(10.0)

    def _say(self, text: str) -> None:
        self.app.panel.job_status.content = text

    # ------------------------------------------------------------------ Rerun export
    def record(self, file_name: str) -> None:
        """Write the shown trial to ``<recordings>/<file_name>.rrd`` in a background thread."""
        app = self.app
        status = app.panel.record_status
        trial = app.trial
        if trial is None:
            status.content = "No trial loaded."
            return
        try:
            from addb_viewer.geometry import trial_search_path
            from addb_viewer.recording.metadata import review_state
            from addb_viewer.recording.rerun_writer import write_rerun
        except ImportError as exc:
            status.content = (
                "Recording to Rerun is not available in this installation yet "
                f"(addb_viewer.recording.rerun_writer: {exc})."
            )
            return
        name = file_name.strip()
        if name.lower().endswith(".rrd"):  # walk.RRD is walk.rrd, not walk.RRD.rrd
            name = name[: -len(".rrd")] + ".rrd"
        try:
            path = app.paths.recording_file(name)  # refuses names leaving the folder
        except AddbError as exc:  # beside the button (the last success message would stay there)
            status.content = f"<span style='color:#c00'>**Not recorded**</span>: {html.escape(str(exc), quote=False)}"
            raise
        review = review_state(app.store.review(trial.trial)) if app.store is not None else None
        status.content = f"Recording {trial.trial} to {path}…"

        def run() -> None:
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
                search = trial_search_path(trial, app.paths.subject_dir, app.geometry)
                write_rerun(trial, path, annotations=review, mesh_path=search)
                app.clear_error()  # an earlier refusal's error no longer applies; cleared before
                # the status says so, so that whoever reads "wrote" never sees the old error
                status.content = f"✓ wrote {path} ({path.stat().st_size / 1e6:.1f} MB)"
            except Exception as exc:  # noqa: BLE001 - shown in the page
                app.show_error("Record to Rerun", exc)  # before the status, as above
                status.content = f"<span style='color:#c00'>Recording failed</span>: {exc}"

        threading.Thread(target=run, name="addb-record", daemon=True).start()

