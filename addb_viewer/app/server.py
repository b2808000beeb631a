"""The review app: one viser server, one subject, the annotation store, playback.

State lives here (loaded trial, playback, flags view); the scene, plots and panel read
it. Threads: viser runs GUI callbacks in a thread pool, a playback thread advances the
frame by the wall clock and polls the store for other writers' edits, and solver runs
report from their own reader threads (:mod:`~addb_viewer.app.reprocess`). ``_lock``
guards the state and the scene; store edits (which fsync) run outside it so playback
never waits for the disk.

Every callback is wrapped so that an exception is shown in the page (and printed on the
terminal) instead of being lost or stopping the server.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import sys
import threading
import time
import traceback
from collections.abc import Callable, Iterator
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from addb_viewer.app.access import TOKEN_PARAM, is_loopback, new_token, start_viser
from addb_viewer.app.camera import CameraPose
from addb_viewer.app.diagnosis import diagnosis_markdown
from addb_viewer.app.flags import (
    FlagView,
    TrialEditor,
    describe_flags,
    describe_frame,
    flags_differ_from_fit,
    pending_replaced,
    unproposed_replaced,
)
from addb_viewer.app.history import ActionHistory
from addb_viewer.app.meshes import body_mesh
from addb_viewer.app.page_cameras import PageCameras
from addb_viewer.app.panel import APPLY_HINT, DEFAULT_FOOT, NO_EDITS, ReviewPanel, build_panel
from addb_viewer.app.paths import ReviewPaths, safe_name
from addb_viewer.app.plots import TrialPlots
from addb_viewer.app.reprocess import Reprocessor, SecondThought, apply_refusal
from addb_viewer.app.scene import SceneSettings, TrialScene
from addb_viewer.app.state import Playback, next_run_start
from addb_viewer.app.summary import hicks_exceeded
from addb_viewer.app.timeline import TrackData, frames_text, timeline_html, track_data
from addb_viewer.geometry import trial_search_path
from annotations import AnnotationError, AnnotationStore, Edit
from annotations.journal import StorePaths
from annotations.recovery import journal_holds_every_edit
from solver.dataset.summary import dynamics_error_message
from solver.errors import AddbError
from solver.results import ProcessedTrial, load_processed, processed_trials

PLOT_INTERVAL_S = 0.25
"""Least time between two chart cursor updates while playing (they re-send the data)."""
TICK_S = 1 / 60
"""Playback thread period (viser sends at most ~60 updates per second anyway)."""
STATUS_MIN_LINES = 6
"""Lines the status line keeps room for (its longest frames' text at the panel's width)."""
STATUS_LINE_EM = 1.55
"""Height of one line of the panel's text, em (viser's markdown: 22.9 px at 14.8 px)."""
REFRESH_S = 1.0
"""How often the store is polled for other writers' edits."""
RELOAD_S = 10.0
"""A loopback page opened within this many seconds of another page closing is taken for
that page reloaded: it keeps the closed page's "Your name", s."""
NO_RECORD = "Flagging is disabled until the review record can be opened (see above)."
"""The edits' line while the review record cannot be opened (in place of :data:`NO_EDITS`)."""


class TrialLoadError(AddbError):
    """A processed trial cannot be shown (not processed, or its file is damaged). Shown in
    the page as ``FILE[:LINE]: message``: the file once, no class name."""

    def _format(self) -> str:
        loc = [x for x in ((self.path or "") + (f":{self.line}" if self.line is not None else ""), self.where or "") if x]
        return f"{', '.join(loc)}: {self.message}" if loc else self.message


class ReviewApp:
    """The ``addb view`` server for one subject.

    Parameters
    ----------
    paths
        The subject's folders (:class:`~addb_viewer.app.paths.ReviewPaths`).
    reviewer
        Name recorded with every annotation edit.
    host, port
        Where to listen (port 0: any free port; viser takes the next port when the one
        asked for is busy, see :attr:`port`).
    background
        Load (and if needed process) the subject in a background thread, so the page is
        reachable at once; False loads before returning (tests).
    geometry
        Extra folder(s) of bone meshes (``--geometry``), looked up before the bundled
        set (:func:`addb_viewer.geometry.mesh_search_path`); None: ``$ADDB_GEOMETRY``.
    token
        Access token every request must carry (:mod:`addb_viewer.app.access`); None: a
        random one when ``host`` is not a loopback address, no token on loopback.
    process_missing
        Process a subject that has no output yet when it is opened (False when a dataset
        runner processes the subjects in the background, :mod:`addb_viewer.app.workbench`).

    Raises
    ------
    AccessSetupError
        A token is needed but cannot be enforced with the installed viser.
    """

    def __init__(
        self,
        paths: ReviewPaths,
        *,
        reviewer: str,
        host: str = "127.0.0.1",
        port: int = 8080,
        background: bool = True,
        geometry: str | os.PathLike[str] | None = None,
        token: str | None = None,
        process_missing: bool = True,
    ) -> None:
        self.paths = paths
        self.process_missing = process_missing
        self.workbench: Any = None  # the dataset queue (addb_viewer.app.workbench), when reviewing a dataset
        self.geometry = geometry
        self.reviewer = reviewer
        self.started_at = time.monotonic()
        self.first_frame_seconds: float | None = None
        self.ready = threading.Event()
        # beyond this machine every request must carry a token (see addb_viewer.app.access)
        self.token = token if token is not None else (None if is_loopback(host) else new_token())
        self.server = start_viser(host, port, token=self.token, label="addb review", verbose=False)
        self.server.scene.set_up_direction("+y")
        self.server.scene.configure_default_lights(cast_shadow=False)
        self.panel: ReviewPanel = build_panel(self.server, title=f"addb · {_converted_from(paths.subject_dir) or paths.subject_dir.name}")
        self.settings = SceneSettings()
        self._lock = threading.RLock()
        self._edit_lock = threading.RLock()
        self._quiet = threading.local()
        self._actor = threading.local()  # the page (viser client id) whose handler runs
        self.client_names: dict[int, str] = {}
        # loopback pages' names across a reload (a reload is a new client): the names of pages
        # that just closed, and the pages that just opened still holding the prefill
        self._left_names: list[tuple[float, str]] = []
        self._fresh_pages: dict[int, float] = {}
        self._names_lock = threading.Lock()
        self.cameras = PageCameras(self.server)
        self.name_fields: dict[int, Any] = {}  # client id -> its "Your name" text field
        self._stop = threading.Event()
        self.store: AnnotationStore | None = None
        #: Why the review record could not be opened (shown again with every trial loaded).
        self.store_problem: tuple[str, BaseException | str] | None = None
        self.actions = ActionHistory()  # who made each edit the store can undo or redo
        self.review_warning = SecondThought()  # "Trial reviewed" with pending proposals: (trial, pending frames)
        self.trials: list[str] = []
        self.trial: ProcessedTrial | None = None
        self._shown_label = ""
        self.scene: TrialScene | None = None
        self.plots: TrialPlots | None = None
        self.playback: Playback | None = None
        self.editor: TrialEditor | None = None
        self.view: FlagView | None = None
        self.hicks: np.ndarray | None = None
        self.tracks: TrackData | None = None
        self.rms: np.ndarray | None = None
        self._last_plot = 0.0
        self.jobs = Reprocessor(self)
        self._wire()
        self.server.on_client_connect(self._client_connected)
        self.server.on_client_disconnect(self._client_disconnected)
        self._player = threading.Thread(target=self._playback_loop, name="addb-playback", daemon=True)
        self._player.start()
        if background:
            threading.Thread(target=self.startup, name="addb-startup", daemon=True).start()
        else:
            self.startup()

    # ================================================================== lifecycle
    @property
    def port(self) -> int:
        """The port the server listens on."""
        return int(self.server.get_port())

    @property
    def url(self) -> str:
        """Address of the page, with ``/?token=...`` when the server requires a token (a
        wildcard host is shown as this machine's name, as the team would reach it)."""
        host = self.server.get_host()
        if host in ("0.0.0.0", "", "::"):
            shown = socket.gethostname() if self.token else "127.0.0.1"
        else:
            shown = f"[{host}]" if ":" in host else host
        base = f"http://{shown}:{self.port}"
        return f"{base}/?{TOKEN_PARAM}={self.token}" if self.token else base

    def startup(self) -> None:
        """Open the review record, then show the first processed trial, processing the
        subject first when it has no output yet. Errors are shown in the page."""
        try:
            self._open_store()
            self.trials = processed_trials(self.paths.out_dir) if self.paths.out_dir.is_dir() else []
            if self.trials:
                self.show_trial()
            elif self.process_missing:
                self.set_status(f"**{self._subject_label(self.paths)}** has not been processed yet: processing…")
                self.jobs.process_subject()
            else:
                self.set_status(f"**{self._subject_label(self.paths)}** has not been processed yet (see the dataset queue).")
        except Exception as exc:  # noqa: BLE001 - shown in the page
            self.show_error("Could not open the subject", exc)
        finally:
            if not self.jobs.running:
                self.ready.set()

    def open_subject(self, paths: ReviewPaths, trial: str | None = None) -> None:
        """Show another subject (the dataset queue's "Open"): a running solver run is
        cancelled (the page says so: its subject keeps its previous result), the review
        record of the shown subject closed and the new one opened; its ``trial`` (default:
        the preferred one) is loaded, or the page says it is not processed yet. The last
        edit's message goes and the Foot choice returns to "both" (they were the other
        subject's). Errors are shown in the page."""
        running, before = self.jobs.running, self._subject_label(self.paths)
        self.jobs.cancel(wait=True)
        with self._lock:
            self._drop_trial()
            self.trial = self.playback = self.editor = self.view = self.tracks = None
            self.trials = []
            if self.store is not None:
                with contextlib.suppress(AnnotationError):
                    self.store.close()
                self.store = None
            self.paths = paths
        self.server.gui.set_panel_label(f"addb · {self._subject_label(paths)}")
        self.panel.comparison.content = ""
        self.panel.job_status.content = (  # the cancelled run's own line, with its subject
            f"{before} · {self.panel.job_status.content} (you opened {self._subject_label(paths)})" if running else ""
        )
        self.panel.saved.content = NO_EDITS
        with self._quiet_updates():
            self.panel.foot.value = DEFAULT_FOOT
        try:
            self._open_store()
            self.trials = processed_trials(paths.out_dir) if paths.out_dir.is_dir() else []
            if not self.trials:
                self.set_status(f"**{self._subject_label(paths)}** has not been processed yet (see the dataset queue).")
                self._clear_trial_controls()
                return
            self.show_trial(trial)
        except Exception as exc:  # noqa: BLE001 - shown in the page
            self.show_error("Could not open the subject", exc)

    def show_trial(self, wanted: str | None = None) -> None:
        """Show trial ``wanted`` of the subject opened (None: the preferred one) from
        :attr:`trials` (those with a trial.npz), with the error area naming any trial that
        could not be shown.

        * ``wanted`` given but not processed (its ``trial.npz`` missing) or unreadable: no
          trial is shown (not another one in its place); the page names the trial and the
          file that is missing or damaged.
        * ``wanted`` None: the preferred trial, else, when its output cannot be read (a
          damaged ``results.json`` or ``trial.npz``), the first other trial that can be;
          the page names the damaged trial, its file and what is wrong.

        Raises
        ------
        TrialLoadError
            ``wanted`` None and no trial of the subject can be read (the first one's error).
        """
        label = self._subject_label(self.paths)
        if wanted is not None:
            try:
                if wanted not in self.trials:
                    raise TrialLoadError(
                        f"trial {wanted!r} is not processed: its trial.npz is missing; process the subject again",
                        path=self.paths.trial_dir(wanted) / "trial.npz",
                    )
                self.set_trial_options(wanted)
                self.load_trial(wanted)
            except AddbError as exc:  # TrialLoadError among them
                with self._lock:  # none shown: not the one shown before either
                    self._drop_trial()
                    self.trial = self.playback = self.editor = self.view = self.tracks = None
                self._clear_trial_controls()
                self.set_status(f"**{label} / {_escape(wanted)}** cannot be opened (see the error below).")
                self.show_error(f"Could not open trial {wanted!r} of {label}", exc)
            return
        first = _preferred(self.trials)
        failed: list[tuple[str, TrialLoadError]] = []
        for name in [first, *(t for t in self.trials if t != first)]:
            try:
                self.set_trial_options(name)
                self.load_trial(name)
            except TrialLoadError as exc:
                failed.append((name, exc))
                continue
            if failed:
                names = ", ".join(repr(n) for n, _ in failed)
                self.show_error(f"Could not open trial {names} of {label}; showing {name!r} instead",
                                "; ".join(str(e) for _, e in failed))  # fmt: skip
            return
        raise failed[0][1]

    def _clear_trial_controls(self) -> None:
        """Empty the trial's controls when no trial is shown (a subject not processed, or
        failed): no trial to pick, no timeline, frame or selection, no flag counts, no
        reviewed box; the previous trial's would read as this subject's."""
        p = self.panel
        with self._quiet_updates():
            p.trial.options = ("(none)",)
            p.trial.value = "(none)"
            p.trial.disabled = True
            for slider in (p.frame, p.timeline_frame):
                slider.value = 0
                slider.disabled = True
            p.selection.value = (0, 0)
            p.selection.disabled = True
            p.reviewed.value = False
            p.reviewed.disabled = True
        p.timeline.content = ""
        p.proposal_info.content = "No trial shown."
        self._show_range_info()  # no playback: the no-range lines
        p.diagnosis.content = ""

    def _trial_picked(self, name: str) -> None:
        """The Playback folder's Trial list: load ``name``; the dataset queue then marks it
        as the trial shown (its ▶ and Open follow)."""
        self.load_trial(name)
        if self.workbench is not None:
            self.workbench.refresh()

    def reload_shown(self, why: str) -> None:
        """Load the shown trial again from the output folder, at the frame shown (its output
        was rewritten by another run: the dataset's background run, or a Reprocess of
        another trial of the subject, which rewrites every trial with dynamics), and say
        ``why`` in the solver-run line. No-op when no trial is shown."""
        with self._lock:
            if self.trial is None:
                return
            name, frame = self.trial.trial, self.playback.frame if self.playback is not None else 0
        try:
            self.trials = processed_trials(self.paths.out_dir)
            self.set_trial_options(name)
            self.load_trial(name, frame=frame)
            self.panel.job_status.content = why
        except Exception as exc:  # noqa: BLE001 - shown in the page
            self.show_error("Could not reload the trial", exc)

    def background_run(self) -> str | None:
        """What the dataset queue's background run does to the subject shown
        (:meth:`addb_viewer.app.workbench.Workbench.background_state`: None, "starting",
        "queued" or "other"); None when no dataset is reviewed."""
        return None if self.workbench is None else self.workbench.background_state(self.paths.out_dir)

    def _subject_label(self, paths: ReviewPaths) -> str:
        """A subject's name as the reviewer knows it: its place in the dataset queue
        (``labB/run``), else the .b3d file it was converted from (``results.b3d``; its
        folder in the cache is named with a digest), else its folder's name."""
        if self.workbench is not None:
            for s in self.workbench.subjects:
                if Path(s.subject_dir).resolve() == Path(paths.subject_dir).resolve():
                    return s.rel
        return _converted_from(paths.subject_dir) or paths.subject_dir.name

    def after_processing(self) -> None:
        """Called once the first processing run has written the output folder."""
        try:
            self.trials = processed_trials(self.paths.out_dir)
            if not self.trials:
                raise FileNotFoundError(f"the solver wrote no trial into {self.paths.out_dir}")
            self.show_trial()
        except Exception as exc:  # noqa: BLE001
            self.show_error("Could not load the processed subject", exc)
        finally:
            self.ready.set()

    def _open_store(self) -> None:
        # the subject's own button first: "Apply the named cause" writes in the subject folder
        refused = apply_refusal(self.paths.subject_dir)
        self.panel.apply_diagnosis.disabled = refused is not None
        self.panel.apply_diagnosis.hint = f"disabled: {refused}" if refused else APPLY_HINT
        self.paths.annotations.parent.mkdir(parents=True, exist_ok=True)
        try:
            self.store = AnnotationStore.open(self.paths.annotations, reviewer=self.reviewer)
            self.store_problem = None
            if self._record_elsewhere():
                print(f"addb view: {self.paths.subject_dir.name}: {self._record_elsewhere_text()}", file=sys.stderr, flush=True)
            self.actions.clear()  # a new store: a new history
        except AnnotationError as exc:
            self.store = None
            rebuildable = journal_holds_every_edit(self.paths.annotations)
            self.store_problem = ("The review record cannot be opened; flagging is disabled", _record_problem(self.paths.annotations, exc, rebuildable))
            self.panel.recover_record.visible = rebuildable
            self.panel.saved.content = NO_RECORD
            self.show_error(*self.store_problem)
            return
        self.panel.recover_record.visible = False

    def recover_record(self) -> None:
        """Rebuild the review record that could not be opened from its journal
        (:meth:`annotations.AnnotationStore.recover`: the journal holds every edit; nothing is
        deleted, the damaged record is renamed ``<name>.damaged-<UTC time>`` beside it), then
        open it and show the shown trial again with its flags. Says what was done in the
        Edits line; a recovery that cannot be done is shown as an error (the files unchanged)."""
        if self.store is not None:
            self._answer("The review record is open; there is nothing to rebuild.")
            return
        report = AnnotationStore.recover(self.paths.annotations)
        print(f"addb view: {self.paths.annotations}: {report.message}", file=sys.stderr, flush=True)
        self._open_store()
        if self.store is None:
            return  # still unreadable: its error is shown again
        with self._lock:
            name = self.trial.trial if self.trial is not None else None
            frame = self.playback.frame if self.playback is not None else 0
        if name is not None:
            self.load_trial(name, frame=frame)
        else:
            self.clear_error()
        if self.workbench is not None:
            self.workbench.refresh()  # its row no longer says "record unreadable"
        self.panel.saved.content = f"✓ {_escape(report.message)} ({report.main})"

    def stop(self) -> None:
        """Stop playback, cancel a running solver (and a dataset's background run), close
        the store, stop the server."""
        self._stop.set()
        if self.workbench is not None:
            self.workbench.stop()
        self.jobs.cancel(wait=True)
        self._player.join(timeout=2.0)
        if self.store is not None:
            with contextlib.suppress(AnnotationError):
                self.store.close()
        self.server.stop()

    # ================================================================== loading
    def set_trial_options(self, selected: str) -> None:
        """Fill the trial list with :attr:`trials` and select ``selected``."""
        with self._quiet_updates():
            self.panel.trial.options = tuple(self.trials)
            self.panel.trial.value = selected
            self.panel.trial.disabled = len(self.trials) < 2

    def load_trial(self, name: str, *, frame: int = 0) -> None:
        """Load ``OUT/<name>`` and show it from ``frame``.

        Raises
        ------
        UnsafePathError
            A name that is not a plain folder name.
        TrialLoadError
            Not a processed trial, or an unreadable trial file.
        """
        name = safe_name(name, what="trial name")
        if name not in self.trials:
            raise TrialLoadError(f"trial {name!r} is not processed: its trial.npz is missing; process the subject again",
                                 path=self.paths.trial_dir(name) / "trial.npz")  # fmt: skip
        try:
            trial = load_processed(self.paths.out_dir, name)
        except AddbError as exc:  # names its file (trial.npz or results.json) and the remedy
            raise TrialLoadError(f"trial {name!r}: {exc.message}", path=exc.path, line=exc.line, where=exc.where) from exc
        except Exception as exc:
            raise TrialLoadError(
                f"cannot read the processed trial ({type(exc).__name__}: {exc}); press Reprocess to recompute it",
                path=self.paths.trial_dir(name) / "trial.npz",
            ) from exc
        search = trial_search_path(trial, self.paths.subject_dir, self.geometry)
        meshes, problems = {}, []
        for body, files in trial.body_meshes.items():
            meshes[body], p = body_mesh(search, files) if files else (None, [])
            problems += p
        if self.store is None and self.store_problem is not None:
            self._open_store()  # a record mended since it failed to open is taken up at the next trial shown
        editor, record_problem = self._editor_for(trial)
        view = editor.view() if editor is not None else None
        self._forget_refusal()
        label = self._subject_label(self.paths)
        with self._lock:
            # the same trial loaded again (its output rewritten by a Reprocess or the background
            # run): the reviewer's in and out points stay (they went, and the next G flagged one frame)
            pb = self.playback
            marks = (pb.in_point, pb.out_point) if pb is not None and self.trial is not None and self.trial.trial == name else None
            self._drop_trial()
            self.trial, self.editor, self.view = trial, editor, view
            self._shown_label = label  # the status line's subject name (read at every frame)
            self.hicks = hicks_exceeded(trial)
            self.rms = trial.marker_rms_per_frame
            self.playback = Playback(trial.n_frames, trial.rate_hz or 100.0, frame=frame)
            self.scene = TrialScene(self.server, trial, meshes, self.settings)
            with self.panel.plots_folder:
                self.plots = TrialPlots(self.server.gui, trial, container=self.panel.plots_folder)
            if view is not None:
                self.plots.update(flagged=view.flagged, proposed=view.pending)
            self.tracks = track_data(trial, view, self.hicks)
            self._sync_controls(name)
            self._setup_timeline(trial)
            if marks is not None:
                for point, mark in zip(marks, (self.playback.mark_in, self.playback.mark_out), strict=True):
                    if point is not None:
                        mark(point)  # clamped to the trial
                sel = self.playback.selection()
                if sel is not None:
                    with self._quiet_updates():
                        self.panel.selection.value = (sel[0], sel[1] - 1)
                self._show_range_info()
            self.panel.diagnosis.content = diagnosis_markdown(self.paths.out_dir, self.paths.subject_dir, name)
            self.camera_view("Sagittal")  # framed from the side, for new pages and every open one
            self.render(self.playback.frame, force_plots=True)
        self.clear_error()
        if self.store is None and self.store_problem is not None:  # stays in view while flagging is off
            self.show_error(*self.store_problem)
        if problems:
            self.show_error("Some bone meshes could not be read (drawn as axes)", "; ".join(problems[:5]))
        if record_problem is not None:
            self.show_error(*record_problem)
        if self.first_frame_seconds is None:
            self.first_frame_seconds = time.monotonic() - self.started_at

    def _editor_for(self, trial: ProcessedTrial) -> tuple[TrialEditor | None, tuple[str, BaseException | str] | None]:
        """The trial's flag editor (None without a review record, or when the record holds the
        trial on other frames) and the problem to show once the trial is loaded, if any."""
        if self.store is None:
            return None, None
        rev = self.store.review(trial.trial)
        if rev.rate_hz is not None and trial.rate_hz and abs(rev.rate_hz / trial.rate_hz - 1.0) > 1e-6:
            # a record on other frames (an older addb convert stored a .b3d's own frames):
            # its flags would be read, and new ones written, on the wrong frames
            return None, (
                "The review record of this trial is on other frames: its flags are not shown or edited",
                (
                    f"the record holds this trial at {rev.rate_hz:g} Hz, the app shows its processed frames at "
                    f"{trial.rate_hz:g} Hz; convert the .b3d again (addb convert --force) to review it here"
                ),
            )
        problem = None
        if rev.n_frames != trial.n_frames:
            try:
                self.store.set_trial_info(trial.trial, n_frames=trial.n_frames, rate_hz=trial.rate_hz or None)
            except AnnotationError as exc:
                problem = ("The review record does not match this trial's length", exc)
        return TrialEditor(self.store, trial.trial, trial.proposed, trial.proposal_reasons), problem

    def _drop_trial(self) -> None:
        if self.scene is not None:
            self.scene.remove()
        if self.plots is not None:
            self.plots.remove()
        self.scene = self.plots = None

    def _sync_controls(self, name: str) -> None:
        p, t = self.panel, self.trial
        assert t is not None and self.playback is not None
        with self._quiet_updates():
            p.trial.value = name
            p.frame.max = max(t.n_frames - 1, 1)
            p.frame.value = self.playback.frame
            p.frame.disabled = False
            p.speed.value = self.playback.speed
            p.loop.value = self.playback.loop
            p.reviewed.value = bool(self.view and self.view.reviewed)
            p.reviewed.disabled = False
            p.record_name.value = f"{name}.rrd"
        self._show_flags_info()
        self._show_range_info()

    def _shown_bodies(self) -> tuple[np.ndarray | None, int]:
        """The shown trial's body origins ``(T, B, 3)`` (None when no trial is shown) and
        the frame shown, as :class:`PageCameras` takes them."""
        t, pb = self.trial, self.playback
        return (t.body_position if t is not None else None), (pb.frame if pb is not None else 0)

    def camera_view(self, view: str) -> CameraPose:
        """Put every page's camera (and new pages') in ``view`` (Sagittal, Frontal, Top),
        framing the shown trial for each page's own canvas (:meth:`PageCameras.show_view`).
        Returns the pose of new pages."""
        return self.cameras.show_view(view, *self._shown_bodies())

    def _camera_moved(self, camera: Any) -> None:
        """A page reported its camera: frame the trial again for it if its canvas changed
        size (:meth:`PageCameras.resized`), and fit the dataset queue's window to the canvas."""
        self._fit_queue()
        with self._lock:
            self.cameras.resized(camera, *self._shown_bodies())

    # ================================================================== drawing
    def render(self, k: int, *, force_plots: bool = False) -> None:
        """Show frame ``k``: scene, frame slider, status line, chart cursors. Call with
        ``_lock`` held."""
        if self.scene is None or self.playback is None or self.trial is None:
            return
        self.scene.show(k, self._banner(k))
        if self.panel.follow.value:
            self.cameras.follow(self.trial.body_position[k, 0, :])
        elif self.cameras.following:  # pages whose canvas cannot hold the whole trial
            self.cameras.follow(self.trial.body_position[k, 0, :], self.cameras.following)
        with self._quiet_updates():
            self.panel.frame.value = k
            self.panel.timeline_frame.value = k
        self.panel.status.content = self._status(k)
        now = time.monotonic()
        if self.plots is not None and (force_plots or not self.playback.playing or now - self._last_plot >= PLOT_INTERVAL_S):
            self.plots.update(frame=k)
            self.draw_timeline()
            self._last_plot = now

    def _banner(self, k: int) -> str | None:
        v = self.view
        if v is None:
            return None
        foot = v.feet[k]
        if foot is not None:
            return "UNMEASURED FORCE" + (f" · {foot}" if foot else "")
        if v.pending[k]:
            return "proposed: unmeasured force"
        return None

    def _status(self, k: int) -> str:
        t, pb = self.trial, self.playback
        assert t is not None and pb is not None
        flag = describe_frame(self.view, k, t.proposal_reasons) if self.view is not None else "flags unavailable"
        rms = self.rms[k] if self.rms is not None else np.nan
        parts = [
            f"**{self._shown_label}** · **{t.trial}** · frame {k} / {t.n_frames - 1} · t = {t.time[k]:.2f} s",
            f"marker RMS {100 * rms:.1f} cm" if np.isfinite(rms) else "no markers seen",
        ]
        if t.has_dynamics:
            f = float(np.linalg.norm(t.residual_force[k]))
            m = float(np.linalg.norm(t.residual_moment[k]))
            over = " · **over a Hicks limit at this frame**" if self.hicks is not None and self.hicks[k] else ""
            if t.unobserved[k]:  # its residual is the force no plate measured, not judged by Hicks
                over = " · left out of the fit (no measured force)"
            parts.append(f"residual {f:.0f} N, {m:.0f} N·m{over}")
        elif not t.plates:
            parts.append("no force plates in this trial: kinematics only (no residuals)")
        elif failed := dynamics_error_message(t.metrics):
            parts.append(f"kinematics only: its dynamics failed: {failed}")
        else:
            parts.append("no dynamics yet (residuals appear after a Reprocess with the dynamics stage)")
        # kept STATUS_MIN_LINES lines high: it wraps to four to six lines from frame to frame,
        # and the folders below jumped up and down during playback (blank lines around the
        # text, so that it is read as markdown inside the block)
        text = " · ".join(parts[:2]) + "<br>" + parts[2] + "<br>" + flag
        return f"<div style='min-height:{STATUS_MIN_LINES * STATUS_LINE_EM:.2f}em'>\n\n{text}\n\n</div>"

    def set_status(self, text: str) -> None:
        """Replace the status line at the top of the panel."""
        self.panel.status.content = text

    def show_error(self, context: str, exc: BaseException | str) -> None:
        """Show an error in the page and on the terminal (with the traceback of an
        unexpected exception)."""
        text = str(exc) if str(exc) else type(exc).__name__
        # a long path breaks anywhere: unbroken, the file's line number ran past the panel's edge
        self.panel.error.content = (
            f"<span style='color:#c00'>**{context}**</span><br><span style='overflow-wrap:anywhere'>{_escape(text)}</span>"
        )
        self.panel.error.visible = True
        print(f"addb view: {context}: {text}", file=sys.stderr, flush=True)
        if isinstance(exc, BaseException) and not isinstance(exc, AnnotationError | FileNotFoundError) and not hasattr(exc, "to_dict"):
            traceback.print_exception(exc, file=sys.stderr)

    def clear_error(self) -> None:
        """Hide the error area."""
        self.panel.error.visible = False
        self.panel.error.content = ""

    # ================================================================== playback
    def _playback_loop(self) -> None:
        last_refresh = time.monotonic()
        while not self._stop.wait(TICK_S):
            now = time.monotonic()
            try:
                with self._lock:
                    pb, sc = self.playback, self.scene
                    if pb is not None and sc is not None and pb.playing:
                        k = pb.tick(now)
                        if k != sc.frame or not pb.playing:
                            self.render(k, force_plots=not pb.playing)
                if now - last_refresh >= REFRESH_S:
                    last_refresh = now
                    if self.store is not None and self.editor is not None and self.store.refresh():
                        self.refresh_flags()
            except Exception as exc:  # noqa: BLE001 - keep playing whatever happens
                self.show_error("Playback", exc)

    def seek(self, frame: int) -> None:
        """Go to ``frame`` (clamped)."""
        with self._lock:
            if self.playback is not None:
                self.render(self.playback.seek(frame, time.monotonic()), force_plots=True)

    def step(self, delta: int) -> None:
        """Pause and move ``delta`` frames."""
        with self._lock:
            if self.playback is not None:
                self.render(self.playback.step(delta, time.monotonic()), force_plots=True)

    def toggle_play(self) -> None:
        """Play or pause."""
        with self._lock:
            if self.playback is not None:
                playing = self.playback.toggle(time.monotonic())
                if not playing:
                    self.render(self.playback.frame, force_plots=True)

    def jump(self, what: str) -> None:
        """Go to the next run of flagged frames ("Flagged"), pending proposals
        ("Proposal") or frames over a Hicks threshold ("Over Hicks")."""
        with self._lock:
            if self.playback is None or self.trial is None:
                return
            v = self.view
            masks = {
                "Flagged": v.flagged if v is not None else None,
                "Proposal": v.pending if v is not None else None,
                "Over Hicks": self.hicks,
            }
            mask = masks.get(what)
            here = self.playback.frame
            target = None if mask is None else next_run_start(mask, here)
        names = {"Flagged": "flagged frames", "Proposal": "pending proposals", "Over Hicks": "frames over Hicks' limits"}
        if target is not None and target == here:  # the search went round to the run it started in
            self._answer(f"Frame {here} starts the only run of {names.get(what, what.lower())} in this trial.")
            return
        if target is None:
            self._answer({
                "Flagged": "No flagged frames in this trial.",
                "Proposal": "No pending proposals in this trial (accepted and rejected ones are decided).",
                "Over Hicks": "No frame with measured force over Hicks' per-frame limits in this trial.",
            }.get(what, f"No {what.lower()} frames in this trial."))
            return
        self._forget_refusal()  # an earlier "No … in this trial" answered another press
        with self._lock:
            self.playback.pause(time.monotonic())
        self.seek(target)

    # ================================================================== reviewers
    def _client_connected(self, client: Any) -> None:
        """Give a new page its own "Your name" field (each edit keeps its reviewer's name).

        Prefilled on a loopback address (one person at this machine) with the name of the
        page that closed just before (:data:`RELOAD_S`: the same page reloaded, so it keeps
        its own name; when its old connection closes just after, the name follows then),
        else ``--reviewer``. Never the name typed on a page still open: the reloaded page's
        edits would be recorded, and its undo judged, as that other reviewer's. Empty on a
        server reached by a team, where a page must name its reviewer before editing."""
        client.camera.on_update(self._camera_moved)
        default = ""
        if self.token is None:
            now = time.monotonic()
            with self._names_lock:
                self._left_names = [(t, n) for t, n in self._left_names if now - t <= RELOAD_S]
                default = self._left_names.pop()[1] if self._left_names else self.reviewer
                self._fresh_pages[client.client_id] = now
        self.client_names[client.client_id] = default
        field = client.gui.add_text(
            "Your name", initial_value=default, order=-1000.0,
            hint="Recorded with each of your edits in the review record",
        )
        field.on_update(lambda e, cid=client.client_id: self._name_typed(cid, str(e.target.value).strip()))
        self.name_fields[client.client_id] = field
        self._camera_moved(client.camera)  # its first report: framed for its canvas, the queue fitted

    def _name_typed(self, client_id: int, name: str) -> None:
        with self._names_lock:
            self._fresh_pages.pop(client_id, None)  # named on this page: a closing page's name no longer follows
        self.client_names[client_id] = name  # this page's own: no other page takes it

    def _client_disconnected(self, client: Any) -> None:
        name = self.client_names.pop(client.client_id, None)
        if self.token is None and name:  # its name goes to its reload (a page opened just before, or next)
            now = time.monotonic()
            with self._names_lock:
                self._fresh_pages.pop(client.client_id, None)
                fresh = [(t, c) for c, t in self._fresh_pages.items() if now - t <= RELOAD_S and c in self.name_fields]
                heir = max(fresh)[1] if fresh else None
                if heir is None:
                    self._left_names.append((now, name))
                else:
                    del self._fresh_pages[heir]
            if heir is not None and self.client_names.get(heir) != name:
                self.client_names[heir] = name
                self.name_fields[heir].value = name
        self.name_fields.pop(client.client_id, None)
        self.cameras.forget(client.client_id)
        self._fit_queue()  # to the narrowest page left (viser has removed this one)

    def _fit_queue(self) -> None:
        """Fit the dataset queue's window, one for every page, to the narrowest page's canvas."""
        widths = [c.camera.image_width for c in self.server.get_clients().values()]
        if self.workbench is not None and widths:
            self.workbench.fit_to_canvas(float(min(widths)))

    def reviewer_name(self, client_id: int | None) -> str | None:
        """The name recorded with an edit from page ``client_id``: the page's "Your name",
        else ``--reviewer`` on a loopback address; None when a page of a team server has
        not named its reviewer. Edits from Python (no page) are the ``--reviewer``'s."""
        if client_id is None:
            return self.reviewer
        name = self.client_names.get(client_id, "")
        if name:
            return name
        return self.reviewer if self.token is None else None

    def edit(self, what: str, action: Callable[[TrialEditor, int, str], Edit | list[Edit] | None], *,
             history: bool = False) -> None:  # fmt: skip
        """Run one store edit on the current trial and frame; say "saved" once it is durable.

        The edit is recorded under the name of the page that asked for it
        (:meth:`reviewer_name`); a page of a team server without a name is asked for one.
        ``history``: the action is an Undo or Redo (:meth:`history`), not a new action of the
        undo history.

        viser runs the page's handlers in a thread pool, so two quick clicks (undo, then the
        reviewed box) would run side by side and the earlier one's message could come last;
        edits therefore run one at a time, each message final before the next edit starts."""
        name = self.reviewer_name(getattr(self._actor, "client", None))
        with self._edit_lock:
            saved = self._edit_as(name, what, action, history)
        if saved and self.workbench is not None:  # review state and pending proposals in the queue
            self.workbench.refresh()

    def _edit_as(self, name: str | None, what: str, action: Callable[[TrialEditor, int, str], Edit | list[Edit] | None],
                 history: bool) -> bool:  # fmt: skip
        """:meth:`edit` under the name ``name`` (None: ask for one); the caller holds
        ``_edit_lock``. False when nothing was asked of the store."""
        if name is None:
            self._answer(
                "<span style='color:#c00'>**not saved**</span>: type your name in “Your name” at the "
                "top of the panel first (each edit keeps its reviewer's name)."
            )
            return False
        acting = self.store.acting_as(name) if self.store is not None else contextlib.nullcontext()
        with acting:
            self._edit(what, action, history)
        return True

    def _edit(self, what: str, action: Callable[[TrialEditor, int, str], Edit | list[Edit] | None], history: bool = False) -> None:
        with self._lock:
            editor, pb = self.editor, self.playback
            frame = pb.frame if pb is not None else 0
        if editor is None:
            why = f": {self.store_problem[1]}" if self.store is None and self.store_problem is not None else " (no trial or no review record)"
            self._answer(f"Flagging is unavailable{_escape(why)}.")
            return
        self.panel.saved.content = f"saving: {what}…"
        try:
            result = action(editor, frame, self.panel.foot.value)
        except AnnotationError as exc:
            self._answer(f"<span style='color:#c00'>**not saved**</span>: {_escape(str(exc))}")
            return
        edits = [e for e in (result if isinstance(result, list) else [result]) if e is not None]
        if not history:
            self.actions.record(edits, what)
        # the flags, timeline and Flags folder first, the line last: a reviewer (and a test)
        # reading "saved" finds the rest of the page already showing the edit
        self.refresh_flags()
        if not edits and history:
            text = (
                "Nothing to undo: the history holds the edits made since this subject was opened "
                "(opening another subject starts a new one)." if what.startswith("undo") else
                "Nothing to redo: no edit has been undone since the last edit."
            )
        elif not edits:
            text = f"Nothing to do: {what}."
        else:
            e = edits[-1]
            when = datetime.now().strftime("%H:%M:%S")
            on = f" on {e.trial}" if e.trial else ""  # the message stays when the reviewer picks another trial
            # no record sequence number: it counts every entry of the record (trial information,
            # other reviewers' edits), so a reviewer's first edit read "#2" and the next "#6"
            text = f"✓ saved: {what}{on} — {e.provenance.reviewer}, {when}" + _conflicts_text(edits, history)
        damaged = self._damaged_record() if edits else None
        if damaged is not None:  # saved in the journal, but no other reader sees it
            text = f"✓ saved in the record's journal only: {what} (see the error above)"
            record = self.paths.annotations
            self.show_error(
                "The review record file is damaged: addb process, addb diagnose and the dataset queue cannot read it",
                f"{record}: {damaged}. Every edit is kept in its journal ({record.with_suffix('.journal')}). Stop addb "
                f"view, then rebuild the file from the journal: python -c \"from annotations import AnnotationStore; "
                f"AnnotationStore.recover('{record}')\"",
            )
        pending = pending_replaced(self.view) if edits and self.view is not None else 0
        if pending:  # the edit made (or left) the trial's flags replace the solver's proposals
            text += (
                f"<br><span style='color:#c00'>{pending} pending proposed frames are now fitted as measured</span> "
                "(the trial's flags replace the solver's choice): accept or reject them (Y / Z)."
            )
        if text.startswith("✓"):
            self.panel.saved.content = text  # names its reviewer
        else:
            self._answer(text)

    def refresh_flags(self) -> None:
        """Re-read the trial's flags from the store and redraw what shows them."""
        editor = self.editor
        if editor is None:
            return
        view = editor.view()
        with self._lock:
            if self.editor is not editor:
                return
            self.view = view
            if self.trial is not None:
                self.tracks = track_data(self.trial, view, self.hicks)
            if self.plots is not None:
                self.plots.update(flagged=view.flagged, proposed=view.pending)
                self._last_plot = time.monotonic()
            with self._quiet_updates():
                self.panel.reviewed.value = view.reviewed
            self._show_flags_info()
            if self.playback is not None:
                self.render(self.playback.frame)

    def _show_flags_info(self) -> None:
        v = self.view
        if v is None:
            self.panel.proposal_info.content = "Flags unavailable."
            return
        record = _escape(self._record_elsewhere_text()) if self._record_elsewhere() else ""
        t = self.trial
        reasons = list(t.metrics.get("unobserved_reasons") or []) if t is not None else []  # the fit shown's
        unproposed = unproposed_replaced(v, t.unobserved, t.proposed, reasons) if t is not None and t.has_dynamics else 0
        differ = self._flags_since_fit(reasons)
        self.panel.proposal_info.content = describe_flags(v, differ=differ, unproposed=unproposed, record=record)

    def _flags_since_fit(self, reasons: list[str]) -> int:
        """Frames the flags as they are now would fit otherwise than the results shown
        (:func:`~addb_viewer.app.flags.flags_differ_from_fit`, ``reasons`` the fit's
        ``unobserved_reasons``); 0 without dynamics, or when the flags cannot be read as the
        solver takes them (a Reprocess says why)."""
        from addb_viewer.review_masks import unmeasured_force

        t = self.trial
        if t is None or self.store is None or not t.has_dynamics:
            return 0
        try:
            mask = unmeasured_force(self.store, self.paths.subject_dir, [t.trial]).get(t.trial)
        except (AnnotationError, AddbError):
            return 0
        return flags_differ_from_fit(mask, t.unobserved, t.proposed, reasons)

    def _damaged_record(self) -> str | None:
        """Why the review record file does not read as JSON (another hand or tool damaged
        it while the app runs: the store keeps saving in its journal), None when it reads
        or does not exist yet."""
        try:
            json.loads(self.paths.annotations.read_text(encoding="utf-8"))
        except FileNotFoundError:
            return None
        except (OSError, ValueError) as exc:
            return f"{type(exc).__name__}: {exc}"
        return None

    def _record_elsewhere(self) -> bool:
        """Whether the review record is outside the subject folder (a read-only folder, or
        the bundled demo: :func:`addb_viewer.locations.annotations_path`)."""
        return not self.paths.annotations.resolve().is_relative_to(self.paths.subject_dir.resolve())

    def _record_elsewhere_text(self) -> str:
        return f"The review record is {self.paths.annotations} (addb does not write in this subject folder)"

    def mark(self, what: str) -> None:
        """"Set in", "Set out" or "Clear marks" at the current frame."""
        with self._lock:
            pb = self.playback
            if pb is None:
                return
            {"Set in": pb.mark_in, "Set out": pb.mark_out, "Clear marks": pb.clear_marks}[what]()
            self._forget_refusal()
            sel = pb.selection()
            with self._quiet_updates():  # cleared: the slider's thumbs go back together at 0
                self.panel.selection.value = (sel[0], sel[1] - 1) if sel is not None else (0, 0)
            self.draw_timeline()
        self._show_range_info()

    def show_diagnosis(self, trial: str | None) -> None:
        """Show ``trial``'s diagnosis report (``OUT/<trial>/diagnosis.json``) in the
        Diagnosis folder when that trial is on screen."""
        if trial is None or self.trial is None or self.trial.trial != trial:
            return
        self.panel.diagnosis.content = diagnosis_markdown(self.paths.out_dir, self.paths.subject_dir, trial)

    def _setup_timeline(self, trial: ProcessedTrial) -> None:
        """Size the timeline's sliders to the trial (no selection yet)."""
        last = max(trial.n_frames - 1, 1)
        p = self.panel
        with self._quiet_updates():
            p.timeline_frame.max = last
            p.timeline_frame.disabled = False
            p.selection.max = last
            p.selection.value = (0, 0)
            p.selection.disabled = False
        p.selection_info.content = "Drag the ends of Selection to choose frames."

    def draw_timeline(self) -> float:
        """Redraw the timeline strip (tracks, playhead, selection); returns the seconds it
        took server-side (HTML built and handed to viser)."""
        t0 = time.perf_counter()
        pb, tracks = self.playback, self.tracks
        if pb is None or tracks is None:
            return 0.0
        reasons = self.trial.proposal_reasons if self.trial is not None else ()
        self.panel.timeline.content = timeline_html(tracks, reasons=reasons, frame=pb.frame, selection=pb.selection())
        return time.perf_counter() - t0

    def select(self, start: int, end: int) -> None:
        """Select frames ``start``..``end`` (inclusive, either order) on the timeline; they
        become the in and out points of the range edits."""
        with self._lock:
            pb = self.playback
            if pb is None:
                return
            pb.mark_in(min(start, end))
            pb.mark_out(max(start, end))
            self._forget_refusal()
            with self._quiet_updates():
                self.panel.selection.value = (pb.in_point, pb.out_point)
            self.draw_timeline()
        self._show_range_info()

    def _answer(self, text: str) -> None:
        """Show ``text`` in the edits' line as the answer to the press of the page whose
        handler runs: on a team server (every page shows the same line) it starts with that
        page's reviewer, so that a refusal is not read as addressed to another reviewer."""
        if self.token is not None:
            name = self.reviewer_name(getattr(self._actor, "client", None))
            text = f"**{_escape(name) if name else 'a page without a name'}**: {text}"
        self.panel.saved.content = text

    def _forget_refusal(self) -> None:
        """Take back the edits' line when it refuses or warns (not a saved edit): it answered
        the reviewer's last press, and would read as an answer to the next ("Select frames
        first" beside a selection, "open trial X" once X is open)."""
        text = self.panel.saved.content
        idle = NO_RECORD if self.store is None and self.store_problem is not None else NO_EDITS
        if text != idle and not text.startswith("✓"):
            self.panel.saved.content = idle

    def selection_edit(self, what: str) -> None:
        """"Flag", "Unflag", "Accept" or "Reject" the timeline's selected frames."""
        pb = self.playback
        sel = pb.selection() if pb is not None else None
        if sel is None:
            self._answer("Select frames on the timeline first (drag the ends of Selection).")
            return
        s, e = sel
        if what in ("Flag", "Unflag"):
            self._flag_frames(what == "Flag", s, e)
        elif what == "Accept":
            self.edit(f"accept proposals in {frames_text(s, e)}", lambda ed, _k, _f: ed.accept_range(s, e))
        else:
            self.edit(f"reject proposals in {frames_text(s, e)}", lambda ed, _k, _f: ed.reject_range(s, e))

    def _show_range_info(self) -> None:
        pb = self.playback
        sel = pb.selection() if pb is not None else None
        if sel is None:
            self.panel.range_info.content = "Range: no in/out points (press I / O)"
            self.panel.selection_info.content = "Drag the ends of Selection to choose frames."
        else:
            n = sel[1] - sel[0]
            text = f"frames {sel[0]}–{sel[1] - 1} ({n} frame{'' if n == 1 else 's'})"
            self.panel.range_info.content = f"Range: {text}"
            self.panel.selection_info.content = f"Selected: {text}; G flag · X unflag · Y accept · Z reject"

    def range_edit(self, what: str) -> None:
        """"Flag range" (for the selected foot) or "Unflag range" over the in/out points."""
        pb = self.playback
        sel = pb.selection() if pb is not None else None
        if sel is None:
            self._answer("Set an in point and an out point first (I / O).")
            return
        self._flag_frames(what == "Flag range", *sel)

    def _flag_frames(self, flag: bool, s: int, e: int) -> None:
        """Flag frames ``[s, e)`` for the selected foot, or clear their flags."""
        feet = _feet(self.panel.foot.value)
        if flag:
            self.edit(f"flag {frames_text(s, e)} ({feet})", lambda ed, _k, foot: ed.flag_range(s, e, foot))
        else:
            self.edit(f"unflag {frames_text(s, e)} ({feet})", lambda ed, _k, foot: ed.clear_range(s, e, foot))

    def history(self, what: str) -> None:
        """"Undo" or "Redo" the page's reviewer's last action (:mod:`~addb_viewer.app.history`).

        The store undoes one edit at a time for the whole server (one history per store,
        over every trial of the subject), so the last action may be another reviewer's (on a
        team server) or on another trial than the one shown: then nothing is undone and the
        page says whose it is, or which trial to open (undo never removes another reviewer's
        work, nor frames the reviewer cannot see)."""
        if self.store is None:
            return
        name = self.reviewer_name(getattr(self._actor, "client", None))
        undo = what == "Undo"
        # the last action is read and taken back with no other edit between: a Redo pressed
        # while another page's Undo was still moving its action to the redo list would
        # otherwise find that list empty, then redo the other reviewer's edit
        with self._edit_lock:
            saved = self._history_step(name, what, undo)
        if saved and self.workbench is not None:
            self.workbench.refresh()

    def _history_step(self, name: str | None, what: str, undo: bool) -> bool:
        action = self.actions.last(undo)
        last = "edit" if undo else "undone edit"
        refused = f"<span style='color:#c00'>**not {'undone' if undo else 'redone'}**</span>: the last {last}"
        if name is not None and action is not None and action.reviewer != name:
            self._answer(
                f"{refused} on this subject is {_escape(action.reviewer)}'s (one history for everyone on this "
                "server); make your own edit instead (flag, unflag, accept or reject)."
            )
            return False
        shown = self.trial.trial if self.trial is not None else None
        if action is not None and action.trial != shown:
            self._answer(f"{refused} is on trial {_escape(action.trial)}: open it to {what.lower()} it.")
            return False
        store = self.store
        assert store is not None
        return self._edit_as(
            name,
            what.lower() + (f" ({action.what})" if action is not None else ""),
            lambda _ed, _k, _f: self.actions.step(store.undo if undo else store.redo, undo),
            history=True,
        )

    # ================================================================== GUI wiring
    @contextlib.contextmanager
    def _quiet_updates(self) -> Iterator[None]:
        """Set GUI values from Python without running their on_update handlers (viser
        calls them synchronously in the setting thread)."""
        prev = getattr(self._quiet, "on", False)
        self._quiet.on = True
        try:
            yield
        finally:
            self._quiet.on = prev

    def _guard(self, context: str, fn: Callable[..., Any]) -> Callable[[Any], None]:
        def handler(event: Any) -> None:
            if getattr(self._quiet, "on", False):
                return
            prev = getattr(self._actor, "client", None)
            self._actor.client = getattr(event, "client_id", None)
            try:
                fn(event)
            except Exception as exc:  # noqa: BLE001 - shown in the page
                self.show_error(context, exc)
            finally:
                self._actor.client = prev

        return handler

    def _wire(self) -> None:
        p = self.panel
        on = self._guard
        p.trial.on_update(on("Trial", lambda e: self._trial_picked(e.target.value)))
        p.frame.on_update(on("Seek", lambda e: self.seek(int(e.target.value))))
        p.timeline_frame.on_update(on("Seek", lambda e: self.seek(int(e.target.value))))
        p.selection.on_update(on("Selection", lambda e: self.select(*(int(v) for v in e.target.value))))
        p.selection_edit.on_click(on("Selected frames", lambda e: self.selection_edit(e.target.value)))
        p.transport.on_click(on("Playback", lambda e: self._transport(e.target.value)))
        p.speed.on_update(on("Speed", lambda e: self._with_playback(lambda pb: pb.set_speed(e.target.value, time.monotonic()))))
        p.loop.on_update(on("Loop", lambda e: self._with_playback(lambda pb: setattr(pb, "loop", bool(e.target.value)))))
        p.jump.on_click(on("Jump", lambda e: self.jump(e.target.value)))
        p.views.on_click(on("View", lambda e: self.camera_view(e.target.value)))
        p.toggle_flag.on_click(on("Flag", lambda e: self.toggle_flag()))
        p.marks.on_click(on("Range", lambda e: self.mark(e.target.value)))
        p.range_flags.on_click(on("Range flags", lambda e: self.range_edit(e.target.value)))
        p.proposal_here.on_click(on("Proposal", lambda e: self._proposal(e.target.value, here=True)))
        p.proposal_all.on_click(on("Proposals", lambda e: self._proposal(e.target.value, here=False)))
        p.reviewed.on_update(on("Reviewed", lambda e: self.set_reviewed(bool(e.target.value))))
        p.history.on_click(on("Undo", lambda e: self.history(e.target.value)))
        p.reprocess.on_click(on("Reprocess", lambda e: self.jobs.reprocess()))
        p.diagnose.on_click(on("Diagnose", lambda e: self.jobs.diagnose()))
        p.apply_diagnosis.on_click(on("Apply the diagnosis", lambda e: self.jobs.apply_diagnosis()))
        p.cancel.on_click(on("Cancel", lambda e: self.jobs.cancel()))
        p.recover_record.on_click(on("Rebuild the review record", lambda e: self.recover_record()))
        for h in (p.show_labels, p.show_markers, p.show_bones, p.show_forces, p.marker_threshold_cm, p.m_per_bw):
            h.on_update(on("Display", lambda e: self._apply_display()))
        p.record.on_click(on("Record to Rerun", lambda e: self.jobs.record(p.record_name.value)))
        commands: dict[str, Callable[[], None]] = {
            "Play / pause": self.toggle_play,
            "Previous frame": lambda: self.step(-1),
            "Next frame": lambda: self.step(1),
            "Toggle flag": self.toggle_flag,
            "Set in point": lambda: self.mark("Set in"),
            "Set out point": lambda: self.mark("Set out"),
            "Next flagged frame": lambda: self.jump("Flagged"),
            "Next proposal": lambda: self.jump("Proposal"),
            "Next frame over Hicks threshold": lambda: self.jump("Over Hicks"),
            "Undo": lambda: self.history("Undo"),
            "Redo": lambda: self.history("Redo"),
            "Flag selection": lambda: self.selection_edit("Flag"),
            "Unflag selection": lambda: self.selection_edit("Unflag"),
            "Accept selection": lambda: self.selection_edit("Accept"),
            "Reject selection": lambda: self.selection_edit("Reject"),
        }
        for label, cmd in commands.items():
            p.commands[label].on_trigger(on(label, lambda _e, cmd=cmd: cmd()))

    def _transport(self, what: str) -> None:
        if what.startswith("◀"):
            self.step(-1)
        elif what.startswith("Next"):
            self.step(1)
        else:
            self.toggle_play()

    def _with_playback(self, fn: Callable[[Playback], Any]) -> None:
        with self._lock:
            if self.playback is not None:
                fn(self.playback)

    def set_reviewed(self, reviewed: bool) -> None:
        """Tick or untick "Trial reviewed" on the trial shown.

        A trial marked reviewed has its reviewer's flags replace the solver's own choice of
        unmeasured frames (:mod:`addb_viewer.review_masks`), in Reprocess and in the dataset
        run, so a proposal neither accepted nor rejected is then fitted as a measured frame.
        With such pending proposals the first tick therefore says so and leaves the box
        unticked; ticked again with the same pending frames, at least
        :data:`~addb_viewer.app.reprocess.CONFIRM_AFTER_S` later (a double click is not a
        second thought: :class:`~addb_viewer.app.reprocess.SecondThought`), it marks the
        trial reviewed."""
        v, t = self.view, self.trial
        pending = int(v.pending.sum()) if reviewed and v is not None and t is not None and not v.reviewed else 0
        if pending and not self.review_warning.confirmed((t.trial, pending)):
            with self._quiet_updates():
                self.panel.reviewed.value = False
            self._answer(
                f"<span style='color:#c00'>**not marked reviewed: {pending} proposed frames of {_escape(t.trial)} "
                "are still pending.**</span> A trial marked reviewed has its flags replace the solver's own "
                "choice, so they would be fitted as measured frames (with the plates' force, often none) by "
                "Reprocess and the dataset run. Accept or reject them first (Y / Z, All proposals), or tick "
                "Trial reviewed again to mark it reviewed as it is."
            )
            return
        self.review_warning.forget()
        self.edit("trial reviewed" if reviewed else "trial not reviewed", lambda ed, _k, _f: ed.set_reviewed(reviewed))

    def toggle_flag(self) -> None:
        """Toggle the selected foot's flag on the current frame."""
        k = self.playback.frame if self.playback is not None else 0
        self.edit(f"toggle flag at frame {k} ({_feet(self.panel.foot.value)})", lambda ed, k, foot: ed.toggle(k, foot))

    def _proposal(self, what: str, *, here: bool) -> None:
        accept = what.startswith("Accept")
        scope = "here" if here else "all"
        self.edit(
            f"{'accept' if accept else 'reject'} proposal ({scope})",
            lambda ed, k, _f: (ed.accept if accept else ed.reject)(k if here else None),
        )

    def _apply_display(self) -> None:
        p, s = self.panel, self.settings
        with self._lock:
            s.show_labels = bool(p.show_labels.value)
            s.show_markers = bool(p.show_markers.value)
            s.show_bones = bool(p.show_bones.value)
            s.show_forces = bool(p.show_forces.value)
            s.marker_threshold_m = max(float(p.marker_threshold_cm.value), 0.0) / 100.0
            s.m_per_bw = max(float(p.m_per_bw.value), 0.01)
            if self.playback is not None:
                self.render(self.playback.frame)


def _conflicts_text(edits: list[Edit], history: bool) -> str:
    """What an undo or redo left as it was because another writer (another page's process,
    another reviewer) changed it since (the store's conflicts): "" when nothing."""
    kept = [c for e in edits for c in e.conflicts] if history else []
    if not kept:
        return ""
    ranges = sorted({r for c in kept for r in c.frames})
    where = ", ".join(frames_text(a, b) for a, b in ranges) or "some values"
    who = ", ".join(dict.fromkeys(c.kept.reviewer for c in kept if c.kept is not None)) or "another writer"
    return f"<br><span style='color:#c00'>**not all restored**</span>: {where} kept as {_escape(who)} edited them since"


def _feet(foot: str) -> str:
    """The Flags folder's Foot choice as the edits' line names it."""
    return "both feet" if foot == "both" else f"{foot} foot"


def _converted_from(subject_dir: Path) -> str | None:
    """The name of the .b3d file a subject folder was converted from (``addb convert``
    writes its source beside the trials), None for other subject folders."""
    from solver.io.b3d_convert import SOURCE_JSON

    try:
        source = json.loads((Path(subject_dir) / SOURCE_JSON).read_text(encoding="utf-8"))["b3d"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return Path(str(source)).name or None


def _preferred(trials: list[str]) -> str:
    """The trial to open first: the first that is not a static trial, if any."""
    moving = [t for t in trials if "static" not in t.lower()]
    return (moving or trials)[0]


def _escape(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def _record_problem(record: Path, exc: BaseException, rebuildable: bool) -> str:
    """Why the review record ``record`` cannot be opened, and what the reviewer can do: its
    journal (beside it) rebuilds it when it holds every edit (:func:`annotations.recovery.
    journal_holds_every_edit`), else the record must be restored from a copy."""
    paths = StorePaths.for_path(record)
    if rebuildable:
        return (
            f"{exc}. Its journal {paths.journal} still holds every edit: press "
            f"“Rebuild the review record from its journal” (below) to rebuild {paths.main.name} from it "
            f"(the damaged file is kept beside it as {paths.main.name}.damaged-<time>), then flag as before."
        )
    return (
        f"{exc}. Its journal {paths.journal} does not hold every edit (it is missing, damaged, or was "
        f"restarted after an earlier save), so it cannot rebuild the record: restore {paths.main} from a "
        "backup, then open the subject again."
    )
