"""AddBiomechanics subject folders.

Layout::

    <subject>/
        _subject.json            massKg, heightM (strings or numbers), sex,
                                 footBodyNames, disableDynamics, ... (all kept in ``raw``)
        unscaled_generic.osim    the generic model with the lab's marker set
        trials/<trial>/
            markers.trc | markers.c3d
            grf.mot              optional: without it the trial is kinematics-only

A C3D trial without ``grf.mot`` takes its forces from the C3D force platforms.
"""

from __future__ import annotations

import json
import math
import os
import shlex
import stat
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from solver.errors import FileFormatError, SubjectFolderError, listed
from solver.files import folders_to_search
from solver.io.c3d import read_c3d
from solver.io.mot import read_forces
from solver.io.spikes import without_spikes
from solver.io.trc import read_trc
from solver.io.types import ForceRecording, MarkerTrajectories
from solver.outputs import TRIAL_RESULTS, output_marker, output_tree_above, read_summary, tree_part

SUBJECT_JSON = "_subject.json"
MODEL_FILE = "unscaled_generic.osim"
DEFAULT_FOOT_BODIES = ("calcn_r", "calcn_l")


@dataclass(frozen=True)
class TrialFiles:
    """The files of one trial folder.

    Attributes
    ----------
    name
        Trial folder name (``walk``).
    markers_path
        ``markers.trc`` or ``markers.c3d``.
    forces_path
        ``grf.mot``, or None (kinematics-only, or forces from the C3D).
    """

    name: str
    markers_path: Path
    forces_path: Path | None


@dataclass(frozen=True)
class Subject:
    """An AddBiomechanics subject folder, validated but not yet loaded.

    Attributes
    ----------
    name
        The folder name.
    path
        The folder.
    mass_kg
        Body mass, kg (``massKg``).
    height_m
        Height, m (``heightM``), or None when the file does not give it.
    foot_body_names
        Bodies that can touch the ground (``footBodyNames``; default calcn_r, calcn_l).
    disable_dynamics
        ``disableDynamics``: fit kinematics only.
    model_path
        ``unscaled_generic.osim``.
    trials
        One entry per ``trials/<name>`` folder, sorted by name.
    raw
        The parsed ``_subject.json`` (read it, do not modify it).
    """

    name: str
    path: Path
    mass_kg: float
    height_m: float | None
    foot_body_names: tuple[str, ...]
    disable_dynamics: bool
    model_path: Path
    trials: tuple[TrialFiles, ...]
    raw: dict[str, Any] = field(default_factory=dict, compare=False, hash=False)

    @property
    def sex(self) -> str:
        """``sex`` from the JSON (``"unknown"`` when absent)."""
        return str(self.raw.get("sex", "unknown"))

    def trial(self, name: str) -> TrialFiles:
        """The trial named ``name``.

        Raises
        ------
        SubjectFolderError
            The subject has no trial ``name`` (the message names its trials).
        """
        for t in self.trials:
            if t.name == name:
                return t
        raise SubjectFolderError(f"no trial {name!r}; the subject's trials are {', '.join(t.name for t in self.trials)}", path=self.path)


@dataclass(frozen=True)
class Trial:
    """A loaded trial: markers and, unless kinematics-only, force plates."""

    name: str
    markers: MarkerTrajectories
    forces: ForceRecording | None


def folder_is_writable(folder: str | Path) -> bool:
    """Whether the folder's permission bits allow writing and this process may write there.

    ``os.access`` alone says yes to root even for a read-only folder (a lab's shared data
    mounted read-only, a folder marked ``r-x``): the mode bits are checked too. A folder
    that does not exist is not writable.
    """
    try:
        mode = stat.S_IMODE(Path(folder).stat().st_mode)
    except OSError:
        return False
    return bool(mode & (stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH)) and os.access(folder, os.W_OK | os.X_OK)


def output_folder_note(folder: str | Path, command: Sequence[str] | None = None) -> str | None:
    """What to tell a user who gave an output folder of addb where a subject folder was
    expected (its ``subject.json``, ``manifest.json`` or cache marks it,
    :func:`solver.outputs.output_marker`), naming its subject folder when that is the folder
    above it (``<subject>/addb_out``) or, for a subject of a dataset run's output tree, the
    subject folder of the dataset its summary records; None for any other folder.

    The message reads "is an output folder of addb (it holds subject.json), not a subject
    folder; expected the subject folder (the one with _subject.json) ...", to follow the
    folder's path in an error.

    Parameters
    ----------
    folder
        The folder given where a subject folder goes.
    command
        The command line to suggest, as arguments after ``addb``, with ``SUBJECT_DIR`` where
        the subject folder goes and without ``--out``: the message ends with it, the subject
        folder filled in when known and ``--out FOLDER`` added. None: the message says only
        "with this folder given as --out".
    """
    folder = Path(folder)
    marker = output_marker(folder)
    if marker is None or (folder / SUBJECT_JSON).is_file():
        return None
    subject = _subject_of_output(folder)
    if command is not None:
        subject_dir = str(subject) if subject is not None else "SUBJECT_DIR"
        line = shlex.join(["addb", *(subject_dir if a == "SUBJECT_DIR" else a for a in command), "--out", str(folder)])
        where = f", with this folder given as --out: {line}"
    elif subject is not None:
        where = f": here probably {subject}, with this folder given as --out"
    else:
        where = ", with this folder given as --out"
    return f"is an output folder of addb (it holds {marker}), not a subject folder; expected the subject folder (the one with {SUBJECT_JSON}){where}"


def _subject_of_output(folder: Path) -> Path | None:
    """The subject folder an output folder was made from, when it can be told: the folder
    above (``<subject>/addb_out``), or, for a subject's folder of a dataset run's output tree,
    the dataset folder its summary records joined with the subject's path in the tree."""
    parent = folder.resolve().parent
    if (parent / SUBJECT_JSON).is_file():
        return parent
    tree = output_tree_above(folder)
    if tree is None:
        return None
    try:
        summary = read_summary(tree)
    except (OSError, FileFormatError):
        return None
    rel = folder.resolve().relative_to(tree).as_posix()
    if rel not in {s["rel"] for s in summary["subjects"]}:
        return None
    subject = Path(summary["dataset"]).joinpath(*rel.split("/"))
    return subject if (subject / SUBJECT_JSON).is_file() else None


def trial_output_note(folder: str | Path) -> str | None:
    """What to tell a user who gave a trial's output folder (``OUT/walk``: it holds
    :data:`solver.outputs.TRIAL_RESULTS`) where a subject folder was expected, naming the
    subject folder when the output folder above it tells it (:func:`output_folder_note`'s
    rule); None for any other folder, and for one with its own ``_subject.json``."""
    folder = Path(folder)
    if not (folder / TRIAL_RESULTS).is_file() or (folder / SUBJECT_JSON).is_file():
        return None
    out = folder.resolve().parent
    subject = _subject_of_output(out)
    where = f": here probably {subject}, with {out} given as --out" if subject is not None else f", with {out} given as --out"
    return (
        f"is the output folder of one trial (it holds {TRIAL_RESULTS}), not a subject folder; expected the subject "
        f"folder (the one with {SUBJECT_JSON}){where}"
    )


def output_tree_part_note(folder: str | Path) -> str | None:
    """What to tell a user who gave a folder inside a dataset run's output tree that is no
    output of its own (``OUT/labA``, :func:`solver.outputs.tree_part`; :func:`output_folder_note`
    and :func:`trial_output_note` name the others) where a subject folder was expected; None for
    any other folder, and for one with its own ``_subject.json``."""
    folder = Path(folder)
    found = None if (folder / SUBJECT_JSON).is_file() else tree_part(folder)
    if found is None:
        return None
    tree = found[0]
    return (
        f"is a folder inside the dataset output tree {tree}, not a subject folder; expected a subject folder of the "
        f"dataset (addb info {tree} names the dataset folder), or addb view {tree} to review its subjects"
    )


def dataset_folder_note(folder: str | Path, depth: int = 3) -> str | None:
    """What to tell a user who gave a dataset folder (subject folders below it, found up to
    ``depth`` levels down, entering the folders the dataset search enters:
    :func:`solver.files.folders_to_search`) where one subject folder was expected; None
    for a folder with its own ``_subject.json`` or none below it."""
    base = Path(folder)
    if (base / SUBJECT_JSON).is_file():
        return None
    found: list[str] = []
    for here, dirs, files in os.walk(base, followlinks=True):
        rel = Path(here).relative_to(base)
        if SUBJECT_JSON in files and rel.parts:
            found.append(rel.as_posix())
            dirs[:] = []
            continue
        if len(rel.parts) >= depth:
            dirs[:] = []
            continue
        dirs[:] = folders_to_search(here, dirs)[0]
    if not found:
        return None
    return (
        f"is a dataset folder, not a subject folder ({SUBJECT_JSON} is in the folders below it: {listed(sorted(found), 3)}); "
        "give one subject folder, or process them all with addb process DATASET_DIR --out OUT"
    )


def check_subject_folder(folder: str | Path) -> None:
    """Refuse a folder given where a subject folder goes that holds no ``_subject.json``,
    saying what it is instead. ``addb view`` calls it to refuse such a folder on the terminal
    before its server starts; :func:`load_subject` calls it first.

    Raises
    ------
    SubjectFolderError
        Naming ``folder``: an output folder of addb (:func:`output_folder_note`), a trial's
        (:func:`trial_output_note`), a folder inside a dataset output tree
        (:func:`output_tree_part_note`) or a dataset folder (:func:`dataset_folder_note`);
        naming ``_subject.json`` when none of these says more: it is missing.
    """
    folder = Path(folder)
    if (folder / SUBJECT_JSON).is_file():
        return  # a subject folder: none of the notes applies
    note = output_folder_note(folder) or trial_output_note(folder) or output_tree_part_note(folder) or dataset_folder_note(folder)
    if note is not None:
        raise SubjectFolderError(note, path=folder)
    raise SubjectFolderError(f"{SUBJECT_JSON} is missing; expected a JSON object with massKg and heightM", path=folder / SUBJECT_JSON)


def load_subject(path: str | Path) -> Subject:
    """Read and check an AddBiomechanics subject folder (JSON, model, trial files).

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist.
    SubjectFolderError
        ``path`` is not a folder, or not a subject folder (:func:`check_subject_folder`:
        an output folder of addb, a folder inside a dataset output tree, a dataset folder,
        ``_subject.json`` missing); ``_subject.json`` not valid JSON (with its
        line), not an object, or without a positive ``massKg`` (naming the file and
        the key); a ``massKg`` over :data:`MOST_KG` or ``heightM`` over :data:`MOST_M` (a
        unit error); a malformed ``heightM``, ``footBodyNames`` (or an empty list, or one
        naming a body twice) or ``disableDynamics``;
        no ``unscaled_generic.osim``; no ``trials`` folder or no trial in it; a trial
        folder without ``markers.trc``/``markers.c3d`` or with both, or with a force file
        under another name than ``grf.mot`` (:func:`_force_file`). A byte-order mark at the
        start of ``_subject.json`` is dropped.
    """
    folder = Path(path)
    if not folder.exists():
        raise FileNotFoundError(2, "No such file or folder", str(folder))
    if not folder.is_dir():
        raise SubjectFolderError("expected a subject folder, found a file", path=folder)
    check_subject_folder(folder)
    raw = _read_json(folder / SUBJECT_JSON)
    json_path = folder / SUBJECT_JSON
    mass = _number(raw, "massKg", json_path, required=True, most=MOST_KG)
    height = _number(raw, "heightM", json_path, required=False, most=MOST_M)
    model = folder / MODEL_FILE
    if not model.is_file():
        raise SubjectFolderError(
            f"the model {MODEL_FILE} is missing; expected it beside {SUBJECT_JSON}", path=model
        )
    return Subject(
        name=folder.name,
        path=folder,
        mass_kg=mass,  # type: ignore[arg-type]
        height_m=height,
        foot_body_names=_foot_bodies(raw, json_path),
        disable_dynamics=_flag(raw, "disableDynamics", json_path),
        model_path=model,
        trials=_trials(folder),
        raw=raw,
    )


def _read_json(path: Path) -> dict[str, Any]:
    """The subject's ``_subject.json`` (:func:`check_subject_folder` found it) as an object."""
    try:
        raw = json.loads(path.read_text(encoding="utf-8-sig"))  # a byte-order mark (Windows editors) is dropped
    except UnicodeDecodeError:
        raise SubjectFolderError("not UTF-8 text", path=path) from None
    except json.JSONDecodeError as exc:
        raise SubjectFolderError(f"not valid JSON: {exc.msg}", path=path, line=exc.lineno) from None
    if not isinstance(raw, dict):
        raise SubjectFolderError(f"expected a JSON object, found {type(raw).__name__}", path=path)
    return raw


#: Largest ``massKg`` (kg) and ``heightM`` (m) read as such: a larger value is a unit error
#: (grams, centimetres), refused with the file and key named, not scaled to a giant.
MOST_KG = 500.0
MOST_M = 3.0


def _number(raw: dict[str, Any], key: str, path: Path, *, required: bool, most: float = math.inf) -> float | None:
    if key not in raw or raw[key] in ("", None):
        if required:
            raise SubjectFolderError(
                f"key {key!r} is missing; expected a positive number (string or number)",
                path=path,
                where=key,
            )
        return None
    value = raw[key]
    try:
        number = float(value) if not isinstance(value, bool) else math.nan
    except (TypeError, ValueError):
        number = math.nan
    if not (math.isfinite(number) and number > 0):
        raise SubjectFolderError(f"{key}={value!r} is not a positive number", path=path, where=key)
    if number > most:
        unit = "kg" if key == "massKg" else "m"
        raise SubjectFolderError(f"{key}={value!r} is more than {most:g} {unit}; expected the value in {unit} (not {'g or lb' if unit == 'kg' else 'cm or mm'})",
                                 path=path, where=key)
    return number


def _foot_bodies(raw: dict[str, Any], path: Path) -> tuple[str, ...]:
    value = raw.get("footBodyNames")
    if value is None:
        return DEFAULT_FOOT_BODIES
    if not isinstance(value, list) or not value or not all(isinstance(v, str) and v for v in value):
        raise SubjectFolderError(
            f"footBodyNames={value!r}; expected a list of one or more body names (the feet: contact is found from them)",
            path=path,
            where="footBodyNames",
        )
    repeated = sorted({v for v in value if value.count(v) > 1})
    if repeated:
        raise SubjectFolderError(
            f"footBodyNames={value!r} names {', '.join(repeated)} more than once; expected each foot body once",
            path=path,
            where="footBodyNames",
        )
    return tuple(value)


def _flag(raw: dict[str, Any], key: str, path: Path) -> bool:
    value = raw.get(key, False)
    if isinstance(value, bool):
        return value
    if isinstance(value, str) and value.strip().lower() in ("true", "false"):
        return value.strip().lower() == "true"
    raise SubjectFolderError(f"{key}={value!r}; expected true or false", path=path, where=key)


def _trials(folder: Path) -> tuple[TrialFiles, ...]:
    trials_dir = folder / "trials"
    if not trials_dir.is_dir():
        raise SubjectFolderError(
            "the trials folder is missing; expected trials/<name>/markers.trc", path=trials_dir
        )
    out = []
    for trial in sorted(p for p in trials_dir.iterdir() if p.is_dir()):
        trc, c3d = trial / "markers.trc", trial / "markers.c3d"
        if trc.is_file() and c3d.is_file():
            raise SubjectFolderError("both markers.trc and markers.c3d; expected one", path=trial)
        markers = trc if trc.is_file() else c3d if c3d.is_file() else None
        if markers is None:
            raise SubjectFolderError(
                "no markers.trc or markers.c3d in the trial folder", path=trial
            )
        out.append(TrialFiles(trial.name, markers, _force_file(trial)))
    if not out:
        raise SubjectFolderError("no trial folders; expected trials/<name>/", path=trials_dir)
    return tuple(out)


def _force_file(trial: Path) -> Path | None:
    """The trial's ``grf.mot``, or None when the trial has no force file.

    Raises
    ------
    SubjectFolderError
        ``grf.mot`` is not a file (a folder), or the trial holds a force file under
        another name (``GRF.mot``, ``grf.sto``: a stem ``grf`` in any case, a ``.mot`` or
        ``.sto`` suffix), which would otherwise leave the trial without forces unsaid.
    """
    grf = trial / "grf.mot"
    if grf.is_file():
        return grf
    if grf.exists():
        raise SubjectFolderError("grf.mot is not a file; expected the force plates' table", path=grf)
    near = sorted(p.name for p in trial.iterdir() if p.stem.lower() == "grf" and p.suffix.lower() in (".mot", ".sto"))
    if near:
        raise SubjectFolderError(
            f"found {', '.join(near)} but addb reads the force plates from grf.mot (that name, lower case); rename it, "
            "or move it out of the trial folder to process the trial without forces",
            path=trial,
        )
    return None


def unapplied_range_note(subject: Subject, trial: str, time: Sequence[float]) -> str | None:
    """What to tell the user when ``_subject.json`` cuts ``trial`` with ``trialRanges``
    (AddBiomechanics' ``{trial: [start, end]}``, seconds), a key addb does not apply: the
    trial is processed whole (README, "The subject folder").

    Parameters
    ----------
    subject
        The subject (its ``raw`` JSON is read).
    trial
        The trial's name.
    time
        ``(T,)`` the trial's marker frame times, s.

    Returns
    -------
    The note (naming the file, the range, the trial's span and the frames outside the
    range), or None when the key names no range for the trial or the range holds every
    frame. An entry that is not two numbers is named as such (the AddBiomechanics engine
    would refuse it).
    """
    ranges = subject.raw.get("trialRanges")
    if not isinstance(ranges, dict) or trial not in ranges:
        return None
    where = f"{subject.path / SUBJECT_JSON}: trialRanges gives trial {trial}"
    entry = ranges[trial]
    ok = isinstance(entry, list | tuple) and len(entry) == 2 and all(isinstance(v, int | float) and not isinstance(v, bool) for v in entry)
    if not ok:
        return f"{where} {entry!r}, not [start, end] in seconds; addb does not apply trialRanges and processes the whole trial"
    start, end = float(entry[0]), float(entry[1])
    times = [float(t) for t in time]
    outside = sum(1 for t in times if not start <= t <= end)
    if not times or outside == 0:
        return None
    return (
        f"{where} [{start!r}, {end!r}] s; addb does not apply trialRanges and processes the whole trial "
        f"({times[0]:.2f}-{times[-1]:.2f} s), the {outside} of its {len(times)} marker frames outside the range "
        "included (cut the trial's files to leave them out)"
    )


def load_trial(files: TrialFiles) -> Trial:
    """Read a trial's markers and forces.

    Returns
    -------
    Trial
        Markers from the TRC/C3D, each single-frame spike read as missing with a
        warning (:func:`solver.io.spikes.without_spikes`); forces from ``grf.mot`` when
        present, else from the C3D platforms, else None (kinematics-only).

    Raises
    ------
    TrcFormatError, C3dFormatError, MotFormatError
        From the readers, naming the file and line.
    """
    if files.markers_path.suffix.lower() == ".c3d":
        markers, c3d_forces = read_c3d(files.markers_path)
    else:
        markers, c3d_forces = read_trc(files.markers_path), None
    forces = read_forces(files.forces_path) if files.forces_path is not None else c3d_forces
    return Trial(files.name, without_spikes(markers), forces)
