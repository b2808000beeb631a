"""AddBiomechanics' own result in a .b3d file beside addb's result for the same subject.

For each trial, AddBiomechanics' pass coordinates (the file's ``pos``, its D coordinates
in the order of :func:`solver.io.b3d.dof_names`) are put through our forward kinematics
with the model embedded in the file (AddBiomechanics' scaled model and marker offsets),
and the marker error is evaluated on the same observed markers and frames as addb's
processed trial (``OUT/<trial>/trial.npz``). Both errors use one formula: the RMS of the
marker distances over every observed (frame, marker) pair, m. addb's residual forces are
summarized on the frames the file marks as having measured force (``notMissingGRF``),
beside the Hicks thresholds of addb's results.json.

Format reference for the pass data: keenon/nimblephysics ``dart/proto/SubjectOnDisk.proto``.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from solver.io.b3d import B3dFile, dof_names, open_b3d


def _rms(err: np.ndarray) -> float:
    seen = np.isfinite(err)
    return float(np.sqrt(np.mean(err[seen] ** 2))) if seen.any() else float("nan")


def compare_with_b3d(b3d: str | Path | B3dFile, out_dir: str | Path, *, pass_index: int = 0, trial_names: dict[str, str] | None = None) -> list[dict[str, Any]]:
    """Marker error and residuals of AddBiomechanics' pass and addb's result, per trial.

    Parameters
    ----------
    b3d
        The .b3d file (or open file).
    out_dir
        addb's output folder for the subject converted from it (``addb convert`` then
        ``addb process``).
    pass_index
        The AddBiomechanics pass to compare (its model is the one in the file's passes).
    trial_names
        .b3d trial name -> addb trial folder name, when they differ (default: the same).

    Returns
    -------
    list of dict
        Per trial: ``trial``, ``frames``, ``markers`` (count used), ``addb_marker_rms_m``,
        ``b3d_marker_rms_m`` (ours FK on their coordinates), ``b3d_reported_marker_rms_m``
        (mean of the file's per-frame float32 marker RMS), ``measured_frames`` (file),
        ``addb_observed_frames`` (ours, among those), ``linear_residual_rms_N`` and
        ``angular_residual_rms_Nm`` (ours on the file's measured frames that addb also
        treated as measured), the Hicks thresholds and verdicts from ``results.json``.

    Raises
    ------
    FileNotFoundError
        A trial of the file was not processed into ``out_dir``.
    ValueError
        Frame counts of the file and the processed trial differ.
    """
    from solver.model.osim import read_osim
    from solver.model.skeleton import Skeleton
    from solver.results import load_processed

    f = b3d if isinstance(b3d, B3dFile) else open_b3d(b3d)
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "b3d_model.osim"
        p.write_text(f.model_text(pass_index), encoding="utf-8")
        model = read_osim(p)
    skel = Skeleton(model)
    names = dof_names(model)
    if len(names) != f.header.n_dofs:
        raise ValueError(f"the embedded model has {len(names)} independent coordinates, the file {f.header.n_dofs}")
    cols = np.array([skel.coordinate_index(n) for n in names])
    rows = []
    for k, info in enumerate(f.header.trials):
        if info.n_frames == 0 or pass_index >= len(info.passes):
            continue
        ours = load_processed(out_dir, (trial_names or {}).get(info.name, info.name))
        if ours.n_frames != info.n_frames:
            raise ValueError(f"trial {info.name}: {info.n_frames} frames in the file, {ours.n_frames} processed")
        fr = f.read_trial(k)
        q = np.zeros((info.n_frames, skel.n))
        q[:, cols] = fr.passes[pass_index].pos
        q = skel.cmap.complete(q)
        model_markers = [m.name for m in model.markers]
        used = [j for j, m in enumerate(ours.marker_names) if m in model_markers]
        idx = skel.marker_index([ours.marker_names[j] for j in used])
        theirs = skel.marker_positions(q, idx)  # (T, M, 3)
        observed = ours.observed[:, used]
        err_theirs = np.linalg.norm(theirs - observed, axis=2)
        err_ours = np.linalg.norm(ours.modeled[:, used] - observed, axis=2)
        measured = np.array([r == "notMissingGRF" for r in info.missing_grf])
        both = measured & ~ours.unobserved
        lin = np.linalg.norm(ours.residual_force[both], axis=1)
        ang = np.linalg.norm(ours.residual_moment[both], axis=1)
        m = ours.metrics
        rows.append({
            "trial": info.name,
            "frames": info.n_frames,
            "markers": len(used),
            "addb_marker_rms_m": _rms(err_ours),
            "b3d_marker_rms_m": _rms(err_theirs),
            "b3d_reported_marker_rms_m": float(np.mean(info.passes[pass_index].marker_rms)) if info.passes[pass_index].marker_rms.size else float("nan"),
            "b3d_pass": info.passes[pass_index].type,
            "measured_frames": int(measured.sum()),
            "addb_observed_frames": int(both.sum()),
            "linear_residual_rms_N": float(np.sqrt(np.mean(lin**2))) if lin.size else float("nan"),
            "angular_residual_rms_Nm": float(np.sqrt(np.mean(ang**2))) if ang.size else float("nan"),
            "hicks_linear_threshold_N": m.get("hicks_linear_threshold_N"),
            "hicks_angular_threshold_Nm": m.get("hicks_angular_threshold_Nm"),
            "addb_mass_kg": float(ours.mass_kg),
            "b3d_mass_kg": f.header.mass_kg,
        })
    return rows
