"""Why ``marker_offset`` draws of the diagnosis benchmark are missed: for each draw, the hidden
marker's candidate as the diagnosis sees it.

For draws ``--first`` .. ``--first + --draws - 1`` of ``marker_offset`` (the benchmark's draws,
:func:`tests.diagnose.harness.draw`: all on the walk), hidden in a copy of the walk's neutral
base (:func:`tests.diagnose.harness.neutral_base`), processed, then diagnosed in-process with
the refit off (naming does not depend on it): the hidden shift |s| (cm), the chosen cause and
marker, and for the hidden marker on the fitted motion the part of the shift its own error
shows (``visible_shift_m``, what is judged worth naming against 0.5 cm) and its share of |s|,
the shift beyond the fitted offset (``residual_shift_m``), the fraction of held-out folds it
improves, its significance (jackknife standard errors) and whether it contends; when the
hidden marker is named, the error of its misplacement estimate against the hidden shift
(relative to the base's own estimate, :func:`tests.diagnose.effects.error`; tolerance 0.5 cm)
and the part of the estimate the scale fit had taken up (``landmark_shift_m``).

    .venv/bin/python tests/benchmarks/probe_marker_draws.py [--draws 20] [--first 0] [--work DIR]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from solver.diagnose.core import DiagnoseOptions, diagnose_trial
from solver.diagnose.selection import ChoiceRule, contends, significance
from tests.diagnose.effects import check, copy_subject, hide
from tests.diagnose.harness import diagnose_json, draw, probe_walk_base


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--draws", type=int, default=20)
    p.add_argument("--first", type=int, default=0)
    p.add_argument("--work", type=Path, default=None, help="working folder (default: a temporary one)")
    args = p.parse_args()
    work, base = probe_walk_base(args.work, "addb_probe_markers_")
    rule = ChoiceRule()
    print(
        "| draw | hidden marker | hidden |s| (cm) | chosen | visible (cm) | visible share | beyond fitted offset (cm) "
        "| folds improved | standard errors | contends | estimate error (cm) | taken up by scaling (cm) |"
    )
    print("|---:|---|---:|---|---:|---:|---:|---:|---:|---|---:|---:|")
    for index in range(args.first, args.first + args.draws):
        _, seed = draw("marker_offset", index)
        dst = work / f"draw-{seed}"
        subject = copy_subject(base.subject, dst)
        hidden = hide("marker_offset", subject, base.trial, seed, base.processed)
        with contextlib.redirect_stderr(io.StringIO()):
            report = diagnose_json(subject, base.trial, "--no-refit")  # processes the copy
            diag = diagnose_trial(subject, base.trial, subject / "addb_out", options=DiagnoseOptions(refit=False))
        chosen = report["chosen"] or "none"
        if report["chosen"] == "marker_offset":
            chosen += f" {report['chosen_parameters']['marker']}"
        size = float(np.linalg.norm(hidden.truth["shift_m"]))
        ev = next((e for e in diag.evaluations if e.cause == "marker_offset" and e.choice == hidden.choice), None)
        res = check(hidden, report, base.report)
        named = res["detected"] and res.get("error") is not None
        err = f"{100 * res['error']:.2f}" if named else ""
        scaled = f"{100 * np.linalg.norm(report['chosen_parameters'].get('landmark_shift_m', [0.0] * 3)):.2f}" if named else ""
        if ev is None:
            print(f"| {seed} | {hidden.choice} | {100 * size:.2f} | {chosen} | (not evaluated) | | | | | | {err} | {scaled} |")
            continue
        visible = float(np.linalg.norm(ev.parameters["visible_shift_m"]))
        residual = float(np.linalg.norm(ev.parameters["residual_shift_m"]))
        folds = float(np.mean(np.asarray(ev.fold_gains) > 0))
        print(
            f"| {seed} | {hidden.choice} | {100 * size:.2f} | {chosen} | {100 * visible:.2f} | {visible / size:.0%} | "
            f"{100 * residual:.2f} | {folds:.0%} | {significance(ev):.1f} | {'yes' if contends(ev, rule) else 'no'} | {err} | {scaled} |",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
