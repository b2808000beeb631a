"""The trial's diagnosis in the review app: what ``addb diagnose`` found, and what is applied.

Reads two files and turns them into the markdown of the panel's "Diagnosis" folder:

* ``OUT/<trial>/diagnosis.json`` (written by ``addb diagnose``, schema ``addb.diagnosis``):
  the chosen cause (or that none stands out), its estimate, the best-ranked candidates,
  the other marker offsets that stand out on their own markers' errors, and the metrics
  before and after the extension;
* ``<subject>/addb_extensions.json`` (written by ``addb diagnose --apply``): the
  extensions the processing applies to this trial (and to the whole subject).

A missing file shows a hint instead; a damaged one shows what is wrong with it. Nothing
here raises: the review goes on whatever these files hold.
"""

from __future__ import annotations

import html
import json
import os
from pathlib import Path
from typing import Any

from solver.dataset.summary import dynamics_error_message
from solver.diagnose.report import (
    STANDING_OUT_HEADING,
    candidate_line,
    held_out_labels,
    metric_row,
    standing_out_line,
)

DIAGNOSIS_FILE = "diagnosis.json"

#: Candidates listed under the chosen cause.
SHOWN_CANDIDATES = 4


def _read_json(path: Path) -> tuple[Any, str | None]:
    try:
        return json.loads(path.read_text(encoding="utf-8")), None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        return None, f"`{path.name}` cannot be read ({type(exc).__name__}: {exc})"


def _applied(subject_dir: Path, trial: str) -> list[str]:
    """One line per saved extension that acts on ``trial`` (or on the whole subject)."""
    from solver.corrections import extensions_path, read_extensions
    from solver.errors import SubjectFolderError

    if not extensions_path(subject_dir).is_file():
        return []
    try:
        exts = read_extensions(subject_dir)
    except SubjectFolderError as exc:
        return [f"the extensions file is damaged: {exc}"]
    lines = []
    for e in exts:
        if e.get("trial") not in (None, trial):
            continue
        detail = {k: v for k, v in e.items() if k not in ("cause", "trial", "time_s", "lab_shift_m", "source", "created", "frames", "n_frames")}
        scope = "this trial" if e.get("trial") else "every trial"
        lines.append(f"`{e['cause']}` ({scope}): {json.dumps(detail)[:160]}")
    return lines


def kept_reports(out_dir: str | Path, trials: list[str] | tuple[str, ...]) -> dict[str, tuple[bytes, int]]:
    """The diagnosis reports of ``trials`` (content and modification time, ns), read before
    a Reprocess replaces their folders (the solver writes a trial's folder anew, without
    the report): :func:`restore_reports` puts them back after it."""
    kept = {}
    for trial in trials:
        path = Path(out_dir) / trial / DIAGNOSIS_FILE
        try:
            kept[trial] = (path.read_bytes(), path.stat().st_mtime_ns)
        except OSError:
            continue
    return kept


def restore_reports(out_dir: str | Path, kept: dict[str, tuple[bytes, int]]) -> None:
    """Put back the reports :func:`kept_reports` read, with their old modification times
    (so :func:`diagnosis_markdown` says they were made on earlier results), where the trial's
    folder has no report now. The evidence behind a correction applied from the page stays."""
    for trial, (data, mtime_ns) in kept.items():
        path = Path(out_dir) / trial / DIAGNOSIS_FILE
        if path.parent.is_dir() and not path.exists():
            try:
                path.write_bytes(data)
                os.utime(path, ns=(mtime_ns, mtime_ns))
            except OSError:
                continue


def diagnosis_markdown(out_dir: str | Path, subject_dir: str | Path, trial: str) -> str:
    """Markdown of the "Diagnosis" folder for ``trial``.

    Parameters
    ----------
    out_dir
        The subject's processed output folder.
    subject_dir
        The subject folder (its ``addb_extensions.json``).
    trial
        Trial name.

    Returns
    -------
    str
        Never raises for missing or damaged files (they are described instead).
    """
    path = Path(out_dir) / trial / DIAGNOSIS_FILE
    blocks: list[str] = []
    if not path.is_file():
        results, _ = _read_json(path.with_name("results.json"))
        if isinstance(results, dict) and "n_observed_frames" not in results:  # the dynamics stage did not run
            failed = dynamics_error_message(results)
            why = f"its dynamics failed: {failed}" if failed else "no force plates"
            blocks.append(f"{trial} has no dynamics ({html.escape(str(why), quote=False)}): nothing to diagnose.")
        else:
            blocks.append(f"Not diagnosed yet: press **Diagnose this trial** (or run `addb diagnose {Path(subject_dir).name} --trial {trial}`).")
    else:
        report, problem = _read_json(path)
        if problem is not None or not isinstance(report, dict) or report.get("schema") != "addb.diagnosis":
            blocks.append(problem or f"`{path.name}` is not an addb diagnosis")
        else:
            results = path.with_name("results.json")
            if results.is_file() and results.stat().st_mtime_ns > path.stat().st_mtime_ns:
                blocks.append(
                    "<span style='color:#c00'>**Made on earlier results**</span> (the trial was reprocessed "
                    "since): press **Diagnose this trial** for the current ones."
                )
            blocks += _report_blocks(report)
    applied = _applied(Path(subject_dir), trial)
    if applied:
        blocks.append("**Applied by `addb diagnose --apply`** (used by the next processing):")
        blocks.append("\n".join(f"- {a}" for a in applied))
    return "\n\n".join(blocks)


def _listed(lines: Any) -> str:
    """Text lines of the CLI's report as a markdown list that wraps in the narrow panel (a
    code block kept their columns but ran 700-1,800 px wide in a 262 px box, the numbers
    off to the right): runs of spaces collapsed, underscores escaped."""
    return "\n".join("- " + " ".join(str(line).split()).replace("_", "\\_") for line in lines)


def _report_blocks(report: dict[str, Any]) -> list[str]:
    chosen = report.get("chosen")
    blocks = [f"**Chosen cause: `{chosen}`**" if chosen else "**No cause stands out.**", str(report.get("reason", ""))]
    judged = (report.get("settings") or {}).get("judged_fit") or {}
    if judged.get("rebuilt"):  # as `addb diagnose` prints it: its figures are not the page's
        blocks.append(
            f"Judged on the `{judged.get('fit')}` dynamics fit the diagnosis is calibrated on, run again for it: "
            f"the trial was processed with the `{judged.get('processed_fit')}` fit, so the figures below differ "
            "from the page's and results.json's."
        )
    candidates = report.get("candidates") or []
    if candidates:
        blocks.append("Candidates (held-out evidence):")
        blocks.append(_listed(candidate_line(c) for c in candidates[:SHOWN_CANDIDATES]))
    others = report.get("also_standing_out") or []
    if others:
        blocks.append(STANDING_OUT_HEADING)
        blocks.append(_listed(standing_out_line(e) for e in others))
    if chosen:
        held = report.get("held_out") or {}
        rows = [
            metric_row("before", report.get("baseline")),
            metric_row("before (refit, none)", report.get("before_refit")),
            metric_row("after (refit)", report.get("after")),
        ]
        if held:
            before, after = held_out_labels(held)
            rows += [metric_row(before, held.get("before")), metric_row(after, held.get("after"))]
        blocks.append("Before and after the extension:")
        blocks.append(_listed(rows))
        if held.get("note"):
            blocks.append(f"Held-out figures: {held['note']}.")
    return blocks
