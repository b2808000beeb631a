"""A trial that is consistent by construction, for the diagnosis' no-false-alarm test.

From a processed real trial: its motion ``q`` and scaled model with the mass distribution
the processing started from (the generic model's, or a neutral base's after its saved
redistributions: ``base``) at the fitted mass, so that the pipeline, which starts from that
distribution, can reproduce it; markers are the model markers (landmark markers at their
landmarks, without the offsets the kinematics stage fitted on the real trials) plus noise (white,
``marker_noise`` m per coordinate (optical motion capture: well under 1 mm), and a smooth soft-tissue drift of ``tissue`` m RMS per
marker, low-passed at 2 Hz); forces are the real plate wrenches corrected on every
measured frame so that the root residual is zero (the correction is shared among the
loaded plates in proportion to their vertical load), resampled to 1000 Hz, plus white
noise of ``force_noise`` N and 0.1 x that in N·m, each plate's wrench written as its own
centre of pressure on the plate's surface and a free moment about the vertical, as a plate
reports it. The frames the real trial had as unmeasured keep their real forces and are
flagged by the reviewer. The real subject's static trials are made the same way from their
processed poses (the scale fit then sees what it saw on the real subject).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
from scipy.signal import butter, sosfiltfilt

from solver.diagnose.data import generic_mass_distribution, load_offsets
from solver.dynamics.preprocess import moment_about_origin
from solver.io.mot import write_forces
from solver.io.trc import write_trc
from solver.io.types import ForcePlate, ForceRecording, MarkerTrajectories
from solver.model.osim import read_osim
from solver.model.skeleton import Skeleton
from solver.results import ProcessedTrial, load_processed
from tests.diagnose.effects import fixed_markers

FORCE_RATE = 1000.0


def consistent_subject(
    processed: ProcessedTrial,
    source_subject: Path,
    dst: Path,
    *,
    seed: int = 0,
    marker_noise: float = 0.0005,
    tissue: float = 0.003,
    force_noise: float = 3.0,
    base: Path | None = None,
) -> Path:
    """Write a subject folder with one consistent trial (see the module docstring).

    Parameters
    ----------
    processed
        The processed real trial (its output folder also holds the static trials' poses).
    source_subject
        The real subject folder (generic model, ``_subject.json``, landmark markers).
    dst
        The new subject folder (must not exist).
    seed, marker_noise, tissue, force_noise
        Noise: seed, white marker noise (m), soft-tissue drift (m RMS), force noise (N).
    base
        A neutral base's subject folder: its saved mass redistributions set the distribution
        (default: the generic model's).

    Returns
    -------
    Path
        The subject folder (with ``annotations.json`` flagging the unmeasured frames).
    """
    rng = np.random.default_rng(seed)
    # the mass distribution the processing started from: the generic model's, or the one a
    # neutral base's saved redistributions made (the model its processing read; a trial
    # with steps off the plates, the run's flight, cannot be made consistent with another:
    # no plate takes up the difference there)
    generic_path = source_subject / "unscaled_generic.osim"
    if base is not None:
        from solver.corrections import extend_subject
        from solver.io.subject import load_subject

        generic_path = Path(extend_subject(load_subject(base)).model_path)
    model = generic_mass_distribution(read_osim(processed.model_path), read_osim(generic_path))
    sk = Skeleton(model)
    time = processed.time
    dt = float(np.median(np.diff(time)))
    idr = sk.inverse_dynamics(processed.q, processed.qd, processed.qdd)
    pelvis = processed.body_position[:, processed.body_names.index(sk.root_body)]
    inertial_f = idr.root_force
    inertial_mo = idr.root_moment + np.cross(pelvis, idr.root_force)  # about the ground origin

    # plates: real wrenches (about the origin), corrected so that the residual is zero
    forces = np.stack([np.nan_to_num(p.force) for p in processed.plates])  # (P, T, 3)
    moments = np.stack([moment_about_origin(np.nan_to_num(p.force), p.cop, np.nan_to_num(p.free_moment)) for p in processed.plates])
    loads = np.maximum(forces[:, :, 1], 0.0)
    share = loads / np.maximum(loads.sum(axis=0), 1e-9)
    fix = (~processed.unobserved) & (loads.sum(axis=0) > 20.0)
    d_f = inertial_f - forces.sum(axis=0)
    d_m = inertial_mo - moments.sum(axis=0)
    forces = forces + np.where(fix[None, :, None], share[..., None] * d_f[None], 0.0)
    moments = moments + np.where(fix[None, :, None], share[..., None] * d_m[None], 0.0)

    t_f = np.arange(time[0], time[-1] + 1e-9, 1.0 / FORCE_RATE)
    plates = []
    for i, p in enumerate(processed.plates):
        f = np.stack([np.interp(t_f, time, forces[i, :, a]) for a in range(3)], axis=1)
        m = np.stack([np.interp(t_f, time, moments[i, :, a]) for a in range(3)], axis=1)
        f += rng.normal(0.0, force_noise, f.shape)
        m += rng.normal(0.0, 0.1 * force_noise, m.shape)
        loaded = np.nan_to_num(p.force[:, 1]) > 20.0
        centre = np.nanmedian(p.cop[loaded], axis=0) if loaded.any() else np.zeros(3)
        cop_frames = np.where(np.isfinite(p.cop), p.cop, centre)
        cop = np.stack([np.interp(t_f, time, cop_frames[:, a]) for a in range(3)], axis=1)
        # a plate reports its wrench as a centre of pressure on its surface and a free
        # moment about the vertical: where it is loaded, that point is the corrected
        # wrench's own (m = cop x f + (0, tau, 0) with cop_y the surface height)
        on = f[:, 1] > 20.0
        h = cop[on, 1]
        cop[on, 0] = (m[on, 2] + h * f[on, 0]) / f[on, 1]
        cop[on, 2] = (h * f[on, 2] - m[on, 0]) / f[on, 1]
        free = m - np.cross(cop, f)
        plates.append(ForcePlate(p.name, f, cop, free))

    # markers: model markers + white noise + smooth soft-tissue drift
    out_dir = Path(processed.model_path).parent
    offsets = load_offsets(out_dir)
    fixed = fixed_markers(source_subject)

    def markers_of(trial: ProcessedTrial) -> np.ndarray:
        names = list(trial.marker_names)
        pos = sk.marker_positions(trial.q, sk.marker_index(names))
        step = float(np.median(np.diff(trial.time))) if trial.time.size > 1 else dt
        if trial.time.size > 12:
            sos = butter(2, 2.0 / (0.5 / step), output="sos")
            drift = sosfiltfilt(sos, rng.normal(size=pos.shape), axis=0)
            drift *= tissue / np.sqrt(np.mean(drift**2, axis=0, keepdims=True))
            pos = pos + drift
        pos = pos + rng.normal(0.0, marker_noise, pos.shape)
        # landmark (fixed) markers at their landmarks: the processed model's markers carry the
        # offsets the kinematics stage fitted on the real trials, up to 2 cm on the walk's
        # shoulders; written into the data, such an offset is a misplaced marker (a cause the
        # diagnosis names since markers are judged on their own errors, 2026-11-23)
        rot, _ = sk.body_poses(trial.q)
        for name, body in fixed:
            if name in names and name in offsets:
                pos[:, names.index(name)] -= rot[:, sk.body_index(body)] @ np.asarray(offsets[name], dtype=float)
        pos[~np.isfinite(trial.observed)] = np.nan
        return pos

    names = list(processed.marker_names)
    pos = markers_of(processed)

    dst.mkdir(parents=True)
    shutil.copy2(generic_path, dst / "unscaled_generic.osim")
    (dst / "unscaled_generic.osim").chmod(0o644)
    raw = json.loads((source_subject / "_subject.json").read_text())
    raw["massKg"] = float(sum(b.mass for b in model.bodies))
    raw.pop("trialRanges", None)
    raw.pop("segmentedTrials", None)
    (dst / "_subject.json").write_text(json.dumps(raw, indent=2))
    folder = dst / "trials" / processed.trial
    folder.mkdir(parents=True)
    write_trc(folder / "markers.trc", MarkerTrajectories(tuple(names), pos, time, 1.0 / dt))
    # the real subject's static trials, made the same way from their processed poses: the
    # scale fit then sees what it saw on the real subject (without them, the run's was fitted
    # to the dynamic trial alone and landed on other segment sizes, torso depth -6 %, feet
    # -3 to -5 %, whose inertia read as a mass redistribution of 1-2 kg to the legs)
    for static in sorted(t.name for t in (source_subject / "trials").iterdir() if not (t / "grf.mot").exists()):
        if (out_dir / static / "trial.npz").is_file():
            st = load_processed(out_dir, static)
            step = float(np.median(np.diff(st.time))) if st.time.size > 1 else dt
            (dst / "trials" / static).mkdir(parents=True)
            write_trc(dst / "trials" / static / "markers.trc", MarkerTrajectories(tuple(st.marker_names), markers_of(st), st.time, 1.0 / step))
    write_forces(folder / "grf.mot", ForceRecording(t_f, FORCE_RATE, tuple(plates)))
    if processed.unobserved.any():
        from annotations import AnnotationStore

        with AnnotationStore.open(dst / "annotations.json", reviewer="synthetic") as store:
            store.set_unmeasured(processed.trial, np.flatnonzero(processed.unobserved).tolist(), source="imported")
    return dst
