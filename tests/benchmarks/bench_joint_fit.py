"""The joint mass fit (the pipeline's default) against the alternation, on the shared subjects (run on demand).

    .venv/bin/python tests/benchmarks/bench_joint_fit.py [SUBJECT ...] [--sigma 1 ...]

For each subject (default: the Rajagopal walk and run and the OpenCap subject of
../shared/data/subjects, and the Camargo circuit, assembled by
``scripts/make_example_subject.py camargo2021_levelground``), one ``process_subject`` in
this process, into a temporary folder, with the alternation of coordinate rounds and mass
solves (:func:`solver.dynamics.fit.alternating_fit`, ``addb process --fit rounds``; the
default until 2026-11-26) and one per ``--sigma`` with the joint fit
(:func:`solver.dynamics.fit.converged_fit`, :mod:`solver.dynamics.joint_fit`, the default)
with that ``mass_sigma`` (the deviation of the anchored prior; the default's is
:data:`solver.dynamics.fit.JOINT_MASS_SIGMA`). Everything but the dynamics fit is the
pipeline's: the inverse dynamics and the metrics run on the model with the fitted masses.
BLAS runs on one thread, as in ``addb process``.

Prints a Markdown table per trial with force plates: the dynamics fit's CPU time (s, the
process' time over the fit call, every trial of the subject), its steps (the alternation:
coordinate steps of every trial, and the rounds it ran of ``rounds``; the joint fit: the
accepted steps, each over every trial, and the solves), how the fit ended ("test": the
alternation's mass factors settled within ``mass_tolerance``, or the joint fit's step
lowered the cost by less than ``tolerance``; "cap": the rounds ran out; "stalled": the joint
fit's last step found no decrease in its solves), the largest change of a body's mass
factor (per cent, relative to the masses the fit started from, on the whole-body total
the centre-of-mass fit set), measured frames, marker RMS (cm), and the linear (N) and angular
(N·m) residual RMS from the trial's results.json.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

import solver.dynamics.stage as stage_module
from solver import single_threaded_blas
from solver.dynamics.fit import (
    JOINT_MASS_SIGMA,
    FitOutput,
    alternating_fit,
    converged_fit,
    fit_dynamics,
)
from solver.dynamics.joint_fit import fit_dynamics_joint
from solver.dynamics.stage import DynamicsOptions
from solver.pipeline import ProcessOptions, process_subject
from tests.benchmarks.example_subjects import subject_folder
from tests.benchmarks.trial_results import force_trial_results


def _largest_change(build: object, factors: dict[str, float]) -> float:
    """Largest relative change of a body's mass between ``build({})`` and ``build(factors)``
    (the built models share the total mass), per cent."""
    before, after = build({}), build(factors)  # type: ignore[operator]
    m0 = {b.name: b.mass for b in before.osim.bodies}
    return max((abs(b.mass / m0[b.name] - 1.0) for b in after.osim.bodies if m0[b.name] > 0), default=0.0) * 100


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("subjects", nargs="*", default=["rajagopal2016_walk", "rajagopal2016_run", "opencap_uhlrich2023", "camargo2021_levelground"])
    ap.add_argument("--sigma", type=float, nargs="+", default=[JOINT_MASS_SIGMA], help="mass_sigma of the joint fit's prior (one row each)")
    args = ap.parse_args()
    record: dict[str, object] = {}

    def alternation(build, trials, settings, progress=None) -> FitOutput:  # type: ignore[no-untyped-def]
        said: list[str] = []
        t0 = time.process_time()
        out = fit_dynamics(build, trials, settings, progress=lambda m, f: said.append(m))
        rounds = len({m.split(",")[0] for m in said})
        stop = "cap" if rounds == settings.rounds and settings.mass_tolerance > 0 else "test"
        record.update(cpu=time.process_time() - t0, steps=f"{len(said)} ({rounds} of {settings.rounds} rounds)", stop=stop, change=_largest_change(build, out.mass_factors))
        return out

    def joint(sigma: float):  # type: ignore[no-untyped-def]
        def run(build, trials, settings, progress=None) -> FitOutput:  # type: ignore[no-untyped-def]
            said: list[str] = []
            t0 = time.process_time()
            out = fit_dynamics_joint(build, trials, settings, progress=lambda m, f: said.append(m))
            h = out.history
            last = (h[-2] - h[-1]) / h[-2] if len(h) > 1 else 0.0
            stop = "test" if last < settings.tolerance else ("cap" if len(said) == settings.rounds * settings.iterations else "stalled")
            record.update(cpu=time.process_time() - t0, steps=f"{len(h) - 1} ({len(said)} linearized)", stop=stop, change=_largest_change(build, out.mass_factors))
            return out

        return run

    print(
        "| subject / trial | fit | dynamics fit CPU (s) | steps | ended on | largest mass change (%) | measured frames "
        "| marker RMS (cm) | linear residual RMS, N | angular residual RMS, N·m |"
    )
    print("| --- | --- | ---: | --- | --- | ---: | ---: | ---: | ---: | ---: |")
    variants = [("alternation (--fit rounds)", alternating_fit(), alternation)] + [
        (f"joint, mass_sigma {s:g}" + (" (default)" if s == JOINT_MASS_SIGMA else ""), converged_fit(mass_sigma=s), joint(s)) for s in args.sigma
    ]
    with tempfile.TemporaryDirectory() as tmp, single_threaded_blas():
        for name in args.subjects:
            subject = subject_folder(name, Path(tmp))
            for i, (label, settings, fit) in enumerate(variants):
                out = Path(tmp) / f"{name}_{i}"
                stage_module.fit_dynamics, stage_module.fit_dynamics_joint = fit, fit  # type: ignore[assignment]
                try:
                    process_subject(subject, out, options=ProcessOptions(dynamics=DynamicsOptions(fit=settings)))
                finally:
                    stage_module.fit_dynamics, stage_module.fit_dynamics_joint = fit_dynamics, fit_dynamics_joint
                for trial, r in force_trial_results(out):
                    print(
                        f"| {name} / {trial} | {label} | {record['cpu']:.2f} | {record['steps']} | {record['stop']} "
                        f"| {record['change']:.1f} | {r['n_observed_frames']} | {r['marker_rms_m'] * 100:.3f} "
                        f"| {r['linear_residual_rms_N']:.2f} | {r['angular_residual_rms_Nm']:.2f} |",
                        flush=True,
                    )


if __name__ == "__main__":
    main()
