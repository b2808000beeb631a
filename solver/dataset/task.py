"""One subject of a dataset run, as it runs on a Dask worker.

:func:`run_subject` processes one subject folder into a private work folder beside its
final output folder, writes ``process.log`` (progress messages, warnings, the error
with its traceback) and ``manifest.json`` (:mod:`solver.dataset.manifest`, with the
summary rows of :mod:`solver.dataset.summary`), and only then moves the work folder into
place, in two renames, as :func:`solver.outputs.staged_output` does. So a worker killed
at any moment leaves the subject's output either complete (with its manifest) or as it
was before; the stale work folder of a killed worker is removed by the next run.

A failure caused by the data or the solver (any exception in the pipeline) is returned
as the subject's outcome, never raised, and recorded in the subject's output folder
(``process.log`` and a manifest with the error; an earlier run's output files stay): a
deterministic failure is not worth a retry, and the batch goes on. Only the death of the worker itself (killed, out of memory)
reaches the runner, which then retries the subject on another worker.

A failure of the output storage (disk full, quota, I/O error: :func:`storage_error`) is no
fault of the subject's data: it is recorded as transient (``error["transient"]``), so that
the next run processes the subject again instead of reporting the failure unchanged
(docs/audits/2026-12-02-dataset.md, finding 3).

Each attempt first writes its task key into :data:`STARTED_NAME` in its work folder: the
runner tells with :func:`attempt_started` a subject that was running when its worker died
from one that was only queued on that worker (finding 1), and charges only the first.
"""

from __future__ import annotations

import errno
import glob
import json
import os
import shutil
import tempfile
import time
import traceback
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from solver.errors import AddbError
from solver.outputs import SUBJECT_RECORD, replace_folder, write_json

LOG_NAME = "process.log"
#: Dask event topic of the subjects' progress (``{"rel", "message", "fraction"}``).
PROGRESS_TOPIC = "addb-subject-progress"
#: Least time between two progress events of one subject, s.
PROGRESS_INTERVAL_S = 0.5
#: Prefix of a subject's private work folder (beside its final output folder).
WORK_PREFIX = ".addb-work-"
#: File of a subject's work folder that holds the key of the attempt that made it, written
#: before anything else: the attempt started (:func:`attempt_started`).
STARTED_NAME = "started"
#: ``errno`` values of a failure of the output storage rather than of the subject
#: (:func:`storage_error`): full disk or quota, I/O error, read-only or stale file system,
#: file too large.
STORAGE_ERRNOS = frozenset(
    getattr(errno, name) for name in ("ENOSPC", "EDQUOT", "EIO", "EROFS", "ESTALE", "EFBIG") if hasattr(errno, name)
)

#: ``(subject_dir, out_dir) -> {trial: (T,) bool}`` or None: the reviewer's
#: unmeasured-force flags of a subject whose output goes to ``out_dir``, at each trial's
#: processed frames (``unmeasured_force``, :mod:`solver.masks`; a module-level function,
#: so that Dask sends it to the workers by name).
MaskLoader = Callable[[str, str], "dict[str, Any] | None"]


@dataclass(frozen=True)
class SubjectJob:
    """What a worker needs to process one subject of a dataset.

    Attributes
    ----------
    rel
        The subject's relative path in the dataset (``labA/s01``).
    subject_dir, out_dir
        The subject folder and its final output folder (absolute paths as text).
    key
        The manifest key computed by the runner (:func:`solver.dataset.manifest.manifest_key`).
    masks
        Loader of the reviewer's unmeasured-force masks, or None (automatic proposals).
    stop_event
        Name of the run's ``distributed.Event`` that asks it to stop, or None: once set,
        the subject is given up (before it starts, at its next progress message, or
        before its output is put in place) and its outcome is ``"cancelled"``.
    attempt
        The Dask key of this attempt, or None (not on Dask): written into the work folder's
        :data:`STARTED_NAME` as the attempt starts (:func:`attempt_started`).
    """

    rel: str
    subject_dir: str
    out_dir: str
    key: dict[str, Any]
    masks: MaskLoader | None = None
    stop_event: str | None = None
    attempt: str | None = None


class Stopped(Exception):
    """The run was asked to stop while this subject ran (:attr:`SubjectJob.stop_event`)."""


class _Log:
    """``process.log``: timestamped lines, flushed as they come (readable while running);
    on a Dask worker, the progress also goes to the client as :data:`PROGRESS_TOPIC`
    events (at most one per :data:`PROGRESS_INTERVAL_S`, but always the last one, at fraction 1,
    so that a fast subject's client still sees it finish)."""

    def __init__(self, path: Path, rel: str = "", stop_event: str | None = None) -> None:
        self.path = path
        self.rel = rel
        self.stop_event = stop_event
        self.t0 = time.perf_counter()
        self._f = open(path, "a", encoding="utf-8")  # noqa: SIM115 (closed in close())
        self._last = ""
        self._sent = -PROGRESS_INTERVAL_S
        try:
            from distributed import get_worker

            self._worker = get_worker()
        except (ImportError, ValueError):  # not inside a Dask task
            self._worker = None

    def __call__(self, message: str, fraction: float | None = None) -> None:
        if message == self._last:
            return
        self._last = message
        now = time.perf_counter()
        if self._worker is not None and fraction is not None and (now - self._sent >= PROGRESS_INTERVAL_S or fraction >= 1.0):
            self._sent = now
            self._worker.log_event(PROGRESS_TOPIC, {"rel": self.rel, "message": message, "fraction": float(fraction)})
            self.check_stop()
        pct = "" if fraction is None else f"[{100 * fraction:5.1f}%] "
        if self._f.closed:  # a failure after the log was closed (run_subject's last steps)
            self._f = open(self.path, "a", encoding="utf-8")  # noqa: SIM115 (closed in close())
        self._f.write(f"{time.perf_counter() - self.t0:8.2f}s {pct}{message}\n")
        self._f.flush()

    def check_stop(self) -> None:
        """Raise :class:`Stopped` when the run's stop event is set (on a Dask worker), or when
        the event can no longer be read: the scheduler is gone (the run was interrupted and
        its cluster closed), so no one waits for this subject. Giving it up then leaves no
        trace; recording the error as the subject's failure would keep the next run from
        processing it (a failure with the same inputs is not run again)."""
        if self._worker is None or self.stop_event is None:
            return
        from distributed import Event

        try:
            stopped = Event(self.stop_event).is_set()
        except Exception as exc:  # noqa: BLE001 - any failure to reach the scheduler
            raise Stopped(f"subject {self.rel}: the run's scheduler cannot be reached ({type(exc).__name__})") from None
        if stopped:
            raise Stopped(f"subject {self.rel}: the run was stopped")

    def close(self) -> None:
        self._f.close()


def storage_error(exc: BaseException) -> OSError | None:
    """The failure of the output storage behind ``exc`` (``exc`` itself or an exception it was
    raised from or while handling: an OSError whose errno is one of :data:`STORAGE_ERRNOS`),
    or None: the failure is the subject's own (its data or the solver)."""
    seen: set[int] = set()
    cur: BaseException | None = exc
    while cur is not None and id(cur) not in seen:
        seen.add(id(cur))
        if isinstance(cur, OSError) and cur.errno in STORAGE_ERRNOS:
            return cur
        cur = cur.__cause__ or cur.__context__
    return None


def storage_failure(exc: BaseException) -> dict[str, Any]:
    """The error record (:meth:`AddbError.to_dict` form) of a failure of the output storage
    behind ``exc``: type ``StorageError``, ``"transient": true``, the file as ``path`` and a
    message that says so and that the next run processes the subject again.

    Raises
    ------
    ValueError
        No failure of the output storage is behind ``exc`` (:func:`storage_error` is None).
    """
    storage = storage_error(exc)
    if storage is None:
        raise ValueError(f"not a failure of the output storage: {type(exc).__name__}: {exc}")
    code = errno.errorcode.get(storage.errno or 0, str(storage.errno))
    return {
        "type": "StorageError",
        "message": f"storage error ({code}: {storage.strerror or storage}), not a fault of the subject's data; "
                   "the next run processes this subject again",
        "path": None if storage.filename is None else os.fsdecode(storage.filename),
        "line": None,
        "where": None,
        "transient": True,
    }


def _error_record(exc: BaseException) -> dict[str, Any]:
    """JSON form of an exception: our errors carry file / line / where; a failure of the
    output storage is a transient ``StorageError`` (:func:`storage_failure`)."""
    if storage_error(exc) is not None:
        return storage_failure(exc)
    if isinstance(exc, AddbError):
        return exc.to_dict()
    return {"type": type(exc).__name__, "message": str(exc), "path": None, "line": None, "where": None}


def attempt_started(out_dir: str | Path, attempt: str) -> bool:
    """Whether the attempt ``attempt`` (a :attr:`SubjectJob.attempt` key) of the subject whose
    final output folder is ``out_dir`` started on its worker: one of the subject's work
    folders holds that key in :data:`STARTED_NAME`. A killed worker leaves its work folder
    (removed by the next :func:`remove_stale_work`); a task that was only queued on a worker
    made none. Raises nothing: an unreadable folder counts as not started."""
    final = Path(out_dir)
    for folder in final.parent.glob(f"{glob.escape(WORK_PREFIX + final.name)}-*"):
        try:
            if (folder / STARTED_NAME).read_text(encoding="utf-8") == attempt:
                return True
        except OSError:
            continue
    return False


def _replace_dir(src: Path, dst: Path) -> None:
    """Move folder ``src`` to ``dst``, replacing ``dst`` in two renames (the old output
    waits in ``.addb-work-old-<name>-*/previous``, see :func:`remove_stale_work`)."""
    replace_folder(src, dst, aside_prefix=f"{WORK_PREFIX}old-{dst.name}-")


def _record_failure(final: Path, log: Path, manifest: dict[str, Any]) -> None:
    """Put a failed subject's log and manifest into ``final`` (each file renamed into
    place), keeping whatever output an earlier run left there."""
    from solver.dataset.manifest import write_manifest

    final.mkdir(parents=True, exist_ok=True)
    tmp = final / f".{LOG_NAME}.tmp"
    shutil.copyfile(log, tmp)
    os.replace(tmp, final / LOG_NAME)
    write_manifest(final, manifest)


def run_subject(job: SubjectJob) -> dict[str, Any]:
    """Process one subject; never raises for a failure of the data or the solver.

    Returns
    -------
    dict
        ``rel``, ``status`` (``"ok"``, ``"kinematics_only"``, ``"failed"``, or
        ``"cancelled"`` when the run's stop event was set: nothing was written), ``error``
        (:meth:`AddbError.to_dict` form, failed only), ``trials`` (summary rows),
        ``mass_kg`` (given) and ``fitted_mass_kg``, ``warnings`` (the distinct messages of
        the warnings raised while the subject ran, also in its ``process.log``; not for a
        cancelled subject), ``seconds`` (wall time of the
        subject), ``worker_pid`` and ``worker_peak_rss_mb`` (the worker process's peak
        resident memory so far, MB, from ``getrusage``).
    """
    from solver.dataset.manifest import MANIFEST_NAME, subject_status
    from solver.dataset.summary import subject_rows
    from solver.pipeline import options_for_fit

    t0 = time.perf_counter()
    final = Path(job.out_dir)
    final.parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=f"{WORK_PREFIX}{final.name}-", dir=final.parent))
    if job.attempt is not None:  # first of all: this attempt started (attempt_started)
        (work / STARTED_NAME).write_text(job.attempt, encoding="utf-8")
    log = _Log(work / LOG_NAME, job.rel, job.stop_event)
    log(f"subject {job.rel}: {job.subject_dir} -> {job.out_dir} (pid {os.getpid()})")
    outcome: dict[str, Any] = {"rel": job.rel, "worker_pid": os.getpid()}
    caught: list[warnings.WarningMessage] = []
    try:
        log.check_stop()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            unmeasured_force = job.masks(job.subject_dir, job.out_dir) if job.masks is not None else None
            if unmeasured_force:
                log(f"reviewer flags used for {', '.join(sorted(unmeasured_force))}")
            fit = str((job.key.get("settings") or {}).get("fit", "default"))
            masses = _processed(job.subject_dir, work / "out", options_for_fit(fit), unmeasured_force, log)
        outcome["warnings"] = _log_warnings(log, caught)
        rows = subject_rows(work / "out")
        status = subject_status(rows)
        outcome.update(status=status, trials=rows, **masses, seconds=time.perf_counter() - t0)
        log(f"done: {status}, {sum(r['frames'] for r in rows)} frames in {outcome['seconds']:.1f} s")
        log.close()
        os.replace(work / LOG_NAME, work / "out" / LOG_NAME)
        write_json(work / "out" / MANIFEST_NAME, {"key": job.key, **outcome})
        log.check_stop()  # the last moment the subject can be given up without a trace
        _replace_dir(work / "out", final)
    except Stopped:
        log.close()
        outcome = {"rel": job.rel, "worker_pid": os.getpid(), "status": "cancelled", "trials": [], "seconds": time.perf_counter() - t0}
    except Exception as exc:  # noqa: BLE001 - the data's or the solver's failure: recorded, the batch goes on
        _take_back_log(work, log)
        outcome["warnings"] = _log_warnings(log, caught)
        log(f"failed: {exc}")
        log(traceback.format_exc().rstrip())
        log.close()
        outcome.update(status="failed", error=_error_record(exc), trials=[], seconds=time.perf_counter() - t0)
        try:
            _record_failure(final, work / LOG_NAME, {"key": job.key, **outcome})
        except OSError:
            if not outcome["error"].get("transient"):
                raise
            # the storage that failed the subject cannot hold its record either: the outcome
            # still reaches the summary, and without a record the next run processes it again
    finally:
        shutil.rmtree(work, ignore_errors=True)
    outcome["worker_peak_rss_mb"] = _peak_rss_mb()
    return outcome


def _take_back_log(work: Path, log: _Log) -> None:
    """Before a failure is written to ``log``: close it, and put it back at ``log.path`` when
    the subject had already moved it into ``work/out`` (a failure in its last steps: renaming
    the log or the output into place, writing the manifest), making ``work`` again if it is
    gone; the failure is then appended to the whole log (:class:`_Log` opens it again), not
    lost in an error about the closed file."""
    log.close()
    moved = work / "out" / LOG_NAME
    try:
        work.mkdir(parents=True, exist_ok=True)
        if moved.is_file() and not log.path.exists():
            os.replace(moved, log.path)
    except OSError:
        pass  # the failure is written to a new log at log.path


def _processed(subject_dir: str, out: Path, options: Any, unmeasured_force: Any, log: Callable[[str], None]) -> dict[str, Any]:
    """:func:`solver.pipeline.process_subject` of the subject into ``out``; returns its
    ``mass_kg`` (given) and ``fitted_mass_kg``. A trial whose recordings the dynamics stage
    could not take is kept as ``addb process SUBJECT_DIR`` keeps it (its kinematics, its
    error in its results.json, the other trials processed): a warning naming it, not a
    failure of the subject. Any other error propagates."""
    from solver.errors import DynamicsError
    from solver.pipeline import process_subject

    try:
        result = process_subject(subject_dir, out, options=options, unmeasured_force=unmeasured_force, progress=log)
    except DynamicsError as exc:
        if not exc.kept_trials:
            raise
        for name, error in exc.kept_trials:
            warnings.warn(f"trial {name}: {error.message}; its kinematics were kept without dynamics (results.json: "
                          "dynamics_error), the other trials were processed", stacklevel=2)  # fmt: skip
        written = json.loads((out / SUBJECT_RECORD).read_text())
        return {"mass_kg": written.get("mass_kg"), "fitted_mass_kg": written.get("fitted_mass_kg")}
    return {"mass_kg": result.kinematics.subject.mass_kg,
            "fitted_mass_kg": result.dynamics.mass_kg if result.dynamics is not None else None}  # fmt: skip


def _log_warnings(log: Callable[[str], None], caught: list[warnings.WarningMessage]) -> list[str]:
    """Write each warning of the subject's run to its log; returns their distinct messages, in
    order (the subject's ``warnings`` in its manifest and the dataset summary)."""
    for w in caught:
        log(f"warning: {w.message}")
    return list(dict.fromkeys(str(w.message) for w in caught))


def _peak_rss_mb() -> float | None:
    """Peak resident memory of this process, MB (Linux ``ru_maxrss`` is in KiB)."""
    try:
        import resource
    except ImportError:  # not on Windows
        return None
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _in_nested_tree(path: Path, root: Path) -> bool:
    """Whether ``path`` lies in another run's output tree below ``root`` (a folder between
    them that :func:`solver.outputs.is_output_tree`): its work folders are that run's."""
    from solver.outputs import is_output_tree

    return any(is_output_tree(folder) for folder in path.parents if folder != root and root in folder.parents)


def remove_stale_work(out_root: str | Path) -> int:
    """Remove work folders left below ``out_root`` by killed workers; returns how many. The
    output trees of other runs below ``out_root`` are left alone (their work folders may be
    in use: dataset audit 2026-12-02, finding 5).

    A worker killed between the two renames of :func:`_replace_dir` leaves the previous
    output in ``.addb-work-old-<name>-*/previous`` and no ``<name>``: that output is put
    back in place first, so no finished subject is lost.
    """
    n = 0
    root = Path(out_root)
    if not root.is_dir():
        return 0
    for path in sorted(root.rglob(f"{WORK_PREFIX}*")):
        if not path.is_dir() or _in_nested_tree(path, root):
            continue
        old_prefix = f"{WORK_PREFIX}old-"
        if path.name.startswith(old_prefix) and (path / "previous").is_dir():
            name = path.name[len(old_prefix):].rsplit("-", 1)[0]  # mkdtemp's suffix has no "-"
            final = path.parent / name
            if name and not final.exists():
                os.replace(path / "previous", final)
        shutil.rmtree(path, ignore_errors=True)
        n += 1
    return n
