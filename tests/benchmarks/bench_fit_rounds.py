"""Rounds and step direction of the alternating dynamics fit: what other settings change (run on demand).

    .venv/bin/python tests/benchmarks/bench_fit_rounds.py [--rounds 4 6 8] [--direction band exact coefficients]
        [--round-tolerance default none 1e-3 ...] [SUBJECT ...]

The dynamics fit alternates ``FitSettings.rounds`` rounds (default 4) of at most
``FitSettings.iterations`` Gauss-Newton steps of the coordinates with a linear solve of the
body mass factors, and stops early on a relative cost decrease under
``FitSettings.tolerance``. ``FitSettings.direction`` says how a step is found: ``band``
(default; the derivative operators truncated to ``band`` frames in the Jacobian and its
gradient), ``exact`` (the exact gradient and Gauss-Newton system, by preconditioned
conjugate gradients) or ``coefficients`` (exact banded steps in the spline's coefficients,
run as ``alternating_fit(rounds=R)``: R is then the most rounds, which stop when the mass
factors settle; what ``addb process --fit rounds`` runs, with R = 4, and ``addb process``
by default until 2026-11-26, when the joint fit replaced it: tests/benchmarks/bench_joint_fit.py).
``--round-tolerance`` gives the ``coefficients`` rows' ``FitSettings.round_tolerance`` (the
looser stop of the rounds while the masses move): ``default`` is :func:`alternating_fit`'s, ``none`` stops every
round on ``tolerance``; one row per value. For each subject (default: the Rajagopal walk and run of
../shared/data/subjects and the Camargo circuit, assembled by
``scripts/make_example_subject.py camargo2021_levelground``) and each pair of round count
and direction, one
``process_subject(SUBJECT, OUT, options=ProcessOptions(dynamics=DynamicsOptions(fit=FitSettings(rounds=R, direction=D))))``
in this process, into a temporary folder. Prints a Markdown table per trial with force
plates: wall time of the whole ``process_subject`` (s), the dynamics fit's own time (s),
Gauss-Newton steps taken (every trial's), measured frames, marker RMS (cm), linear residual RMS and mean
(N) and angular residual RMS (N·m), from the trial's results.json.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

import solver.dynamics.fit as fit_module
from solver.dynamics.fit import FitSettings, alternating_fit
from solver.dynamics.stage import DynamicsOptions
from solver.pipeline import ProcessOptions, process_subject
from tests.benchmarks.example_subjects import subject_folder
from tests.benchmarks.trial_results import force_trial_results


def _variants(directions: list[str], rounds: list[int], round_tolerances: list[str]) -> list[tuple[str, int, str]]:
    """(direction, rounds, round tolerance) of every row of a subject; the round tolerance
    varies on ``coefficients`` rows only (the others stop every round on ``tolerance``)."""
    return [(d, r, t) for d in directions for r in rounds for t in (round_tolerances if d == "coefficients" else ["-"])]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("subjects", nargs="*", default=["rajagopal2016_walk", "rajagopal2016_run", "camargo2021_levelground"])
    ap.add_argument("--rounds", type=int, nargs="+", default=[4, 6])
    ap.add_argument("--direction", nargs="+", default=["band", "exact", "coefficients"], choices=["band", "exact", "coefficients"])
    ap.add_argument("--round-tolerance", nargs="+", default=["default"], help="coefficients only: default, none or a number")
    args = ap.parse_args()
    steps = [0]
    step = fit_module._TrialProblem.step

    def counted(self, *a, **k):
        steps[0] += 1
        return step(self, *a, **k)

    fit_module._TrialProblem.step = counted  # type: ignore[method-assign]
    print(
        "| subject / trial | direction | rounds | round tolerance | wall (s) | dynamics fit (s) | steps | measured frames | marker RMS (cm) "
        "| linear residual RMS (mean), N | angular residual RMS, N·m |"
    )
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- | ---: |")
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.subjects:
            subject = subject_folder(name, Path(tmp))
            for direction, rounds, rtol in _variants(args.direction, args.rounds, args.round_tolerance):
                out = Path(tmp) / f"{name}_{direction}_{rounds}_{rtol}"
                if direction != "coefficients":
                    fit = FitSettings(rounds=rounds, direction=direction)
                elif rtol == "default":
                    fit = alternating_fit(rounds=rounds)
                else:
                    fit = alternating_fit(rounds=rounds, round_tolerance=None if rtol == "none" else float(rtol))
                rt = "-" if fit.round_tolerance is None else f"{fit.round_tolerance:g}"
                options = ProcessOptions(dynamics=DynamicsOptions(fit=fit))
                steps[0] = 0
                t0 = time.perf_counter()
                process_subject(subject, out, options=options)
                wall = time.perf_counter() - t0
                fit_s = (json.loads((out / "subject.json").read_text()).get("dynamics_seconds") or {}).get("dynamics_fit", float("nan"))
                for trial, r in force_trial_results(out):
                    print(
                        f"| {name} / {trial} | {direction} | {rounds} | {rt} | {wall:.1f} | {fit_s:.1f} | {steps[0]} "
                        f"| {r['n_observed_frames']} "
                        f"| {r['marker_rms_m'] * 100:.3f} | {r['linear_residual_rms_N']:.2f} ({r['linear_residual_mean_N']:.2f}) "
                        f"| {r['angular_residual_rms_Nm']:.2f} |",
                        flush=True,
                    )


if __name__ == "__main__":
    main()
