"""Reprocess after a flag edit: time from the button to the updated before/after table.

    .venv/bin/python tests/benchmarks/bench_reprocess.py [--repeat N] [--fit band] [--host-reference] [walk] [camargo]

For each subject (the shared rajagopal2016_walk; the Camargo level-ground circuit assembled
by scripts/make_example_subject.py) in a temporary folder: one full ``process_subject``
(which writes the kinematics cache), then the trial's flags (at its processed frames) = its unmeasured
frames plus 20 frames of stance, and ``--repeat`` times each (median and range printed):

* ``dynamics only``: the app's Reprocess as it is now: a :class:`SolverJob` child running
  :func:`solver.pipeline.reprocess_dynamics` on the cached kinematics, handed to the warm
  spare child (:func:`addb_viewer.app.jobs.prestart_solver`, its imports finished before
  the button, as in the app where the reviewer edits flags meanwhile);
* ``dynamics only, cold child``: the same with ``ADDB_WARM_SOLVER=0`` (a new process
  per job: Python's start and the solver's imports inside the timed span);
* ``full run``: the same job with ``dynamics_only=False`` (the Reprocess before: scaling +
  IK of every trial, then the dynamics);
* both measured from ``SolverJob.start`` to the table: the child's end, then
  ``load_processed`` of the trial and ``comparison_markdown`` of the before/after summaries
  (what the app does in ``Reprocessor._install``; the 3-D scene reload is not counted);
* ``in process``: ``reprocess_dynamics`` called in this process (no child start and
  imports), without and with the warm start, to show where the time goes.

``--fit NAME``: the first full process uses ``addb process --fit NAME``'s options (default:
the converged fit); every Reprocess then uses the fit recorded in the output (as the app
does), which for the converged fit is warm-started by default (the job rows; the band fit is
not), and the ``in process`` row is asked for no warm start explicitly.

``--host-reference`` also times OpenSim's IK tool on the walk, ``--repeat`` runs before the
subjects and as many after (``bench_kinematics.opensim_reference``, as ``bench_process.py``
does): the host's speed that day, to compare this block with one made on another day.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

from bench_kinematics import (  # this folder; the reference needs ``pip install opensim``
    host_reference_line,
    opensim_reference,
)

from addb_viewer.app.jobs import JobSpec, SolverJob, prestart_solver, wait_for_spare
from addb_viewer.app.reprocess import written_trials
from addb_viewer.app.summary import comparison_markdown, trial_summary
from solver.pipeline import FIT_CHOICES, options_for_fit, process_subject, reprocess_dynamics
from solver.results import load_processed

SUBJECTS = REPO.parent / "shared" / "data" / "subjects"


def _subject(which: str, root: Path) -> tuple[Path, str]:
    if which == "walk":
        dst = root / "rajagopal2016_walk"
        shutil.copytree(SUBJECTS / "rajagopal2016_walk", dst)
        for p in [dst, *dst.rglob("*")]:
            p.chmod(0o644 if p.is_file() else 0o755)
        return dst, "walk"
    dst = root / "camargo2021_levelground"
    subprocess.run([sys.executable, str(REPO / "scripts" / "make_example_subject.py"), "camargo2021_levelground", str(dst)], check=True, stdout=subprocess.DEVNULL)
    return dst, "levelground"


def _flags(out: Path, trial: str) -> dict[str, np.ndarray]:
    """The trial's unmeasured frames of the first run plus 20 frames from the middle of its
    measured ones, at the trial's processed frames (``trial.npz``; solver.masks)."""
    with np.load(out / trial / "trial.npz") as z:
        mask = np.asarray(z["unobserved"], dtype=bool).copy()
    free = np.flatnonzero(~mask)
    start = int(free[len(free) // 2])  # 20 frames from the middle of the measured frames
    mask[start : start + 20] = True
    return {trial: mask}


def _job_to_table(subject: Path, out: Path, trial: str, flags: dict[str, np.ndarray], dynamics_only: bool, work: Path,
                  warm: bool = True) -> float:  # fmt: skip
    before = trial_summary(load_processed(out, trial))
    os.environ["ADDB_WARM_SOLVER"] = "1" if warm else "0"
    if warm:
        prestart_solver()
        assert wait_for_spare(120), "the warm solver child did not start"
    t0 = time.perf_counter()
    job = SolverJob(JobSpec(subject, out, written_trials(subject, out, trial), flags, dynamics_only=dynamics_only), work,
                    on_progress=lambda m, f: None, on_done=lambda r: None)  # fmt: skip
    job.start()
    result = job.wait(600)
    if result is None or result.status != "done":
        raise RuntimeError(f"job failed: {result and result.message}")
    table = comparison_markdown(before, trial_summary(load_processed(out, trial)))
    seconds = time.perf_counter() - t0
    assert table
    job.cleanup()
    os.environ["ADDB_WARM_SOLVER"] = "1"
    wait_for_spare(120)  # the next spare's imports (started as the job ended) must not overlap the next timing
    return seconds


def _fmt(xs: list[float]) -> str:
    return f"{statistics.median(xs):.2f} ({min(xs):.2f}-{max(xs):.2f})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("which", nargs="*", default=["walk", "camargo"], choices=["walk", "camargo"])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--fit", default="default", choices=FIT_CHOICES, help="the first full process's fit (addb process --fit)")
    ap.add_argument("--host-reference", action="store_true", help="also time OpenSim's IK tool on the walk (the host's speed)")
    args = ap.parse_args()
    reference = opensim_reference(args.repeat) if args.host_reference else []
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for which in args.which:
            root = Path(tmp) / which
            root.mkdir()
            subject, trial = _subject(which, root)
            out = root / "out"
            t0 = time.perf_counter()
            process_subject(subject, out, options=options_for_fit(args.fit))
            first = time.perf_counter() - t0
            flags = _flags(out, trial)
            times: dict[str, list[float]] = {"dynamics only": [], "cold child": [], "full run": [], "in process": [], "in process, warm": []}
            for i in range(args.repeat):
                times["dynamics only"].append(_job_to_table(subject, out, trial, flags, True, root / f"job-d{i}"))
                times["cold child"].append(_job_to_table(subject, out, trial, flags, True, root / f"job-c{i}", warm=False))
                times["full run"].append(_job_to_table(subject, out, trial, flags, False, root / f"job-f{i}"))
                t0 = time.perf_counter()
                reprocess_dynamics(subject, out, (trial,), flags, warm_start=False)
                times["in process"].append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                reprocess_dynamics(subject, out, (trial,), flags, warm_start=True)
                times["in process, warm"].append(time.perf_counter() - t0)
                reprocess_dynamics(subject, out, (trial,), flags, warm_start=False)  # back to the cold answer for the next round
            r = json.loads((out / trial / "results.json").read_text())
            rows.append((which, trial, r["n_frames"], first, times, r["stage_seconds"]))
    print(f"Reprocess after a flag edit, button to table, s (median (range) of {args.repeat}); fit {args.fit}; {time.strftime('%Y-%m-%d')}")
    print("| subject | trial | frames | first full process (in process) | Reprocess: dynamics only (job, warm child) | same, cold child | Reprocess: full run (job, warm child) | dynamics only, in process | same, warm start |")
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for which, trial, n, first, t, _ in rows:
        print(f"| {which} | {trial} | {n} | {first:.2f} | {_fmt(t['dynamics only'])} | {_fmt(t['cold child'])} | {_fmt(t['full run'])} | {_fmt(t['in process'])} | {_fmt(t['in process, warm'])} |")
    for which, trial, _, _, _, stage in rows:
        print(f"{which} stage_seconds of the last dynamics-only run: " + json.dumps({k: round(v, 3) for k, v in stage.items()}))
    if args.host_reference:
        print("\n" + host_reference_line(reference, opensim_reference(args.repeat)))


if __name__ == "__main__":
    main()
