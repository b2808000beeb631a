"""What ``addb diagnose`` finds on the unmodified real subjects of ../shared/data/subjects.

For each trial with force plates, on a writable copy of its subject: diagnose, and while a
cause stands out, apply it (``--apply``) and diagnose the reprocessed subject again (at
most ``--rounds`` rounds). Prints (and with ``--markdown`` writes) each round's four
best-scoring candidates, and the named one when it is not among them (a marker offset is
scored on its marker's own error), each with its estimate, uncertainty and held-out gain;
the metrics before and after; and the final verdict. ``--json`` keeps every report.

Run::

    .venv/bin/python tests/benchmarks/findings_diagnose.py --rounds 4 \
        --markdown docs/diagnose/findings_runs.md --json docs/diagnose/findings.json
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from solver.diagnose.report import _fmt_params, held_out_labels, metric_row
from tests.conftest import SHARED_DATA
from tests.diagnose.effects import copy_subject
from tests.diagnose.harness import TRIALS, diagnose_json


def findings(key: str, work: Path, rounds: int) -> list[dict[str, Any]]:
    folder, trial = TRIALS[key]
    src = SHARED_DATA / "subjects" / folder
    keep = tuple(t.name for t in (src / "trials").iterdir() if t.name == trial or not (t / "grf.mot").exists())
    subject = copy_subject(src, work / key, keep)
    reports = []
    for _ in range(rounds):
        shutil.rmtree(subject / "addb_out", ignore_errors=True)
        report = diagnose_json(subject, trial, "--apply")
        reports.append(report)
        if report["chosen"] is None:
            break
    return reports


def _candidate_line(c: dict[str, Any]) -> str:
    """One candidate: cause, score, held-out gain, estimate ± standard error."""
    return f"{c['cause']:<26s} score {c['score']:10.0f}  gain {100 * (c['gain'] or 0):5.1f}%  {_fmt_params(c['cause'], c['parameters'], c['uncertainty'])}"


def _named_candidate(report: dict[str, Any]) -> dict[str, Any] | None:
    """The candidate the report names (its cause and parameters), or None."""
    return next(
        (c for c in report["candidates"] if c["cause"] == report["chosen"] and c["parameters"] == report.get("chosen_parameters")),
        None,
    )


def markdown(all_reports: dict[str, list[dict[str, Any]]], command: str) -> str:
    lines = ["# Findings on the unmodified real trials (raw runs)", "", f"Made by `{command}`.", ""]
    for key, reports in all_reports.items():
        folder, trial = TRIALS[key]
        lines += [f"## {folder} / {trial}", ""]
        for i, r in enumerate(reports, 1):
            a = r["analysis"]["over_time"]
            lines.append(f"Round {i}: residual force RMS {a['linear_rms_N']:.1f} N, moment RMS {a['angular_rms_Nm']:.1f} N·m on the evaluated frames.")
            lines.append("")
            lines.append("```")
            for c in r["candidates"][:4]:
                lines.append(_candidate_line(c))
            named = _named_candidate(r)
            if named is not None and named not in r["candidates"][:4]:  # e.g. a marker offset, scored on its marker's own error
                lines.append(_candidate_line(named) + f"  (named; number {r['candidates'].index(named) + 1} by score)")
            lines.append("```")
            lines.append("")
            lines.append(r["reason"])
            if r["chosen"]:
                lines.append("")
                lines.append("```")
                lines.append(metric_row("before (processed)", r["baseline"]).strip())
                lines.append(metric_row("before (refit, none)", r.get("before_refit")).strip())
                lines.append(metric_row("after (refit)", r["after"]).strip())
                if r.get("held_out"):
                    before, after = held_out_labels(r["held_out"])
                    lines.append(metric_row(before, r["held_out"]["before"]).strip())
                    lines.append(metric_row(after, r["held_out"]["after"]).strip())
                lines.append("```")
            lines.append("")
    return "\n".join(lines) + "\n"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--trials", default=",".join(TRIALS))
    p.add_argument("--rounds", type=int, default=4)
    p.add_argument("--json", type=Path)
    p.add_argument("--markdown", type=Path)
    args = p.parse_args()
    work = Path(tempfile.mkdtemp(prefix="addb-findings-"))
    try:
        out = {}
        for key in args.trials.split(","):
            out[key] = findings(key, work, args.rounds)
            print(f"{key}: " + " -> ".join(str(r["chosen"]) for r in out[key]), flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    text = markdown(out, "python tests/benchmarks/findings_diagnose.py " + " ".join(sys.argv[1:]))
    print(text)
    if args.json:
        args.json.write_text(json.dumps(out, indent=1) + "\n")
    if args.markdown:
        args.markdown.write_text(text)


if __name__ == "__main__":
    main()
