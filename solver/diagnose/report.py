"""The diagnosis as JSON (``addb diagnose --json``, ``OUT/<trial>/diagnosis.json``) and as text.

JSON object (schema ``addb.diagnosis`` version 1; every number SI, NaN -> null)::

    subject, trial
    baseline      the trial's results.json metrics (marker_rms_m, linear_residual_rms_N,
                  angular_residual_rms_Nm, *_BW, *_BWh, hicks_linear_ok, hicks_angular_ok, ...)
    analysis      where the residuals concentrate (:mod:`solver.diagnose.analysis`)
    candidates    one object per cause, best score first:
                    cause, choice (plate / marker / null), parameters (physical units),
                    uncertainty (jackknife standard error over the folds, same keys),
                    score (held-out gain - k log T, cost units), gain (held-out relative
                    gain: fraction of the reference cost of the cause's channels removed
                    on held-out frames), held_out_gain (cost units), folds_improved,
                    n_params, parameters_fitted_motion (estimate on the processed motion),
                    motion (the motion score and gain were computed on: "fitted", or
                    "marker-only" for a delay decided on the marker-only motion),
                    alternatives (plate/marker causes: every plate or marker with its
                    parameters, score and gain)
    chosen        cause name or null
    reason        one sentence
    chosen_parameters   parameters of the chosen cause (null when none)
    after         metrics of the trial refitted with the chosen extension (baseline keys;
                  null when none)
    before_refit  metrics of the same refit without the extension (baseline keys; null when
                  none): the refit starts from the processed motion and may improve on it
                  by itself, so the extension's gain is ``after`` against this
    held_out      {"before": {...}, "after": {...}, "motion", "note"}: marker RMS (m), linear
                  (N) and angular (N·m) residual RMS on held-out frames (each frame corrected
                  with parameters fitted without its fold; fixed kinematics: the motion the
                  chosen cause was decided on; for a plate-reading correction decided on the
                  fitted motion, the motions refitted without and with it: "refitted")
    extension     the entry ``--apply`` saves (:mod:`solver.corrections`)
    also_standing_out  marker offsets other than the chosen cause that stand out on their
                  own markers' errors, each {cause, parameters, uncertainty, score,
                  extension}: findings too (markers do not compete), not saved by ``--apply``
    settings      sigmas, folds (K), folds_mixing_phases (the causes whose folds mix the
                  phases of the stride; the others' blocks are dealt in turn,
                  :class:`solver.diagnose.selection.Folds`), block_seconds, the choice rule,
                  masses and frame counts
    seconds
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from solver.diagnose.causes.registry import CAUSES, cause, registered
from solver.diagnose.core import Diagnosis
from solver.diagnose.selection import Evaluation

SCHEMA = "addb.diagnosis"
VERSION = 1

#: The main parameter of each cause (the key its uncertainty is reported under;
#: :attr:`solver.diagnose.causes.base.Cause.main_parameter`).
MAIN_PARAMETER = {c.name: c.main_parameter for c in CAUSES}


def clean(obj: Any) -> Any:
    """A JSON-ready copy: numpy scalars and arrays to Python, NaN and inf to None."""
    if isinstance(obj, dict):
        return {str(k): clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [clean(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return clean(obj.tolist())
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        x = float(obj)
        return x if math.isfinite(x) else None
    return obj


def _params(p: dict[str, Any] | None) -> dict[str, Any] | None:
    return None if p is None else {k: v for k, v in p.items() if k != "value"}


def _uncertainty(ev: Evaluation) -> dict[str, Any] | None:
    if ev.uncertainty is None:
        return None
    return cause(ev.cause).uncertainty_json(ev.uncertainty, ev.parameters)


def candidate_json(ev: Evaluation, alternatives: list[Evaluation]) -> dict[str, Any]:
    """One entry of ``candidates``."""
    out = {
        "cause": ev.cause,
        "choice": ev.choice,
        "parameters": _params(ev.parameters),
        "uncertainty": _uncertainty(ev),
        "score": ev.score,
        "gain": ev.relative_gain,
        "held_out_gain": ev.gain,
        "folds_improved": ev.folds_improved,
        "n_params": ev.n_params,
        "parameters_fitted_motion": _params(ev.parameters_fitted_motion),
        "motion": ev.motion,
    }
    if len(alternatives) > 1:
        out["alternatives"] = [
            {"choice": a.choice, "parameters": _params(a.parameters), "uncertainty": _uncertainty(a), "score": a.score, "gain": a.relative_gain}
            for a in sorted(alternatives, key=lambda e: e.score, reverse=True)
        ]
    return out


def write_report(diag: Any, out_dir: str | Path, trial: str) -> Path:
    """Write ``out_dir/<trial>/diagnosis.json`` (:func:`to_json`) atomically (a temporary
    file renamed into place, so the review app never reads half a file); returns its path."""
    import json as _json

    target = Path(out_dir) / trial / "diagnosis.json"
    tmp = target.with_name(target.name + ".tmp")
    tmp.write_text(_json.dumps(to_json(diag), indent=1) + "\n", encoding="utf-8")
    tmp.replace(target)
    return target


def to_json(diag: Diagnosis) -> dict[str, Any]:
    """The JSON object of the module docstring."""
    by_cause: dict[str, list[Evaluation]] = {}
    for ev in diag.evaluations:
        by_cause.setdefault(ev.cause, []).append(ev)
    return clean(
        {
            "schema": SCHEMA,
            "version": VERSION,
            "subject": diag.subject,
            "trial": diag.trial,
            "baseline": diag.baseline,
            "analysis": diag.analysis,
            "candidates": [candidate_json(ev, by_cause[ev.cause]) for ev in diag.ranked],
            "chosen": None if diag.chosen is None else diag.chosen.cause,
            "reason": diag.reason,
            "chosen_parameters": _params(diag.parameters),
            "after": diag.after,
            "before_refit": diag.before_refit,
            "held_out": diag.held_out,
            "extension": diag.extension,
            "also_standing_out": [
                {"cause": e.cause, "parameters": _params(e.parameters), "uncertainty": _uncertainty(e), "score": e.score, "extension": entry}
                for e, entry in diag.also_standing_out
            ],
            "settings": diag.settings,
            "seconds": diag.seconds,
        }
    )


# --------------------------------------------------------------------------- text


def _fmt_params(cause_name: str, p: dict[str, Any] | None, unc: dict[str, Any] | None = None) -> str:
    """The estimate ``p`` (JSON parameters) with its uncertainty ``unc`` (JSON) as one line
    (:meth:`solver.diagnose.causes.base.Cause.describe`); a cause this version does not
    know (a report written by another one) prints its parameters as they are."""
    if not p:
        return ""
    if not registered(cause_name):
        return str(p)
    return cause(cause_name).describe(p, unc)


def candidate_line(c: dict[str, Any]) -> str:
    """One text line of a ``candidates`` entry of the JSON object."""
    return (
        f"{c['cause']:<26s} score {c['score']:10.0f}  gain {100 * (c['gain'] or 0.0):5.1f}%  "
        f"folds {100 * (c['folds_improved'] or 0.0):3.0f}%  {_fmt_params(c['cause'], c['parameters'], c['uncertainty'])}"
        + (" (on the marker-only motion)" if c.get("motion") == "marker-only" else "")
    )


#: Heading of the ``also_standing_out`` list in the text report and the review app.
STANDING_OUT_HEADING = "Other markers that stand out on their own errors (findings too; `--apply` saves only the chosen cause):"


def standing_out_line(e: dict[str, Any]) -> str:
    """One text line of an ``also_standing_out`` entry of the JSON object (a marker offset
    that stands out on its own marker's error besides the chosen cause)."""
    return f"score {e['score']:10.0f}  {_fmt_params(e['cause'], e['parameters'], e['uncertainty'])}"


def held_out_labels(held_out: dict[str, Any]) -> tuple[str, str]:
    """Row labels of the held-out "before" and "after" figures (naming the refitted motions
    when used)."""
    if held_out.get("motion") == "refitted":
        return "held-out before (refit)", "held-out after (refit)"
    return "held-out before", "held-out after"


def metric_row(name: str, m: dict[str, Any] | None) -> str:
    """One text line of metrics (results.json keys, or the held-out figures)."""
    if not m:
        return f"  {name:<23s} -"
    lin, ang = m.get("linear_residual_rms_N"), m.get("angular_residual_rms_Nm")
    hicks = ""
    if "hicks_linear_ok" in m:
        hicks = f"  Hicks lin {'ok' if m.get('hicks_linear_ok') else 'no'}, ang {'ok' if m.get('hicks_angular_ok') else ('no' if m.get('hicks_angular_ok') is not None else '-')}"
    mk = m.get("marker_rms_m")

    def num(x: Any, scale: float, width: int, digits: int) -> str:
        return f"{'-':>{width}s}" if x is None or not math.isfinite(float(x)) else f"{scale * float(x):{width}.{digits}f}"

    return f"  {name:<23s} markers {num(mk, 100, 5, 2)} cm  linear {num(lin, 1, 7, 1)} N  angular {num(ang, 1, 7, 1)} N·m{hicks}"


def to_text(diag: Diagnosis) -> str:
    """A human-readable report."""
    a = diag.analysis
    ot = a["over_time"]
    lines = [
        f"Diagnosis of {diag.subject} / {diag.trial}",
        "",
        "What is wrong",
        (
            f"  frames evaluated {a['frames_evaluated']} (flagged by the reviewer: {a['frames_flagged']}, "
            f"left out of the dynamic fit by the solver: {a['left_out']['frames']})"
        ),
        (
            f"  residual force RMS {ot['linear_rms_N']:.1f} N (peak {ot['linear_peak_N']:.1f} N at {ot['linear_peak_time_s']:.2f} s), "
            f"moment RMS {ot['angular_rms_Nm']:.1f} N·m (peak {ot['angular_peak_Nm']:.1f} N·m at {ot['angular_peak_time_s']:.2f} s)"
        ),
    ]
    judged = diag.settings.get("judged_fit", {})
    if judged.get("rebuilt"):
        lines.insert(1, (
            f"  (judged on the {judged['fit']!r} dynamics fit the diagnosis is calibrated on, run again "
            f"for it: the trial was processed with the {judged['processed_fit']!r} fit, whose figures differ from "
            "the ones below)"
        ))  # fmt: skip
    lo = a["left_out"]
    if lo["frames"]:
        spans = ", ".join(f"{s:.2f}-{e:.2f} s" for s, e in lo["times_s"][:8])
        lines.append(f"  left out by the solver: {spans}; force missing there RMS {lo['linear_rms_N']:.1f} N ({'; '.join(lo['reasons'][:3])})")
    if ot["hot_spots_s"]:
        lines.append("  residual force above twice its RMS: " + ", ".join(f"{s:.2f}-{e:.2f} s" for s, e in ot["hot_spots_s"][:8]))
    for name, ph in a["by_phase"].items():
        lines.append(f"  {name:<24s} {ph['frames']:4d} frames  force {ph['linear_rms_N']:6.1f} N  moment {ph['angular_rms_Nm']:6.1f} N·m  share {100 * ph['share']:4.0f}%")
    fx, mx = a["by_axis"]["force_rms_N"], a["by_axis"]["moment_rms_Nm"]
    lines.append(
        "  by axis: force x/y/z " + "/".join(f"{fx[k]:.1f}" for k in "xyz") + " N, moment x/y/z " + "/".join(f"{mx[k]:.1f}" for k in "xyz") + " N·m"
    )
    corr = [(k, v["linear"]) for k, v in a["correlations"].items() if v["linear"] is not None]
    corr.sort(key=lambda kv: -abs(kv[1]))
    if corr:
        lines.append("  residual force correlates with: " + ", ".join(f"{k} {v:+.2f}" for k, v in corr[:4]))
    lines += ["", "Candidate causes (held-out evidence; score = held-out gain - k log T)"]
    for ev in diag.ranked:
        lines.append("  " + candidate_line(candidate_json(ev, [])))
    lines += ["", diag.reason]
    if diag.also_standing_out:
        lines.append(STANDING_OUT_HEADING)
        lines += [f"  {_fmt_params(e.cause, _params(e.parameters), _uncertainty(e))}" for e, _ in diag.also_standing_out]
    if diag.chosen is not None:
        lines.append(f"Estimate: {_fmt_params(diag.chosen.cause, _params(diag.parameters), _uncertainty(diag.chosen))}")
        lines += ["", "Gain of the extension"]
        lines.append(metric_row("before (processed)", diag.baseline))
        lines.append(metric_row("before (refit, none)", diag.before_refit))
        lines.append(metric_row("after (refit)", diag.after))
        if diag.held_out:
            before, after = held_out_labels(diag.held_out)
            lines.append(metric_row(before, diag.held_out["before"]))
            lines.append(metric_row(after, diag.held_out["after"]))
            if diag.held_out.get("note"):
                lines.append(f"  (held-out: {diag.held_out['note']})")
    return "\n".join(lines)
