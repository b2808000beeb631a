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
from solver.kinematics.observations import find_marker_settings
from solver.kinematics.result import KinematicsResult, TrialKinematics
from solver.kinematics.stage import KinematicsOptions, run_kinematics
from solver.model.osim import read_osim
from solver.model.osim_writer import write_osim
from solver.outputs import staged_output, write_json

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
        write_subject_summary(tmp, sk)
    return sk


def _selected(requested: Sequence[str] | None, available: Sequence[str]) -> set[str]:
    if not requested:
        return set(available)
    missing = [t for t in requested if t not in available]
    if missing:
        raise KinematicsError(f"unknown trial(s) {', '.join(missing)}; the subject has {', '.join(available)}")
    return set(requested)
