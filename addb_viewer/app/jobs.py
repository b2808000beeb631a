"""The solver in a separate process, with progress and cancel, never blocking the server.

:class:`SolverJob` starts ``python -m addb_viewer.app.jobs SPEC.json`` in a child process.
The child runs :func:`solver.pipeline.process_subject` (for a Reprocess after a flag edit
:func:`solver.pipeline.reprocess_dynamics`, which skips the kinematics stage; for a diagnosis job,
:func:`solver.diagnose.core.diagnose_trial` and writes its report) and reports on its standard
output, one JSON object per line after :data:`PREFIX` (other output is ignored):
``{"progress": message, "fraction": f}``, then ``{"done": true}`` or
``{"error": {type, message, path, line, where, traceback}}``. A thread of the parent reads
those lines and calls back; :meth:`SolverJob.cancel` terminates the child. The solver
writes its output folder atomically, so a cancelled or failed run leaves the previous
result in place.

A job names the trials to write (a Reprocess: the edited trial and every other trial with
dynamics, :func:`addb_viewer.app.reprocess.dynamics_trials`): the solver stages them and
then replaces, by renames, those trials' folders, the model and subject.json in the output
folder (the other trials stay).

Warm children. Python's start and the solver's imports take about 1 s, half the walk's
Reprocess. :func:`prestart_solver` (called when the app opens a subject, and again after
every job) starts a spare child, ``python -m addb_viewer.app.jobs --warm``, that imports
the solver and then waits for a spec path on its standard input; :meth:`SolverJob.start`
hands the spec to that spare when there is one (started with the same interpreter and
environment) instead of starting a new process. Each child still runs one job only and
exits, so a job's numbers are those of a fresh process. A spare that died (or whose
imports failed) is replaced by a fresh child; a spare exits when its standard input
closes (the app ended) and the app terminates it at exit. ``ADDB_WARM_SOLVER=0`` turns
the spares off.
"""

from __future__ import annotations

import atexit
import json
import os
import shutil
import subprocess
import sys
import threading
import time
import traceback
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

PREFIX = "@@addb-job "
"""Marks the protocol lines on the child's standard output."""


@dataclass(frozen=True)
class JobSpec:
    """What a solver run does.

    Attributes
    ----------
    subject_dir
        AddBiomechanics subject folder.
    out_dir
        Output folder (replaced atomically by the solver).
    trials
        Trials to write (all trials are used for scaling); None: all.
    unmeasured_force
        Trial -> ``(T,)`` bool at the trial's processed frames: the reviewer's flags of
        unmeasured force (:func:`addb_viewer.review_masks.unmeasured_force`).
    kind
        ``"process"`` (the pipeline) or ``"diagnose"`` (``addb diagnose`` of the single
        trial in ``trials``: writes ``OUT/<trial>/diagnosis.json``).
    dynamics_only
        For ``"process"`` with ``trials``: rerun the dynamics stage only, on the kinematics
        cached in ``out_dir`` by the last full run
        (:func:`solver.pipeline.reprocess_dynamics`; a full run when that cache is missing
        or stale). The reviewer's flags do not change the kinematics. Either way the
        dynamics fit is the one ``out_dir`` was made with
        (:func:`solver.pipeline.recorded_dynamics_options`; the default for a first run).
    review_record
        The review record (``annotations.json``) the ``unmeasured_force`` flags were read
        from; the solver records it in the output's ``subject.json`` (``review_record``).
        None: no record (flags given without one are recorded as such).
    """

    subject_dir: Path
    out_dir: Path
    trials: tuple[str, ...] | None = None
    unmeasured_force: dict[str, np.ndarray] = field(default_factory=dict)
    kind: str = "process"
    dynamics_only: bool = False
    review_record: Path | None = None


@dataclass(frozen=True)
class JobResult:
    """How a run ended.

    Attributes
    ----------
    status
        "done", "failed" or "cancelled".
    error
        For "failed": ``type``, ``message`` and, when known, ``path``, ``line``,
        ``where``, ``traceback``; None otherwise.
    seconds
        Wall time of the run, s.
    """

    status: str
    error: dict[str, Any] | None
    seconds: float

    @property
    def message(self) -> str:
        """One line for the page."""
        if self.status != "failed" or not self.error:
            return self.status
        e = self.error
        where = ", ".join(str(x) for x in (e.get("path"), e.get("line"), e.get("where")) if x)
        return f"{e.get('type', 'Error')}{f' ({where})' if where else ''}: {e.get('message', '')}"


Progress = Callable[[str, float], None]
Done = Callable[[JobResult], None]


class SolverJob:
    """One solver run in a child process.

    Parameters
    ----------
    spec
        What to run.
    work_dir
        Scratch folder for the spec, masks and the child's log (created; removed by
        :meth:`cleanup`).
    on_progress
        Called from the reader thread with (message, fraction in [0, 1]).
    on_done
        Called once from the reader thread when the child has exited.
    """

    def __init__(self, spec: JobSpec, work_dir: Path, *, on_progress: Progress, on_done: Done) -> None:
        self.spec = spec
        self.work_dir = Path(work_dir)
        self.on_progress = on_progress
        self.on_done = on_done
        self.result: JobResult | None = None
        self._proc: subprocess.Popen[str] | None = None
        self._cancelled = threading.Event()
        self._finished = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def running(self) -> bool:
        """True from :meth:`start` until the child has exited and ``on_done`` ran."""
        return self._thread is not None and not self._finished.is_set()

    def start(self) -> None:
        """Write the spec and start the child process and its reader thread."""
        self.work_dir.mkdir(parents=True, exist_ok=True)
        masks = self.work_dir / "unmeasured_force.npz"
        np.savez(masks, **{f"m{i}": np.asarray(m, bool) for i, m in enumerate(self.spec.unmeasured_force.values())})
        spec_file = self.work_dir / "job.json"
        spec_file.write_text(
            json.dumps(
                {
                    "subject_dir": str(self.spec.subject_dir),
                    "out_dir": str(self.spec.out_dir),
                    "trials": list(self.spec.trials) if self.spec.trials is not None else None,
                    "unmeasured_force_trials": list(self.spec.unmeasured_force),
                    "unmeasured_force": str(masks),
                    "kind": self.spec.kind,
                    "dynamics_only": self.spec.dynamics_only,
                    "review_record": str(self.spec.review_record) if self.spec.review_record is not None else None,
                }
            )
        )
        self._t0 = time.monotonic()
        spare = _take_spare()
        if spare is not None:  # a warm child: it opens its own log (child.log) beside the spec
            try:
                assert spare.stdin is not None
                spare.stdin.write(str(spec_file) + "\n")
                spare.stdin.close()
            except OSError:  # it died just now (broken pipe): a fresh child instead
                spare.kill()
                spare.wait()
                if spare.stdout is not None:
                    spare.stdout.close()
                spare = None
        if spare is not None:
            self._proc = spare
            log = None
        else:
            log = open(self.work_dir / "child.log", "w")  # noqa: SIM115 (closed by the reader)
            self._proc = subprocess.Popen(
                [sys.executable, "-m", "addb_viewer.app.jobs", str(spec_file)],
                stdout=subprocess.PIPE,
                stderr=log,
                stdin=subprocess.DEVNULL,
                text=True,
                env=_child_env(),
            )
        self._thread = threading.Thread(target=self._read, args=(log,), name="addb-solver-job", daemon=True)
        self._thread.start()

    def cancel(self) -> None:
        """Stop the child (SIGTERM, then SIGKILL after 3 s). Safe to call at any time."""
        self._cancelled.set()
        proc = self._proc
        if proc is None or proc.poll() is not None:
            return
        proc.terminate()
        try:
            proc.wait(3.0)
        except subprocess.TimeoutExpired:
            proc.kill()

    def wait(self, timeout: float | None = None) -> JobResult | None:
        """Wait until the run has ended and ``on_done`` returned; the result or None."""
        self._finished.wait(timeout)
        return self.result

    def cleanup(self) -> None:
        """Remove the scratch folder (call after the result has been used)."""
        shutil.rmtree(self.work_dir, ignore_errors=True)

    def _read(self, log: Any) -> None:
        assert self._proc is not None and self._proc.stdout is not None
        error: dict[str, Any] | None = None
        done = False
        try:
            for line in self._proc.stdout:
                if not line.startswith(PREFIX):
                    continue
                try:
                    msg = json.loads(line[len(PREFIX) :])
                except ValueError:
                    continue
                if "progress" in msg:
                    self._safe_progress(str(msg["progress"]), float(msg.get("fraction", 0.0)))
                elif msg.get("done"):
                    done = True
                elif "error" in msg:
                    error = dict(msg["error"])
            code = self._proc.wait()
        finally:
            if log is not None:
                log.close()
        prestart_solver(self.work_dir.parent)  # the next job's child imports while the reviewer reads the result
        seconds = time.monotonic() - self._t0
        if self._cancelled.is_set() and not done:
            result = JobResult("cancelled", None, seconds)
        elif done and code == 0:
            result = JobResult("done", None, seconds)
        else:
            if error is None:
                error = {"type": "SolverCrashed", "message": f"the solver process exited with code {code}; {self._log_tail()}"}
            result = JobResult("failed", error, seconds)
        self.result = result
        try:
            self.on_done(result)
        finally:
            self._finished.set()

    def _safe_progress(self, message: str, fraction: float) -> None:
        try:
            self.on_progress(message, min(max(fraction, 0.0), 1.0))
        except Exception:  # noqa: BLE001 - a display problem must not stop the reader
            traceback.print_exc()

    def _log_tail(self, n: int = 600) -> str:
        try:
            text = (self.work_dir / "child.log").read_text(errors="replace")
        except OSError:
            return "no log"
        return "last output: " + text[-n:].strip() if text.strip() else "no output"


def _child_env() -> dict[str, str]:
    """The child's environment: this one, with the repository first on PYTHONPATH."""
    env = {k: v for k, v in os.environ.items() if k != "ADDB_WARM_SOLVER"}
    root = str(Path(__file__).resolve().parents[2])
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env["PYTHONUNBUFFERED"] = "1"
    return env


class _Spare:
    """A warm child and the thread that waits for its ``ready`` line."""

    def __init__(self, tag: str) -> None:
        self.env = _child_env()
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "addb_viewer.app.jobs", "--warm", tag],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,  # until the spec arrives; then the job's child.log
            stdin=subprocess.PIPE,
            text=True,
            env=self.env,
        )
        self.ready = False
        self._thread = threading.Thread(target=self._wait_ready, name="addb-solver-spare", daemon=True)
        self._thread.start()

    def _wait_ready(self) -> None:
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()  # imports done (or EOF: the child died)
        self.ready = line.startswith(PREFIX) and '"ready"' in line

    def usable(self, timeout: float) -> bool:
        """Wait (at most ``timeout`` s) for its imports; True when it is alive and ready."""
        self._thread.join(timeout)
        return not self._thread.is_alive() and self.ready and self.proc.poll() is None and self.env == _child_env()

    def kill(self) -> None:
        """End the child and close its pipes."""
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
        self._thread.join(5.0)
        for f in (self.proc.stdin, self.proc.stdout):
            if f is not None:
                f.close()


_spare: _Spare | None = None
_spare_lock = threading.Lock()
_closing = False  # set at exit: no new spare after that


def warm_children_enabled() -> bool:
    """False when ``ADDB_WARM_SOLVER=0`` (every job starts a fresh process)."""
    return os.environ.get("ADDB_WARM_SOLVER", "1") != "0"


def prestart_solver(jobs_dir: str | Path | None = None) -> None:
    """Start a spare solver child (imports done ahead of the next job) unless one exists.

    Returns at once; the child imports in the background (about 1 s of one core). Called
    when the app opens a subject and after every job; a no-op with ``ADDB_WARM_SOLVER=0``.
    ``jobs_dir`` (the app's job folder) is only written on the child's command line, so
    that the app's solver processes can be told apart (``ps``); any job may use the spare.
    """
    global _spare
    if not warm_children_enabled():
        return
    with _spare_lock:
        if _closing or (_spare is not None and _spare.proc.poll() is None and _spare.env == _child_env()):
            return
        if _spare is not None:  # dead, or started with another environment
            _spare.kill()
        try:
            _spare = _Spare(str(jobs_dir or ""))
        except OSError:  # pragma: no cover - no process to spare; jobs start their own
            _spare = None


def wait_for_spare(timeout: float = 60.0) -> bool:
    """Block until the spare child (if any) has finished its imports; True when one is ready.
    For benchmarks and tests: the app never waits for it."""
    with _spare_lock:
        spare = _spare
    return spare is not None and spare.usable(timeout)


def _take_spare() -> subprocess.Popen[str] | None:
    """The spare child's process for a job (removed from the pool), or None: no spare, or it
    died, failed its imports or has another environment (then it is ended)."""
    global _spare
    with _spare_lock:
        spare, _spare = _spare, None
    if spare is None:
        return None
    if warm_children_enabled() and spare.usable(timeout=30.0):
        return spare.proc
    spare.kill()
    return None


@atexit.register
def _end_spare() -> None:
    global _spare, _closing
    with _spare_lock:
        _closing = True
        spare, _spare = _spare, None
    if spare is not None:
        spare.kill()


def new_work_dir(jobs_dir: Path, label: str) -> Path:
    """A fresh scratch folder ``jobs_dir/<label>-<time>-<id>`` (not created)."""
    return Path(jobs_dir) / f"{label}-{time.strftime('%Y%m%d-%H%M%S')}-{uuid.uuid4().hex[:6]}"


# ---------------------------------------------------------------------- child process
def _emit(obj: dict[str, Any]) -> None:
    sys.stdout.write(PREFIX + json.dumps(obj) + "\n")
    sys.stdout.flush()


def _child(spec_path: str) -> int:
    try:
        spec = json.loads(Path(spec_path).read_text())
        with np.load(spec["unmeasured_force"]) as data:
            unmeasured_force = {t: data[f"m{i}"] for i, t in enumerate(spec["unmeasured_force_trials"])}
        from solver.pipeline import ProcessOptions, process_subject, recorded_dynamics_options

        trials = tuple(spec["trials"]) if spec["trials"] is not None else None
        _emit({"progress": "loading the subject", "fraction": 0.0})
        if spec.get("kind") == "diagnose":
            from solver.diagnose.core import diagnose_trial
            from solver.diagnose.report import write_report

            (trial,) = trials or ("",)
            diag = diagnose_trial(spec["subject_dir"], trial, spec["out_dir"], unmeasured_force=unmeasured_force.get(trial),
                                  subject_flags=unmeasured_force, progress=lambda m, f: _emit({"progress": m, "fraction": f}))  # fmt: skip
            write_report(diag, spec["out_dir"], trial)
            _emit({"done": True})
            return 0
        if spec.get("dynamics_only") and trials:
            from solver.pipeline import reprocess_dynamics

            reprocess_dynamics(
                spec["subject_dir"],
                spec["out_dir"],
                trials,
                unmeasured_force or None,
                lambda m, f: _emit({"progress": m, "fraction": f}),
                review_record=spec.get("review_record"),
            )
            _emit({"done": True})
            return 0
        process_subject(
            spec["subject_dir"],
            spec["out_dir"],
            # the fit the output was made with (a first processing: the default)
            options=ProcessOptions(trials=trials, dynamics=recorded_dynamics_options(spec["out_dir"])),
            unmeasured_force=unmeasured_force or None,
            progress=lambda m, f: _emit({"progress": m, "fraction": f}),
            review_record=spec.get("review_record"),
        )
    except Exception as exc:  # noqa: BLE001 - every failure is reported to the page
        info = exc.to_dict() if hasattr(exc, "to_dict") else {"type": type(exc).__name__, "message": str(exc)}
        info["traceback"] = traceback.format_exc(limit=8)
        _emit({"error": info})
        return 1
    _emit({"done": True})
    return 0


def _warm_child() -> int:
    """A spare child: import the solver, say ``ready``, wait for a spec path on standard
    input (EOF: the app ended, exit), send standard error to ``child.log`` beside the spec,
    then run that one job (:func:`_child`)."""
    try:  # what a Reprocess / process job imports; a failure is reported by the job itself
        from solver.scipy_imports import import_scipy

        import_scipy("scipy.signal")  # the dynamics' filter
        import solver.dynamics.stage
        import solver.pipeline
        import solver.results  # noqa: F401
    except Exception:  # noqa: BLE001, S110
        pass
    _emit({"ready": True})
    spec_path = sys.stdin.readline().strip()
    if not spec_path:
        return 0
    fd = os.open(Path(spec_path).parent / "child.log", os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    os.dup2(fd, 2)
    os.close(fd)
    return _child(spec_path)


if __name__ == "__main__":  # pragma: no cover - run as the child process
    sys.exit(_warm_child() if sys.argv[1] == "--warm" else _child(sys.argv[1]))  # --warm [JOBS_DIR]
