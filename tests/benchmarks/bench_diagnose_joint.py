"""``addb diagnose``'s benchmark with the joint mass fit in the alternation's place (run on demand).

    .venv/bin/python tests/benchmarks/bench_diagnose_joint.py [--sigma 1] -- BENCH_DIAGNOSE_ARGS ...
    .venv/bin/python tests/benchmarks/bench_diagnose_joint.py --compare DEFAULT.json ... --with JOINT.json ...

The first form runs ``tests/benchmarks/bench_diagnose.py`` with the arguments after ``--``
in this process, with :func:`solver.dynamics.fit.fit_dynamics` replaced in the dynamics
stage by :func:`solver.dynamics.joint_fit.fit_dynamics_joint` (the pipeline's default
since 2026-11-26, its ``mass_sigma`` set to ``--sigma``, default
:data:`solver.dynamics.fit.JOINT_MASS_SIGMA`) wherever the stage runs the alternation that
converges (:func:`solver.dynamics.fit.alternating_fit`, which the diagnosis judges on: the
neutral bases, every draw, and the diagnosis' own refits); the band fit is left as it is.
Everything else is the diagnosis as calibrated on the alternation
(docs/diagnose/RESULTS.md): the question is what its table becomes on the default fit,
before its rules are re-derived.

The second form compares two sets of ``--json`` results draw by draw: per cause, the draws
named within tolerance with each, and every draw whose named cause or verdict changed, and
the false alarms on the consistent synthetic trials. The second set may hold some of the
causes only (``--causes``), all their draws; ``--sigma`` then names its fit's prior.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

import solver.dynamics.stage as stage_module
from solver.dynamics.fit import JOINT_MASS_SIGMA, FitOutput, FitSettings, fit_dynamics
from solver.dynamics.joint_fit import fit_dynamics_joint


def joint_in_place(sigma: float) -> Callable[..., FitOutput]:
    """A stand-in for :func:`~solver.dynamics.fit.fit_dynamics`: the joint fit with
    ``mass_sigma=sigma`` for settings that converge (the judged alternation), the band fit otherwise."""

    def fit(build, trials, settings: FitSettings, progress=None) -> FitOutput:  # type: ignore[no-untyped-def]
        if settings.converges:
            return fit_dynamics_joint(build, trials, replace(settings, mass_fit="joint", mass_sigma=sigma), progress)
        return fit_dynamics(build, trials, settings, progress)

    return fit


def _rows(paths: list[Path]) -> tuple[dict[tuple[str, str, int], dict[str, Any]], list[dict[str, Any]]]:
    rows: dict[tuple[str, str, int], dict[str, Any]] = {}
    synthetic: list[dict[str, Any]] = []
    for p in paths:
        d = json.loads(p.read_text())
        rows.update({(r["cause"], r["trial"], r["seed"]): r for r in d["rows"]})
        synthetic += d.get("synthetic") or []
    return rows, synthetic


def compare(default: list[Path], joint: list[Path], sigma: float = JOINT_MASS_SIGMA, label: str | None = None) -> str:
    """Markdown: per cause, draws within tolerance on each fit; the draws that changed.

    ``joint`` may hold a subset of the causes of ``default`` (all their draws): the
    comparison is then on those causes alone. ``sigma`` names the joint fit's
    ``mass_sigma`` in the table's heading; ``label``, when given, names the second set of
    results there and in the false alarms' line instead (another rule or fit, as the probes'
    ``compare`` puts it: :func:`probe_rule_replay.compare`).

    Raises
    ------
    SystemExit
        ``joint`` holds a draw ``default`` has not, or leaves out a draw of a cause it holds.
    """
    a, a_syn = _rows(default)
    b, b_syn = _rows(joint)
    causes_b = {k[0] for k in b}
    a = {k: v for k, v in a.items() if k[0] in causes_b}
    if set(a) != set(b):
        raise SystemExit(f"the two sets hold different draws: {sorted(set(a) ^ set(b))[:5]} ...")
    causes = list(dict.fromkeys(k[0] for k in a))
    joint_name = label or ("joint fit (default)" if sigma == JOINT_MASS_SIGMA else f"joint fit, mass_sigma {sigma:g}")
    lines = [f"| cause | draws | within tolerance, alternation (judged fit) | within tolerance, {joint_name} |", "| --- | ---: | ---: | ---: |"]
    for c in causes:
        keys = [k for k in a if k[0] == c]
        lines.append(f"| {c} | {len(keys)} | {sum(bool(a[k]['within_tolerance']) for k in keys)} | {sum(bool(b[k]['within_tolerance']) for k in keys)} |")
    alarms = [sum(s.get("chosen") is not None for s in syn) for syn in (a_syn, b_syn)]
    lines += ["", f"False alarms on consistent synthetic trials: {alarms[0]} of {len(a_syn)} (alternation), {alarms[1]} of {len(b_syn)} ({label or 'joint fit'}).", ""]
    changed = sorted((k for k in a if (a[k]["chosen"], a[k]["within_tolerance"]) != (b[k]["chosen"], b[k]["within_tolerance"])), key=lambda k: (causes.index(k[0]), k[2]))
    lines.append(f"Draws whose verdict changed ({len(changed)} of {len(a)}; named cause, within tolerance):")
    lines.append("")
    for k in changed:
        lines.append(f"- {k[0]}, {k[1]} draw {k[2]}: {a[k]['chosen']} ({'yes' if a[k]['within_tolerance'] else 'no'}) -> {b[k]['chosen']} ({'yes' if b[k]['within_tolerance'] else 'no'})")
    return "\n".join(lines)


def main() -> None:
    argv = sys.argv[1:]
    passed = argv[argv.index("--") + 1 :] if "--" in argv else []
    own = argv[: argv.index("--")] if "--" in argv else argv
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sigma", type=float, default=JOINT_MASS_SIGMA, help="mass_sigma of the joint fit (with --compare: the one the --with results were made with, for the heading)")
    ap.add_argument("--compare", type=Path, nargs="+", help="--json results of the default fit")
    ap.add_argument("--with", dest="joint", type=Path, nargs="+", help="--json results of the joint fit")
    args = ap.parse_args(own)
    if args.compare and not args.joint:
        ap.error("--compare needs --with: the joint fit's --json results to put beside the default fit's")
    if args.compare:
        print(compare(args.compare, args.joint, args.sigma))
        return
    import bench_diagnose  # this folder

    stage_module.fit_dynamics = joint_in_place(args.sigma)  # type: ignore[assignment]
    sys.argv = [str(Path(bench_diagnose.__file__)), *passed]
    bench_diagnose.main()


if __name__ == "__main__":
    main()
