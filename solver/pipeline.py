"""The solver's stages in order, on an AddBiomechanics subject folder.

``process_subject`` reads the subject, runs the kinematics stage (scaling + IK over all
trials) and, when the trials have force plates, the dynamics stage, then writes the
output folder (:mod:`solver.outputs`) atomically. Stages are pure functions of their
inputs; the functions here only load, sequence and write.

``process_subject`` also saves the kinematics stage's result in
``OUT/.addb_cache/kinematics.pkl`` (:func:`save_kinematics_cache`), keyed by everything
that stage depends on. :func:`reprocess_dynamics` (the review app's Reprocess after a flag
edit) reuses it: the reviewer's flags (unmeasured-force masks) enter the dynamics stage
only (``run_dynamics(unmeasured_force=...)``), never scaling or IK, so a flag edit invalidates
the dynamics alone.
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from solver import single_threaded_blas
from solver.corrections import apply_extensions, extend_subject, extension_masks
from solver.errors import DynamicsError, KinematicsError, listed
from solver.io.external_loads import ExternalForce, ExternalLoads, write_external_loads
from solver.io.mot import write_coordinates, write_forces, write_table
from solver.io.subject import Subject, Trial, load_subject, load_trial
from solver.io.types import ForcePlate, ForceRecording, Table
from solver.kinematics.observations import MarkerSettings, find_marker_settings, mapping_mistakes
from solver.kinematics.result import KinematicsResult, TrialKinematics
from solver.kinematics.stage import KinematicsOptions, run_ik, run_kinematics
from solver.model.osim import OsimModel, read_osim
from solver.model.osim_writer import write_osim
from solver.model.rotations import rotations_to_wxyz
from solver.model.skeleton import Skeleton
from solver.outputs import (
    CACHE_DIR,
    REVIEW_RECORD_KEY,
    SUBJECT_DIR_KEY,
    SUBJECT_RECORD,
    TRIAL_RESULTS,
    check_output_folder,
    staged_output,
    write_json,
)
from solver.provenance import addb_version, code_digest
from solver.results import PlateData, ProcessedTrial, save_processed
from solver.sampling import frame_rate

if TYPE_CHECKING:  # the dynamics stage (scipy.signal) loads only when it runs
    from solver.dynamics.stage import DynamicsOptions, DynamicsResult, TrialDynamics

Progress = Callable[[str, float], None]


@dataclass(frozen=True)
class ProcessOptions:
    """Options of :func:`process_subject`.

    Attributes
    ----------
    kinematics
        Options of the kinematics stage.
    dynamics
        Options of the dynamics stage (a :class:`solver.dynamics.stage.DynamicsOptions`;
        None: its defaults).
    trials
        Names of the trials to write (all trials are still used for scaling); None: all.
        With names, an existing output folder keeps its other trials (only the named trial
        folders, the model and subject.json are replaced).
    """

    kinematics: KinematicsOptions = field(default_factory=KinematicsOptions)
    dynamics: Any = None
    trials: tuple[str, ...] | None = None


@dataclass(frozen=True)
class SubjectKinematics:
    """A loaded subject with its kinematics (input of the dynamics stage and of writers)."""

    subject: Subject
    trials: tuple[Trial, ...]
    kinematics: KinematicsResult
    load_seconds: float


def load_trials(subject: Subject, names: Sequence[str] | None = None) -> tuple[Trial, ...]:
    """Read the trials of ``subject`` (markers and, when present, forces), with the
    corrections saved by ``addb diagnose --apply`` (:mod:`solver.corrections`).

    ``names``: only these trials, in file order (None: every trial); an unknown name
    raises :class:`KinematicsError` naming the subject's trials."""
    files = subject.trials
    if names:
        wanted = _selected(names, [t.name for t in files])
        files = tuple(t for t in files if t.name in wanted)
    return apply_extensions(subject, tuple(load_trial(t) for t in files))


def subject_kinematics(
    subject: Subject,
    options: KinematicsOptions | None = None,
    progress: Progress | None = None,
    *,
    scaled_model: str | Path | None = None,
    trials: Sequence[str] | None = None,
    check_model: Callable[[OsimModel, Sequence[Trial]], None] | None = None,
) -> SubjectKinematics:
    """Load a subject's trials and run the kinematics stage on all of them.

    With ``scaled_model`` (an .osim already scaled to the subject) scaling is skipped and
    only inverse kinematics runs (:func:`solver.kinematics.stage.run_ik`), on the trials
    named in ``trials`` (None: all); without it every trial is read, as scaling uses all,
    and the final inverse kinematics runs on the trials of ``trials`` (None: all).
    ``check_model`` is called with the model and the loaded trials before the stage runs
    (what it raises is raised before any fit: the dynamics' checks of the model)."""
    t0 = time.perf_counter()
    markers = find_marker_settings(subject.path)
    opts = options or KinematicsOptions()
    if scaled_model is not None:
        loaded = load_trials(subject, trials)
        model = read_osim(scaled_model)
        if check_model is not None:
            check_model(model, loaded)
        _warn_mapping_mistakes(markers, model, loaded)
        load_seconds = time.perf_counter() - t0
        kin = run_ik(model, [(t.name, t.markers) for t in loaded], mapping=markers.mapping, options=opts, progress=progress)
        warn_marker_mismatch(kin)
        return SubjectKinematics(subject, loaded, kin, load_seconds)
    loaded = load_trials(subject)
    generic = read_osim(subject.model_path)
    if check_model is not None:
        check_model(generic, loaded)
    _warn_mapping_mistakes(markers, generic, loaded)
    if markers.attach_unmatched:
        opts = replace(opts, attach_unmatched=True)
    load_seconds = time.perf_counter() - t0
    kin = run_kinematics(
        generic,
        [(t.name, t.markers) for t in loaded],
        height_m=subject.height_m,
        mapping=markers.mapping,
        options=opts,
        progress=progress,
        ik_trials=trials,
    )
    warn_marker_mismatch(kin)
    return SubjectKinematics(subject, loaded, kin, load_seconds)


def _warn_mapping_mistakes(markers: MarkerSettings, model: OsimModel, loaded: Sequence[Trial]) -> None:
    """Warn (UserWarning) of each mistake of the subject's marker mapping that leaves a
    marker out of the fit (:func:`solver.kinematics.observations.mapping_mistakes`)."""
    import warnings

    trials = [(t.name, t.markers.names) for t in loaded]
    for message in mapping_mistakes(markers, [m.name for m in model.markers], trials):
        warnings.warn(message, stacklevel=3)


#: A trial is warned about (:func:`warn_marker_mismatch`) when it matches fewer than this
#: share of the model's markers and at least as many of its own markers are ignored (not in
#: the model) as are matched: a lab marker set that does not fit the model, whose few
#: matched markers give a small marker RMS error that says little. Fewer than half of the
#: model's markers alone is no sign: the walk subject's model carries 107 markers (several
#: labs' sets) and its trials match 41 (its static trial ignores 23 more, medial and joint
#: centre markers); OpenCap's trials match 45 of 49 and ignore 6.
MIN_MATCHED_SHARE = 0.5


def _some(names: Sequence[str], shown: int) -> str:
    """The first ``shown`` names, then "and N more"."""
    return ", ".join(names[:shown]) + (f" and {len(names) - shown} more" if len(names) > shown else "")


def marker_mismatch(kin: KinematicsResult, trial: TrialKinematics) -> str | None:
    """The warning about a trial whose markers mostly do not match the model's (the rule of
    :data:`MIN_MATCHED_SHARE`), or None when they do.

    The model's markers are those of the kinematics' model that were not attached from the
    trials (``markers.yaml``'s ``attach_unmatched``); matched are those the trial was fitted
    on; ignored are the trial's markers that the model does not carry (``markers_ignored``
    of results.json). Nothing is computed that the stage uses.
    """
    model = [m.name for m in kin.model.markers if m.name not in kin.attached]
    used = set(trial.marker_names)
    matched = [n for n in model if n in used]
    ignored = list(trial.unmatched)
    if not model or len(matched) >= MIN_MATCHED_SHARE * len(model) or len(ignored) < len(matched):
        return None
    missing = [n for n in model if n not in used]
    return (
        f"trial {trial.name}: only {len(matched)} of the model's {len(model)} markers are matched by the trial's "
        f"marker names (the model's {_some(missing, 5)} are left without data); {len(ignored)} of the trial's "
        f"markers are not in the model and are ignored: {_some(ignored, 8)} (all listed in results.json, "
        "markers_ignored). Its marker RMS error is over the matched markers only: check the marker names against "
        "the model's, or map them in markers.yaml next to the subject"
    )


def warn_marker_mismatch(kin: KinematicsResult) -> None:
    """Warn (UserWarning: on the console, and in a dataset run's process.log) about each
    trial of ``kin`` whose markers mostly do not match the model's (:func:`marker_mismatch`)."""
    import warnings

    for trial in kin.trials:
        message = marker_mismatch(kin, trial)
        if message is not None:
            warnings.warn(message, UserWarning, stacklevel=2)


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
        folder / SUBJECT_RECORD,
        {
            "subject": sk.subject.name,
            "mass_kg": sk.subject.mass_kg,
            "height_m": sk.subject.height_m,
            "body_scales": kin.body_scales,
            "marker_offsets_m": kin.marker_offsets,
            "landmark_scale_response": kin.landmark_scale_response,
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
    scaled_model: str | Path | None = None,
) -> SubjectKinematics:
    """Run the kinematics stage alone and write its outputs.

    Writes ``OUT/<subject>_scaled.osim``, ``OUT/<trial>/<trial>_ik.mot`` and
    ``OUT/<trial>/results.json`` (``n_frames``, ``marker_rms_m``, ``marker_max_m``,
    ``stage_seconds``, ...), replacing ``OUT`` only once everything is written.

    With ``scaled_model`` (an .osim already scaled to the subject, e.g. the
    ``<subject>_scaled.osim`` of an earlier run) only inverse kinematics runs, as OpenSim's
    InverseKinematicsTool does, on the trials of ``options.trials`` (None: all): the model
    file is copied into ``OUT`` as it is and subject.json names it.

    Raises
    ------
    SubjectFolderError, FileFormatError, KinematicsError, MarkerMismatchError
        Bad input, naming the file or trial; a name in ``options.trials`` that the subject
        does not have raises KinematicsError before the stage runs.
    OutputFolderError
        Before the stage runs: ``out_dir`` cannot be replaced
        (:func:`solver.outputs.check_output_folder`).
    """
    with single_threaded_blas(load_scipy=False):  # the kinematics stage uses numpy's BLAS only
        return _process_kinematics(subject_dir, out_dir, options, progress, scaled_model)


def _process_kinematics(
    subject_dir: str | Path,
    out_dir: str | Path,
    options: ProcessOptions | None,
    progress: Progress | None,
    scaled_model: str | Path | None,
) -> SubjectKinematics:
    opts = options or ProcessOptions()
    t0 = time.perf_counter()
    check_output_folder(out_dir, (subject_dir,))  # before the stage runs: OUT is replaced whole at the end
    subject = load_subject(subject_dir)
    _selected(opts.trials, [t.name for t in subject.trials])  # a wrong name fails before the stage runs
    sk = subject_kinematics(subject, opts.kinematics, progress, scaled_model=scaled_model, trials=opts.trials)
    kin = sk.kinematics
    wanted = _selected(opts.trials, [t.name for t in kin.trials])
    model_name = Path(scaled_model).name if scaled_model else f"{subject.name}_scaled.osim"
    with staged_output(out_dir) as tmp:
        if scaled_model:
            shutil.copyfile(scaled_model, tmp / model_name)
        else:
            write_osim(kin.model, tmp / model_name, name=f"{subject.name}_scaled", path_point_scales=kin.body_scales)
        rotational = [n for n, m in zip(kin.model.coordinate_names, (c.motion_type for c in kin.model.coordinates)) if m == "rotational"]
        total = time.perf_counter() - t0
        for trial in kin.trials:
            if trial.name not in wanted:
                continue
            write_trial_kinematics(tmp / trial.name, trial, rotational)
            metrics = kinematics_metrics(trial)
            metrics["rate_hz"] = frame_rate(trial.time) if trial.time.size > 1 else None
            metrics["stage_seconds"] = {
                "load": sk.load_seconds,
                "scaling": kin.seconds.get("initial_poses", 0.0) + kin.seconds.get("scale_fit", 0.0),
                "ik_trial": trial.seconds,
                "kinematics_total": total,
            }
            write_json(tmp / trial.name / TRIAL_RESULTS, metrics)
            model_file = str(Path(out_dir).resolve() / model_name)
            save_processed(tmp / trial.name / "trial.npz", build_processed(sk, trial, model_path=model_file, metrics=metrics))
        write_subject_summary(tmp, sk, {"scaled_model": str(Path(scaled_model).resolve())} if scaled_model else None)
    return sk


def process_subject(
    subject_dir: str | Path,
    out_dir: str | Path,
    *,
    options: ProcessOptions | None = None,
    unmeasured_force: dict[str, np.ndarray] | None = None,
    progress: Progress | None = None,
    review_record: str | Path | None = None,
) -> ProcessResult:
    """Run every stage on a subject and write ``out_dir`` (see :mod:`solver.outputs`).

    Parameters
    ----------
    subject_dir
        AddBiomechanics subject folder.
    out_dir
        Output folder, replaced atomically (nothing is half-written on an error).
    options
        Stage options and the trials to write.
    unmeasured_force
        Trial name -> ``(T,)`` bool at the trial's processed frames (those of
        ``OUT/<trial>/trial.npz``, :func:`solver.dynamics.stage.trial_frames`), True on
        frames with unmeasured external force (the reviewer's flags); they replace the
        automatic proposals of the dynamics stage for that trial. See :mod:`solver.masks`.
    progress
        Called with (message, fraction done).
    review_record
        The review record ``unmeasured_force`` was read from, recorded in subject.json
        (:data:`solver.outputs.REVIEW_RECORD_KEY`, with the subject folder,
        :data:`solver.outputs.SUBJECT_DIR_KEY`) for ``addb export``.

    Returns
    -------
    ProcessResult

    Raises
    ------
    SubjectFolderError, FileFormatError, KinematicsError, MarkerMismatchError, DynamicsError
        Bad input, naming the file or trial; a name in ``options.trials`` that the subject
        does not have raises KinematicsError before any stage runs.
    DynamicsError
        After ``out_dir`` was written, when a trial's own recordings could not enter the
        dynamics stage (NaN or absurd plate forces, forces that do not overlap the markers:
        :func:`solver.dynamics.stage.run_dynamics`'s ``skip_trial``): that trial is written
        as a kinematics-only trial is (motion, marker errors) with the error in its
        results.json (``dynamics_error``, the error's ``to_dict()``), the other trials'
        dynamics are fitted without it, and the error of the first such trial is raised as
        it is, with every such trial in its ``kept_trials`` (``addb process`` adds what was
        written: :func:`addb_viewer.commands.process.with_kept_kinematics`).
    OutputFolderError
        Before any stage runs: ``out_dir`` is a file, is or holds ``subject_dir``, or holds
        what is not an output of addb (:func:`solver.outputs.check_output_folder`).
    """
    with single_threaded_blas():
        return _process_subject(subject_dir, out_dir, options, unmeasured_force, progress, keep_kinematics=True, review_record=review_record)


def reprocess_dynamics(
    subject_dir: str | Path,
    out_dir: str | Path,
    trials: Sequence[str],
    unmeasured_force: dict[str, np.ndarray] | None = None,
    progress: Progress | None = None,
    *,
    options: ProcessOptions | None = None,
    warm_start: bool | None = None,
    review_record: str | Path | None = None,
) -> ProcessResult:
    """Rerun the dynamics stage only (after a flag edit) and write ``trials`` into ``out_dir``.

    The kinematics stage (scaling + IK of every trial) is read from the cache that the last
    :func:`process_subject` into ``out_dir`` saved (:func:`load_kinematics_cache`); the
    reviewer's flags do not enter that stage, so a flag edit leaves it valid. When the cache
    is missing or stale (an input file, ``addb_extensions.json``, the kinematics options, the
    solver's code or version changed), this is a full :func:`process_subject` run, and the
    progress messages say why.

    The dynamics stage still runs on every trial with force plates (the subject's mass and
    body mass factors are fitted over all of them), with the same settings as a full run.
    By default nothing is warm-started: the cached kinematics are bit for bit those a full
    run computes, so the result *equals* a full run with the same flags (the tests check
    it), only without the kinematics stage's time.

    With ``warm_start`` the dynamics fit of each trial starts from that trial's previous
    solution (the coordinates ``q`` of ``OUT/<trial>/trial.npz``, used when its frame times
    equal the stage's common frames) instead of the filtered, centre-of-mass shifted IK.
    Contact, the centre-of-mass mass fit (so the mass and the unobserved frames stay exactly
    those of a full run) and the bounds are computed as in a full run; the body mass
    factors start from 1. A fit that runs to convergence
    (:func:`solver.dynamics.fit.converged_fit`) lands on a full run's answer to its
    tolerance from there, in fewer steps (tests/dynamics/test_reprocess_dynamics.py). The
    ``"band"`` fit (``--fit band``) does not: it stops after ``rounds x iterations`` steps, well
    before the coordinates stop moving, so its end point depends on its start (measured on
    the walk with frames 100-120 flagged: marker RMS 2 % apart, linear residual RMS 4.3 N
    vs 2.7 N, coordinates up to 0.43 rad apart). By default (``None``) the warm start is
    therefore on exactly when the fit runs to convergence.

    Parameters
    ----------
    subject_dir
        AddBiomechanics subject folder.
    out_dir
        Output folder of a previous :func:`process_subject` of that subject; the named
        trial folders, the model and subject.json are replaced (merged), as a Reprocess does.
    trials
        Names of the trials to write (at least one).
    unmeasured_force
        Trial name -> ``(T,)`` bool at the trial's processed frames (the reviewer's flags),
        as for :func:`process_subject`.
    progress
        Called with (message, fraction done).
    options
        Stage options (its ``trials`` is replaced by ``trials``); the kinematics options
        are part of the cache key. Default: those of the run that wrote ``out_dir``, as far
        as it recorded them (the dynamics stage's settings in subject.json:
        :func:`recorded_dynamics_options`).
    warm_start
        Start the dynamics fit from the previous solutions (see above); None: when the fit
        runs to convergence.
    review_record
        As for :func:`process_subject`.

    Returns
    -------
    ProcessResult

    Raises
    ------
    SubjectFolderError, FileFormatError, KinematicsError, MarkerMismatchError, DynamicsError
        As :func:`process_subject`.
    """
    if options is None:
        options = ProcessOptions(dynamics=recorded_dynamics_options(out_dir))
    opts = replace(options, trials=tuple(trials))
    if not opts.trials:
        raise KinematicsError("reprocess_dynamics: name at least one trial to write")
    if warm_start is None:
        warm_start = opts.dynamics is not None and opts.dynamics.fit.converges
    with single_threaded_blas():
        return _process_subject(
            subject_dir, out_dir, opts, unmeasured_force, progress, dynamics_only=True, warm_start=warm_start, review_record=review_record
        )


# ---------------------------------------------------------------------- kinematics cache
#: Name prefix of the review record's files in a subject folder (the annotations package's
#: ``annotations.json``, ``annotations.journal``, ``annotations.lock``): not inputs of the
#: kinematics stage (:func:`kinematics_cache_key`).
REVIEW_RECORD_PREFIX = "annotations."
KINEMATICS_CACHE = "kinematics.pkl"
"""The kinematics stage's cached result inside :data:`CACHE_DIR`."""
_CACHE_SCHEMA = "addb.kinematics_cache/1"


def _file_digest(path: Path) -> str:
    h = hashlib.blake2b(digest_size=16)
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def kinematics_cache_key(subject: Subject, options: KinematicsOptions | None = None) -> dict[str, Any]:
    """What the kinematics stage of ``subject`` depends on, as a JSON-like dict.

    The subject folder's top-level files (``_subject.json``, the model,
    ``addb_extensions.json`` / ``.osim``, marker settings) and every file under ``trials/``
    (links followed), each by size, modification time (ns) and content digest; the model
    file the subject names (it may live elsewhere); the kinematics options; addb's version
    and a digest of the solver's source. The reviewer's flags are not part of it: they
    enter the dynamics stage only, so the review record (``annotations.json`` and its
    journal and lock, :data:`REVIEW_RECORD_PREFIX`) and hidden files are left out.
    """
    folder = Path(subject.path).resolve()
    files = [f for f in folder.iterdir() if f.is_file() and not f.name.startswith((REVIEW_RECORD_PREFIX, "."))]
    if (folder / "trials").is_dir():
        files += [f for f in (folder / "trials").rglob("*") if f.is_file()]
    inputs = {}
    for f in sorted(files):
        st = f.stat()
        inputs[str(f.relative_to(folder))] = [st.st_size, st.st_mtime_ns, _file_digest(f)]
    model = Path(subject.model_path).resolve()
    mst = model.stat()
    return {
        "schema": _CACHE_SCHEMA,
        "subject_dir": str(folder),
        "inputs": inputs,
        "model": [str(model), mst.st_size, mst.st_mtime_ns, _file_digest(model)],
        "options": repr(options or KinematicsOptions()),
        "addb_version": addb_version(),
        "solver_code": code_digest(),
    }


def save_kinematics_cache(folder: Path, sk: SubjectKinematics, key: dict[str, Any]) -> Path:
    """Write ``folder/.addb_cache/kinematics.pkl`` (the key and ``sk``); returns its path."""
    path = Path(folder) / CACHE_DIR / KINEMATICS_CACHE
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    with open(tmp, "wb") as f:
        pickle.dump({"schema": _CACHE_SCHEMA, "key": key, "kinematics": sk}, f, protocol=pickle.HIGHEST_PROTOCOL)
    os.replace(tmp, path)
    return path


def load_kinematics_cache(out_dir: str | Path, key: dict[str, Any]) -> tuple[SubjectKinematics | None, str]:
    """The cached kinematics of ``out_dir`` when its key equals ``key``.

    Returns
    -------
    (SubjectKinematics or None, reason)
        None with the reason (missing, unreadable, or which part of the key changed) when
        the cache cannot be used; never raises for a bad cache file.
    """
    path = Path(out_dir) / CACHE_DIR / KINEMATICS_CACHE
    if not path.is_file():
        return None, f"no kinematics cache ({path})"
    try:
        with open(path, "rb") as f:
            data = pickle.load(f)  # our own output folder: trusted as its other files are
    except Exception as exc:  # noqa: BLE001 - any unreadable cache means a full run
        return None, f"kinematics cache {path} unreadable ({type(exc).__name__}: {exc})"
    if not isinstance(data, dict) or data.get("schema") != _CACHE_SCHEMA or not isinstance(data.get("kinematics"), SubjectKinematics):
        return None, f"kinematics cache {path} has another format"
    old = data.get("key") or {}
    if old != key:
        changed = [k for k in key if old.get(k) != key[k]]
        if "inputs" in changed:
            a, b = old.get("inputs") or {}, key["inputs"]
            files = sorted(n for n in set(a) | set(b) if a.get(n) != b.get(n))
            changed[changed.index("inputs")] = "input files " + listed(files, 5)
        return None, f"kinematics cache is stale ({'; '.join(changed) or 'key'} changed)"
    return data["kinematics"], "kinematics cache is valid"


FIT_CHOICES = ("default", "converged", "rounds", "band")
"""Names of the dynamics fits ``addb process --fit`` offers (:func:`options_for_fit`)."""


def options_for_fit(name: str, trials: Sequence[str] | None = None) -> ProcessOptions:
    """Process options for a named dynamics fit: ``"default"`` (the same as ``"converged"``),
    ``"converged"`` (:func:`solver.dynamics.fit.converged_fit`: exact banded Gauss-Newton
    steps of the coordinates and the body mass factors together until the cost settles,
    :mod:`solver.dynamics.joint_fit`), ``"rounds"`` (:func:`solver.dynamics.fit.alternating_fit`:
    the same steps alternating with mass solves, the default until 2026-11-26 and the fit the
    diagnosis judges on, :mod:`solver.diagnose.judged_fit`) or ``"band"`` (``FitSettings()``:
    truncated-band steps, a fixed number of rounds; the older default).

    Raises
    ------
    ValueError
        An unknown name.
    """
    if name not in FIT_CHOICES:
        raise ValueError(f"unknown dynamics fit {name!r} (use one of {', '.join(FIT_CHOICES)})")
    dynamics = None
    if name in ("band", "rounds"):
        from solver.dynamics.fit import FitSettings, alternating_fit
        from solver.dynamics.stage import DynamicsOptions

        dynamics = DynamicsOptions(fit=FitSettings() if name == "band" else alternating_fit())
    return ProcessOptions(trials=tuple(trials) if trials else None, dynamics=dynamics)


def recorded_dynamics_options(out_dir: str | Path) -> DynamicsOptions:
    """The dynamics stage's options recorded in ``out_dir/subject.json`` by the run that wrote it.

    The fit's settings (``dynamics_settings["fit"]``) are restored, fields this version does
    not know ignored; everything else, and everything when the file or the record is missing
    or unreadable, is the default."""
    from solver.dynamics.fit import FitSettings
    from solver.dynamics.stage import DynamicsOptions

    try:
        record = json.loads((Path(out_dir) / SUBJECT_RECORD).read_text())["dynamics_settings"]["fit"]
        known = {k: v for k, v in record.items() if k in FitSettings.__dataclass_fields__}
        return DynamicsOptions(fit=FitSettings(**known))
    except (OSError, ValueError, KeyError, TypeError):
        return DynamicsOptions()


def previous_solutions(out_dir: str | Path, names: Sequence[str]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Trial -> ``(time (T,), q (T, n))`` of the dynamics solution in
    ``out_dir/<trial>/trial.npz`` (trials without dynamics or without the file: absent)."""
    out = {}
    for name in names:
        path = Path(out_dir) / name / "trial.npz"
        try:
            with np.load(path, allow_pickle=False) as data:
                if "q" not in data.files or "time" not in data.files or "residual_force" not in data.files:
                    continue
                if not np.isfinite(data["residual_force"]).any():
                    continue  # a kinematics-only trial
                out[name] = (np.array(data["time"], dtype=float), np.array(data["q"], dtype=float))
        except (OSError, ValueError, KeyError):
            continue
    return out


def _process_subject(
    subject_dir: str | Path,
    out_dir: str | Path,
    options: ProcessOptions | None,
    unmeasured_force: dict[str, np.ndarray] | None,
    progress: Progress | None,
    *,
    dynamics_only: bool = False,
    warm_start: bool = False,
    keep_kinematics: bool = False,
    review_record: str | Path | None = None,
) -> ProcessResult:
    """:func:`process_subject` (``keep_kinematics``: a trial the dynamics stage cannot take
    is written without dynamics, then its DynamicsError raised) and
    :func:`reprocess_dynamics` (``dynamics_only``: that error is raised before anything is
    written, as every other)."""
    opts = options or ProcessOptions()
    say = progress or (lambda m, f: None)
    t0 = time.perf_counter()
    check_output_folder(out_dir, (subject_dir,))  # before any stage runs: OUT is replaced whole at the end
    subject = load_subject(subject_dir)
    _selected(opts.trials, [t.name for t in subject.trials])  # a wrong name fails before any stage runs
    subject = extend_subject(subject)  # mass and model saved by `addb diagnose --apply`
    key = kinematics_cache_key(subject, opts.kinematics)
    sk = None
    start_q = None
    if dynamics_only:
        sk, why = load_kinematics_cache(out_dir, key)
        if sk is None:
            say(f"{why}: running the kinematics stage too (full run)", 0.0)
            dynamics_only = False
        else:
            say("kinematics reused from the cache (flags change the dynamics only)", 0.4)
            if warm_start:
                start_q = previous_solutions(out_dir, [t.name for t in sk.kinematics.trials])
    if sk is None:
        check = None if subject.disable_dynamics else partial(_check_feet, subject.foot_body_names)
        sk = subject_kinematics(subject, opts.kinematics, lambda m, f: say(m, 0.4 * f), check_model=check)
    t_kin = time.perf_counter()
    load_s = t_kin - t0 if dynamics_only else sk.load_seconds  # from the cache: loading is all it took
    dyn = None
    failed: dict[str, DynamicsError] = {}  # trial -> why the dynamics stage left it out (keep_kinematics)
    if not subject.disable_dynamics:
        from solver.dynamics.stage import DynamicsOptions, run_dynamics

        dyn = run_dynamics(
            sk.kinematics,
            [(t.name, t.markers, t.forces) for t in sk.trials],
            mass_kg=subject.mass_kg,
            foot_bodies=subject.foot_body_names,
            height_m=subject.height_m,
            unmeasured_force=unmeasured_force,
            known_unmeasured=extension_masks(subject) or None,
            options=opts.dynamics or DynamicsOptions(),
            progress=lambda m, f: say(m, 0.4 + 0.55 * f),
            start_q=start_q or None,
            skip_trial=failed.__setitem__ if keep_kinematics else None,
        )
    t_dyn = time.perf_counter()
    say("writing results", 0.96)
    kin = sk.kinematics
    model = dyn.model if dyn is not None else kin.model
    wanted = _selected(opts.trials, [t.name for t in kin.trials])
    rotational = [c.name for c in model.coordinates if c.motion_type == "rotational"]
    out_path = Path(out_dir).resolve()
    model_file = out_path / f"{subject.name}_scaled.osim"
    with staged_output(out_dir, merge=bool(opts.trials)) as tmp:
        write_osim(model, tmp / model_file.name, name=f"{subject.name}_scaled", path_point_scales=kin.body_scales)
        for trial in kin.trials:
            if trial.name not in wanted:
                continue
            folder = tmp / trial.name
            metrics = kinematics_metrics(trial)
            seconds = {"load": load_s, "kinematics": t_kin - t0 - load_s, "ik_trial": trial.seconds}
            td = _trial_dynamics(dyn, trial.name)
            if td is None:
                write_trial_kinematics(folder, trial, rotational)
                metrics["rate_hz"] = frame_rate(trial.time) if trial.time.size > 1 else None
                if trial.name in failed:
                    metrics["dynamics_error"] = failed[trial.name].to_dict()
                processed = build_processed(sk, trial, model_path=str(model_file), metrics=metrics)
            else:
                write_dynamics_files(folder, trial.name, td, model, rotational)
                if not td.metrics["n_observed_frames"]:
                    _warn_no_measured_frame(trial.name, td)
                metrics.update(td.metrics)
                metrics["opensim_convention_max_diff"] = float(np.abs(td.tau_opensim - td.tau).max())
                metrics["rate_hz"] = dyn.settings["rate_hz"]
                metrics["mass_kg"] = dyn.mass_kg
                metrics["unobserved_frames"] = np.flatnonzero(td.unobserved).tolist()
                metrics["unobserved_reasons"] = sorted({r for r in td.reasons if r})
                seconds.update(dyn.seconds)
                processed = build_processed(
                    sk, trial, model_path=str(model_file), plates=td.plates, metrics=metrics, dynamics=_dynamics_fields(td, dyn)
                )
            seconds["total"] = time.perf_counter() - t0
            metrics["stage_seconds"] = seconds
            write_json(folder / TRIAL_RESULTS, metrics)
            save_processed(folder / "trial.npz", replace(processed, metrics=metrics))
        write_subject_summary(
            tmp,
            sk,
            {
                "fitted_mass_kg": dyn.mass_kg if dyn else None,
                "dynamics_seconds": dyn.seconds if dyn else None,
                "dynamics_settings": dyn.settings if dyn else None,
                "total_seconds": time.perf_counter() - t0,
                "stage_seconds": {"kinematics": t_kin - t0, "dynamics": t_dyn - t_kin},
                **({"kinematics_from_cache": True} if dynamics_only else {}),
                **_recorded_inputs(subject_dir, unmeasured_force, review_record),
            },
        )
        if not dynamics_only:
            save_kinematics_cache(tmp, sk, key)
    say("done", 1.0)
    if failed:  # written: now the first trial's error, as it was before the outputs were kept
        error = next(iter(failed.values()))
        error.kept_trials = tuple(failed.items())
        raise error
    return ProcessResult(sk, dyn, out_path)


def _recorded_inputs(subject_dir: str | Path, unmeasured_force: object, review_record: str | Path | None) -> dict[str, Any]:
    """The inputs subject.json records (:data:`solver.outputs.SUBJECT_DIR_KEY`,
    :data:`solver.outputs.REVIEW_RECORD_KEY`): the subject folder; the review record, None
    when no flags were given, left out when flags were given without their record."""
    out: dict[str, Any] = {SUBJECT_DIR_KEY: str(Path(subject_dir).resolve())}
    if unmeasured_force is None:
        out[REVIEW_RECORD_KEY] = None
    elif review_record is not None:
        out[REVIEW_RECORD_KEY] = str(Path(review_record).resolve())
    return out


def _check_feet(foot_bodies: Sequence[str], model: OsimModel, loaded: Sequence[Trial]) -> None:
    """Before the kinematics of a subject whose dynamics will run: its ``footBodyNames``
    must be bodies of its model when a trial has force plates (else the dynamics stage
    would refuse them after the whole kinematics stage)."""
    if any(t.forces is not None and t.forces.plates for t in loaded):
        from solver.dynamics.stage import check_foot_bodies

        check_foot_bodies(model, foot_bodies)


@dataclass(frozen=True)
class ProcessResult:
    """What :func:`process_subject` computed (and wrote to ``out_dir``)."""

    kinematics: SubjectKinematics
    dynamics: DynamicsResult | None
    out_dir: Path


def _warn_no_measured_frame(name: str, td: TrialDynamics) -> None:
    """Warn (UserWarning) that trial ``name``, which has force plates, has no frame with
    measured force in the fit, naming the first frame's reason for leaving it out: its
    residuals and Hicks verdicts are not defined (results.json holds None)."""
    import warnings

    from solver.dynamics.contact import reason_kind

    why = next((reason_kind(r) for r in td.reasons if r), "flagged")
    warnings.warn(f"trial {name}: no frame with measured force enters the fit (all {td.time.size} frames left out, "
                  f"first for: {why}): it has no residuals or Hicks verdicts", stacklevel=3)  # fmt: skip


def _trial_dynamics(dyn: DynamicsResult | None, name: str) -> TrialDynamics | None:
    if dyn is None:
        return None
    try:
        return dyn.trial(name)
    except KeyError:
        return None


def _dynamics_fields(td: TrialDynamics, dyn: DynamicsResult) -> dict[str, Any]:
    """The dynamics arrays of :func:`build_processed`."""
    return {
        "model": dyn.model,
        "time": td.time,
        "q": td.q,
        "qd": td.qd,
        "qdd": td.qdd,
        "observed": td.observed_markers,
        "com": td.com,
        "com_acc": td.com_acc,
        "residual_force": td.residual_force,
        "residual_moment": td.residual_moment,
        "tau": td.tau,
        "unobserved": td.unobserved,
        "proposed": td.contact.proposed,
        "proposal_reasons": list(td.contact.reasons),
        "mass_kg": dyn.mass_kg,
        "settings": dyn.settings,
    }


def write_dynamics_files(folder: Path, name: str, td: TrialDynamics, model: OsimModel, rotational: Sequence[str]) -> None:
    """Write ``_ik.mot``, ``_id.sto``, ``_grf.mot`` and ``_external_loads.xml`` of a trial.

    ``_id.sto`` holds the generalized forces in OpenSim's convention (``tau_opensim``: they
    include Simbody's inexact CustomJoint velocity term, see
    :mod:`solver.model.opensim_compat`), so that OpenSim reproduces them; the exact ones
    are in ``trial.npz`` and results.json reports the largest difference.

    The GRF file holds one column set per foot: the sum of the plate wrenches applied to
    that foot, as a force at a centre of pressure on the ground plane plus a vertical free
    moment; the ExternalLoads file applies each set to its foot body in the ground frame.
    OpenSim's InverseDynamicsTool on these files (no extra filtering) reproduces ``_id.sto``.
    """
    from solver.dynamics.preprocess import cop_from_wrench

    folder.mkdir(parents=True, exist_ok=True)
    names = [c.name for c in model.coordinates]
    write_coordinates(folder / f"{name}_ik.mot", names, td.q, td.time, rotational=rotational)
    kinds = {c.name: ("force" if c.motion_type == "translational" else "moment") for c in model.coordinates}
    write_table(
        folder / f"{name}_id.sto",
        Table(tuple(f"{n}_{kinds[n]}" for n in names), td.tau_opensim, td.time, {"name": f"{name} inverse dynamics"}),
        kind="sto",
    )
    heights = np.concatenate([p.cop[:, 1] for p in td.plates] or [np.zeros(1)])
    heights = heights[np.isfinite(heights)]  # no centre of pressure where a plate carries no force
    plane = float(np.median(heights)) if heights.size else 0.0
    plates, forces = [], []
    for w in td.wrenches:
        m_o = np.cross(w.point, w.force) + w.moment
        cop, free = cop_from_wrench(w.force, m_o, plane, 1e-6)
        # where the vertical force is ~0 the wrench is expressed at the origin's projection
        zero = ~np.isfinite(cop).all(axis=1)
        cop[zero] = [0.0, plane, 0.0]
        free[zero] = m_o[zero] - np.cross(cop[zero], w.force[zero])
        plates.append(ForcePlate(w.body, w.force, cop, free))
        forces.append(
            ExternalForce(
                name=f"{w.body}_GRF",
                applied_to_body=w.body,
                force_identifier=f"ground_force_{w.body}_v",
                point_identifier=f"ground_force_{w.body}_p",
                torque_identifier=f"ground_torque_{w.body}_",
            )
        )
    grf = folder / f"{name}_grf.mot"
    rate = frame_rate(td.time, what=f"trial {name}")
    write_forces(grf, ForceRecording(td.time, rate, tuple(plates), str(grf)))
    write_external_loads(folder / f"{name}_external_loads.xml", ExternalLoads(f"{name}_external_loads", tuple(forces), grf.name))


def plates_on_frames(forces: ForceRecording | None, time: np.ndarray) -> tuple[PlateData, ...]:
    """Plate wrenches linearly interpolated onto the trial's frame times ``time`` ``(T,)``, s
    (no assignment): each plate's ``(T, 3)`` force (N), centre of pressure (m) and free
    moment (N·m), as the recording gives them (NaN outside the recording; the centre of
    pressure also where unloaded), applied to no body (-1 on every frame)."""
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
    dyn = dynamics or {}
    model = dyn.get("model", sk.kinematics.model)
    skel = Skeleton(model)
    q = dyn.get("q", trial.q)
    t = q.shape[0]
    rot, pos = skel.body_poses(q)
    wxyz = rotations_to_wxyz(rot)
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
