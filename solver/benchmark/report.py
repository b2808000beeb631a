"""The benchmark's table (the paper's layout: one row per method, the four metrics as
columns) as JSON and Markdown, and the dataset summary printed beside it.

The paper's numbers (Werling et al. 2024, §5, on its own test set of the AddBiomechanics
Dataset, ~20x more subjects and thousands of times more frames than a lab's handful) are
context, never targets: :data:`PAPER` keeps them in the order and units the project's
issue quotes them.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from solver.benchmark.dataset import Dataset
from solver.benchmark.evaluate import contact_phases
from solver.benchmark.metrics import METRICS, TITLES
from solver.benchmark.run import BenchmarkResult

#: The paper's test-set errors, as the issue quotes them (CoM acc. m/s², joint torque
#: N·m/kg, GRM N·m/kg, GRF N/kg; the two N·m/kg columns assigned by that order).
PAPER = {
    "analytical": {"com_acc": 4.47, "torque": 2.77, "grm": 6.15, "grf": 2.79},
    "MLP": {"com_acc": 1.41, "torque": 1.33, "grm": 0.03, "grf": 1.29},
}

PAPER_CAVEAT = (
    "The paper's numbers come from its own test split of the AddBiomechanics Dataset (273 subjects, "
    "over 70 hours, millions of test frames, many activities); ours from a handful of subjects and "
    "a few thousand frames. They are context, not targets."
)

#: What each row of the table is, printed under the Markdown table for the rows present.
ROW_NOTES = {
    "analytical (measured contact)": (
        "the paper's analytical baseline handed the force plates' contact state (which foot is loaded): "
        "information a motion-only method does not have, so a reference rather than a competitor"
    ),
    "analytical (kinematic contact)": (
        "the analytical baseline from the motion alone: a foot is in contact within 0.1 m of its own lowest "
        "point in 0.5 s (the paper's code uses a 0.1 m foot-height rule)"
    ),
    "MLP": "the paper's MLP baseline: per-foot wrenches predicted directly from a 50-frame history",
    "hybrid (analytical force, MLP contact split)": (
        "not one of the paper's baselines: the analytical total force, from q̃ low-passed at a cut-off chosen "
        "on the training subjects, split between the feet by a network of the MLP's shape that sees per-foot "
        "heights and velocities (solver/benchmark/hybrid.py); motion only"
    ),
}


def dataset_summary(dataset: Dataset, *, activities: dict[str, float] | None = None) -> dict[str, Any]:
    """Size and composition of the scored dataset.

    Parameters
    ----------
    dataset
        The benchmark dataset.
    activities
        Activity label -> seconds annotated (from the review records); None when no
        subject has annotations.

    Returns
    -------
    dict
        ``subjects``, ``trials``, ``frames`` (benchmark frames), ``hours``, ``phases``
        (shares of flight / single / double support), ``hicks_pass_rate`` (share of trials
        meeting both Hicks thresholds; None if unknown), ``activities_s``, ``skipped``.
    """
    frames = dataset.n_frames
    known = [t.hicks_ok for t in dataset.trials if t.hicks_ok is not None]
    return {
        "subjects": dataset.subjects,
        "trials": [f"{t.subject}/{t.trial}" for t in dataset.trials],
        "frames": frames,
        "hours": frames / 100.0 / 3600.0,
        "phases": contact_phases(dataset.trials),
        "hicks_pass_rate": (sum(known) / len(known)) if known else None,
        "activities_s": activities,
        "skipped": [f"{s.subject}/{s.trial}: {s.reason}" for s in dataset.skipped],
        "inputs": sorted({t.inputs for t in dataset.trials}),
    }


def _num(x: float) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.2f}"


def table_rows(result: BenchmarkResult) -> list[list[str]]:
    """Rows [method, frames, four metrics] as text (2 decimals)."""
    return [[r.method, str(r.n_frames)] + [_num(r.metrics[k]) for k in METRICS] for r in result.rows]


def table_header() -> list[str]:
    """Column titles of :func:`table_rows`."""
    return ["method", "frames"] + [TITLES[k] for k in METRICS]


def to_json(result: BenchmarkResult, summary: dict[str, Any], *, command: str = "") -> dict[str, Any]:
    """The whole report as a JSON-serializable dict."""
    return {
        "schema": "addb.benchmark",
        "version": 1,
        "command": command,
        "protocol": result.protocol,
        "test_subjects": list(result.test_subjects),
        "units": METRICS,
        "rows": [
            {
                "method": r.method,
                "frames": r.n_frames,
                **r.metrics,
                "seconds": r.seconds,
                "per_trial": r.per_trial,
                "notes": r.notes,
            }
            for r in result.rows
        ],
        "dataset": summary,
        "paper": {"rows": PAPER, "caveat": PAPER_CAVEAT},
    }


def _md_table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join("---" for _ in header) + " |"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def summary_lines(summary: dict[str, Any]) -> list[str]:
    """The dataset summary as short lines of text."""
    p = summary["phases"]
    hicks = summary["hicks_pass_rate"]
    acts = summary["activities_s"]
    lines = [
        (
            f"subjects: {len(summary['subjects'])} ({', '.join(summary['subjects'])}); trials: {len(summary['trials'])}; "
            f"inputs: {', '.join(summary['inputs'])}"
        ),
        f"benchmark frames: {summary['frames']} ({summary['hours'] * 3600:.1f} s = {summary['hours']:.4f} h at 100 Hz)",
        (
            f"contact: single support {100 * p['single_support']:.1f} %, double support {100 * p['double_support']:.1f} %, "
            f"flight {100 * p['flight']:.1f} %"
        ),
        "Hicks pass rate (both thresholds): " + ("unknown" if hicks is None else f"{100 * hicks:.0f} % of trials"),
        "activities (annotations): "
        + ("none annotated" if not acts else ", ".join(f"{k} {v:.1f} s" for k, v in sorted(acts.items()))),
    ]
    if summary["skipped"]:
        lines.append("skipped trials: " + "; ".join(summary["skipped"]))
    return lines


def to_markdown(result: BenchmarkResult, summary: dict[str, Any], *, command: str = "", paper: bool = True) -> str:
    """The table, protocol and dataset summary as Markdown (with the paper's numbers)."""
    out = []
    if command:
        out += [f"`{command}`", ""]
    out += [_md_table(table_header(), table_rows(result)), "", f"Protocol: {result.protocol}.", ""]
    notes = [f"* {r.method}: {ROW_NOTES[r.method]}" for r in result.rows if r.method in ROW_NOTES]
    if notes:
        out += ["Rows:", "", *notes, ""]
    out += [f"* {line}" for line in summary_lines(summary)]
    if paper:
        rows = [[f"{name} (paper)", "-"] + [_num(v[k]) for k in METRICS] for name, v in PAPER.items()]
        out += ["", "For context, the paper's test-set errors:", "", _md_table(table_header(), rows), "", PAPER_CAVEAT]
    return "\n".join(out) + "\n"


def write_report(folder: str | Path, result: BenchmarkResult, summary: dict[str, Any], *, command: str = "") -> tuple[Path, Path]:
    """Write ``benchmark.json`` and ``benchmark.md`` into ``folder``; returns both paths."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    js, md = folder / "benchmark.json", folder / "benchmark.md"
    js.write_text(json.dumps(to_json(result, summary, command=command), indent=2, allow_nan=True) + "\n")
    md.write_text(to_markdown(result, summary, command=command))
    return js, md
