"""The solver's stages in order, on an AddBiomechanics subject folder.

``process_subject`` reads the subject, runs the kinematics stage (scaling + IK over all
trials) and, when the trials have force plates, the dynamics stage, then writes the
output folder (:mod:`solver.outputs`) atomically. Stages are pure functions of their
inputs; the functions here only load, sequence and write.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from solver.errors import KinematicsError
from solver.io.mot import write_coordinates
from solver.io.subject import Subject, Trial, load_subject, load_trial
from solver.io.types import ForceRecording
from solver.kinematics.observations import find_marker_settings
from solver.kinematics.result import KinematicsResult, TrialKinematics
from solver.kinematics.stage import KinematicsOptions, run_kinematics
from solver.model.osim import read_osim
from solver.model.osim_writer import write_osim
from solver.model.skeleton import Skeleton
from solver.outputs import staged_output, write_json
from solver.results import PlateData, ProcessedTrial, save_processed

Progress = Callable[[str, float], None]


@dataclass(frozen=True)
class ProcessOptions:
    """Options of :func:`process_subject`.

    Attributes
    ----------
    kinematics
        Options of the kinematics stage.
    trials
        Names of the trials to write (all trials are still used for scaling); None: all.
    """

    kinematics: KinematicsOptions = field(default_factory=KinematicsOptions)
    trials: tuple[str, ...] | None = None


@dataclass(frozen=True)
class SubjectKinematics:
    """A loaded subject with its kinematics (input of the dynamics stage and of writers)."""

    subject: Subject
    trials: tuple[Trial, ...]
    kinematics: KinematicsResult
    load_seconds: float


def load_trials(subject: Subject) -> tuple[Trial, ...]:
    """Read every trial of ``subject`` (markers and, when present, forces)."""
    return tuple(load_trial(t) for t in subject.trials)


def subject_kinematics(
    subject: Subject, options: KinematicsOptions | None = None, progress: Progress | None = None
) -> SubjectKinematics:
    """Load a subject's trials and run the kinematics stage on all of them."""
    t0 = time.perf_counter()
    trials = load_trials(subject)
    generic = read_osim(subject.model_path)
    markers = find_marker_settings(subject.path)
    opts = options or KinematicsOptions()
    if markers.attach_unmatched:
        opts = replace(opts, attach_unmatched=True)
    load_seconds = time.perf_counter() - t0
    kin = run_kinematics(
        generic,
        [(t.name, t.markers) for t in trials],
        height_m=subject.height_m,
        mapping=markers.mapping,
        options=opts,
        progress=progress,
    )
    return SubjectKinematics(subject, trials, kin, load_seconds)


def kinematics_metrics(trial: TrialKinematics) -> dict[str, Any]:
    """The kinematics part of a trial's results.json."""
    by_marker = trial.marker_rms_by_marker()
    return {
        "n_frames": int(trial.q.shape[0]),
        "marker_rms_m": trial.marker_rms,
        "marker_max_m": trial.marker_max,
        "worst_marker": trial.worst_marker,
        "marker_rms_by_marker_m": by_marker,
        "markers_used": list(trial.marker_names),
        "markers_ignored": list(trial.unmatched),
    }


def write_trial_kinematics(folder: Path, trial: TrialKinematics, rotational: Sequence[str]) -> None:
    """Write ``<trial>_ik.mot`` (degrees for rotational coordinates) into ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    write_coordinates(folder / f"{trial.name}_ik.mot", trial.coordinate_names, trial.q, trial.time, rotational=rotational)


def write_subject_summary(folder: Path, sk: SubjectKinematics, extra: dict[str, Any] | None = None) -> None:
    """Write ``subject.json``: scales, marker offsets, fit RMS and timings."""
    kin = sk.kinematics
    write_json(
        folder / "subject.json",
        {
            "subject": sk.subject.name,
            "mass_kg": sk.subject.mass_kg,
            "height_m": sk.subject.height_m,
            "body_scales": kin.body_scales,
            "marker_offsets_m": kin.marker_offsets,
            "scale_fit_marker_rms_m": kin.fit_marker_rms,
            "kinematics_seconds": kin.seconds,
            **(extra or {}),
        },
    )


def process_kinematics(
    subject_dir: str | Path,
    out_dir: str | Path,
    *,
    options: ProcessOptions | None = None,
    progress: Progress | None = None,
) -> SubjectKinematics:
    """Run the kinematics stage alone and write its outputs.

    Writes ``OUT/<subject>_scaled.osim``, ``OUT/<trial>/<trial>_ik.mot`` and
    ``OUT/<trial>/results.json`` (``n_frames``, ``marker_rms_m``, ``marker_max_m``,
    ``stage_seconds``, ...), replacing ``OUT`` only once everything is written.

    Raises
    ------
    SubjectFolderError, FileFormatError, KinematicsError, MarkerMismatchError
        Bad input, naming the file or trial.
    """
    opts = options or ProcessOptions()
    t0 = time.perf_counter()
    subject = load_subject(subject_dir)
    sk = subject_kinematics(subject, opts.kinematics, progress)
    kin = sk.kinematics
    wanted = _selected(opts.trials, [t.name for t in kin.trials])
    with staged_output(out_dir) as tmp:
        write_osim(kin.model, tmp / f"{subject.name}_scaled.osim", name=f"{subject.name}_scaled", path_point_scales=kin.body_scales)
        rotational = [n for n, m in zip(kin.model.coordinate_names, (c.motion_type for c in kin.model.coordinates)) if m == "rotational"]
        total = time.perf_counter() - t0
        for trial in kin.trials:
            if trial.name not in wanted:
                continue
            write_trial_kinematics(tmp / trial.name, trial, rotational)
            metrics = kinematics_metrics(trial)
            metrics["rate_hz"] = float(1.0 / np.median(np.diff(trial.time))) if trial.time.size > 1 else None
            metrics["stage_seconds"] = {
                "load": sk.load_seconds,
                "scaling": kin.seconds.get("initial_poses", 0.0) + kin.seconds.get("scale_fit", 0.0),
                "ik_trial": trial.seconds,
                "kinematics_total": total,
            }
            write_json(tmp / trial.name / "results.json", metrics)
            model_file = str(Path(out_dir).resolve() / f"{subject.name}_scaled.osim")
            save_processed(tmp / trial.name / "trial.npz", build_processed(sk, trial, model_path=model_file, metrics=metrics))
        write_subject_summary(tmp, sk)
    return sk


def process_subject(
    subject_dir: str | Path,
    out_dir: str | Path,
    *,
    options: ProcessOptions | None = None,
    unmeasured: dict[str, np.ndarray] | None = None,
    progress: Progress | None = None,
) -> SubjectKinematics:
    """Run every stage on a subject and write ``out_dir`` (see :mod:`solver.outputs`).

    Parameters
    ----------
    subject_dir
        AddBiomechanics subject folder.
    out_dir
        Output folder, replaced atomically.
    options
        Stage options and the trials to write.
    unmeasured
        Trial name -> ``(T,)`` bool mask, at the trial's marker frame rate, of frames with
        unmeasured external force (the reviewer's flags); they override the automatic
        proposals of the dynamics stage.
    progress
        Called with (message, fraction done).

    Notes
    -----
    Until the dynamics stage lands this runs the kinematics stage only.
    """
    return process_kinematics(subject_dir, out_dir, options=options, progress=progress)


def plates_on_frames(forces: ForceRecording | None, time: np.ndarray) -> tuple[PlateData, ...]:
    """Plate wrenches linearly interpolated onto the trial's frame times (no assignment)."""
    if forces is None:
        return ()
    out = []
    for p in forces.plates:
        def interp(a: np.ndarray) -> np.ndarray:
            return np.stack([np.interp(time, forces.time, a[:, k], left=np.nan, right=np.nan) for k in range(3)], axis=1)

        force = interp(np.asarray(p.force))
        cop = interp(np.nan_to_num(np.asarray(p.cop)))
        cop[np.linalg.norm(force, axis=1) < 1e-6] = np.nan
        out.append(PlateData(p.name, force, cop, interp(np.asarray(p.free_moment)), p.corners, np.full(time.size, -1)))
    return tuple(out)


def build_processed(
    sk: SubjectKinematics,
    trial: TrialKinematics,
    *,
    model_path: str = "",
    plates: tuple[PlateData, ...] | None = None,
    dynamics: dict[str, Any] | None = None,
    metrics: dict[str, Any] | None = None,
) -> ProcessedTrial:
    """Assemble the :class:`ProcessedTrial` of one trial from the stage results.

    ``dynamics`` holds the dynamics stage's arrays (``q``, ``qd``, ``qdd``, ``com``,
    ``com_acc``, ``residual_force``, ``residual_moment``, ``tau``, ``unobserved``,
    ``proposed``, ``proposal_reasons``, ``mass_kg``, ``model``); without it the dynamic
    fields are NaN and the kinematics coordinates are used.
    """
    from scipy.spatial.transform import Rotation

    dyn = dynamics or {}
    model = dyn.get("model", sk.kinematics.model)
    skel = Skeleton(model)
    q = dyn.get("q", trial.q)
    t = q.shape[0]
    rot, pos = skel.body_poses(q)
    wxyz = Rotation.from_matrix(rot.reshape(-1, 3, 3)).as_quat(scalar_first=True).reshape(t, -1, 4)
    nan3 = np.full((t, 3), np.nan)
    raw = next(x for x in sk.trials if x.name == trial.name)
    return ProcessedTrial(
        subject=sk.subject.name,
        trial=trial.name,
        time=dyn.get("time", trial.time),
        coordinate_names=skel.coordinate_names,
        q=q,
        qd=dyn.get("qd", np.full_like(q, np.nan)),
        qdd=dyn.get("qdd", np.full_like(q, np.nan)),
        marker_names=trial.marker_names,
        observed=dyn.get("observed", trial.observed),
        modeled=skel.marker_positions(q, skel.marker_index(list(trial.marker_names))),
        body_names=skel.body_names,
        body_position=pos,
        body_wxyz=wxyz,
        body_meshes={b.name: [(m.file, m.scale) for m in b.meshes] for b in model.bodies},
        plates=plates if plates is not None else plates_on_frames(raw.forces, trial.time),
        mass_kg=float(dyn.get("mass_kg", sk.subject.mass_kg)),
        height_m=sk.subject.height_m,
        com=dyn.get("com", skel.center_of_mass(q)),
        com_acc=dyn.get("com_acc", nan3),
        residual_force=dyn.get("residual_force", nan3),
        residual_moment=dyn.get("residual_moment", nan3),
        tau=dyn.get("tau", np.full_like(q, np.nan)),
        unobserved=dyn.get("unobserved", np.zeros(t, dtype=bool)),
        proposed=dyn.get("proposed", np.zeros(t, dtype=bool)),
        proposal_reasons=tuple(dyn.get("proposal_reasons", [""] * t)),
        metrics=metrics or {},
        model_path=model_path,
        geometry_dir=str(geometry_dir(sk.subject.model_path)),
        settings=dyn.get("settings", {}),
    )


def geometry_dir(model_path: Path) -> Path:
    """Where the model's mesh files are: a ``Geometry`` folder beside the model (the model
    file may be a link into a models folder), else the model's folder."""
    for base in (Path(model_path).absolute().parent, Path(model_path).resolve().parent):
        if (base / "Geometry").is_dir():
            return base / "Geometry"
    return Path(model_path).resolve().parent


def _selected(requested: Sequence[str] | None, available: Sequence[str]) -> set[str]:
    if not requested:
        return set(available)
    missing = [t for t in requested if t not in available]
    if missing:
        raise KinematicsError(f"unknown trial(s) {', '.join(missing)}; the subject has {', '.join(available)}")
    return set(requested)
