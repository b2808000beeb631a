"""Probe: the plates' registration judged on the marker-only motion with a smaller share of the cost.

    .venv/bin/python tests/benchmarks/probe_registration_gain.py [--gain 0.05] [--after-bases] -- BENCH_DIAGNOSE_ARGS ...
    .venv/bin/python tests/benchmarks/probe_registration_gain.py [--gain 0.05] --compare TABLE.json ... --with PROBE.json ...

Not a change of ``addb diagnose``. The first form runs ``tests/benchmarks/bench_diagnose.py``
(the diagnosis' benchmark, judged on the alternation as ``addb diagnose`` judges) with one
threshold changed where the force-side causes are compared on the marker-only motion
(:func:`solver.diagnose.core.choice_on_marker_motion`): ``plate_registration`` is named there
when it removes ``--gain`` of its channels' held-out cost instead of
:attr:`solver.diagnose.selection.ChoiceRule.min_relative_gain` (0.10); every other check, and
the threshold on the fitted motion, as they are. Why (tests/benchmarks/RESULTS.md, block
``diagnose-run-registration-probe``): on the treadmill run's marker-only motion, whose
inertial noise holds most of the cost, hidden registrations of 1.3-1.5 cm and 0.8-2 degrees
stand out from every rival and improve every fold but remove 5.0-8.7 % of the cost, and the
run names nothing in 8 of its 20 registration draws. The second form compares the probe's
``--json`` results with the table's draw by draw (the same seeds): per cause the draws within
tolerance, every draw whose named cause or verdict changed, and the false alarms.

The benchmark builds its neutral bases (each trial with its own findings applied,
:func:`tests.diagnose.harness.neutral_base`) in the same process, so the changed threshold
also decides which of the trial's own findings the base applies first; ``--after-bases``
builds them under the rule as it is (the table's bases) and changes the threshold for the
draws only.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_diagnose_joint import _rows  # this folder

from solver.diagnose import core

CAUSE = "plate_registration"


def apply(gain: float, after_bases: bool = False) -> None:
    """Judge ``CAUSE`` on the marker-only motion with relative gain ``gain`` (this process);
    with ``after_bases``, not while :func:`bench_diagnose.neutral_base` builds a base."""
    original = core.choice_on_marker_motion

    def on_marker_motion(chosen, evaluations_ik, rule, blocks, kept=None, own_noise=None):  # type: ignore[no-untyped-def]
        rule = replace(rule, relative_gain_of={**rule.relative_gain_of, CAUSE: gain})
        return original(chosen, evaluations_ik, rule, blocks, kept, own_noise)

    core.choice_on_marker_motion = on_marker_motion  # type: ignore[assignment]
    if after_bases:
        import bench_diagnose  # this folder

        build = bench_diagnose.neutral_base

        def neutral_base(*args, **kwargs):  # type: ignore[no-untyped-def]
            core.choice_on_marker_motion = original
            try:
                return build(*args, **kwargs)
            finally:
                core.choice_on_marker_motion = on_marker_motion  # type: ignore[assignment]

        bench_diagnose.neutral_base = neutral_base


def compare(table: list[Path], probe: list[Path], gain: float) -> str:
    """Markdown: the probe's draws against the same draws of the table.

    Raises
    ------
    SystemExit
        The probe holds a draw the table has not.
    """
    a, a_syn = _rows(table)
    b, b_syn = _rows(probe)
    if not set(b) <= set(a):
        raise SystemExit(f"draws the table has not: {sorted(set(b) - set(a))[:5]}")
    causes = list(dict.fromkeys(k[0] for k in b))
    lines = [f"| cause | draws | within tolerance, the table | within tolerance, registration at {100 * gain:g} % on the marker-only motion |",
             "| --- | ---: | ---: | ---: |"]  # fmt: skip
    for c in causes:
        keys = [k for k in b if k[0] == c]
        lines.append(f"| {c} | {len(keys)} | {sum(bool(a[k]['within_tolerance']) for k in keys)} | {sum(bool(b[k]['within_tolerance']) for k in keys)} |")
    pairs = {(s["trial"], s["seed"]): s for s in a_syn}
    same = [pairs[(s["trial"], s["seed"])] for s in b_syn if (s["trial"], s["seed"]) in pairs]
    named = [sum(s.get("chosen") is not None for s in syn) for syn in (same, b_syn)]
    lines += ["", f"False alarms on consistent synthetic trials: {named[0]} of {len(same)} (the table), {named[1]} of {len(b_syn)} (probe).", ""]
    changed = [k for k in b if (a[k]["chosen"], a[k]["within_tolerance"]) != (b[k]["chosen"], b[k]["within_tolerance"])]
    lines += [f"Draws whose verdict changed ({len(changed)} of {len(b)}; named cause, within tolerance):", ""]
    for k in sorted(changed, key=lambda k: (causes.index(k[0]), k[2])):
        yes = ["yes" if r[k]["within_tolerance"] else "no" for r in (a, b)]
        lines.append(f"- {k[0]}, {k[1]} draw {k[2]}: {a[k]['chosen']} ({yes[0]}) -> {b[k]['chosen']} ({yes[1]})")
    return "\n".join(lines)


def main() -> None:
    """The two forms of the module docstring."""
    argv = sys.argv[1:]
    cut = argv.index("--") if "--" in argv else len(argv)
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--gain", type=float, default=0.05, help="relative gain that names the registration on the marker-only motion")
    ap.add_argument("--compare", type=Path, nargs="+", help="--json results of the table (bench_diagnose.py)")
    ap.add_argument("--with", dest="probe", type=Path, nargs="+", help="--json results of this probe")
    ap.add_argument("--after-bases", action="store_true", help="build the neutral bases under the rule as it is; the gain for the draws only")
    args = ap.parse_args(argv[:cut])
    if not args.compare:
        import bench_diagnose  # this folder

        apply(args.gain, args.after_bases)
        sys.argv = [str(Path(bench_diagnose.__file__)), *argv[cut + 1 :]]
        bench_diagnose.main()
    elif not args.probe:
        ap.error("--compare needs --with")
    else:
        print(compare(args.compare, args.probe, args.gain))


if __name__ == "__main__":
    main()
