"""What is wrong: where the residuals of a processed trial concentrate.

All figures are on the frames of the processed trial's dynamic fit (not flagged by the
reviewer, not left out by the solver), for the root residual as the pipeline computed it
(force N, moment about the pelvis origin N·m, ground frame):

* ``over_time``: RMS and peak, and the time ranges where the residual force exceeds twice
  its RMS (and 0.05 BW);
* ``by_phase``: frames, RMS force and moment, share of the squared residual, per phase
  from the kinematic foot contact (double support, single support on each foot, flight);
* ``by_foot``: the same on the frames where a plate carries each foot;
* ``by_axis``: RMS per axis of force and moment (x forward, y up, z right in OpenSim's
  lab frame) and each axis' share;
* ``correlations``: Pearson correlation, over frames, of the residual force norm (and of
  the moment norm) with the measured total force, its rate of change, the centre-of-mass
  acceleration, each plate's vertical load and the per-frame marker RMS;
* ``left_out``: the frames the solver left out of its dynamic fit on its own (unmeasured
  force proposals, not reviewer flags): how many, when, why, and the RMS of the force
  missing there (the residual force of the free motion on those frames).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from solver.diagnose.data import DiagnosisData
from solver.dynamics.contact import reason_kind
from solver.dynamics.preprocess import true_runs

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


def _rms(x: FloatArray) -> float:
    return float(np.sqrt(np.mean(np.sum(x**2, axis=-1)))) if x.size else float("nan")


def _corr(a: FloatArray, b: FloatArray) -> float | None:
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 5 or np.std(a[ok]) == 0 or np.std(b[ok]) == 0:
        return None
    return float(np.corrcoef(a[ok], b[ok])[0, 1])


def phases(data: DiagnosisData) -> list[str]:
    """``(T,)`` phase of each frame from the kinematic contact of the feet."""
    t = data.n_frames
    if data.foot_contact is None or not data.feet:
        return ["unknown"] * t
    out = []
    for k in range(t):
        on = [f for i, f in enumerate(data.feet) if data.foot_contact[i, k]]
        out.append("double support" if len(on) >= 2 else f"single support {on[0]}" if on else "flight")
    return out


def analyse(data: DiagnosisData) -> dict[str, Any]:
    """The concentration report of the module docstring (a JSON-ready dict)."""
    trial = data.trial
    left = data.left_out
    ev = ~data.flagged & ~left
    force, moment = trial.residual_force, trial.residual_moment
    fn, mn = np.linalg.norm(force, axis=1), np.linalg.norm(moment, axis=1)
    total = float(np.sum(fn[ev] ** 2) + np.sum(mn[ev] ** 2)) or 1.0
    time = trial.time
    rms_f = _rms(force[ev])
    hot = ev & (fn > max(2 * rms_f, 0.05 * data.bw))
    over_time = {
        "linear_rms_N": rms_f,
        "angular_rms_Nm": _rms(moment[ev]),
        "linear_peak_N": float(fn[ev].max()) if ev.any() else float("nan"),
        "linear_peak_time_s": float(time[ev][np.argmax(fn[ev])]) if ev.any() else None,
        "angular_peak_Nm": float(mn[ev].max()) if ev.any() else float("nan"),
        "angular_peak_time_s": float(time[ev][np.argmax(mn[ev])]) if ev.any() else None,
        "hot_spots_s": [[float(time[a]), float(time[b - 1])] for a, b in true_runs(hot)],
    }
    ph = np.array(phases(data))
    by_phase = {}
    for name in sorted(set(ph[ev].tolist())):
        sel = ev & (ph == name)
        by_phase[name] = {
            "frames": int(sel.sum()),
            "linear_rms_N": _rms(force[sel]),
            "angular_rms_Nm": _rms(moment[sel]),
            "share": float((np.sum(fn[sel] ** 2) + np.sum(mn[sel] ** 2)) / total),
        }
    by_foot = {}
    if data.foot_loaded is not None:
        for k, foot in enumerate(data.feet):
            sel = ev & data.foot_loaded[k]
            by_foot[foot] = {"frames": int(sel.sum()), "linear_rms_N": _rms(force[sel]), "angular_rms_Nm": _rms(moment[sel])}
    axes = ("x", "y", "z")
    f_axis = np.sqrt(np.mean(force[ev] ** 2, axis=0)) if ev.any() else np.full(3, np.nan)
    m_axis = np.sqrt(np.mean(moment[ev] ** 2, axis=0)) if ev.any() else np.full(3, np.nan)
    by_axis = {
        "force_rms_N": dict(zip(axes, f_axis.tolist())),
        "moment_rms_Nm": dict(zip(axes, m_axis.tolist())),
        "force_share": dict(zip(axes, (f_axis**2 / max(np.sum(f_axis**2), 1e-30)).tolist())),
        "moment_share": dict(zip(axes, (m_axis**2 / max(np.sum(m_axis**2), 1e-30)).tolist())),
    }
    f_plates, _, _ = data.plates.on(time)
    total_force = f_plates.sum(axis=0)
    rate = np.gradient(total_force, data.dt, axis=0)
    signals = {
        "total_force_N": np.linalg.norm(total_force, axis=1),
        "force_rate_N_per_s": np.linalg.norm(rate, axis=1),
        "com_acceleration_m_per_s2": np.linalg.norm(trial.com_acc, axis=1),
        "marker_rms_m": trial.marker_rms_per_frame,
        **{f"plate_{n}_vertical_N": f_plates[i][:, 1] for i, n in enumerate(data.plates.names)},
    }
    correlations = {
        name: {"linear": _corr(fn[ev], sig[ev]), "angular": _corr(mn[ev], sig[ev])} for name, sig in signals.items()
    }
    return {
        "frames_evaluated": int(ev.sum()),
        "frames_flagged": int(data.flagged.sum()),
        "left_out": {
            "frames": int(left.sum()),
            "times_s": [[float(time[a]), float(time[b - 1])] for a, b in true_runs(left)],
            "reasons": sorted({reason_kind(trial.proposal_reasons[j]) for j in np.flatnonzero(left) if trial.proposal_reasons[j]}),
            "linear_rms_N": _rms(force[left]) if left.any() else None,
        },
        "over_time": over_time,
        "by_phase": by_phase,
        "by_foot": by_foot,
        "by_axis": by_axis,
        "correlations": correlations,
    }
