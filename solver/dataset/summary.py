"""Per-trial summary rows of a processed subject, and dataset totals in the terms of the
AddBiomechanics Dataset paper (Werling et al., "AddBiomechanics Dataset: Capturing the
Physics of Human Motion at Scale", ECCV 2024): hours of motion, hours with measured
ground reaction force, the share of frames in flight / single support / double support,
the share of clinical-grade frames, and distributions of marker RMS error and residuals.

Definitions used here (per frame, on frames with measured external force only, the frames
the dynamics fit trusts):

* contact class: a foot is on the ground when the vertical ground reaction force applied
  to it is above :data:`CONTACT_THRESHOLD_N` (20 N, the usual force-plate event threshold);
  0 feet: flight, 1: single support, 2 or more: double support.
* clinical-grade frame: its residual force is below 5 % of body weight and its residual
  moment below 10 % of body weight x height, the thresholds Hicks et al. (2015) set for
  the RMS over a trial (:mod:`solver.dynamics.metrics`), applied frame by frame.
* residual distributions: per-frame |residual force| / BW and |residual moment| / (BW·h)
  counted in the fixed bins :data:`RESIDUAL_BINS_BW` / :data:`RESIDUAL_BINS_BWH` (twenty bins
  up to the Hicks threshold, then one bin for every frame above it), so that subjects add up without keeping frames.
* source: the first folder of a subject's path in the dataset (``labA`` of ``labA/s01``), the
  lab or study it came from, as the paper's table of its 15 source datasets counts them
  (:func:`totals_by_source`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from solver.dynamics.metrics import GRAVITY, HICKS_ANGULAR_BWH, HICKS_LINEAR_BW
from solver.masks import true_runs
from solver.results import ProcessedTrial, load_processed
from solver.sampling import frame_rate

#: Vertical force on a foot above which it counts as in contact, N.
CONTACT_THRESHOLD_N = 20.0
#: Bin edges of per-frame residual force / BW: 20 bins up to the Hicks threshold (0.05 BW);
#: a last open bin holds the frames above it.
RESIDUAL_BINS_BW = tuple(round(HICKS_LINEAR_BW * k / 20, 6) for k in range(21))
#: Bin edges of per-frame residual moment / (BW·h): 20 bins up to the Hicks threshold
#: (0.1 BW·h); a last open bin holds the frames above it.
RESIDUAL_BINS_BWH = tuple(round(HICKS_ANGULAR_BWH * k / 20, 6) for k in range(21))

CONTACT_CLASSES = ("flight", "single_support", "double_support")

_METRICS = (
    "marker_rms_m", "marker_max_m", "linear_residual_rms_N", "linear_residual_mean_N",
    "angular_residual_rms_Nm", "linear_residual_rms_BW", "angular_residual_rms_BWh",
    "hicks_linear_ok", "hicks_angular_ok", "mass_kg", "stage_seconds",
)  # fmt: skip


def _hist(values: np.ndarray, edges: tuple[float, ...]) -> list[int]:
    """Counts of ``values`` in ``edges`` plus one open bin above the last edge."""
    counts, _ = np.histogram(np.clip(values, edges[0], None), bins=[*edges, math.inf])
    return [int(c) for c in counts]


def contact_frames(trial: ProcessedTrial, measured: np.ndarray) -> dict[str, int]:
    """Frames of each contact class among the ``measured`` frames (see module doc).

    Parameters
    ----------
    trial
        A processed trial whose plates carry the body each wrench is applied to.
    measured
        ``(T,)`` bool, frames with measured external force.
    """
    fy: dict[int, np.ndarray] = {}
    for plate in trial.plates:
        if plate.body is None:
            continue
        for b in np.unique(plate.body[plate.body >= 0]):
            on = plate.body == b
            fy.setdefault(int(b), np.zeros(trial.time.size))[on] += np.nan_to_num(plate.force[on, 1])
    feet = sum(((f > CONTACT_THRESHOLD_N).astype(int) for f in fy.values()), np.zeros(trial.time.size, dtype=int))
    feet = feet[measured]
    return {
        "flight": int((feet == 0).sum()),
        "single_support": int((feet == 1).sum()),
        "double_support": int((feet >= 2).sum()),
    }


def dynamics_error_message(metrics: Mapping[str, Any]) -> str | None:
    """The message of a trial's ``dynamics_error`` (results.json of a trial written with its
    kinematics because the dynamics stage could not take its recordings), or None."""
    error = metrics.get("dynamics_error")
    return str(error.get("message")) if isinstance(error, Mapping) and error.get("message") else None


def proposed_ranges(proposed: Any) -> list[list[int]]:
    """A trial's frames the solver proposes as unmeasured, as a manifest row holds them.

    Parameters
    ----------
    proposed
        ``(T,)`` booleans, True on a frame proposed as unmeasured (``ProcessedTrial.proposed``,
        the ``proposed`` array of trial.npz).

    Returns
    -------
    Half-open ``[start, stop]`` frame ranges, in order (:func:`solver.masks.true_runs`), as
    lists (JSON arrays).

    Raises
    ------
    ValueError
        ``proposed`` is not one-dimensional.
    """
    return [list(r) for r in true_runs(np.asarray(proposed, dtype=bool))]


def trial_row(trial: ProcessedTrial) -> dict[str, Any]:
    """The summary row of one processed trial.

    Returns
    -------
    dict
        ``trial``, ``status`` (``"ok"`` when the dynamics stage ran, else
        ``"kinematics_only"``), ``frames``, ``rate_hz``, ``duration_s``,
        ``measured_frames``, ``measured_s``, ``proposed_ranges`` (half-open frame ranges
        the solver proposes as unmeasured), the metrics of results.json (marker RMS m,
        residual RMS in N, N·m, BW, BW·h, Hicks verdicts, fitted mass kg, stage seconds),
        ``contact_frames`` (class -> frames), ``clinical_frames``, and the per-frame
        residual histograms ``residual_force_hist_BW`` / ``residual_moment_hist_BWh``.
    """
    m = trial.metrics
    n = int(trial.time.size)
    rate = m.get("rate_hz") or (frame_rate(trial.time) if n > 1 else None)
    dynamics = "n_observed_frames" in m
    row: dict[str, Any] = {
        "trial": trial.trial,
        "status": "ok" if dynamics else "kinematics_only",
        "frames": n,
        "rate_hz": rate,
        "duration_s": n / rate if rate else None,
    }
    row.update({k: m.get(k) for k in _METRICS})
    error = dynamics_error_message(m)
    if error is not None:  # kept with its kinematics: the dynamics failed
        row["dynamics_error"] = error
    row["proposed_ranges"] = proposed_ranges(trial.proposed)
    if not dynamics:
        row.update(measured_frames=0, measured_s=0.0, contact_frames=None, clinical_frames=0,
                   residual_force_hist_BW=None, residual_moment_hist_BWh=None)  # fmt: skip
        return row
    measured = ~np.asarray(trial.unobserved, dtype=bool)
    bw = trial.mass_kg * GRAVITY
    f = np.linalg.norm(trial.residual_force[measured], axis=1) / bw
    bwh = bw * trial.height_m if trial.height_m else None
    mom = np.linalg.norm(trial.residual_moment[measured], axis=1)
    row["measured_frames"] = int(measured.sum())
    row["measured_s"] = row["measured_frames"] / rate if rate else None
    row["contact_frames"] = contact_frames(trial, measured)
    row["residual_force_hist_BW"] = _hist(f, RESIDUAL_BINS_BW)
    if bwh:
        row["clinical_frames"] = int(((f < HICKS_LINEAR_BW) & (mom / bwh < HICKS_ANGULAR_BWH)).sum())
        row["residual_moment_hist_BWh"] = _hist(mom / bwh, RESIDUAL_BINS_BWH)
    else:
        row["clinical_frames"] = None
        row["residual_moment_hist_BWh"] = None
    return row


def subject_rows(out_dir: str | Path) -> list[dict[str, Any]]:
    """The rows of every trial processed into a subject output folder, by trial name.

    Raises
    ------
    FileNotFoundError, ValueError
        A trial folder without a readable ``trial.npz`` (see :func:`load_processed`).
    """
    base = Path(out_dir)
    names = sorted(p.name for p in base.iterdir() if (p / "trial.npz").is_file())
    return [trial_row(load_processed(base, name)) for name in names]


def _sum_hist(rows: list[dict[str, Any]], key: str, width: int) -> list[int]:
    total = [0] * width
    for r in rows:
        for i, c in enumerate(r.get(key) or []):
            total[i] += c
    return total


def dataset_totals(subjects: list[dict[str, Any]]) -> dict[str, Any]:
    """Dataset totals from the subject entries of ``dataset_summary.json``.

    Parameters
    ----------
    subjects
        Entries with ``status`` (ok, kinematics_only, failed, skipped) and ``trials``
        (rows of :func:`trial_row`; a skipped subject carries the rows of its stored output).

    Returns
    -------
    dict
        ``subjects`` (count by status), ``trials``, ``frames``, ``hours``,
        ``hours_with_measured_force``, ``contact_share`` (class -> fraction of measured
        frames), ``clinical_grade_share`` (fraction of measured frames), marker RMS
        per trial (mean and median, m), the summed residual histograms with their bin
        edges, and the share of dynamics trials meeting each Hicks threshold (among those
        with a verdict).
    """
    by_status: dict[str, int] = {}
    for s in subjects:
        by_status[s["status"]] = by_status.get(s["status"], 0) + 1
    rows = [r for s in subjects if s["status"] != "failed" for r in s.get("trials") or []]
    dyn = [r for r in rows if r["status"] == "ok"]
    seconds = sum(r["duration_s"] or 0.0 for r in rows)
    measured = sum(r["measured_frames"] for r in dyn)
    contact = {c: sum((r["contact_frames"] or {}).get(c, 0) for r in dyn) for c in CONTACT_CLASSES}
    n_contact = sum(contact.values())
    clinical = [r["clinical_frames"] for r in dyn if r["clinical_frames"] is not None]
    clinical_measured = sum(r["measured_frames"] for r in dyn if r["clinical_frames"] is not None)
    rms = [r["marker_rms_m"] for r in rows if r.get("marker_rms_m") is not None]
    return {
        "subjects": by_status,
        "n_subjects": len(subjects),
        "trials": len(rows),
        "dynamics_trials": len(dyn),
        "frames": sum(r["frames"] for r in rows),
        "measured_frames": measured,
        "hours": seconds / 3600.0,
        "hours_with_measured_force": sum(r["measured_s"] or 0.0 for r in dyn) / 3600.0,
        "contact_share": {c: (v / n_contact if n_contact else None) for c, v in contact.items()},
        "clinical_grade_share": sum(clinical) / clinical_measured if clinical_measured else None,
        "marker_rms_mean_m": float(np.mean(rms)) if rms else None,
        "marker_rms_median_m": float(np.median(rms)) if rms else None,
        "hicks_linear_share": _share_within(dyn, "hicks_linear_ok"),
        "hicks_angular_share": _share_within(dyn, "hicks_angular_ok"),
        "residual_force_bins_BW": list(RESIDUAL_BINS_BW),
        "residual_force_hist_BW": _sum_hist(dyn, "residual_force_hist_BW", len(RESIDUAL_BINS_BW)),
        "residual_moment_bins_BWh": list(RESIDUAL_BINS_BWH),
        "residual_moment_hist_BWh": _sum_hist(dyn, "residual_moment_hist_BWh", len(RESIDUAL_BINS_BWH)),
    }


def _share_within(rows: list[dict[str, Any]], verdict: str) -> float | None:
    """The share of ``rows`` whose Hicks ``verdict`` is True among those that have one (a
    trial without a frame with measured force, or without a height for the moment, has
    none); None when no row has one."""
    judged = [bool(r[verdict]) for r in rows if r.get(verdict) is not None]
    return sum(judged) / len(judged) if judged else None


#: The source of a subject at the top of the dataset folder (no folder above it).
TOP_LEVEL = "."


def source_of(rel: str) -> str:
    """The source (lab, study) of the subject at relative path ``rel``: its first folder
    (``labA`` of ``labA/s01``), :data:`TOP_LEVEL` for a subject at the top of the dataset."""
    return rel.split("/", 1)[0] if "/" in rel else TOP_LEVEL


def totals_by_source(subjects: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """:func:`dataset_totals` of each source's subjects (:func:`source_of`), sources sorted by
    name: the paper's per-dataset counts (subjects, trials, hours, hours with measured force).

    Parameters
    ----------
    subjects
        Entries of ``dataset_summary.json`` (each with its ``rel`` path), as for
        :func:`dataset_totals`.
    """
    groups: dict[str, list[dict[str, Any]]] = {}
    for s in subjects:
        groups.setdefault(source_of(s["rel"]), []).append(s)
    return {name: dataset_totals(group) for name, group in sorted(groups.items())}
