"""A dataset run on Dask distributed: every subject folder of a dataset as one task.

By default the run starts a ``distributed.LocalCluster`` sized to the machine: one
process per worker (``workers``, default the number of cores), one thread each, a memory
limit per worker (default: the machine's memory divided among the workers), and the
numeric libraries limited to one thread inside each worker (Dask's
``distributed.nanny.pre-spawn-environ`` sets ``OMP_NUM_THREADS`` and friends to 1, and the
pipeline limits BLAS with threadpoolctl), so N workers do not oversubscribe the cores.
One of Dask's pre-spawn variables is removed: ``MALLOC_TRIM_THRESHOLD_`` (Dask sets it
to 65536 so that workers hand freed memory back to the system). Setting it at all turns off
glibc's adaptive mmap threshold (mallopt(3)), so every numpy temporary over 128 kB is
mapped and unmapped afresh; the pipeline makes many, and each subject took 23-39 % longer
in a worker started with Dask's defaults (tests/benchmarks/RESULTS.md, block ``dataset``:
per-subject times, throughput and each worker's peak memory, both ways). Workers started
by hand need the same setting in their Dask configuration (README, "On a lab's machines").
With ``scheduler`` it submits to a running cluster instead (``tcp://HOST:PORT``): any
machine with addb installed that can read the dataset and write the output folder.

Failures: a subject whose data or solve fails is recorded by its task
(:func:`solver.dataset.task.run_subject`) and the batch goes on. A subject whose worker
dies (killed, out of memory) while it runs is submitted again, up to ``retries`` more times
(a subject only queued on that worker, which had not started, is submitted again without
counting an attempt: :func:`solver.dataset.task.attempt_started`); on the
local cluster the scheduler gives up on a task at its first worker death
(``distributed.scheduler.allowed-failures = 0``) so that ``retries`` counts every death.
A remote scheduler applies its own ``allowed-failures`` (Dask's default 3) before ours.

A failure of the output storage (disk full, I/O error) is recorded as transient, not as the
subject's failure (:func:`solver.dataset.task.storage_error`): the next run processes it again.

Resume: a subject whose output carries a manifest with the same key as now (same input
files, addb version and solver source digest, settings and review record) is skipped without starting a cluster,
and so is a subject whose unchanged data failed before (reported failed again, with its
stored error); ``force`` reprocesses both. One run at a time per output folder.
"""

from __future__ import annotations

import contextlib
import json
import os
import time
import uuid
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from solver.dataset.discover import (
    REPORT_NAME,
    SUMMARY_NAME,
    DatasetScan,
    DatasetSubject,
    b3d_note,
    loop_note,
    scan_dataset,
    subjects_below,
)
from solver.dataset.lock import output_tree_lock
from solver.dataset.manifest import KeyUnreadable, current_manifest, run_settings, subject_key_now
from solver.dataset.summary import dataset_totals
from solver.dataset.task import (
    PROGRESS_TOPIC,
    MaskLoader,
    SubjectJob,
    attempt_started,
    remove_stale_work,
    run_subject,
    storage_error,
    storage_failure,
)
from solver.errors import DatasetError, OutputFolderError, listed
from solver.outputs import check_output_folder, output_marker, output_tree_above, write_json
from solver.provenance import addb_version

Progress = Callable[[str, float], None]


@dataclass(frozen=True)
class DatasetOptions:
    """Options of :func:`process_dataset`.

    Attributes
    ----------
    workers
        Worker processes of the local cluster (default: the machine's cores); ignored
        with ``scheduler``.
    scheduler
        Address of a running Dask scheduler (``tcp://HOST:PORT``); None: a local cluster.
    retries
        How many more times a subject is submitted after its worker died.
    force
        Reprocess subjects whose output is up to date.
    memory_limit
        Memory limit per local worker (``"4GB"``, bytes, or ``"auto"``: the machine's
        memory divided among the workers).
    settings
        Settings recorded in each manifest (a change reprocesses every subject); the
        worker reads ``"fit"`` (a name of :data:`solver.pipeline.FIT_CHOICES`, default
        ``"default"``) to choose the dynamics fit.
    """

    workers: int | None = None
    scheduler: str | None = None
    retries: int = 1
    force: bool = False
    memory_limit: str | int = "auto"
    settings: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class DatasetRun:
    """What :func:`process_dataset` did.

    Attributes
    ----------
    out_dir
        The output tree.
    subjects
        One entry per subject (the ``subjects`` of ``dataset_summary.json``).
    totals
        Dataset totals (:func:`solver.dataset.summary.dataset_totals`).
    seconds
        Wall time of the run, s.
    dashboard
        The Dask dashboard address, when the cluster had one.
    """

    out_dir: Path
    subjects: tuple[dict[str, Any], ...]
    totals: dict[str, Any]
    seconds: float
    dashboard: str | None = None

    @property
    def failed(self) -> tuple[dict[str, Any], ...]:
        """The failed subjects' entries."""
        return tuple(s for s in self.subjects if s["status"] == "failed")

    @property
    def counts(self) -> dict[str, int]:
        """How many subjects this run processed, skipped as up to date, found failed and
        gave up (:func:`subject_counts`)."""
        return subject_counts(self.subjects)


def subject_counts(entries: Iterable[Mapping[str, Any]]) -> dict[str, int]:
    """Subjects by what a run did with them, from their entries (outcomes).

    Returns
    -------
    dict
        ``processed`` (run now: ``ok`` or ``kinematics_only``), ``up_to_date`` (skipped,
        their output current), ``failed`` (run now and failed, not started because of their
        output folder or files, or failed before on the same inputs and not run again) and
        ``cancelled`` (given up when the run was stopped).
    """
    out = {"processed": 0, "up_to_date": 0, "failed": 0, "cancelled": 0}
    for e in entries:
        kind = {"skipped": "up_to_date", "failed": "failed", "cancelled": "cancelled"}.get(e["status"], "processed")
        out[kind] += 1
    return out


def _progress_line(counts: dict[str, int], frames: int | None, to_process: int = 0) -> str:
    """The progress message of a run, each kind of subject counted apart (a subject skipped
    as up to date was counted as processed); ``frames``: of the subjects processed so far,
    None before any ran. The counts come first: the command line's bar shows 50 characters."""
    if frames is None:
        return f"{counts['up_to_date']} up to date, {counts['failed']} failed, {to_process} to process"
    line = f"{counts['processed']} processed, {counts['failed']} failed, {counts['up_to_date']} up to date"
    line += f", {counts['cancelled']} cancelled" if counts["cancelled"] else ""
    return f"{line} ({frames} frames processed)"


#: How many times a subject is submitted again, free of charge, after the worker it was only
#: queued on died (it had not started there: :func:`solver.dataset.task.attempt_started`);
#: past that, such a death counts as an attempt.
MAX_UNSTARTED_REQUEUES = 10

#: The variable Dask's nanny sets in its workers that slows the pipeline (module docstring).
TRIM_VARIABLE = "MALLOC_TRIM_THRESHOLD_"


def _local_cluster(options: DatasetOptions) -> Any:
    """A LocalCluster of one-thread worker processes (see the module docstring).

    The worker processes start with SIGINT ignored (inherited from this process, which
    ignores it while they start): Ctrl-C in the terminal reaches every process of the
    command, and the workers would each print a page of tracebacks; this process alone
    stops the run (:func:`process_dataset`) and closes the cluster. A worker the nanny
    starts again after a death (a retry) would take the handler this process has then:
    :class:`solver.dataset.interrupt.IgnoreInterrupt`, registered on the cluster, ignores
    SIGINT in every worker as it starts."""
    import logging
    import signal
    import threading

    import dask
    from distributed import LocalCluster
    from distributed.system import MEMORY_LIMIT

    n = options.workers or os.cpu_count() or 1
    # Dask's own "auto" gives each worker the RAM over the machine's cores, not over the
    # workers: with --workers 1 on 8 cores the one worker had an eighth (paused, then
    # restarted, on a large subject); with more workers than cores their limits exceeded the RAM
    memory_limit = MEMORY_LIMIT // n if options.memory_limit == "auto" else options.memory_limit
    # None unsets a pre-spawn variable (module docstring: glibc's adaptive mmap threshold).
    # No pause at 80 % of the memory limit: a worker paused there runs nothing more, and one
    # that stayed between the pause and the kill (95 %) thresholds hung the run without a
    # word (docs/audits/2026-12-02-dataset.md, finding 2); a worker over its limit is killed
    # and the subject retried or failed as WorkerDied, which names the limit
    settings = {"distributed.scheduler.allowed-failures": 0, f"distributed.nanny.pre-spawn-environ.{TRIM_VARIABLE}": None,
                "distributed.worker.memory.pause": False}  # fmt: skip
    main = threading.current_thread() is threading.main_thread()  # signal handlers: the main thread only
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None
    try:
        with dask.config.set(settings):
            return LocalCluster(
                n_workers=n,
                threads_per_worker=1,
                processes=True,
                memory_limit=memory_limit,
                dashboard_address=":0",  # any free port: two runs on one machine do not collide
                silence_logs=logging.ERROR,
            )
    finally:
        if main:
            signal.signal(signal.SIGINT, previous)


def local_client(cluster: Any) -> Any:
    """A Dask client of the local cluster (:func:`_local_cluster`) whose workers ignore SIGINT,
    those its nannies start again after a death included
    (:class:`solver.dataset.interrupt.IgnoreInterrupt`)."""
    from distributed import Client

    from solver.dataset.interrupt import IgnoreInterrupt

    client = Client(cluster)
    client.register_plugin(IgnoreInterrupt())
    return client


def _malloc_trim_threshold() -> str | None:
    """This process's :data:`TRIM_VARIABLE` (run on each worker)."""
    return os.environ.get(TRIM_VARIABLE)


def _check_worker_environment(client: Any, tell: Callable[[str], None]) -> None:
    """Tell the user when workers of a cluster started by hand run with
    ``MALLOC_TRIM_THRESHOLD_`` set (Dask's default; module docstring): the run works, slower."""
    try:
        values = client.run(_malloc_trim_threshold)
    except Exception:  # noqa: BLE001 - a worker that cannot answer: nothing to say about it
        return
    slow = sorted(w for w, v in values.items() if v is not None)
    if slow:
        tell(
            f"{len(slow)} of {len(values)} Dask workers run with {TRIM_VARIABLE} set (Dask's default), "
            "which makes each subject take 23-39 % longer; README, \"On a lab's machines\", says how to start them without it"
        )


def _failure(entry: DatasetSubject, kind: str, message: str, **extra: Any) -> dict[str, Any]:
    return {
        "rel": entry.rel,
        "status": "failed",
        "error": {"type": kind, "message": message, "path": str(entry.path), "line": None, "where": None},
        "trials": [],
        **extra,
    }


def _refuse_subject_output(out: Path) -> None:
    """Raise DatasetError when ``out`` is the output folder of one subject (it holds one of
    :data:`solver.outputs.OUTPUT_MARKERS`, as ``addb process SUBJECT_DIR --out OUT`` or a
    dataset run's subject writes it): a dataset run would write its tree among those files."""
    marker = output_marker(out)
    if marker is not None:
        raise DatasetError(
            f"is the output folder of one subject (it holds {marker}, as `addb process SUBJECT_DIR --out` writes it), "
            f"and a dataset run would write its output tree (a folder per subject, {SUMMARY_NAME}) among that "
            f"subject's files; expected a new folder, an empty one, or an earlier dataset output tree (it holds "
            f"{SUMMARY_NAME})", path=out)


def _refuse_output_among_subjects(scan: DatasetScan, source: Path, out: Path) -> None:
    """Raise DatasetError when the output tree ``out``, inside the dataset folder ``source``,
    holds subject folders of the dataset (the search leaves it out, so the run would skip
    them silently; an earlier output tree holds none: addb writes no ``_subject.json``) or
    lies inside one (its outputs would become that subject's input files)."""
    for entry in scan.subjects:
        if entry.path.resolve() in out.parents:
            raise DatasetError(
                f"the output tree lies inside the subject folder {entry.rel} of the dataset {source}, whose files "
                "are that subject's inputs; expected an output folder outside every subject folder, e.g. "
                f"{source / 'addb_out'}", path=out)
    for folder in scan.excluded:
        held = subjects_below(source, folder)
        if held:
            raise DatasetError(
                f"the output tree lies inside the dataset folder {source} and holds {len(held)} of its subject folder(s) "
                f"({listed([s.rel for s in held], 5)}), which the run would leave out (the output tree is not searched for subjects) and write "
                "its outputs among; expected an output folder that holds no subject folder, e.g. "
                f"{source / 'addb_out'} or a folder outside the dataset", path=out)


def process_dataset(
    dataset_dir: str | Path,
    out_dir: str | Path,
    *,
    options: DatasetOptions | None = None,
    masks: MaskLoader | None = None,
    review_digest: Callable[[str, str], str | None] | None = None,
    progress: Progress | None = None,
    log: Callable[[str], None] | None = None,
    events: Callable[[str, dict[str, Any]], None] | None = None,
    stop: Any = None,
) -> DatasetRun:
    """Process every subject folder below ``dataset_dir`` into the mirrored tree ``out_dir``.

    Parameters
    ----------
    dataset_dir
        A folder holding subject folders at any depth (:mod:`solver.dataset.discover`).
    out_dir
        The output tree: ``out_dir/<rel>/`` per subject, in the one-subject layout plus
        ``manifest.json`` and ``process.log``; ``dataset_summary.json`` and
        ``dataset_report.html`` at its root.
    options
        Cluster, retries, resume.
    masks, review_digest
        ``(subject_dir, out_dir) ->`` the reviewer's unmeasured-force masks of a subject,
        and a digest of those flags (part of the manifest key, so that a changed review
        reprocesses the subject); module-level functions (Dask sends them by name).
    progress
        Called with (message, fraction of subjects finished).
    log
        Called with one-line messages for the user (the dashboard address, retries, the
        ``.b3d`` files below ``dataset_dir`` that are not processed: they are no subject folders).
    events
        Called with ``("queued", {"rels": [...]})`` once the subjects to process are known
        ``("progress", {"rel", "message", "fraction"})`` while a subject runs (from its
        worker, at most twice a second) and ``("done", outcome)`` as each finishes (the
        review workbench's queue).
    stop
        A ``threading.Event``: once set, the subjects not finished are given up (their
        outputs stay as they were) and listed with status ``"cancelled"``. A running
        subject stops at its next progress message (at most
        :data:`~solver.dataset.task.PROGRESS_INTERVAL_S` apart) or just before its output
        would be put in place, through a ``distributed.Event`` its task reads: the
        cluster cannot interrupt a running task, and a task cancelled only on the client
        would still put its output in place after the run called it cancelled.

    Returns
    -------
    DatasetRun

    Raises
    ------
    DatasetError
        No subject below ``dataset_dir``, the scheduler cannot be reached, or ``out_dir``
        is ``dataset_dir`` or a folder above it, or lies inside it and holds subject folders
        (the search leaves the output tree out, so they would be silently left out) or lies
        inside a subject folder, or is the output folder of one subject (checked before
        anything is written), or another run holds it
        (:func:`solver.dataset.lock.output_tree_lock`). A subject whose output
        folder holds what addb did not write (:func:`solver.outputs.check_output_folder`)
        fails alone, with that error, and the others run.
    """
    opts = options or DatasetOptions()
    say = progress or (lambda m, f: None)
    tell = log or (lambda m: None)
    t0 = time.perf_counter()
    out = Path(out_dir).resolve()
    source = Path(dataset_dir).resolve()
    if out == source or out in source.parents:
        raise DatasetError(
            f"the output tree {out} {'is' if out == source else 'holds'} the dataset folder {source}; each subject's "
            "output folder replaces its namesake in the output tree, so it must be another folder (e.g. "
            f"{source / 'addb_out'})", path=out)
    _refuse_subject_output(out)
    scan = scan_dataset(dataset_dir, exclude=(out,))
    _refuse_output_among_subjects(scan, source, out)
    subjects = scan.require_subjects(dataset_dir)
    if (note := b3d_note(scan)) is not None:  # not processed: say so, and what is expected
        tell(note)
    if (note := loop_note(scan)) is not None:
        tell(note)
    out.mkdir(parents=True, exist_ok=True)
    with contextlib.ExitStack() as held:
        # a tree inside another run's output tree holds that tree too (refused while another
        # run writes it), as a one-subject run into it does (dataset audit 2026-12-02, finding 5)
        if (outer := output_tree_above(out)) is not None:
            held.enter_context(output_tree_lock(outer))
        held.enter_context(output_tree_lock(out))  # one run per output tree: each removes the work folders it finds
        remove_stale_work(out)
        context = _Run(subjects, out, source, opts, t0)
        results, jobs = _plan(context, masks, review_digest)
        notify = events or (lambda kind, data: None)
        notify("queued", {"rels": [j.rel for j in jobs]})
        total = len(subjects)
        say(_progress_line(subject_counts(results.values()), None, len(jobs)), len(results) / total)
        dashboard = None
        if jobs:
            try:
                dashboard = _run_jobs(jobs, opts, results, lambda frames: say(
                    _progress_line(subject_counts(results.values()), frames), len(results) / total), tell, notify, stop)
            except KeyboardInterrupt:  # Ctrl-C: what finished is kept, and the summary says what did not
                tell(_keep_interrupted(context, jobs, results))
                raise
            remove_stale_work(out)  # work folders of attempts whose worker was killed
        return _summarize(context, results, dashboard)


def _plan(
    run: _Run,
    masks: MaskLoader | None,
    review_digest: Callable[[str, str], str | None] | None,
) -> tuple[dict[str, dict[str, Any]], list[SubjectJob]]:
    """What each of the run's subjects needs: (outcomes known without running, keyed by relative path, and
    the jobs to run). A subject whose output folder holds another's files, or whose files or
    review record cannot be read, has failed; one whose manifest matches its inputs now is
    skipped (or, if it failed with the same inputs, not run again) unless ``run.opts.force``."""
    settings = run_settings(run.opts.settings)
    results: dict[str, dict[str, Any]] = {}
    jobs: list[SubjectJob] = []
    for entry in run.subjects:
        target = entry.out_dir(run.out)
        try:
            check_output_folder(target, (entry.path,))
        except OutputFolderError as exc:  # a folder of someone else's where the subject's output would go
            results[entry.rel] = _failure(entry, "OutputFolderError", str(exc))
            continue
        try:
            key = subject_key_now(entry.path, target, settings, review_digest)
        except KeyUnreadable as exc:
            results[entry.rel] = _failure(entry, exc.error_type, str(exc))
            continue
        stored = None if run.opts.force else current_manifest(target, key)
        if stored is not None:
            stored.pop("key")
            if stored["status"] == "failed":  # the same inputs failed before: not run again
                results[entry.rel] = {**stored, "rel": entry.rel, "unchanged": True}
            else:
                results[entry.rel] = {**stored, "rel": entry.rel, "status": "skipped", "result_status": stored["status"]}
            continue
        jobs.append(SubjectJob(entry.rel, str(entry.path), str(target), key, masks))
    return results, jobs


@dataclass(frozen=True)
class _Run:
    """What a run's summary is written from, besides the subjects' outcomes: the subjects in
    their order, the output tree, the dataset folder, the options and the start time
    (``time.perf_counter()``)."""

    subjects: Sequence[DatasetSubject]
    out: Path
    source: Path
    opts: DatasetOptions
    t0: float


def _keep_interrupted(run: _Run, jobs: list[SubjectJob], results: dict[str, dict[str, Any]]) -> str:
    """After Ctrl-C: keep what finished (a worker may have put a subject in place after the
    interrupt, before the cluster closed), list the rest as cancelled in the summary, and
    return the message for the user."""
    for job in jobs:
        stored = None if job.rel in results else current_manifest(job.out_dir, job.key)
        if stored is not None:
            results[job.rel] = {**{k: v for k, v in stored.items() if k != "key"}, "rel": job.rel}
    unfinished = [j.rel for j in jobs if j.rel not in results]
    for rel in unfinished:
        results[rel] = {"rel": rel, "status": "cancelled", "trials": []}
    _summarize(run, results, None)
    done = f"{len(jobs) - len(unfinished)} of {len(jobs)} subjects to process finished and are kept in {run.out}"
    if unfinished:
        return (
            f"interrupted: {done}; {SUMMARY_NAME} lists {listed(unfinished, 3)} as cancelled. Run the same command "
            "again for them (the finished subjects are up to date and skipped)."
        )
    return f"interrupted: {done}, and {SUMMARY_NAME} lists them."


def _summarize(run: _Run, results: dict[str, dict[str, Any]], dashboard: str | None) -> DatasetRun:
    """The run's outcome, in the subjects' order, written as the summary and the report."""
    ordered = tuple(results[s.rel] for s in run.subjects)
    outcome = DatasetRun(run.out, ordered, dataset_totals(list(ordered)), time.perf_counter() - run.t0, dashboard)
    write_summary(outcome, run.source, run.opts)
    return outcome


def _run_jobs(
    jobs: list[SubjectJob],
    opts: DatasetOptions,
    results: dict[str, dict[str, Any]],
    step: Callable[[int], None],
    tell: Callable[[str], None],
    notify: Callable[[str, dict[str, Any]], None],
    stop: Any = None,
) -> str | None:
    """Submit ``jobs`` to the cluster, collect their outcomes into ``results``; ``step`` is
    called after each with the frames of the subjects processed so far."""
    import threading

    from distributed import CancelledError, Client, as_completed
    from distributed.scheduler import KilledWorker

    cluster = None
    try:
        if opts.scheduler:
            client = Client(opts.scheduler, timeout="20s")
        else:
            cluster = _local_cluster(opts)
            client = local_client(cluster)
    except OSError as exc:
        if cluster is not None:
            cluster.close()
        raise DatasetError(f"cannot reach the Dask scheduler: {exc}", where=opts.scheduler or "local cluster") from None
    dashboard = None
    run_over = threading.Event()
    watcher: threading.Thread | None = None
    stop_event: Any = None
    try:
        info = client.scheduler_info()
        if info.get("services", {}).get("dashboard"):
            import importlib.util

            dashboard = client.dashboard_link
            if importlib.util.find_spec("bokeh") is not None:
                tell(f"Dask dashboard: {dashboard}")
            else:
                tell(f"Dask dashboard: {dashboard} (its plots need `pip install bokeh`)")
        tell(f"{len(info.get('workers', {}))} Dask workers, scheduler {client.scheduler.address}")
        if opts.scheduler:
            _check_worker_environment(client, tell)
        run_id = uuid.uuid4().hex[:8]
        attempts: dict[str, int] = {}  # per subject: the attempts charged (those that started), this one included
        unstarted: dict[str, int] = {}  # per subject: submissions lost with a worker before they started
        by_key: dict[str, SubjectJob] = {}

        futures: list[Any] = []

        def submit(job: SubjectJob, *, charged: bool = True) -> Any:
            if charged:
                attempts[job.rel] = attempts.get(job.rel, 0) + 1
            key = f"addb-subject-{job.rel}-{run_id}-{attempts[job.rel]}"
            key += f"-requeued{unstarted[job.rel]}" if not charged else ""
            job = replace(job, attempt=key)  # the task writes it as it starts (attempt_started)
            by_key[key] = job
            futures.append(client.submit(run_subject, job, key=key, pure=False, retries=0))
            return futures[-1]

        client.subscribe_topic(PROGRESS_TOPIC, lambda event: notify("progress", dict(event[1])))
        # every task reads it: the tasks themselves give up their subject (``stop``, Ctrl-C)
        from distributed import Event

        stop_event = Event(f"addb-stop-{run_id}", client=client)
        jobs = [replace(j, stop_event=stop_event.name) for j in jobs]
        pending = as_completed([submit(j) for j in jobs])
        if stop is not None:  # ask the tasks to stop once asked to (while the run lasts)
            def watch() -> None:
                while not run_over.is_set():
                    if stop.wait(0.2):
                        stop_event.set()
                        return

            watcher = threading.Thread(target=watch, name="addb-dataset-stop", daemon=True)
            watcher.start()
        frames = 0
        for future in pending:
            job = by_key[future.key]
            try:
                outcome = future.result()
            except CancelledError:
                if stop is not None and stop.is_set():
                    outcome = {"rel": job.rel, "status": "cancelled", "trials": []}
                else:
                    outcome = _failure(DatasetSubject(job.rel, Path(job.subject_dir)), "CancelledError",
                                       "the cluster cancelled this subject's task")  # fmt: skip
            except KilledWorker:
                # a worker holds queued tasks besides the running one, and its death fails them
                # all: one that never started there is submitted again, not charged an attempt
                # (docs/audits/2026-12-02-dataset.md, finding 1); the cap keeps a subject from
                # waiting for ever on a cluster whose workers keep dying
                if job.attempt is not None and not attempt_started(job.out_dir, job.attempt) \
                        and unstarted.get(job.rel, 0) < MAX_UNSTARTED_REQUEUES:
                    unstarted[job.rel] = unstarted.get(job.rel, 0) + 1
                    tell(f"{job.rel}: the worker it was queued on died before the subject started there; "
                         "submitted again (no attempt counted)")
                    pending.add(submit(job, charged=False))
                    continue
                if attempts[job.rel] <= opts.retries:
                    tell(f"{job.rel}: its worker died; retrying (attempt {attempts[job.rel] + 1})")
                    pending.add(submit(job))
                    continue
                outcome = _failure(
                    DatasetSubject(job.rel, Path(job.subject_dir)),
                    "WorkerDied",
                    f"the worker processing this subject died {attempts[job.rel]} time(s) "
                    "(killed, or over its memory limit)",
                )
            except Exception as exc:  # noqa: BLE001 - a failure outside the pipeline (e.g. sending the task)
                outcome = _failure(DatasetSubject(job.rel, Path(job.subject_dir)), type(exc).__name__, str(exc))
                if storage_error(exc) is not None:  # e.g. its work folder could not be made: transient
                    error = storage_failure(exc)
                    outcome["error"] = {**error, "path": error["path"] or job.subject_dir}
            outcome["attempts"] = attempts[job.rel]
            results[job.rel] = outcome
            notify("done", outcome)
            frames += sum(r["frames"] for r in outcome.get("trials") or [])
            step(frames)
    except KeyboardInterrupt:  # the running subjects give up at their next progress message
        if stop_event is not None:
            with contextlib.suppress(Exception):
                stop_event.set()
        raise
    finally:
        with contextlib.suppress(Exception):  # the client may already be closing
            client.unsubscribe_topic(PROGRESS_TOPIC)
        run_over.set()
        if watcher is not None:
            watcher.join()
        client.close()
        if cluster is not None:
            cluster.close()
    return dashboard


def write_summary(run: DatasetRun, dataset_dir: Path, opts: DatasetOptions) -> tuple[Path, Path]:
    """Write ``dataset_summary.json`` and ``dataset_report.html`` at the root of the tree
    (each written to a temporary file first, then renamed into place)."""
    from solver.dataset.report import render_report

    summary = {
        "dataset": str(dataset_dir),
        "out": str(run.out_dir),
        "addb_version": addb_version(),
        "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "seconds": run.seconds,
        "workers": opts.workers if not opts.scheduler else None,
        "scheduler": opts.scheduler,
        "totals": run.totals,
        "subjects": list(run.subjects),
    }
    json_path = run.out_dir / SUMMARY_NAME
    tmp = run.out_dir / f".{SUMMARY_NAME}.tmp"
    write_json(tmp, summary)
    os.replace(tmp, json_path)
    html_path = run.out_dir / REPORT_NAME
    tmp = run.out_dir / f".{REPORT_NAME}.tmp"
    tmp.write_text(render_report(json.loads(json_path.read_text())), encoding="utf-8")
    os.replace(tmp, html_path)
    return json_path, html_path
