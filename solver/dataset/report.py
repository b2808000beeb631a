"""``dataset_report.html``: the summary of a dataset run as one static page.

Opens from disk without a server or a network: the figures are inline SVG (bar charts
drawn here from the summary's counts), no scripts. Sections: dataset totals in the
paper's terms, failures (subject, error, file and line), the subjects' warnings, the distributions of marker RMS
error and of per-frame residual force and moment (with the Hicks thresholds), and one
table row per subject and trial.
"""

from __future__ import annotations

import html
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from solver.dataset.discover import REPORT_NAME
from solver.dataset.summary import dataset_totals, totals_by_source
from solver.errors import FileFormatError, listed
from solver.outputs import SUMMARY_NAME, read_summary, summary_subjects

_CSS = """
body{font:14px/1.4 system-ui,sans-serif;margin:24px;color:#222}
table{border-collapse:collapse;margin:8px 0 20px}
th,td{border:1px solid #ccc;padding:3px 7px;text-align:right}
th{background:#f3f3f3} td.l,th.l{text-align:left}
tr.failed td{background:#fde8e8} tr.skipped td{color:#666}
.figs{display:flex;flex-wrap:wrap;gap:24px} figure{margin:0} figcaption{font-size:12px;color:#444}
"""


def _esc(x: Any) -> str:
    return html.escape("" if x is None else str(x))


def _num(x: Any, fmt: str = "{:.2f}", scale: float = 1.0) -> str:
    return "-" if x is None else fmt.format(x * scale)


#: Font size of the charts' labels, px, and a bound on the width of one of their characters
#: (digits of common sans-serif fonts are 0.55-0.64 em wide): the margins are sized from it.
CHART_FONT_PX = 10
CHART_CHAR_PX = 0.68 * CHART_FONT_PX


def _text_px(text: str) -> float:
    """An upper bound on the drawn width of a chart label, px."""
    return CHART_CHAR_PX * len(text)


def bar_chart(counts: list[float], labels: list[str], title: str, *, mark: int | None = None,
              width: int = 420, height: int = 180) -> str:
    """An inline SVG bar chart.

    The left margin holds the y-axis label (the tallest bar's count) and half the first
    x-axis label, the right margin half the last one, so that no label is cut off at the
    figure's edge (large counts such as ``1.23e+04`` were).

    Parameters
    ----------
    counts
        Bar heights (any unit), one per bar.
    labels
        One label per bar (the first, a middle and the last are drawn under the axis).
    title
        Caption under the figure.
    mark
        Index of the bar where a threshold starts (a dashed line is drawn before it).

    Returns
    -------
    str
        A ``<figure>`` holding the ``<svg>`` and its caption.
    """
    n = max(len(counts), 1)
    top = max(max(counts, default=0), 1)
    ymax_label = f"{top:.3g}"
    ends = (labels[0], labels[n - 1]) if labels else ("", "")
    left = max(35.0, _text_px(ymax_label) + 6, _text_px(ends[0]) / 2 + 2)
    right = max(5.0, _text_px(ends[1]) / 2 + 2)
    pad, bw = 30, (width - left - right) / n
    bars = []
    for i, c in enumerate(counts):
        h = (height - pad - 10) * c / top
        x = left + i * bw
        bars.append(
            f'<rect x="{x:.1f}" y="{height - pad - h:.1f}" width="{max(bw - 1, 1):.1f}" height="{h:.1f}" '
            f'fill="#4a7bb7"><title>{_esc(labels[i])}: {c:g}</title></rect>'
        )
    ticks = sorted({0, n // 2, n - 1}) if labels else []
    text = [
        f'<text x="{left + i * bw + bw / 2:.1f}" y="{height - pad + 14}" font-size="{CHART_FONT_PX}" text-anchor="middle">'
        f"{_esc(labels[i])}</text>"
        for i in ticks
    ]
    line = ""
    if mark is not None:
        x = left + mark * bw
        line = f'<line x1="{x:.1f}" x2="{x:.1f}" y1="5" y2="{height - pad}" stroke="#c33" stroke-dasharray="4 3"/>'
    axis = f'<line x1="{left:.1f}" x2="{width - right:.1f}" y1="{height - pad}" y2="{height - pad}" stroke="#333"/>'
    ymax = f'<text x="{left - 3:.1f}" y="14" font-size="{CHART_FONT_PX}" text-anchor="end">{_esc(ymax_label)}</text>'
    svg = (
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" role="img">'
        + "".join(bars) + axis + line + ymax + "".join(text) + "</svg>"
    )
    return f"<figure>{svg}<figcaption>{_esc(title)}</figcaption></figure>"


def _by_status(t: dict[str, Any]) -> str:
    """The subjects of totals ``t`` counted by status, in the statuses' order by name (``"1 failed, 3 ok"``)."""
    return ", ".join(f"{v} {k}" for k, v in sorted(t["subjects"].items()))


def totals_rows(t: dict[str, Any]) -> list[tuple[str, str]]:
    """The dataset's totals as (label, value) text rows, in the paper's terms: subjects by
    status, trials and frames (with dynamics, with measured force), hours, the contact
    classes' shares, the clinical-grade share (Hicks), the Hicks shares of trials and the
    marker RMS error. ``t``: the ``totals`` of a dataset summary
    (:func:`solver.dataset.summary.dataset_totals`). Shared by the HTML report and ``addb info``."""
    share = t.get("contact_share") or {}
    return [
        ("subjects", f"{_by_status(t)} ({t['n_subjects']} in all)"),
        ("trials (with dynamics)", f"{t['trials']} ({t['dynamics_trials']})"),
        ("frames (with measured force)", f"{t['frames']} ({t['measured_frames']})"),
        ("hours", _num(t["hours"], "{:.4f}")),
        ("hours with measured force", _num(t["hours_with_measured_force"], "{:.4f}")),
        ("flight / single support / double support (share of measured frames)",
         " / ".join(_num(share.get(k), "{:.1%}") for k in ("flight", "single_support", "double_support"))),
        ("clinical-grade frames (both Hicks thresholds met)", _num(t["clinical_grade_share"], "{:.1%}")),
        ("trials meeting the Hicks linear / angular threshold",
         f"{_num(t['hicks_linear_share'], '{:.1%}')} / {_num(t['hicks_angular_share'], '{:.1%}')}"),
        ("marker RMS per trial, mean / median (cm)",
         f"{_num(t['marker_rms_mean_m'], scale=100)} / {_num(t['marker_rms_median_m'], scale=100)}"),
    ]  # fmt: skip


@contextmanager
def _summary_read(tree: str | Path, what: str) -> Iterator[None]:
    """Turn a missing key or a value of the wrong type met while reading the summary of the
    output tree ``tree`` into a FileFormatError naming the file and ``what`` was expected
    ("its totals", "each subject's trials")."""
    try:
        yield
    except (KeyError, TypeError):
        raise FileFormatError(f"expected a dataset summary with {what} (written by addb process DATASET_DIR)", path=Path(tree) / SUMMARY_NAME) from None


def run_text(out_dir: str | Path) -> str:
    """A dataset run's output tree as text (``addb info OUT``): the dataset folder, when the
    run ended, its wall time and workers, the totals (:func:`totals_rows`), one line per
    source when there are several (:func:`source_rows`) and the report.

    Raises
    ------
    FileFormatError
        ``dataset_summary.json`` is not a dataset summary (:func:`solver.outputs.read_summary`) or has no totals.
    """
    summary = read_summary(out_dir)
    with _summary_read(out_dir, "its totals"):
        rows = totals_rows(summary["totals"])
    when = f", finished {summary['finished']}" if summary.get("finished") else ""
    took = f" in {summary['seconds']:.1f} s" if isinstance(summary.get("seconds"), (int, float)) else ""
    n = summary.get("workers")
    workers = f" on {n} worker{'s' if n != 1 else ''}" if isinstance(n, int) else ""
    lines = [f"{Path(out_dir)}: dataset output", f"  dataset run of {summary.get('dataset')}{when}{took}{workers}"]
    lines += [f"  {label}: {value}" for label, value in rows]
    with _summary_read(out_dir, "each subject's trials"):
        by_source = source_rows(summary["subjects"])
    if by_source:
        lines.append(f"  by source ({'; '.join(SOURCE_HEAD[1:])}):")
        lines += [f"    {r[0]}: {'; '.join(r[1:])}" for r in by_source]
    if (Path(out_dir) / REPORT_NAME).is_file():
        lines.append(f"  report: {Path(out_dir) / REPORT_NAME}")
    return "\n".join(lines)


def part_text(tree: str | Path, part: str) -> str | None:
    """A folder inside a dataset run's output tree as text (``addb info OUT/labA``): the totals
    (:func:`totals_rows`) of the subjects the run listed below it, and the commands for the
    whole run and for one subject; None when the run listed none there.

    Parameters
    ----------
    tree
        The output tree (it holds ``dataset_summary.json``).
    part
        The folder's path relative to ``tree``, with ``/`` separators (``labA``).

    Raises
    ------
    FileFormatError
        ``dataset_summary.json`` is not a dataset summary (:func:`solver.outputs.read_summary`).
    """
    summary = read_summary(tree)
    below = summary_subjects(summary, part)
    if not below:
        return None
    with _summary_read(tree, "each subject's trials"):
        rows = totals_rows(dataset_totals(below))
    rels = [s["rel"] for s in below]
    lines = [
        f"{Path(tree) / part}: part of the dataset output tree {tree}",
        f"  {len(below)} of the run's {len(summary['subjects'])} subjects: {listed(rels, 5)}",
    ]
    lines += [f"  {label}: {value}" for label, value in rows]
    one = next((s["rel"] for s in below if s["status"] != "failed"), rels[0])
    lines.append(f"  addb info {tree} summarizes the whole run, addb info {Path(tree) / one} one subject")
    return "\n".join(lines)


def source_rows(subjects: list[dict[str, Any]]) -> list[tuple[str, ...]]:
    """One text row per source of the dataset (:func:`solver.dataset.summary.totals_by_source`):
    source, subjects by status, trials (with dynamics), frames (with measured force), hours,
    hours with measured force, clinical-grade share, median marker RMS (cm); none when every
    subject comes from one source. Shared by the HTML report and ``addb info OUT``."""
    by_source = totals_by_source(subjects)
    if len(by_source) < 2:
        return []
    return [
        (name, _by_status(t), f"{t['trials']} ({t['dynamics_trials']})",
         f"{t['frames']} ({t['measured_frames']})", _num(t["hours"], "{:.4f}"), _num(t["hours_with_measured_force"], "{:.4f}"),
         _num(t["clinical_grade_share"], "{:.1%}"), _num(t["marker_rms_median_m"], scale=100))
        for name, t in by_source.items()
    ]  # fmt: skip


#: Column heads of :func:`source_rows`.
SOURCE_HEAD = ("source", "subjects", "trials (with dynamics)", "frames (with measured force)", "hours",
               "hours with measured force", "clinical-grade frames", "marker RMS median (cm)")  # fmt: skip


def _sources_table(subjects: list[dict[str, Any]]) -> str:
    rows = source_rows(subjects)
    if not rows:
        return ""
    head = "".join(f'<th class="l">{_esc(h)}</th>' for h in SOURCE_HEAD)
    body = "".join("<tr>" + f'<td class="l">{_esc(r[0])}</td>' + "".join(f"<td>{_esc(v)}</td>" for v in r[1:]) + "</tr>" for r in rows)
    return f"<h2>By source (the first folder of each subject's path)</h2><table><tr>{head}</tr>{body}</table>"


def _totals_table(t: dict[str, Any]) -> str:
    body = "".join(f'<tr><th class="l">{_esc(k)}</th><td class="l">{_esc(v)}</td></tr>' for k, v in totals_rows(t))
    return f"<table>{body}</table>"


def _figures(summary: dict[str, Any]) -> str:
    t = summary["totals"]
    rms = [
        r["marker_rms_m"] * 100
        for s in summary["subjects"] if s["status"] != "failed"
        for r in s.get("trials") or [] if r.get("marker_rms_m") is not None
    ]  # fmt: skip
    figs = []
    if rms:
        edges = np.arange(0.0, max(4.0, np.ceil(max(rms) * 2) / 2) + 0.25, 0.25)
        counts, _ = np.histogram(np.clip(rms, 0, edges[-1] - 1e-9), bins=edges)
        figs.append(bar_chart(counts.tolist(), [f"{e:.2f}" for e in edges[:-1]],
                              f"marker RMS per trial (cm), {len(rms)} trials"))  # fmt: skip
    for key, bins, unit in (
        ("residual_force_hist_BW", "residual_force_bins_BW", "BW"),
        ("residual_moment_hist_BWh", "residual_moment_bins_BWh", "BW·h"),
    ):
        counts = t.get(key) or []
        if sum(counts):
            edges = t[bins]
            labels = [f"{e:g}" for e in edges] + [f">{edges[-1]:g}"]
            what = "force" if unit == "BW" else "moment"
            figs.append(bar_chart(counts, labels[: len(counts)],
                                  f"per-frame residual {what} ({unit}), measured frames; "
                                  f"dashed: Hicks threshold {edges[-1]:g} {unit}", mark=len(edges) - 1))  # fmt: skip
    share = t.get("contact_share") or {}
    if any(v for v in share.values()):
        names = ["flight", "single_support", "double_support"]
        figs.append(bar_chart([100 * (share.get(k) or 0) for k in names], ["flight", "single", "double"],
                              "contact classes, % of measured frames"))  # fmt: skip
    return f'<div class="figs">{"".join(figs)}</div>' if figs else "<p>No processed trial to plot.</p>"


def _error_text(err: dict[str, Any] | None) -> str:
    if not err:
        return ""
    where = ":".join(str(x) for x in (err.get("path"), err.get("line")) if x is not None)
    return f"{err.get('type')}: {err.get('message')}" + (f" ({where})" if where else "")


def _subject_table(subjects: list[dict[str, Any]]) -> str:
    head = ("subject", "status", "trial", "frames", "measured", "duration s", "marker RMS cm",
            "linear residual N (BW)", "angular residual N·m (BW·h)", "Hicks lin", "Hicks ang",
            "fitted mass kg", "stage s")  # fmt: skip
    out = ["<table><tr>" + "".join(f'<th class="l">{_esc(h)}</th>' for h in head) + "</tr>"]
    for s in subjects:
        status = s["status"] + (f" ({s['result_status']})" if s.get("result_status") else "")
        status += " (unchanged)" if s.get("unchanged") else ""
        rows = s.get("trials") or []
        if not rows:
            out.append(
                f'<tr class="{_esc(s["status"])}"><td class="l">{_esc(s["rel"])}</td><td class="l">{_esc(status)}</td>'
                f'<td class="l" colspan="11">{_esc(_error_text(s.get("error")))}</td></tr>'
            )
            continue
        for r in rows:
            yn = {True: "yes", False: "no", None: "-"}
            stage = r.get("stage_seconds") or {}
            out.append(
                f'<tr class="{_esc(s["status"])}"><td class="l">{_esc(s["rel"])}</td><td class="l">{_esc(status)}</td>'
                f'<td class="l">{_esc(r["trial"])}</td><td>{r["frames"]}</td><td>{r["measured_frames"]}</td>'
                f'<td>{_num(r["duration_s"])}</td><td>{_num(r.get("marker_rms_m"), scale=100)}</td>'
                f'<td>{_num(r.get("linear_residual_rms_N"), "{:.1f}")} ({_num(r.get("linear_residual_rms_BW"), "{:.3f}")})</td>'
                f'<td>{_num(r.get("angular_residual_rms_Nm"), "{:.1f}")} ({_num(r.get("angular_residual_rms_BWh"), "{:.3f}")})</td>'
                f'<td>{yn[r.get("hicks_linear_ok")]}</td><td>{yn[r.get("hicks_angular_ok")]}</td>'
                f'<td>{_num(r.get("mass_kg"))}</td><td>{_num(stage.get("total"), "{:.1f}")}</td></tr>'
            )
    out.append("</table>")
    return "".join(out)


def render_report(summary: dict[str, Any]) -> str:
    """The HTML page of a ``dataset_summary.json`` (as parsed JSON)."""
    return (
        "<!DOCTYPE html><html><head><meta charset='utf-8'><title>addb dataset report</title>"
        f"<style>{_CSS}</style></head><body>"
        f"<h1>Dataset report</h1><p>{_esc(summary['dataset'])} &rarr; {_esc(summary['out'])}<br>"
        f"addb {_esc(summary['addb_version'])}, finished {_esc(summary['finished'])} "
        f"in {summary['seconds']:.1f} s</p>"
        f"<h2>Totals</h2>{_totals_table(summary['totals'])}{_sources_table(summary['subjects'])}"
        f"{_failures(summary['subjects'])}{_warnings(summary['subjects'])}"
        f"<h2>Distributions</h2>{_figures(summary)}"
        f"<h2>Subjects and trials</h2>{_subject_table(summary['subjects'])}"
        "</body></html>\n"
    )


def _failures(subjects: list[dict[str, Any]]) -> str:
    """The Failures section: each failed subject and its error ("" when none failed)."""
    failed = [s for s in subjects if s["status"] == "failed"]
    if not failed:
        return ""
    items = "".join(
        f'<tr class="failed"><td class="l">{_esc(s["rel"])}</td><td class="l">{_esc(_error_text(s.get("error")))}</td></tr>'
        for s in failed
    )
    return f'<h2>Failures ({len(failed)})</h2><table><tr><th class="l">subject</th><th class="l">error</th></tr>{items}</table>'


def _warnings(subjects: list[dict[str, Any]]) -> str:
    """The Warnings section: each subject's distinct warnings, all of them also in its
    process.log ("" when no subject warned)."""
    warned = [s for s in subjects if s.get("warnings")]
    if not warned:
        return ""
    items = "".join(
        f'<tr><td class="l">{_esc(s["rel"])}</td><td class="l">{"<br>".join(_esc(w) for w in s["warnings"])}</td></tr>' for s in warned
    )
    return f'<h2>Warnings ({len(warned)} subject{"s" if len(warned) != 1 else ""})</h2><table><tr><th class="l">subject</th><th class="l">warning</th></tr>{items}</table>'
