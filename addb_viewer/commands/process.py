"""``addb process SUBJECT_DIR --out OUT``: kinematics and dynamics, OpenSim-ready outputs.

``addb process DATASET_DIR --out OUT`` (a folder of subject folders at any depth) runs
every subject as a Dask task (:mod:`solver.dataset.runner`) and mirrors the tree in OUT.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from addb_viewer.commands import FIT_CHOICES, fit_settings, memory_size, output_folder, whole_number


def run_dataset(args: argparse.Namespace) -> int:
    """A dataset folder: every subject on the Dask cluster, a table of them, the subjects
    processed, up to date and failed, the dataset's totals, the subjects with warnings (the
    first of each, the others counted) and the failures listed.

    Returns
    -------
    The exit code: 1 when a subject failed (also one that failed before on the same inputs), else 0.

    Raises
    ------
    SystemExit
        ``--trial`` or ``--annotations`` is given (they apply to one subject folder), before
        anything runs.
    """
    from addb_viewer.progress import ProgressBar, table
    from addb_viewer.review_masks import review_digest, subject_masks
    from solver.dataset.runner import REPORT_NAME, SUMMARY_NAME, DatasetOptions, process_dataset
    from solver.dataset.task import LOG_NAME

    if args.trial or args.annotations:
        raise SystemExit("addb process: --trial and --annotations apply to one subject folder, not a dataset")
    opts = DatasetOptions(
        workers=args.workers, scheduler=args.scheduler, retries=args.retries, force=args.force,
        memory_limit=args.memory_limit, settings=fit_settings(args.fit),
    )  # fmt: skip
    run = process_dataset(
        args.subject, args.out, options=opts, masks=subject_masks, review_digest=review_digest,
        progress=ProgressBar(), log=lambda m: print(f"addb process: {m}", file=sys.stderr),
    )  # fmt: skip
    rows = []
    for s in run.subjects:
        trials = s.get("trials") or []
        frames = sum(r["frames"] for r in trials)
        measured = sum(r["measured_frames"] for r in trials)
        status = s["status"] + (f" ({s['result_status']})" if s.get("result_status") else "")
        status += " (unchanged)" if s.get("unchanged") else ""
        rms = [r["marker_rms_m"] for r in trials if r.get("marker_rms_m") is not None]
        lin = [r["linear_residual_rms_N"] for r in trials if r.get("linear_residual_rms_N") is not None]
        rows.append([
            s["rel"], status, str(len(trials)), f"{measured}/{frames}",
            f"{100 * max(rms):.2f}" if rms else "-", f"{max(lin):.1f}" if lin else "-",
            f"{s['seconds']:.1f}" if s.get("seconds") is not None else "-",
        ])  # fmt: skip
    print(table(rows, ["subject", "status", "trials", "frames (measured/all)", "worst marker RMS (cm)",
                       "worst linear residual (N)", "wall (s)"]))  # fmt: skip
    t, c = run.totals, run.counts
    # each kind counted apart: "2 subjects" read as two processed when one was up to date
    print(
        f"{t['n_subjects']} subjects: {c['processed']} processed, {c['up_to_date']} up to date, {c['failed']} failed"
        + (f", {c['cancelled']} cancelled" if c["cancelled"] else "") + f" in {run.seconds:.1f} s; the dataset: "
        f"{t['trials']} trials, {t['frames']} frames ({t['hours']:.4f} h, {t['hours_with_measured_force']:.4f} h with measured force)"
    )
    warned = [s for s in run.subjects if s.get("warnings")]
    if warned:
        # each subject's warnings were only in its process.log: the terminal names them
        print(f"\n{len(warned)} subject(s) with warnings (each in full in {run.out_dir}/SUBJECT/{LOG_NAME}):", file=sys.stderr)
        for s in warned:
            more = len(s["warnings"]) - 1
            print(f"  {s['rel']}: {s['warnings'][0]}" + (f" (and {more} more)" if more else ""), file=sys.stderr)
    if run.failed:
        print(f"\n{len(run.failed)} subject(s) failed:", file=sys.stderr)
        for s in run.failed:
            e = s.get("error") or {}
            where = ":".join(str(x) for x in (e.get("path"), e.get("line")) if x is not None)
            print(f"  {s['rel']}: {e.get('type')}: {e.get('message')}" + (f" ({where})" if where else ""), file=sys.stderr)
    print(f"wrote {run.out_dir / SUMMARY_NAME} and {run.out_dir / REPORT_NAME}")
    return 1 if run.failed else 0


def review_file(path: str | os.PathLike[str]) -> Path:
    """The file an ``--annotations`` argument names (of ``addb process`` and ``addb diagnose``),
    checked before anything runs: a review record would otherwise be created at a mistyped
    path (:meth:`annotations.AnnotationStore.open` creates one) and the subject processed as
    if no flags were given.

    Returns
    -------
    Path
        ``path`` when it is a file (a review record, or an AddBiomechanics ``review.json``:
        :func:`addb_viewer.review_masks.masks_from_file` tells them apart), or
        ``path/annotations.json`` when ``path`` is a folder holding a record.

    Raises
    ------
    annotations.AnnotationFileError
        Nothing of the kind is at ``path`` (naming it; nothing is created).
    """
    from annotations import AnnotationFileError
    from annotations.journal import StorePaths

    p = Path(path)
    if p.is_file():
        return p
    record = StorePaths.for_path(p).main
    if p.is_dir() and record.is_file():
        return record
    raise AnnotationFileError(
        ("no such file or folder" if not p.exists() else f"a folder without {record.name}")
        + ": --annotations expects an existing review record (the .json that addb view or addb "
        "convert keeps, or a subject folder holding annotations.json) or an AddBiomechanics review.json; "
        "nothing was created",
        path=p,
    )


def with_kept_kinematics(exc: Exception, out: Path) -> Exception:
    """``exc`` (a DynamicsError of :func:`solver.pipeline.process_subject`) saying which
    trials were written to ``out`` without dynamics (its ``kept_trials``): a trial whose
    recordings the dynamics stage could not take keeps its kinematics, with the error in its
    results.json (``dynamics_error``). Any other error, and one raised before anything was
    written, is returned as it is."""
    from solver.errors import DynamicsError

    if not isinstance(exc, DynamicsError) or not exc.kept_trials:
        return exc
    trial = next(name for name, error in exc.kept_trials if error is exc)
    others = [name for name, error in exc.kept_trials if error is not exc]
    return DynamicsError(
        f"{exc.message}; the trial's kinematics were written without dynamics ({out / trial}: motion and marker "
        "errors; results.json: dynamics_error)"
        + (f", and those of {', '.join(others)} with their own errors" if others else "")
        + "; the other trials were processed as usual",
        path=exc.path, line=exc.line, where=exc.where,
    )  # fmt: skip


def _process_one(args: argparse.Namespace, process: Callable[[], Any]) -> Any:
    """Run ``process()`` (the one-subject pipeline into ``args.out``) holding the dataset
    output tree ``args.out`` lies in, if any (:func:`solver.dataset.lock.subject_output_lock`:
    not while a dataset run writes it). Into a tree, a whole run (no ``--trial``; no
    ``--annotations``, or the subject's own review record, which a dataset run reads) leaves
    the manifest a dataset run would, so that the next dataset run skips the subject while
    nothing changed; another run removes the folder's manifest, which no longer describes it
    (:mod:`solver.dataset.one_subject`). The run's warnings are
    shown as usual, after it."""
    import time
    import warnings

    from solver.dataset.lock import subject_output_lock

    with subject_output_lock(args.out) as tree:
        if tree is None:
            return process()
        from solver.dataset.one_subject import (
            forget_subject_run,
            record_subject_run,
            subject_run_key,
        )

        whole, review = not args.trial, None
        if args.annotations:  # whole only with the record a dataset run reads: then keyed on its flags
            from addb_viewer.review_masks import review_digest, review_record

            record = review_record(str(args.subject), str(args.out))
            whole = whole and record is not None and review_file(args.annotations).resolve() == record.resolve()
            review = review_digest
        key = subject_run_key(args.subject, args.out, fit_settings(args.fit), review) if whole else None
        t0 = time.perf_counter()
        caught: list[warnings.WarningMessage] = []
        try:
            with warnings.catch_warnings(record=True) as caught:  # the filters as they are: kept for the manifest
                result = process()
        finally:
            for w in caught:
                warnings.showwarning(w.message, w.category, w.filename, w.lineno, w.file, w.line)
        if key is None:
            forget_subject_run(args.out)
        else:
            record_subject_run(
                args.out, tree, key, mass_kg=result.kinematics.subject.mass_kg,
                fitted_mass_kg=result.dynamics.mass_kg if result.dynamics is not None else None,
                seconds=time.perf_counter() - t0, warnings=list(dict.fromkeys(str(w.message) for w in caught)),
            )  # fmt: skip
        return result


def run(args: argparse.Namespace) -> int:
    """``addb process SUBJECT_DIR --out OUT``: kinematics and dynamics of one subject, with a table
    of each trial's measured frames, marker RMS error, residual forces and Hicks verdicts; a
    folder that is no subject folder is processed as a dataset (:func:`run_dataset`).

    Returns
    -------
    The exit code: 0 when the subject's outputs were written; for a dataset, 1 when a
    subject failed.

    Bad input raises, as in every subcommand (:mod:`addb_viewer.commands`); a trial whose
    recordings the dynamics stage could not take is written with its kinematics first, and
    its DynamicsError says so (:func:`solver.pipeline.process_subject`).
    """
    from solver.dataset.discover import is_subject_folder

    if not is_subject_folder(args.subject) and Path(args.subject).is_dir():
        return run_dataset(args)
    if any(x is not None for x in (args.workers, args.scheduler)) or args.force:
        raise SystemExit("addb process: --workers, --scheduler and --force apply to a dataset folder")
    from addb_viewer.progress import ProgressBar, table
    from solver.errors import DynamicsError
    from solver.pipeline import options_for_fit, process_subject

    opts = options_for_fit(args.fit, args.trial)
    unmeasured_force, record = None, None
    if args.annotations:
        from addb_viewer.review_masks import masks_from_file

        record = review_file(args.annotations)  # before anything is created
        unmeasured_force = masks_from_file(record, args.subject, reviewer="addb process", trials=tuple(args.trial or ()) or None) or None
    try:
        result = _process_one(args, lambda: process_subject(
            args.subject, args.out, options=opts, unmeasured_force=unmeasured_force, progress=ProgressBar(),
            review_record=record))  # fmt: skip
    except DynamicsError as exc:
        raise with_kept_kinematics(exc, Path(args.out)) from None
    rows = []
    for t in result.kinematics.kinematics.trials:
        if opts.trials and t.name not in opts.trials:
            continue
        d = None
        if result.dynamics is not None:
            d = next((x for x in result.dynamics.trials if x.name == t.name), None)
        if d is None:
            rows.append([t.name, str(t.q.shape[0]), f"{t.marker_rms * 100:.2f}", "-", "-", "-", "-"])
        elif not d.metrics["n_observed_frames"]:  # no residual, no verdict: nothing was measured
            rows.append([t.name, f"0/{d.time.size}", f"{d.metrics['marker_rms_m'] * 100:.2f}", "-", "-", "-", "-"])
        else:
            m = d.metrics
            ang = m["angular_residual_rms_BWh"]
            rows.append([
                t.name, f"{m['n_observed_frames']}/{d.time.size}", f"{m['marker_rms_m'] * 100:.2f}",
                f"{m['linear_residual_rms_N']:.1f} ({m['linear_residual_rms_BW']:.3f})",
                f"{m['angular_residual_rms_Nm']:.1f} ({ang:.3f})" if ang is not None else f"{m['angular_residual_rms_Nm']:.1f}",
                "yes" if m["hicks_linear_ok"] else "no", "yes" if m["hicks_angular_ok"] else ("no" if m["hicks_angular_ok"] is not None else "-"),
            ])
    print(table(rows, ["trial", "frames (measured/all)", "marker RMS (cm)", "linear residual N (BW)", "angular residual N·m (BW·h)", "Hicks lin", "Hicks ang"]))
    if result.dynamics is not None:
        print(f"fitted mass: {result.dynamics.mass_kg:.2f} kg")
    print(f"wrote {result.out_dir}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``process`` subcommand's parser to ``sub`` (its ``handler``: :func:`run`)."""
    p = sub.add_parser(
        "process",
        help="scaling, inverse kinematics and the dynamics fit; writes OpenSim files (one subject or a dataset)",
        description=(
            "Process one AddBiomechanics subject folder, or a dataset folder holding subject folders at "
            "any depth: then every subject runs as a Dask task (a local cluster, or --scheduler), OUT "
            "mirrors the tree, unchanged subjects are skipped, failures are listed and make the exit "
            "code 1, and OUT/dataset_summary.json and OUT/dataset_report.html summarize the dataset."
        ),
    )
    p.add_argument("subject", help="AddBiomechanics subject folder, or a dataset folder of subject folders")
    p.add_argument("--out", required=True, type=output_folder, help="output folder: new, empty, or an earlier output of addb (replaced atomically; for a dataset, the output tree)")
    p.add_argument("--trial", action="append", help="write only this trial (repeatable)")
    p.add_argument(
        "--fit", choices=FIT_CHOICES, default="default",
        help="dynamics fit: 'default' = 'converged' (exact banded Gauss-Newton steps of the coordinates and the "
             "body mass factors together until the cost settles), 'rounds' (the same steps alternating with "
             "mass solves; the fit addb diagnose judges on) or 'band' (truncated-band steps, a fixed number of "
             "rounds: the older default; see tests/benchmarks/RESULTS.md)",
    )  # fmt: skip
    p.add_argument("--annotations", help="an existing review record (the reviewer's unmeasured-force flags) or an AddBiomechanics review.json of a one-trial subject")
    d = p.add_argument_group("dataset folders")
    d.add_argument("--workers", type=whole_number(1), help="worker processes of the local Dask cluster (default: the cores)")
    d.add_argument("--scheduler", help="submit to a running Dask scheduler, tcp://HOST:PORT, instead")
    d.add_argument("--retries", type=whole_number(0), default=1, help="resubmissions of a subject whose worker died (default 1)")
    d.add_argument("--force", action="store_true", help="reprocess subjects whose output is up to date")
    d.add_argument("--memory-limit", type=memory_size, default="auto", help="memory limit per local worker, e.g. 4GB (default: RAM / workers)")
    p.set_defaults(handler=run)
