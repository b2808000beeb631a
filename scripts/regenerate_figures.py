"""Regenerate every measured figure of the documentation with the current code (not CI).

Run from the repository root::

    .venv/bin/python scripts/regenerate_figures.py              # everything, in order (hours)
    .venv/bin/python scripts/regenerate_figures.py --list       # names, kinds, docs, commands
    .venv/bin/python scripts/regenerate_figures.py --only model io kinematics
    .venv/bin/python scripts/regenerate_figures.py --kind timing
    .venv/bin/python scripts/regenerate_figures.py --check      # every figure has its block
    .venv/bin/python scripts/regenerate_figures.py --stale      # blocks made before the code they measure changed
    .venv/bin/python scripts/regenerate_figures.py --run-stale --jobs 2   # re-make those, two at a time

Every figure is one shell command (run from the repository root with ``bash -c``) and one
place in a document:

* most commands print their figure; the output replaces the document's marked block
  ``<!-- begin: NAME -->`` ... ``<!-- end: NAME -->`` (prose outside the blocks is left
  alone, so prose must not repeat a block's numbers);
* some commands write their document(s) themselves (``writes``); those files get the same
  marked block appended, holding only the stamp.

Each block starts with the stamp ``Made by `COMMAND` on DATE, commit HASH (DURATION).``;
when the working tree differs from the commit in the code the figure measures
(:func:`measured_paths`: the scripts its command runs and the repository files those import
or run, the packages' modules among them, followed file by file), the stamp says so.
``--stale`` lists the blocks made before a change to the code they measure (:func:`stale`;
a change to docstrings, comments or command-line help alone is none). A failed
command leaves its block as it was and makes the exit status 1 (the others still run, but
not those that read its data).

``--jobs N`` runs up to N accuracy figures at a time (:func:`run_all`); a timing figure
always runs alone, and a figure waits for those that write a file it reads or read a file
it writes (:func:`prerequisites`: a pooling block after its draws). ``--run-stale`` runs
only what ``--stale`` lists, so a regeneration longer than one sitting is resumed by running
it again: each block is written as its command ends. A data writer that finished before
the interruption is run again when the block that pools it was not yet re-made (its data
files carry no stamp of their own).

A *retired* figure (:attr:`Figure.retired`: the diagnosis' probes of leads it has not taken)
keeps its block as the record of the code at its stamp's commit: ``--stale`` does not list
it, a plain run or ``--run-stale`` leaves it out, and ``--only NAME`` re-makes it with the
current code. To reproduce it as it was, run its command in a worktree of that commit
beside this one, with this checkout's virtual environment::

    git worktree add ../addb-COMMIT COMMIT && ln -s "$PWD/.venv" ../addb-COMMIT/.venv
    cd ../addb-COMMIT && COMMAND

(``../shared`` is beside the worktree too, and the benchmark scripts put the worktree's root
first on ``sys.path``; done so for block ``diagnose-currency-compare`` on 2026-11-27, its
output identical to the block.)

The command's standard error goes to the terminal (progress); only its standard output
goes into the document.

Before it makes a timing figure, the script times the host reference (OpenSim's IK tool on
the walk, best of 3: about 20 s) and stops with exit status 2 when the host runs more than
:data:`HOST_SLACK` times slower than the median of the references the timing blocks record
(:func:`host_check`): figures made on a slowed host would not compare with the others
(``--any-host`` makes them all the same; the prose should then say so). During the run,
before each timing figure, the host is timed again when it was last timed more than 5
minutes before (:class:`HostGate`); a host found slowed is waited for (``--host-wait``
minutes, default 30), and a timing figure it does not come back for is left out, its block
as it was.

``kind`` is ``timing`` (wall times: run on a quiet machine) or ``accuracy`` (errors,
residuals, counts: deterministic given the code and data, up to round-off and network
training seeds). Durations in ``--list`` are rough, from the last runs on the 2-core
development machine.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import re
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO

REPO = Path(__file__).resolve().parents[1]
PY = ".venv/bin/python"
RESULTS = "tests/benchmarks/RESULTS.md"


@dataclass(frozen=True)
class Figure:
    """One regenerated figure.

    Attributes
    ----------
    name
        Block name (``<!-- begin: name -->``) and ``--only`` key.
    doc
        Document holding the block (repository-relative); empty when the command writes
        its documents itself (``writes``).
    command
        Shell command, run from the repository root.
    kind
        ``"timing"`` or ``"accuracy"``.
    minutes
        Rough duration on the development machine.
    fence
        Put the output in a code fence (plain-text output) rather than as Markdown.
    writes
        Documents the command writes itself (each gets a stamp block appended).
    retired
        Empty for a live figure; else when and why it was retired (:data:`RETIRED`): its
        block stays as the record of the code at its stamp's commit, is never listed by
        :func:`stale` and is re-made only when named with ``--only``.
    """

    name: str
    doc: str
    command: str
    kind: str
    minutes: float
    fence: bool = True
    writes: tuple[str, ...] = ()
    retired: str = ""


# git archive of the commit before the fit's speed-ups (tests/benchmarks/RESULTS.md, "Process speed")
BEFORE = "e0336e8"
BEFORE_TREE = f"/tmp/addb_{BEFORE}"
EXPORT_BEFORE = f"rm -rf {BEFORE_TREE} && mkdir -p {BEFORE_TREE} && git archive {BEFORE} solver addb_viewer annotations | tar -x -C {BEFORE_TREE}"
# git archive of the commit before the kinematics' exact speed-ups of 2026-11-25 (same section)
AGAINST = "ef4449a"
AGAINST_TREE = f"/tmp/addb_{AGAINST}"
EXPORT_AGAINST = f"rm -rf {AGAINST_TREE} && mkdir -p {AGAINST_TREE} && git archive {AGAINST} solver addb_viewer annotations | tar -x -C {AGAINST_TREE}"
# git archive of the commit before the input checks of 2026-11-28 (output folder, extensions, subject values)
CHECKS = "faf2215"
CHECKS_TREE = f"/tmp/addb_{CHECKS}"
EXPORT_CHECKS = f"rm -rf {CHECKS_TREE} && mkdir -p {CHECKS_TREE} && git archive {CHECKS} solver addb_viewer annotations | tar -x -C {CHECKS_TREE}"
CHECKED_SUBJECTS = "rajagopal2016_walk rajagopal2016_run opencap_uhlrich2023 camargo2021_levelground"
DIAG = f"{PY} tests/benchmarks/bench_diagnose.py"
#: The diagnosis table's draws 0-19 (blocks diagnose-draws-0-9 and -10-19), and with draws 20-39: what the comparisons read.
TABLE = "docs/diagnose/results_draws_0_9.json docs/diagnose/results_draws_10_19.json"
TABLE_40 = f"{TABLE} docs/diagnose/results_draws_20_39.json"


def _halves(name: str, run: str, stem: str, size: int, minutes: tuple[float, float], retired: str,
            part: str = "draws") -> tuple[list[str], tuple[Figure, Figure]]:
    """A benchmark of the diagnosis (``run``: the command up to the benchmark's own
    arguments) in two halves to run side by side: draws 0 to ``size`` - 1 with 5 consistent
    synthetic trials per trial, and the next ``size`` draws, into
    ``docs/diagnose/<stem>_draws_<first>_<last>.json`` (figures ``<name>-<part>-<first>-<last>``);
    returns the two files and the two figures."""
    data, figures = [], []
    for first, synthetic, duration in ((0, 5, minutes[0]), (size, 0, minutes[1])):
        last = first + size - 1
        data.append(f"docs/diagnose/{stem}_draws_{first}_{last}.json")
        start = f"--first {first} " if first else ""
        figures.append(Figure(f"{name}-{part}-{first}-{last}", "", f"{run} {start}--draws {size} --synthetic {synthetic} --json {data[-1]}",
                              "accuracy", duration, retired=retired))
    return data, (figures[0], figures[1])


def _probe_table(name: str, probe: str, stem: str, retired: str = "") -> tuple[Figure, Figure, Figure]:
    """The diagnosis' table with a probe of tests/benchmarks in its place (``probe``: the
    script and its switches): draws 0-9 with the synthetic trials and draws 10-19
    (:func:`_halves`), then their comparison with the table's own draws in RESULTS
    (``retired``: :attr:`Figure.retired` of all three)."""
    cmd = f"{PY} tests/benchmarks/{probe}"
    halves, draws = _halves(name, f"{cmd} --", stem, 10, (25.0, 25.0), retired)
    return (
        *draws,
        Figure(f"{name}-compare", RESULTS, f"{cmd} --compare {TABLE} --with {' '.join(halves)}", "accuracy", 0.1, fence=False,
               retired=retired),
    )


#: Why the diagnosis' probes of leads not taken were retired (:attr:`Figure.retired`).
RETIRED = ("2026-11-27: a lead for the diagnosis' rules that addb diagnose has not taken; re-made with every change of "
           "the code it reaches it cost 50-60 min of runs per probe (a change to any solver module staled about 7 h "
           "of figures before these were retired), so its block is kept as the record of the code at its stamp's commit")

#: Probes recorded once and retired as they were made (:attr:`Figure.retired`).
RECORDED = ("2026-11-27: a probe recorded once to close a question (is the joint fit's mass prior the lever for the "
            "diagnosis?), retired as it was made: its block is the record of the code at its stamp's commit")


#: The thresholds' replay, recorded once and retired as made (:attr:`Figure.retired`).
RECORDED_RULE = ("2026-11-27: a probe recorded once to close a question (can the choice rule's thresholds, re-derived on "
                 "the joint fit, give back the rows the alternation names?), retired as it was made: its block is the record "
                 "of the code at its stamp's commit")
#: Where the replay's captures are kept (one folder each, so that the two run side by side).
REPLAY = "/tmp/addb_rule_replay_{}/capture.pkl"
#: The choice rule's probe (capture, replay, live, compare).
RULE_PROBE = f"{PY} tests/benchmarks/probe_rule_replay.py"
#: The table's 40 draws before the plates' registration was confirmed on the marker-only motion
#: (git archive of their files at the last commit before; block diagnose-confirmation-compare).
UNCONFIRMED = "4ca3423"
UNCONFIRMED_TREE = f"/tmp/addb_table_{UNCONFIRMED}"
EXPORT_UNCONFIRMED = f"rm -rf {UNCONFIRMED_TREE} && mkdir -p {UNCONFIRMED_TREE} && git archive {UNCONFIRMED} {TABLE_40} | tar -x -C {UNCONFIRMED_TREE}"
UNCONFIRMED_TABLE_40 = " ".join(f"{UNCONFIRMED_TREE}/{path}" for path in TABLE_40.split())

#: The registration confirmed on the marker-only motion, recorded once and retired as made (:attr:`Figure.retired`).
RECORDED_CONFIRMED = ("2026-11-27: a probe recorded once to close a question (does the registration confirmed on the "
                      "marker-only motion, with thresholds re-derived on top of it, give the joint fit back the rows the "
                      "alternation names?), retired as it was made: its block is the record of the code at its stamp's commit")

#: The joint fit's probes of the choice rule as it was before the registration's confirmation
#: (:attr:`solver.diagnose.causes.base.Cause.confirmed_on_marker_motion`), retired when it landed.
BEFORE_CONFIRMATION = ("2026-11-27: a probe of one lead for the joint fit's diagnosis (its choices under the rule before the "
                       "plates' registration was confirmed on the marker-only motion), not taken by addb diagnose; retired when "
                       "the confirmation landed, its block kept as the record of the code at its stamp's commit")


def _replay_command(stem: str, options: str) -> str:
    """``probe_rule_replay.py replay`` deriving on the captures ``REPLAY.format(stem + "0_19")``
    and checking on ``(stem + "20_39")``, each against the table's own draws, with ``options``."""
    return (f"{RULE_PROBE} replay --derive {REPLAY.format(stem + '0_19')} --table {TABLE} --check "
            f"{REPLAY.format(stem + '20_39')} --table-check docs/diagnose/results_draws_20_39.json {options}")


def _rule_replay(name: str, fit: str, label: str) -> tuple[Figure, Figure, Figure]:
    """The choice's thresholds replayed on the fit ``fit`` (the capture's switches) and, with
    ``label``, its name in the headings (empty: the probe's default, the joint fit): draws
    0-19 with 10 consistent trials per trial and draws 20-39 captured to :data:`REPLAY`
    (folders ``[label_]0_19`` and ``[label_]20_39``, side by side), then the replay that
    derives the thresholds on the first and checks them on the second in RESULTS
    (recorded once, :data:`RECORDED_RULE`)."""
    cmd = RULE_PROBE
    stem = f"{label}_" if label else ""
    first, second = REPLAY.format(f"{stem}0_19"), REPLAY.format(f"{stem}20_39")
    return (
        Figure(f"{name}-capture-0-19", "", f"{cmd} capture {fit} --out {first} -- --draws 20 --synthetic 10", "accuracy", 31.0,
               retired=RECORDED_RULE),
        Figure(f"{name}-capture-20-39", "", f"{cmd} capture {fit} --out {second} -- --first 20 --draws 20 --synthetic 0", "accuracy",
               31.0, retired=RECORDED_RULE),
        Figure(name, RESULTS, _replay_command(stem, "--random 3000" + (f" --fit-label {label}" if label else "")), "accuracy", 7.0,
               fence=False, retired=RECORDED_RULE),
    )


def _rule_confirmed(values: str) -> tuple[Figure, ...]:
    """The rule's structure changed: the plates' registration named from the fitted motion
    only when the marker-only motion confirms it (``--confirm-registration 0``). Replayed on
    the captures of ``diagnose-rule-replay`` (the joint fit at ``mass_sigma`` 0.1) and of
    ``diagnose-rule-replay-alternation`` (the fit the diagnosis judges on), which must be in
    :data:`REPLAY`, with thresholds re-derived on top of it; then run live on draws 0-19 with
    5 consistent trials per trial and draws 20-39 (side by side, into
    ``docs/diagnose/<stem>_draws_*.json``): on the joint fit with the thresholds re-derived
    there (``values``, the replay's result), and on the alternation with the thresholds as
    they are; each compared with the table's 40 draws (all recorded once,
    :data:`RECORDED_CONFIRMED`)."""
    cmd = RULE_PROBE
    replay = "--random 1000 --confirm-registration 0"

    def live(name: str, fit: str, stem: str, label: str) -> tuple[Figure, Figure, Figure]:
        data, draws = _halves(name, f"{cmd} live {fit} --confirm-registration 0 --", stem, 20, (35.0, 31.0), RECORDED_CONFIRMED, "live")
        return (
            *draws,
            Figure(f"{name}-compare", RESULTS, f"{cmd} compare --table {TABLE_40} --with {' '.join(data)} --label {shlex.quote(label)}",
                   "accuracy", 0.1, fence=False, retired=RECORDED_CONFIRMED),
        )

    return (
        Figure("diagnose-rule-confirmed", RESULTS, _replay_command("", replay), "accuracy", 6.0, fence=False, retired=RECORDED_CONFIRMED),
        Figure("diagnose-rule-confirmed-alternation", RESULTS, _replay_command("alternation_", f"{replay} --fit-label alternation"),
               "accuracy", 6.0, fence=False, retired=RECORDED_CONFIRMED),
        *live("diagnose-rule-confirmed", f"--sigma 0.1 --values {values}", "joint_fit_confirmed",
              "joint fit (mass_sigma 0.1), registration confirmed, thresholds re-derived"),
        *live("diagnose-rule-confirmed-alternation", "--alternation", "alternation_confirmed",
              "alternation, registration confirmed, thresholds as they are"),
    )


def _joint_two_rows(sigma: str) -> tuple[Figure, Figure]:
    """The two rows the joint fit loses (plate position, segment masses; 40 draws) with its
    mass prior at ``sigma`` into ``docs/diagnose/joint_fit_sigma_<sigma>_two_rows.json``, then
    their comparison with the table's 40 draws in RESULTS (recorded once, :data:`RECORDED`)."""
    cmd = f"{PY} tests/benchmarks/bench_diagnose_joint.py --sigma {sigma}"
    name = f"diagnose-joint-sigma-{sigma.replace('.', '-')}"
    data = f"docs/diagnose/joint_fit_sigma_{sigma.replace('.', '_')}_two_rows.json"
    return (
        Figure(f"{name}-draws", "", f"{cmd} -- --causes plate_position_offset,segment_mass_distribution --draws 40 --synthetic 0 "
               f"--json {data}", "accuracy", 12.0, retired=RECORDED),
        Figure(f"{name}-compare", RESULTS, f"{cmd} --compare {TABLE_40} --with {data}", "accuracy", 0.1, fence=False, retired=RECORDED),
    )


#: The diagnosis judged on the joint fit (blocks diagnose-joint-*), and the last probe of it,
#: retired on 2026-11-29 (:attr:`Figure.retired`).
JOINT_FIT_JUDGED = ("2026-11-29: the diagnosis judged on the joint fit, a lead addb diagnose has not taken (it judges on "
                    "the alternation, solver/diagnose/judged_fit.py); its draws cost about 2 h of runs (one core) with every "
                    "change of the solver's code, which held back every fix there, so its blocks are kept as the record "
                    "of the code at their stamps' commits (issue 29's remaining gap is read from them as they were)")

#: The walk's two overlapping force causes on both fits, recorded once and retired as made (:attr:`Figure.retired`).
RECORDED_WALK = ("2026-11-28: a probe recorded once to close a question (on the walk, does the joint fit lose the plates' "
                 "shifts, or trade them with the plates' registration?), retired as it was made: its block is the record of "
                 "the code at its stamp's commit")


def _walk_two_rows() -> tuple[Figure, Figure, Figure]:
    """Plate position and plate registration, 40 draws each, every draw on the walk (the
    benchmark's draws alternate between the walk and the run; here seeds 5000-5039 and
    9000-9039 all hide their effect in the walk), on the alternation the diagnosis judges on
    and on the joint fit at ``mass_sigma`` 0.1, into
    ``docs/diagnose/walk_two_rows_{alternation,joint_fit_sigma_0_1}.json``; then the two
    compared draw by draw in RESULTS (recorded once, :data:`RECORDED_WALK`)."""
    args = "--causes plate_position_offset,plate_registration --trials walk --draws 40 --synthetic 0"
    alternation, joint = "docs/diagnose/walk_two_rows_alternation.json", "docs/diagnose/walk_two_rows_joint_fit_sigma_0_1.json"
    joint_cmd = f"{PY} tests/benchmarks/bench_diagnose_joint.py --sigma 0.1"
    return (
        Figure("diagnose-walk-two-rows-alternation", "", f"{DIAG} {args} --json {alternation}", "accuracy", 14.0, retired=RECORDED_WALK),
        Figure("diagnose-walk-two-rows-joint", "", f"{joint_cmd} -- {args} --json {joint}", "accuracy", 14.0, retired=RECORDED_WALK),
        Figure("diagnose-walk-two-rows-compare", RESULTS, f"{joint_cmd} --compare {alternation} --with {joint}", "accuracy", 0.1,
               fence=False, retired=RECORDED_WALK),
    )


FIGURES: tuple[Figure, ...] = (
    # ---- tests/benchmarks/RESULTS.md, in the document's order
    Figure("model", RESULTS, f"OPENBLAS_NUM_THREADS=1 taskset -c 0 {PY} tests/benchmarks/bench_model.py", "timing", 0.2),
    Figure("io", RESULTS, f"{PY} tests/benchmarks/bench_io.py", "timing", 0.2),
    Figure("kinematics", RESULTS, f"{PY} tests/benchmarks/bench_kinematics.py", "timing", 0.5, fence=False),
    Figure("imports", RESULTS, f"{PY} tests/benchmarks/bench_imports.py", "timing", 0.5),
    Figure("startup", RESULTS, f"{PY} tests/benchmarks/bench_startup.py --repeat 5", "timing", 1.5),
    Figure("imports-scipy-1.16", RESULTS, "rm -rf /tmp/addb_scipy_1_16 && .venv/bin/pip install -q --no-deps --target /tmp/addb_scipy_1_16 scipy==1.16.3 "
           f"&& PYTHONPATH=/tmp/addb_scipy_1_16 {PY} tests/benchmarks/bench_imports.py", "timing", 0.7),
    Figure("process-scipy-1.16", RESULTS, "rm -rf /tmp/addb_scipy_1_16 && .venv/bin/pip install -q --no-deps --target /tmp/addb_scipy_1_16 scipy==1.16.3 "
           f"&& PYTHONPATH=/tmp/addb_scipy_1_16 {PY} tests/benchmarks/bench_process.py --repeat 3 --host-reference "
           "rajagopal2016_walk opencap_uhlrich2023", "timing", 1.0, fence=False),
    Figure("process", RESULTS, f"{PY} tests/benchmarks/bench_process.py --repeat 3 --host-reference "
           "rajagopal2016_walk rajagopal2016_run opencap_uhlrich2023 camargo2021_levelground", "timing", 1.0, fence=False),
    Figure("process-band", RESULTS, f"{PY} tests/benchmarks/bench_process.py --repeat 3 --fit band "
           "rajagopal2016_walk rajagopal2016_run opencap_uhlrich2023 camargo2021_levelground", "timing", 2.5, fence=False),
    Figure("joint-torques", RESULTS, f"{PY} tests/benchmarks/bench_joint_torques.py", "accuracy", 0.3, fence=False),
    Figure("converged-weights", RESULTS, f"{PY} tests/benchmarks/bench_converged_weights.py", "accuracy", 4.0, fence=False),
    Figure("fit-rounds", RESULTS, f"{PY} tests/benchmarks/bench_fit_rounds.py", "accuracy", 1.0, fence=False),
    Figure("fit-round-tolerance", RESULTS, f"{PY} tests/benchmarks/bench_fit_rounds.py rajagopal2016_walk rajagopal2016_run opencap_uhlrich2023 "
           "camargo2021_levelground --direction coefficients --rounds 4 --round-tolerance none 3e-4 1e-3 2e-3",
           "timing", 1.5, fence=False),
    Figure("joint-fit", RESULTS, f"{PY} tests/benchmarks/bench_joint_fit.py --sigma 0.5 1", "timing", 1.5, fence=False),
    Figure("growth", RESULTS, f"{PY} tests/benchmarks/bench_growth.py --memory-runs 3", "timing", 0.7, fence=False),
    Figure("growth-mmap-32", RESULTS, f"{PY} tests/benchmarks/bench_growth.py --cuts --memory-runs 3 --mmap-threshold-mb 32", "timing", 0.5, fence=False),
    Figure("growth-band", RESULTS, f"{PY} tests/benchmarks/bench_growth.py --fit band", "timing", 1.0, fence=False),
    Figure("annotations", RESULTS, f"{PY} tests/benchmarks/bench_annotations.py", "timing", 0.3),
    Figure("recordings", RESULTS, f"{PY} tests/benchmarks/bench_recordings.py", "timing", 0.5),
    Figure("viewer", RESULTS, f"{PY} tests/benchmarks/bench_viewer.py", "timing", 0.5),
    Figure("queue", RESULTS, f"{PY} tests/benchmarks/bench_queue.py", "timing", 0.3),
    Figure("seed-benchmark", RESULTS, f"{PY} tests/benchmarks/bench_benchmark.py --work /tmp/addb_bench_benchmark --fresh",
           "accuracy", 2.0, fence=False,
           writes=("docs/benchmark/benchmark_kinematic_inputs.md", "docs/benchmark/benchmark_processed_inputs.md",
                   "docs/benchmark/filtering_study.md")),
    Figure("benchmark-variants", RESULTS, f"{PY} tests/benchmarks/bench_benchmark_variants.py --work /tmp/addb_bench_benchmark --fresh",
           "accuracy", 5.0, fence=False),
    Figure("b3d", RESULTS, f"{PY} tests/benchmarks/bench_b3d.py", "timing", 0.5),
    Figure("process-before", RESULTS, f"{EXPORT_BEFORE} && {PY} tests/benchmarks/bench_process.py --repeat 3 --src {BEFORE_TREE}",
           "timing", 6.0, fence=False),
    Figure(
        "process-exactness", RESULTS,
        f"{EXPORT_BEFORE} && rm -rf /tmp/addb_exact_before /tmp/addb_exact_after && R=$PWD && "
        "for s in rajagopal2016_walk rajagopal2016_run opencap_uhlrich2023; do "
        f"(cd /tmp && PYTHONPATH={BEFORE_TREE} $R/.venv/bin/addb process $R/../shared/data/subjects/$s --out /tmp/addb_exact_before/$s >/dev/null) && "
        ".venv/bin/addb process ../shared/data/subjects/$s --out /tmp/addb_exact_after/$s --fit band >/dev/null; done && "
        f"{PY} tests/benchmarks/compare_process_outputs.py /tmp/addb_exact_before /tmp/addb_exact_after",
        "accuracy", 4.0),
    Figure("process-against", RESULTS, f"{EXPORT_AGAINST} && {PY} tests/benchmarks/bench_process.py --repeat 5 --against {AGAINST_TREE} "
           "--fit rounds --against-fit default rajagopal2016_walk rajagopal2016_run opencap_uhlrich2023", "timing", 2.0, fence=False),
    Figure(
        "process-against-exactness", RESULTS,
        f"{EXPORT_AGAINST} && rm -rf /tmp/addb_against_before /tmp/addb_against_after && R=$PWD && "
        "for s in rajagopal2016_walk rajagopal2016_run opencap_uhlrich2023; do "
        f"(cd /tmp && PYTHONPATH={AGAINST_TREE} $R/.venv/bin/addb process $R/../shared/data/subjects/$s --out /tmp/addb_against_before/$s >/dev/null) && "
        ".venv/bin/addb process ../shared/data/subjects/$s --out /tmp/addb_against_after/$s --fit rounds >/dev/null; done && "
        f"{PY} tests/benchmarks/compare_process_outputs.py /tmp/addb_against_before /tmp/addb_against_after && "
        "{ diff -r -q -x results.json -x trial.npz -x subject.json -x .addb_cache /tmp/addb_against_before /tmp/addb_against_after "
        "&& echo 'every other file byte-identical' || echo 'the files listed differ'; }",
        "accuracy", 1.0),
    Figure(
        "input-checks-exactness", RESULTS,
        f"{EXPORT_CHECKS} && rm -rf /tmp/addb_checks && R=$PWD && mkdir -p /tmp/addb_checks/subjects && "
        f"{PY} scripts/make_example_subject.py camargo2021_levelground /tmp/addb_checks/subjects/camargo2021_levelground >/dev/null && "
        "for s in rajagopal2016_walk rajagopal2016_run opencap_uhlrich2023; do ln -s $R/../shared/data/subjects/$s /tmp/addb_checks/subjects/$s; done && "
        f"for f in default rounds; do for s in {CHECKED_SUBJECTS}; do "
        f"(cd /tmp && PYTHONPATH={CHECKS_TREE} $R/.venv/bin/addb process /tmp/addb_checks/subjects/$s --out /tmp/addb_checks/before_$f/$s --fit $f >/dev/null 2>&1) && "
        ".venv/bin/addb process /tmp/addb_checks/subjects/$s --out /tmp/addb_checks/after_$f/$s --fit $f >/dev/null 2>&1; done && echo \"--fit $f\" && "
        f"{PY} tests/benchmarks/compare_process_outputs.py /tmp/addb_checks/before_$f /tmp/addb_checks/after_$f && "
        "{ diff -r -q -x results.json -x trial.npz -x subject.json -x .addb_cache /tmp/addb_checks/before_$f /tmp/addb_checks/after_$f "
        "&& echo 'every other file byte-identical' || echo 'the files listed differ'; }; done",
        "accuracy", 3.0),
    Figure("band-solve", RESULTS, f"{PY} tests/benchmarks/probe_band_solve.py --repeat 7", "timing", 1.0, fence=False),
    Figure("dataset", RESULTS, f"{PY} tests/benchmarks/bench_dataset.py --dask-defaults --host-reference", "timing", 4.0),
    Figure("dataset-client", RESULTS, f"{PY} tests/benchmarks/bench_dataset_client.py", "timing", 1.5, fence=False),
    Figure("reprocess", RESULTS, f"{PY} tests/benchmarks/bench_reprocess.py --repeat 3 --host-reference walk camargo", "timing", 2.5, fence=False),
    Figure("reprocess-band", RESULTS, f"{PY} tests/benchmarks/bench_reprocess.py --repeat 3 --fit band --host-reference walk camargo",
           "timing", 6.0, fence=False),
    # ---- documents of their own
    Figure("ablation", "docs/dynamics/ABLATION.md", f"{PY} tests/benchmarks/bench_ablation.py", "accuracy", 0.5, fence=False),
    Figure("expert-comparison", "docs/kinematics/EXPERT_COMPARISON.md", f"{PY} tests/benchmarks/bench_expert_comparison.py",
           "accuracy", 0.5, fence=False),
    Figure("b3d-comparison", "", f"{PY} scripts/b3d_compare.py --md docs/b3d/comparison.md", "accuracy", 0.2,
           writes=("docs/b3d/comparison.md",)),
    # ---- the diagnosis (docs/diagnose; the commands named at the head of each document)
    Figure("diagnose-draws-0-9", "", f"{DIAG} --draws 10 --synthetic 5 --json docs/diagnose/results_draws_0_9.json", "accuracy", 20.0),
    Figure("diagnose-draws-10-19", "", f"{DIAG} --first 10 --draws 10 --synthetic 0 --json docs/diagnose/results_draws_10_19.json",
           "accuracy", 15.0),
    Figure("diagnose-results", "docs/diagnose/RESULTS.md",
           f"{DIAG} --pool --from-json {TABLE}", "accuracy", 0.1,
           fence=False),
    Figure("diagnose-joint-draws-0-9", "", f"{PY} tests/benchmarks/bench_diagnose_joint.py -- --draws 10 --synthetic 5 "
           "--json docs/diagnose/joint_fit_draws_0_9.json", "accuracy", 20.0, retired=JOINT_FIT_JUDGED),
    Figure("diagnose-joint-draws-10-19", "", f"{PY} tests/benchmarks/bench_diagnose_joint.py -- --first 10 --draws 10 "
           "--synthetic 0 --json docs/diagnose/joint_fit_draws_10_19.json", "accuracy", 15.0, retired=JOINT_FIT_JUDGED),
    Figure("diagnose-joint-compare", RESULTS, f"{PY} tests/benchmarks/bench_diagnose_joint.py --compare {TABLE} "
           "--with docs/diagnose/joint_fit_draws_0_9.json docs/diagnose/joint_fit_draws_10_19.json",
           "accuracy", 0.1, fence=False, retired=JOINT_FIT_JUDGED),
    Figure("diagnose-joint-sigma-draws", "", f"{PY} tests/benchmarks/bench_diagnose_joint.py --sigma 0.1 -- --causes "
           "plate_position_offset,marker_offset,segment_mass_distribution --draws 20 --synthetic 5 "
           "--json docs/diagnose/joint_fit_sigma_0_1_draws.json", "accuracy", 15.0, retired=JOINT_FIT_JUDGED),
    Figure("diagnose-joint-sigma-compare", RESULTS, f"{PY} tests/benchmarks/bench_diagnose_joint.py --sigma 0.1 --compare {TABLE} "
           "--with docs/diagnose/joint_fit_sigma_0_1_draws.json",
           "accuracy", 0.1, fence=False, retired=JOINT_FIT_JUDGED),
    # the same comparison on 40 draws of every cause (draws 20-39 and the six causes left out above)
    Figure("diagnose-draws-20-39", "", f"{DIAG} --first 20 --draws 20 --synthetic 0 --json docs/diagnose/results_draws_20_39.json",
           "accuracy", 30.0),
    # the table on its 40 draws (draws 0-39 pooled)
    Figure("diagnose-results-40", "docs/diagnose/RESULTS.md", f"{DIAG} --pool --from-json {TABLE_40}", "accuracy", 0.1, fence=False),
    # what the registration's confirmation changed, draw by draw: the 40 draws before it (the table's files at
    # 4ca3423, the last commit with the rule before) beside the table's files now
    Figure("diagnose-confirmation-compare", "docs/diagnose/RESULTS.md",
           f"{EXPORT_UNCONFIRMED} && {RULE_PROBE} compare --table {UNCONFIRMED_TABLE_40} --with {TABLE_40} "
           "--label 'alternation, the registration confirmed (now)'",
           "accuracy", 0.1, fence=False),
    Figure("diagnose-joint-sigma-draws-20-39", "", f"{PY} tests/benchmarks/bench_diagnose_joint.py --sigma 0.1 -- --first 20 "
           "--draws 20 --synthetic 0 --json docs/diagnose/joint_fit_sigma_0_1_draws_20_39.json", "accuracy", 30.0, retired=JOINT_FIT_JUDGED),
    Figure("diagnose-joint-sigma-draws-rest", "", f"{PY} tests/benchmarks/bench_diagnose_joint.py --sigma 0.1 -- --causes "
           "force_time_offset,body_mass,plate_force_offset,plate_force_gain,unmeasured_force,plate_registration --draws 20 "
           "--synthetic 0 --json docs/diagnose/joint_fit_sigma_0_1_draws_rest.json", "accuracy", 20.0, retired=JOINT_FIT_JUDGED),
    Figure("diagnose-joint-sigma-compare-40", RESULTS, f"{PY} tests/benchmarks/bench_diagnose_joint.py --sigma 0.1 --compare {TABLE_40} "
           "--with docs/diagnose/joint_fit_sigma_0_1_draws.json docs/diagnose/joint_fit_sigma_0_1_draws_rest.json "
           "docs/diagnose/joint_fit_sigma_0_1_draws_20_39.json", "accuracy", 0.1, fence=False, retired=JOINT_FIT_JUDGED),
    # the two rows the joint fit loses, with its mass prior a third and three times 0.1 (recorded once, retired as made)
    *_joint_two_rows("0.03"),
    *_joint_two_rows("0.3"),
    *_walk_two_rows(),
    # a lead for the walk's two rows: the centre of pressure's place in the foot as a tie-break
    Figure("diagnose-cop-symmetry-probe", RESULTS, f"{PY} tests/benchmarks/probe_cop_symmetry.py --sigma 0.1", "accuracy", 14.0, fence=False, retired=JOINT_FIT_JUDGED),
    Figure("diagnose-run-registration-probe", RESULTS, f"{PY} tests/benchmarks/probe_joint_choice.py --sigma 0.1 --seeds 9021 9023 9025",
           "accuracy", 3.0, fence=False, retired=BEFORE_CONFIRMATION),
    Figure("diagnose-registration-gain-draws-0-19", "", f"{PY} tests/benchmarks/probe_registration_gain.py --gain 0.05 -- --draws 20 "
           "--synthetic 5 --json docs/diagnose/registration_gain_draws_0_19.json", "accuracy", 30.0, retired=RETIRED),
    Figure("diagnose-registration-gain-draws-20-39", "", f"{PY} tests/benchmarks/probe_registration_gain.py --gain 0.05 -- --first 20 "
           "--draws 20 --synthetic 0 --json docs/diagnose/registration_gain_draws_20_39.json", "accuracy", 30.0, retired=RETIRED),
    Figure("diagnose-registration-gain-compare", RESULTS, f"{PY} tests/benchmarks/probe_registration_gain.py --gain 0.05 --compare {TABLE_40} "
           "--with "
           "docs/diagnose/registration_gain_draws_0_19.json docs/diagnose/registration_gain_draws_20_39.json", "accuracy", 0.1, fence=False,
           retired=RETIRED),
    # the run's body-mass draw 2009 that the probe above lost: on the run's base built with and without the changed threshold
    Figure("diagnose-registration-gain-base", RESULTS, " && echo && ".join(
        f"{PY} tests/benchmarks/probe_registration_gain.py --gain 0.05{flag} -- --trials run --causes body_mass --first 9 --draws 1 --synthetic 0"
        for flag in ("", " --after-bases")), "accuracy", 1.5, retired=BEFORE_CONFIRMATION),
    Figure("diagnose-joint-choice-probe", RESULTS, f"{PY} tests/benchmarks/probe_joint_choice.py --sigma 0.1 --seeds 5006 5014 7006 5007 7007",
           "accuracy", 5.0, fence=False, retired=BEFORE_CONFIRMATION),
    *_probe_table("diagnose-currency", "probe_motion_currency.py --segment-on-residuals", "motion_currency", RETIRED),
    *_probe_table("diagnose-hybrid", "probe_hybrid_currency.py --channel-gain --fitted-motion-only", "hybrid_currency", RETIRED),
    Figure("diagnose-fixed-base-run", RESULTS, f"{PY} tests/benchmarks/probe_fixed_base.py --trial run --draws "
           "segment_mass_distribution:1 segment_mass_distribution:3 segment_mass_distribution:5 segment_mass_distribution:7 "
           "segment_mass_distribution:13 body_mass:9", "accuracy", 8.0, fence=False, retired=BEFORE_CONFIRMATION),
    # the choice rule's thresholds re-derived on the joint fit: every draw's candidates captured once, the choice replayed
    *_rule_replay("diagnose-rule-replay", "--sigma 0.1", ""),
    # the same on the fit the diagnosis judges on: are the table's own thresholds at their best, in and out of sample?
    *_rule_replay("diagnose-rule-replay-alternation", "--alternation", "alternation"),
    # a change of the rule's structure instead: the registration confirmed on the marker-only motion (joint fit)
    *_rule_confirmed("registration_gain=0.03 min_t=2.5"),
    Figure("diagnose-marker-draws", "docs/diagnose/RESULTS.md",
           f"{PY} tests/benchmarks/probe_marker_draws.py --draws 20", "accuracy", 2.5),
    Figure("diagnose-marker-folds", "docs/diagnose/RESULTS.md",
           f"{PY} tests/benchmarks/probe_marker_folds.py --draws 20", "accuracy", 5.0),
    Figure("diagnose-marker-offset-opencap-DJ1", "docs/diagnose/RESULTS.md",
           f"{DIAG} --trials DJ1 --causes marker_offset --draws 10 --synthetic 0 --json docs/diagnose/results_marker_offset_opencap_DJ1.json",
           "accuracy", 1.5),
    Figure("diagnose-marker-offset-opencap-walking1", "docs/diagnose/RESULTS.md",
           f"{DIAG} --trials walking1 --causes marker_offset --draws 10 --synthetic 0 "
           "--json docs/diagnose/results_marker_offset_opencap_walking1.json", "accuracy", 1.5),
    Figure("diagnose-findings", "", f"{PY} tests/benchmarks/findings_diagnose.py --rounds 4 --markdown docs/diagnose/findings_runs.md",
           "accuracy", 5.0, writes=("docs/diagnose/findings_runs.md",)),
    Figure("diagnose-findings-run", "",
           f"{PY} tests/benchmarks/findings_diagnose.py --trials run --rounds 4 --markdown docs/diagnose/findings_runs_run.md",
           "accuracy", 3.0, writes=("docs/diagnose/findings_runs_run.md",)),
)

BEGIN = "<!-- begin: {} -->"
END = "<!-- end: {} -->"


def _git(*args: str) -> str:
    return subprocess.run(["git", *args], cwd=REPO, check=True, capture_output=True, text=True).stdout.strip()


def stamp(fig: Figure, seconds: float) -> str:
    """The first line of a block: command, date, commit and duration; "plus uncommitted
    changes to the measured code" when the working tree differs from HEAD in
    :func:`measured_paths` (the one definition :func:`stale` reads too), a file not yet
    committed included, by more than what :func:`_same_code` allows (a docstring or a
    comment edited while a figure runs is no change of its code, as for :func:`stale`)."""
    commit = _git("rev-parse", "--short", "HEAD")
    dirty = bool(_dirty_code(measured_paths(fig)))
    minutes, secs = divmod(round(seconds), 60)
    took = f"{minutes} min {secs} s" if minutes else f"{secs} s"
    note = " plus uncommitted changes to the measured code" if dirty else ""
    return f"Made by `{fig.command}` on {_dt.date.today().isoformat()}, commit {commit}{note} ({took})."


def _dirty_code(paths: list[str]) -> list[str]:
    """Of ``paths``, the files whose working-tree code differs from HEAD's (new files
    included; :func:`_same_code` with the working tree)."""
    changed = _git("diff", "--name-only", "HEAD", "--", *paths).split() + _git("ls-files", "--others", "--exclude-standard", "--", *paths).split()
    return [path for path in changed if not _same_code("HEAD", path, None)]


def block_text(fig: Figure, head: str, output: str) -> str:
    """The whole marked block: begin marker, stamp, output, end marker."""
    body = output.rstrip("\n")
    if fig.fence and body:
        body = f"```\n{body}\n```"
    parts = [BEGIN.format(fig.name), head]
    if body:
        parts += ["", body]
    parts.append(END.format(fig.name))
    return "\n".join(parts)


def _pattern(name: str) -> re.Pattern[str]:
    """A whole block: its markers each on a line of their own."""
    return re.compile("^" + re.escape(BEGIN.format(name)) + r"$.*?^" + re.escape(END.format(name)) + "$", re.DOTALL | re.MULTILINE)


def replace_block(path: Path, fig: Figure, text: str, *, append: bool = False) -> None:
    """Put ``text`` (a whole block) in place of ``path``'s block ``fig.name``; with
    ``append``, add it at the end when the document has none.

    Raises
    ------
    ValueError
        The document has no such block (and ``append`` is false), or has it twice.
    """
    doc = path.read_text()
    found = _pattern(fig.name).findall(doc)
    if len(found) > 1:
        raise ValueError(f"{path}: block {fig.name!r} appears {len(found)} times")
    if not found:
        if not append:
            raise ValueError(f"{path}: no block {BEGIN.format(fig.name)} ... {END.format(fig.name)}")
        doc = doc.rstrip("\n") + "\n\n" + text + "\n"
    else:
        doc = _pattern(fig.name).sub(lambda _m: text, doc)
    path.write_text(doc)


def check() -> list[str]:
    """Problems: a figure whose document lacks its block, a block no figure makes."""
    problems = []
    names = {f.name for f in FIGURES}
    docs = {f.doc for f in FIGURES if f.doc}
    for fig in FIGURES:
        if fig.doc and len(_pattern(fig.name).findall((REPO / fig.doc).read_text())) != 1:
            problems.append(f"{fig.doc}: block {fig.name!r} missing or repeated")
    for doc in sorted(docs | {"tests/benchmarks/RESULTS.md"}):
        for name in re.findall(r"^<!-- begin: (\S+) -->$", (REPO / doc).read_text(), re.MULTILINE):
            if name not in names:
                problems.append(f"{doc}: block {name!r} made by no figure")
    return problems


#: The stamp :func:`stamp` writes, read back by :func:`stamp_of`: the commit, and whether the
#: tree had uncommitted changes then.
STAMP = re.compile(r"^Made by `.*` on \d{4}-\d{2}-\d{2}, commit ([0-9a-f]{7,40})( plus uncommitted changes to the measured code)? \(", re.MULTILINE)
#: The repository's packages: a figure measures those of their modules its command reaches
#: (:func:`script_closure`), and their data files beside them.
PACKAGES = ("solver", "addb_viewer", "annotations")

#: Folders searched for a script a file names by its file name alone (``"make_example_subject.py"``
#: joined to ``REPO / "scripts"``, a sibling imported as ``from user_env import ...``).
_SCRIPT_FOLDERS = ("scripts", "tests/benchmarks")

#: The ``addb`` command line: its subcommands' modules are the string constants of
#: ``COMMANDS`` there, each reached only by a figure that runs that subcommand.
_CLI = "addb_viewer/cli.py"
_COMMANDS_PACKAGE = "addb_viewer.commands."

#: A module of the packages named in text: ``python -m addb_viewer.cli``, code passed to
#: ``python -c``, ``importlib.import_module("solver.x")``.
_MODULE_NAME = re.compile(r"\b((?:" + "|".join(PACKAGES) + r")(?:\.\w+)+)")


def measured_paths(fig: Figure) -> tuple[str, ...]:
    """The paths whose change can change ``fig``'s figures: the repository scripts its
    command runs (``scripts/*.py``, ``tests/**/*.py``), the modules it names (``python -m``)
    or runs through ``addb``, and the repository files those import or run, followed from
    file to file into the packages (:func:`script_closure`).

    A benchmark's script, and a module of the packages, is measured only by the figures
    whose commands reach it: a change to the diagnosis leaves the timing of ``addb
    process`` current, and a new benchmark the other figures."""
    named = re.findall(r"((?:scripts|tests)/[\w./-]+\.py)", fig.command)
    return tuple(script_closure(named, fig.command))


def script_closure(start: list[str] | tuple[str, ...], command: str = "") -> list[str]:
    """Repository files reached from the scripts ``start`` (paths from the repository root)
    and the shell ``command`` that runs them.

    Followed, in every file reached (scripts and modules of :data:`PACKAGES` alike):
    ``import``/``from`` statements anywhere in a file (``tests.diagnose.harness`` from the
    root, a bare ``bench_kinematics`` from the importing file's folder; the ``__init__.py``
    of each package on the way); string constants other than docstrings that name a ``.py``
    file (a script run with ``subprocess``) beside the file, in the root or in
    :data:`_SCRIPT_FOLDERS`, or a module of the packages (``-m addb_viewer.cli``, code for
    ``python -c``, ``importlib``); the ``addb`` executable (a constant ``"addb"`` or a path
    ending in ``/addb``, or ``addb`` in ``command``) reaches :data:`_CLI`, and a
    subcommand's module (``COMMANDS`` there) is followed whole when a file reached or
    ``command`` names that subcommand (a constant equal to its name, or ``addb NAME``); the
    others, which the command line imports to register them, are followed without their
    functions' bodies (what their handlers import lazily is not loaded). A module of
    the packages brings the data files of its folder (those in no subpackage: the viewer's
    bundled geometry, the demo subject). A file that cannot be read or parsed is kept, and
    not followed.

    Returns
    -------
    Sorted paths from the repository root, ``start``'s included (also one that does not exist:
    ``git diff`` then lists it if it was there at the stamp's commit).
    """
    import ast

    seen: set[str] = set()  # followed whole
    shallow_seen: set[str] = set()  # loaded, their functions' imports not followed
    words: set[str] = set(re.findall(r"(?:^|[\s/])addb(?:_viewer\.cli)?\s+([a-z]\w*)", command))
    deferred: dict[str, list[Path]] = {}  # subcommand -> its module's files, until it is named
    data_folders: set[Path] = set()
    todo = [(rel, False) for rel in (*start, *_files_of_text(command, REPO))]
    if re.search(r"(?:^|[\s/])addb\s", command):
        todo.append((_CLI, False))
    unnamed_loaded = False
    while True:
        while todo:
            rel, shallow = todo.pop()
            if rel in seen or (shallow and rel in shallow_seen):
                continue
            (shallow_seen if shallow else seen).add(rel)
            path = REPO / rel
            if rel.startswith(tuple(p + "/" for p in PACKAGES)) and path.parent not in data_folders:
                data_folders.add(path.parent)
                todo += [(f, False) for f in _data_files(path.parent)]
            if path.suffix != ".py":
                continue
            try:
                tree = ast.parse(path.read_text(), filename=rel)
            except (OSError, SyntaxError, UnicodeDecodeError):
                continue
            docstrings = {id(owner.body[0].value) for owner in _docstring_owners(tree)}
            for node in _walk(tree, functions=not shallow):
                found: list[Path] = []
                if isinstance(node, ast.Import):
                    for alias in node.names:
                        found += _module_files(alias.name, path.parent)
                elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                    found += _module_files(node.module, path.parent)
                    for alias in node.names:  # ``from tests.diagnose import harness``
                        found += _module_files(f"{node.module}.{alias.name}", path.parent)
                elif isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings:
                    text = node.value
                    if re.fullmatch(r"[\w./-]+\.py", text):
                        found += [f for f in (path.parent / text, REPO / text, *(REPO / d / text for d in _SCRIPT_FOLDERS)) if f.is_file()]
                    if text == "addb" or text.endswith("/addb"):
                        found.append(REPO / _CLI)
                    if re.fullmatch(r"[a-z]\w*", text):
                        words.add(text)
                    if rel == _CLI and text.startswith(_COMMANDS_PACKAGE):
                        deferred[text.removeprefix(_COMMANDS_PACKAGE)] = _module_files(text, REPO)
                    else:
                        found += [REPO / f for f in _files_of_text(text, REPO)]
                for f in map(Path.resolve, found):
                    if not f.is_relative_to(REPO):  # e.g. "../x.py": not this repository's
                        continue
                    r = f.relative_to(REPO).as_posix()
                    if r not in seen:
                        todo.append((r, shallow))
        named = [w for w in deferred if w in words]
        for w in named:
            todo += [(f.relative_to(REPO).as_posix(), False) for f in deferred.pop(w)]
        if not named and not unnamed_loaded:
            # the command line imports every subcommand's module to register it: those not
            # run are loaded, without what their handlers import
            unnamed_loaded = True
            todo += [(f.relative_to(REPO).as_posix(), True) for files in deferred.values() for f in files]
        if not todo:
            return sorted(seen | shallow_seen)


def _docstring_owners(tree: object) -> list[object]:
    """The module, classes and functions of ``tree`` whose first statement is a docstring."""
    import ast

    return [
        n for n in ast.walk(tree)
        if isinstance(n, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and n.body
        and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant) and isinstance(n.body[0].value.value, str)
    ]  # fmt: skip


def _walk(tree: object, functions: bool = True) -> Iterator[object]:
    """The nodes of ``tree`` (:func:`ast.walk`), without the bodies of functions unless
    ``functions``: the statements that run when the module is imported."""
    import ast

    todo = [tree]
    while todo:
        node = todo.pop()
        yield node
        for child in ast.iter_child_nodes(node):
            if functions or not isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                todo.append(child)
            elif not isinstance(child, ast.Lambda):  # decorators and defaults run at import
                todo += [*child.decorator_list, *child.args.defaults, *(d for d in child.args.kw_defaults if d is not None)]


def _files_of_text(text: str, root: Path) -> list[str]:
    """The files of the modules of :data:`PACKAGES` that ``text`` names (the longest dotted
    prefix of each name that is a module: ``solver.dynamics.fit.converged_fit`` names
    ``solver/dynamics/fit.py``)."""
    out: list[str] = []
    for name in _MODULE_NAME.findall(text):
        parts = name.split(".")
        for n in range(len(parts), 0, -1):
            files = _module_files(".".join(parts[:n]), root)
            if files:
                out += [f.relative_to(root).as_posix() for f in files]
                break
    return out


def _data_files(folder: Path) -> list[str]:
    """The files other than Python sources under ``folder`` that belong to no subpackage
    (a subfolder with an ``__init__.py`` is a package of its own), bytecode caches and
    Markdown notes for readers aside."""
    out: list[str] = []
    for f in sorted(folder.rglob("*")):
        if f.suffix in (".py", ".pyc", ".md") or "__pycache__" in f.parts or not f.is_file():
            continue
        owner = f.parent
        while owner != folder and not (owner / "__init__.py").is_file():
            owner = owner.parent
        if owner == folder:
            out.append(f.relative_to(REPO).as_posix())
    return out


def _module_files(module: str, folder: Path) -> list[Path]:
    """The repository files an absolute import of ``module`` from a file in ``folder`` runs:
    each package's ``__init__.py`` and the module's file, looked up from the root, or (for
    a bare name) from ``folder``, as a script's own folder is first on its path."""
    parts = module.split(".")
    for base in (REPO, folder):
        files = [base.joinpath(*parts[:i], "__init__.py") for i in range(1, len(parts) + 1)]
        leaf = base.joinpath(*parts).with_suffix(".py")
        hits = [f for f in (*files, leaf) if f.is_file()]
        if leaf.is_file() or base.joinpath(*parts, "__init__.py").is_file():
            return hits
    return []


def _block(fig: Figure) -> tuple[str, str | None]:
    """``(document, whole block text)`` of ``fig``: its document's block, or the first
    document it writes; the text is None when there is no such document or block."""
    doc = fig.doc or next((w for w in fig.writes if w.endswith(".md")), "")
    if not doc or not (REPO / doc).exists():
        return doc, None
    found = _pattern(fig.name).findall((REPO / doc).read_text())
    return doc, (found[0] if found else None)


def stamp_of(fig: Figure) -> tuple[str, bool] | None:
    """``(commit, uncommitted)`` from the stamp of ``fig``'s block (its document's, or the
    first document it writes), or None when it has no block (figures that only write data
    files, whose stamp is the block of the figure that reads them).

    Raises
    ------
    ValueError
        The block's first line is not a stamp :data:`STAMP` reads (naming the document).
    """
    doc, block = _block(fig)
    if block is None:
        return None
    match = STAMP.search(block)
    if match is None:
        raise ValueError(f"{doc}: block {fig.name!r} has no stamp 'Made by `COMMAND` on DATE, commit HASH (DURATION).'")
    return match.group(1), bool(match.group(2))


def _unmade(fig: Figure) -> bool:
    """Whether ``fig``'s block is in its document but holds nothing yet (a figure registered
    and not made: no stamp to read, and nothing to be stale against)."""
    block = _block(fig)[1]
    return block is not None and not block[len(BEGIN.format(fig.name)) : -len(END.format(fig.name))].strip()


def _reader(fig: Figure, figures: tuple[Figure, ...] | list[Figure]) -> Figure | None:
    """The first figure of ``figures`` with a block whose command names a ``.json`` file that
    ``fig``'s command names (the block that pools the data ``fig`` writes), or None."""
    data = {t for t in shlex.split(fig.command) if t.endswith(".json")}
    for other in figures:
        if other.name != fig.name and data & set(shlex.split(other.command)) and _block(other)[1] is not None:
            return other
    return None


def stale(figures: tuple[Figure, ...] | list[Figure] | None = None, readers: tuple[Figure, ...] | list[Figure] | None = None) -> list[tuple[Figure, str, list[str]]]:
    """Figures whose block was made before a change to the code it measures.

    Parameters
    ----------
    figures, readers
        The figures to judge, and those whose blocks may pool their data; None: the
        registry :data:`FIGURES` as it is when called.

    Returns
    -------
    ``(figure, stamp commit, changed paths)`` for each empty block (never made: commit
    ``""``) and each stamped block whose commit differs
    from HEAD in :func:`measured_paths` (``git diff --name-only COMMIT HEAD``; a Python file
    whose code is the same but for docstrings, comments and layout, :func:`_same_code`, is
    no change), or whose
    stamp says the tree had uncommitted changes then (``["uncommitted changes"]``; those
    changes cannot be compared). Timing figures are also moved by the host, which this
    does not see.

    A figure that only writes data files (no block of its own, such as the diagnosis'
    draws) is read against the stamp of the first of ``readers`` that pools its ``.json``
    output (:func:`_reader`), with its own measured code: when the code changes after that
    block was made, the writer is listed beside it (re-making the pooling block alone would
    stamp the old data with the new code); while that block is empty (registered, not yet
    made), the writer is listed with it. A writer no block reads is left out, and so is a
    retired figure (:attr:`Figure.retired`), as a judge and as a reader.

    Raises
    ------
    subprocess.CalledProcessError
        A stamp names a commit this clone does not have.
    """
    figures = [f for f in (FIGURES if figures is None else figures) if not f.retired]  # the registry as it is at the call
    readers = [f for f in (FIGURES if readers is None else readers) if not f.retired]
    out = []
    same: dict[tuple[str, str], bool] = {}  # (commit, path) -> _same_code, within this call
    for fig in figures:
        if _unmade(fig):
            out.append((fig, "", ["its block is empty"]))
            continue
        found = stamp_of(fig)
        if found is None:
            reader = _reader(fig, readers)
            if reader is not None and _unmade(reader):
                out.append((fig, "", [f"block {reader.name!r}, which reads its data, is empty"]))
                continue
            found = stamp_of(reader) if reader is not None else None
        if found is None:
            continue
        commit, uncommitted = found
        changed = []
        for f in _git("diff", "--name-only", commit, "HEAD", "--", *measured_paths(fig)).split():
            if (commit, f) not in same:
                same[commit, f] = _same_code(commit, f)
            if not same[commit, f]:
                changed.append(f)
        if uncommitted:
            changed = ["uncommitted changes", *changed]
        if changed:
            out.append((fig, commit, changed))
    return out


def _same_code(commit: str, path: str, against: str | None = "HEAD") -> bool:
    """Whether the Python file ``path`` runs the same code at ``commit`` and at ``against``
    (a revision; None: the working tree): its syntax trees without docstrings and
    command-line help texts (the string of a ``help=`` keyword) are equal (comments,
    docstrings, help and layout may differ). False for any other file, one missing at
    either, or one that does not parse."""
    import ast

    if not path.endswith(".py"):
        return False
    trees = []
    for rev in (commit, against):
        if rev is None:
            try:
                text = (REPO / path).read_text()
            except OSError:
                return False
        else:
            shown = subprocess.run(["git", "show", f"{rev}:{path}"], cwd=REPO, capture_output=True, text=True, check=False)
            if shown.returncode != 0:
                return False
            text = shown.stdout
        try:
            tree = ast.parse(text)
        except SyntaxError:
            return False
        for owner in _docstring_owners(tree):  # a module may be empty; a body may not
            owner.body = owner.body[1:] or ([] if isinstance(owner, ast.Module) else [ast.Pass()])
        for node in ast.walk(tree):
            if isinstance(node, ast.keyword) and node.arg == "help" and isinstance(node.value, (ast.Constant, ast.JoinedStr)):
                node.value = ast.Constant("")
        trees.append(ast.dump(tree))
    return trees[0] == trees[1]


def run(fig: Figure) -> bool:
    """Run one figure's command and write its block(s); False when the command failed."""
    return finish(start(fig))


@dataclass
class Job:
    """A figure's command started by :func:`start`: its process, its standard output's file
    and its start time."""

    fig: Figure
    proc: subprocess.Popen[str]
    out: IO[str]
    t0: float


def start(fig: Figure) -> Job:
    """Start ``fig``'s command (``bash -c``, from the repository root); its standard output
    goes to a temporary file, its standard error to the terminal."""
    print(f"== {fig.name}: {fig.command}", file=sys.stderr, flush=True)
    out = tempfile.TemporaryFile(mode="w+")  # noqa: SIM115 - closed by finish()
    proc = subprocess.Popen(["bash", "-c", fig.command], cwd=REPO, stdout=out, text=True)
    return Job(fig, proc, out, time.perf_counter())


def finish(job: Job) -> bool:
    """Wait for ``job`` and write its figure's block(s) from its output; False (the block
    left as it was) when the command failed."""
    fig = job.fig
    code = job.proc.wait()
    seconds = time.perf_counter() - job.t0
    job.out.seek(0)
    output = job.out.read()
    job.out.close()
    sys.stdout.write(output)
    if code != 0:
        print(f"!! {fig.name} failed (exit {code}) after {seconds:.0f} s; its block is left as it was", file=sys.stderr)
        return False
    head = stamp(fig, seconds)
    if fig.doc:
        replace_block(REPO / fig.doc, fig, block_text(fig, head, output))
    for written in fig.writes:
        if written.endswith(".md"):
            replace_block(REPO / written, fig, block_text(fig, head, ""), append=True)
    print(f"== {fig.name} done in {seconds:.0f} s", file=sys.stderr, flush=True)
    return True


#: A scratch folder named in a command (``--work /tmp/addb_bench_benchmark``, a ``git archive``
#: target): read and written by every command that names it.
_SCRATCH = re.compile(r"/tmp/[\w.-]+")
#: A data or document file named in a command, and the switches that name one it writes.
_DATA = re.compile(r"[\w./-]+\.(?:json|md)\b")
_WRITTEN = re.compile(r"--(?:json|markdown|md)\s+([\w./-]+)")


def _files(fig: Figure) -> tuple[set[str], set[str]]:
    """``(named, written)``: the data files, documents and scratch folders ``fig``'s command
    names, and those of them it writes (its ``--json``/``--markdown``/``--md`` outputs, its
    ``writes``, every scratch folder; its block's document is written by this script, not
    by the command)."""
    scratch = set(_SCRATCH.findall(fig.command))
    written = set(_WRITTEN.findall(fig.command)) | set(fig.writes) | scratch
    return set(_DATA.findall(fig.command)) | written, written


def prerequisites(chosen: list[Figure]) -> dict[str, set[str]]:
    """For each figure of ``chosen`` (in the registry's order), the earlier ones it must
    wait for: those that write a file it names (the draws a pooling block reads), and those
    that name a file it writes (it must not overwrite what they read, or share their scratch
    folder). Figures that only read the same file do not wait for each other."""
    files = {f.name: _files(f) for f in chosen}
    out: dict[str, set[str]] = {}
    for i, fig in enumerate(chosen):
        named, written = files[fig.name]
        out[fig.name] = {e.name for e in chosen[:i] if (files[e.name][1] & named) or (files[e.name][0] & written)}
    return out


def run_all(chosen: list[Figure], jobs: int = 1, poll: float = 0.5,
            gate: Callable[[Figure], bool] | None = None) -> list[str]:
    """Run ``chosen`` (in the registry's order), up to ``jobs`` accuracy figures at a time.

    A figure starts when every figure it waits for (:func:`prerequisites`) has succeeded;
    one whose prerequisite failed is not run. A timing figure runs alone: while one is
    ready, no other starts, and it starts when the others have finished (its wall times
    would otherwise measure the others' load). With ``jobs`` 1 the figures run one after
    another in the registry's order, as before this option. ``gate`` (a :class:`HostGate`)
    is asked before each timing figure starts, with nothing else running; a figure it
    refuses is not run (nor what reads its data) and counts as failed.

    Returns
    -------
    The names of the figures that failed or were not run, in the registry's order.
    """
    needs = prerequisites(chosen)
    pending = list(chosen)
    running: list[Job] = []
    done: set[str] = set()
    failed: set[str] = set()
    while pending or running:
        for job in [j for j in running if j.proc.poll() is not None]:
            running.remove(job)
            (done if finish(job) else failed).add(job.fig.name)
        for fig in [f for f in pending if needs[f.name] & failed]:
            pending.remove(fig)
            failed.add(fig.name)
            print(f"!! {fig.name} not run: it needs {', '.join(sorted(needs[fig.name] & failed))}, which did not succeed", file=sys.stderr)
        ready = [f for f in pending if needs[f.name] <= done]
        if jobs > 1 and any(f.kind == "timing" for f in ready):
            ready = [next(f for f in ready if f.kind == "timing")]  # it waits for the others to finish
        for fig in ready:
            alone = fig.kind == "timing" or jobs == 1
            if running and (alone or len(running) >= jobs or any(j.fig.kind == "timing" for j in running)):
                break
            pending.remove(fig)
            if fig.kind == "timing" and gate is not None and not gate(fig):
                failed.add(fig.name)
                break
            running.append(start(fig))
            if alone:
                break
        if running:
            time.sleep(poll)
    return [f.name for f in chosen if f.name in failed]


#: How much slower than the timing blocks' recorded host references (their median) the host
#: may run for new timing figures to be made beside them (:func:`host_check`).
HOST_SLACK = 1.15
#: The host reference's line that ``--host-reference`` ends a timing block with
#: (``bench_kinematics.host_reference_line``): the best of its runs, in seconds.
_HOST_REFERENCE = re.compile(r"^host reference, OpenSim [\d.]+ IK tool on the walk\b.*?: best (\d+(?:\.\d+)?) s\b", re.MULTILINE)
#: Times OpenSim's IK tool on the walk three times and prints the best (s), run by the venv's
#: interpreter: the measurement behind every block's host reference line.
_MEASURE_HOST = ("import sys; sys.path.insert(0, 'tests/benchmarks'); "
                 "from bench_kinematics import opensim_reference; print(min(opensim_reference(3)))")


def recorded_host_references(figures: tuple[Figure, ...] | list[Figure] | None = None) -> dict[str, float]:
    """Block name -> the best host reference time (s) its block records, for the live timing
    figures of ``figures`` (default: the registry) whose block has a host reference line."""
    found: dict[str, float] = {}
    for fig in FIGURES if figures is None else figures:
        block = _block(fig)[1] if fig.kind == "timing" and not fig.retired else None
        match = _HOST_REFERENCE.search(block) if block else None
        if match:
            found[fig.name] = float(match.group(1))
    return found


def measure_host_reference() -> float:
    """The host reference now: OpenSim's IK tool on the walk, best of 3 whole processes (s).

    Raises
    ------
    RuntimeError
        The measurement failed (OpenSim not installed in the venv: ``pip install opensim``),
        with its error output.
    """
    command = [str(REPO / PY), "-c", _MEASURE_HOST]
    try:
        done = subprocess.run(command, cwd=REPO, capture_output=True, text=True, check=False)
        return float(done.stdout.strip().splitlines()[-1])
    except OSError as err:  # no venv interpreter
        raise RuntimeError(f"could not time the host reference ({shlex.join(command)}): {err}") from None
    except (IndexError, ValueError):
        raise RuntimeError(f"could not time the host reference ({shlex.join(command)}): "
                           f"{(done.stderr.strip().splitlines() or ['no output'])[-1]}") from None


def timing_reference(chosen: list[Figure], figures: tuple[Figure, ...] | list[Figure] | None = None) -> float | None:
    """The host reference (s) timing figures made now are compared with: the median of the
    references the live timing blocks record (:func:`recorded_host_references`); None when
    ``chosen`` holds no timing figure or no block records a reference."""
    if not any(f.kind == "timing" for f in chosen):
        return None
    recorded = list(recorded_host_references(figures).values())
    return statistics.median(recorded) if recorded else None


def host_check(chosen: list[Figure], measure: Callable[[], float] | None = None,
               figures: tuple[Figure, ...] | list[Figure] | None = None) -> str | None:
    """Why timing figures should not be made on this host now, or None when they may.

    Timing figures measure wall and CPU time, which drift with the host's speed from day to
    day (tests/benchmarks/RESULTS.md); blocks made on a host slower than the others' are not
    comparable with them. When ``chosen`` holds a timing figure, the host reference is timed
    (``measure``, default :func:`measure_host_reference`: s) and compared with the median of the references the live timing blocks
    record (:func:`recorded_host_references`); slower than :data:`HOST_SLACK` times that
    median, the reason is returned. Nothing is timed when ``chosen`` holds no timing figure
    or no block records a reference.
    """
    median = timing_reference(chosen, figures)
    if median is None:
        return None
    try:
        now = (measure or measure_host_reference)()
    except RuntimeError as err:
        return f"{err}; the timing figures' host cannot be compared with their blocks'"
    print(f"host reference now {now:.2f} s; the timing blocks record {median:.2f} s (their median)", file=sys.stderr)
    if now > HOST_SLACK * median:
        return (f"the host runs {now / median:.2f}x slower than when the timing blocks were made (OpenSim's IK tool on "
                f"the walk: best {now:.2f} s now, median {median:.2f} s in their blocks; at most {HOST_SLACK:g}x): timing "
                "figures made now would not compare with the others. Run them when the host is quiet, run the accuracy "
                "figures alone (--kind accuracy), or pass --any-host and say in the document's prose which host made them")
    return None


#: A timing figure starts without the host being timed again when it was last found quick
#: less than this long before (s; :class:`HostGate`): a block of a few minutes after another.
HOST_RECHECK = 300.0
#: The pause (s) between two timings of a host found slowed (:class:`HostGate`).
HOST_PAUSE = 120.0


@dataclass
class HostGate:
    """Asked before each timing figure of a run whether the host is still quick enough.

    :func:`host_check` times the host once, before the run; over the 40 minutes of a run of
    every timing figure the host can slow (on 2026-12-02 it passed that check and then ran
    up to 1.26x slower, and one block was made at its slowest). The gate times the host
    reference again (``measure``, s) when it was last found quick more than ``recheck``
    seconds before; slower than :data:`HOST_SLACK` times ``median`` (the references the
    timing blocks recorded when the run began), it pauses ``pause`` seconds and times it
    again, for at most ``wait`` seconds in all, and then refuses the figure (its block is
    left as it was; ``--run-stale`` later makes it). A measurement that fails refuses it too.
    ``clock`` and ``sleep`` are :func:`time.monotonic` and :func:`time.sleep`, replaceable
    in tests.
    """

    median: float
    measure: Callable[[], float]
    wait: float
    pause: float = HOST_PAUSE
    recheck: float = HOST_RECHECK
    last_quick: float | None = None
    clock: Callable[[], float] = time.monotonic
    sleep: Callable[[float], None] = time.sleep

    def __call__(self, fig: Figure) -> bool:
        """True when ``fig`` may start now (after any waiting), False when it is refused."""
        if self.last_quick is not None and self.clock() - self.last_quick < self.recheck:
            return True
        deadline = self.clock() + self.wait
        limit = HOST_SLACK * self.median
        while True:
            try:
                now = self.measure()
            except RuntimeError as err:
                print(f"!! {fig.name} not run: {err}", file=sys.stderr, flush=True)
                return False
            if now <= limit:
                self.last_quick = self.clock()
                print(f"host reference now {now:.2f} s (at most {limit:.2f} s): {fig.name} starts", file=sys.stderr, flush=True)
                return True
            if self.clock() + self.pause > deadline:
                print(f"!! {fig.name} not run: the host reference is {now:.2f} s, {now / self.median:.2f}x the "
                      f"{self.median:.2f} s its blocks record (at most {HOST_SLACK:g}x), after waiting up to "
                      f"{self.wait / 60:g} min; its block is left as it was (--run-stale makes it later)",
                      file=sys.stderr, flush=True)
                return False
            print(f"host reference now {now:.2f} s, above {limit:.2f} s: waiting {self.pause:g} s before "
                  f"timing it again for {fig.name}", file=sys.stderr, flush=True)
            self.sleep(self.pause)


def main(argv: list[str] | None = None) -> int:
    """The command line (the module docstring); returns the exit code."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--list", action="store_true", help="list the figures and exit")
    ap.add_argument("--only", nargs="+", metavar="NAME", help="run only these figures (in the registry's order)")
    ap.add_argument("--kind", choices=("timing", "accuracy"), help="run only figures of this kind")
    ap.add_argument("--skip-diagnose", action="store_true", help="leave out the diagnosis figures (hours)")
    ap.add_argument("--check", action="store_true", help="check that every document has exactly the blocks of the registry")
    ap.add_argument("--stale", action="store_true", help="list the blocks made before a change to the code they measure")
    ap.add_argument("--run-stale", action="store_true",
                    help="run only the figures --stale lists (with --only/--kind/--skip-diagnose: those of them); "
                         "run again after an interruption, it goes on with the ones still stale")
    ap.add_argument("--jobs", type=int, default=1, metavar="N",
                    help="run up to N accuracy figures at a time (timing figures always alone; a figure waits for "
                         "those whose data it reads)")
    ap.add_argument("--any-host", action="store_true",
                    help="make timing figures even when the host runs slower than when their blocks were made "
                         f"(more than {HOST_SLACK:g}x their recorded host reference)")
    ap.add_argument("--host-wait", type=float, default=30.0, metavar="MINUTES",
                    help="before each timing figure, how long to wait for a slowed host to be quick again before "
                         "leaving that figure out (default 30; the host is timed again at most every "
                         f"{HOST_RECHECK / 60:g} min)")
    args = ap.parse_args(argv)
    if args.jobs < 1:
        ap.error(f"--jobs must be 1 or more, not {args.jobs}")
    retired = sum(f.retired != "" for f in FIGURES)
    if args.stale:
        found = stale()
        for fig, commit, changed in found:
            shown = ", ".join(changed[:4]) + (f" and {len(changed) - 4} more" if len(changed) > 4 else "")
            made = f"made at {commit}; changed since: {shown}" if commit else f"not made: {shown}"
            print(f"{fig.name:40s} {fig.kind:8s} {made}")
        print(f"{len(found)} of {len(FIGURES) - retired} figures made before a change to the code they measure "
              f"({retired} retired ones not judged)")
        return 0
    if args.check:
        problems = check()
        print("\n".join(problems) if problems else f"{len(FIGURES)} figures, every block in place")
        return 1 if problems else 0
    chosen = list(FIGURES)
    if args.only:
        unknown = sorted(set(args.only) - {f.name for f in FIGURES})
        if unknown:
            ap.error(f"unknown figure(s) {', '.join(unknown)}; see --list")
        chosen = [f for f in chosen if f.name in args.only]
    if args.kind:
        chosen = [f for f in chosen if f.kind == args.kind]
    if args.skip_diagnose:
        chosen = [f for f in chosen if not f.name.startswith("diagnose")]
    if not args.only:  # a retired figure runs only when named
        chosen = [f for f in chosen if not f.retired]
    if args.run_stale:
        listed = {fig.name for fig, _, _ in stale()}
        chosen = [f for f in chosen if f.name in listed]
    if args.list:
        for f in chosen:
            where = f.doc or ", ".join(f.writes) or "(data files named in the command)"
            print(f"{f.name:40s} {f.kind:8s} ~{f.minutes:g} min  {where}\n    {f.command}")
            if f.retired:
                print(f"    retired {f.retired}")
        print(f"{len(chosen)} figures, about {sum(f.minutes for f in chosen) / 60:.1f} h in all"
              + ("" if args.only else f" (and {retired} retired ones, run only when named)"))
        return 0
    reason = None if args.any_host else host_check(chosen)
    if reason:
        print(f"error: {reason}", file=sys.stderr)
        return 2
    median = None if args.any_host else timing_reference(chosen)
    gate = None
    if median is not None:
        gate = HostGate(median, measure_host_reference, 60.0 * args.host_wait,
                        last_quick=time.monotonic())  # host_check has just found it quick
    failed = run_all(chosen, args.jobs, gate=gate)
    if failed:
        print(f"failed or not run: {', '.join(failed)}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
