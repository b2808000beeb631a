"""Model extensions saved by ``addb diagnose --apply`` and applied by the next ``addb process``.

The file ``addb_extensions.json`` beside the subject's ``_subject.json`` lists extensions
in the order they were applied; each corrects the raw recordings (or the subject) the way
its cause says they are wrong, so applying them in order composes (two time offsets add,
two gains multiply)::

    {"schema": "addb.extensions", "version": 1, "extensions": [
        {"cause": "force_time_offset", "trial": "walk", "delay_s": 0.038},
        {"cause": "plate_force_offset", "trial": "walk", "plate": "l", "offset_N": [20.1, 39.8, -17.5],
         "centre_m": [0.35, 0.0, 0.2]},
        {"cause": "plate_force_gain", "trial": "walk", "plate": "r", "gain": 1.05},
        {"cause": "plate_position_offset", "trial": "walk", "plate": "r", "shift_m": [0.03, 0.0, 0.0]},
        {"cause": "plate_registration", "trial": "run", "shift_m": [0.013, 0.0, 0.0], "rotation_rad": 0.01,
         "centre_m": [0.89, 0.0, -0.34]},
        {"cause": "marker_offset", "trial": "walk", "marker": "R.Knee", "body": "femur_r",
         "shift_m": [0.0, 0.02, 0.0], "time_s": [...], "lab_shift_m": [[...], ...]},
        {"cause": "body_mass", "trial": null, "mass_change_kg": 4.9},
        {"cause": "segment_mass_distribution", "trial": null, "mass_change_kg": {"trunk": -2.0, "legs": 2.0},
         "model": "addb_extensions.osim"},
        {"cause": "unmeasured_force", "trial": "walk", "n_frames": 238, "frames": [[0, 47], [196, 238]],
         "times_s": [[0.0, 0.46], [1.96, 2.37]]}
    ]}

(each entry also records ``source`` and ``created``). Corrections (one entry per cause in
the table :data:`CORRECTIONS`; a cause it does not know is refused when the file is read):

* ``force_time_offset``: the force samples move to ``time - delay_s`` (forces were late);
* ``plate_force_offset``: the plate's force minus ``offset_N`` acting at ``centre_m``, the
  plate's centre (its moment about that point as recorded; centre of pressure and free
  moment derived again, :func:`offset_plate`); entries without ``centre_m`` (saved before
  2026-11-22) subtract it at the centre of pressure;
* ``plate_force_gain``: the plate's force and free moment divided by ``gain``;
* ``plate_position_offset``: the plate's centre of pressure minus ``shift_m``;
* ``plate_registration``: every plate's readings moved back rigidly (the plates as a whole
  misregistered against the motion-capture frame): centre of pressure
  ``centre_m + Rᵀ (cop - centre_m - shift_m)``, force and free moment turned by ``Rᵀ``, with
  ``R`` the rotation by ``rotation_rad`` (0 when absent) about the vertical
  (:func:`register_plates` makes such a misregistration);
* ``marker_offset``: the marker's recorded positions minus ``lab_shift_m`` (its body-fixed
  ``shift_m`` rotated by its body's orientation in the diagnosed trial, one row per time in
  ``time_s``, interpolated onto the marker frames). ``shift_m`` is the shift beyond the
  offset the kinematics stage already gives the model marker (fitted on every trial, the
  static one included); ``misplacement_m`` (for reading) adds that offset, the whole
  misplacement from the generic model's landmark. Entries saved before 2026-11-23 applied
  the whole misplacement, which counted the fitted offset twice;
* ``body_mass``: the subject's mass plus ``mass_change_kg``;
* ``segment_mass_distribution``: the subject's model is replaced by ``model`` (the generic
  model with the groups' masses changed, written by ``--apply`` beside this file);
* ``unmeasured_force``: the marker frames in ``frames`` (half-open ranges of a trial of
  ``n_frames`` marker frames; ``times_s`` for reading) are unmeasured: they join the
  trial's unmeasured-force mask, or replace the automatic proposals when the reviewer
  gave no mask for the trial.

:func:`apply_extensions` (the trials), :func:`extend_subject` (mass, model) and
:func:`extension_masks` (unmeasured frames) are pure functions of their inputs and the
file; the pipeline calls all three.
"""

from __future__ import annotations

import json
import time as _time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from solver.dynamics.preprocess import cop_from_wrench, moment_about_origin
from solver.errors import SubjectFolderError
from solver.io.subject import Subject, Trial
from solver.io.types import ForcePlate, ForceRecording, MarkerTrajectories
from solver.masks import join_masks

FILE_NAME = "addb_extensions.json"
MODEL_NAME = "addb_extensions.osim"
SCHEMA = "addb.extensions"
VERSION = 1

BoolArray = NDArray[np.bool_]
FloatArray = NDArray[np.float64]


def extensions_path(subject_dir: str | Path) -> Path:
    """``<subject_dir>/addb_extensions.json``."""
    return Path(subject_dir) / FILE_NAME


def read_extensions(subject_dir: str | Path) -> list[dict[str, Any]]:
    """The saved extensions of a subject folder, in order ([] when there is no file).

    Raises
    ------
    SubjectFolderError
        The file is not valid JSON or not of this schema, or an extension's cause has no
        correction (:data:`CORRECTIONS`).
    """
    path = extensions_path(subject_dir)
    if not path.is_file():
        return []
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SubjectFolderError(f"not a valid extensions file: {exc}", path=path) from None
    if not isinstance(data, dict) or data.get("schema") != SCHEMA or data.get("version") != VERSION:
        raise SubjectFolderError(f"expected {SCHEMA} version {VERSION}", path=path)
    exts = data.get("extensions", [])
    if not isinstance(exts, list) or not all(isinstance(e, dict) and "cause" in e for e in exts):
        raise SubjectFolderError("'extensions' must be a list of objects with a 'cause'", path=path)
    for i, e in enumerate(exts):
        if e["cause"] not in CORRECTIONS:
            raise SubjectFolderError(
                f"extension {i + 1} has cause {e['cause']!r}, which this version cannot apply (known: {', '.join(CORRECTIONS)})", path=path
            )
        _check_fields(i, e, path)
    return exts


def _check_fields(i: int, entry: Mapping[str, Any], path: Path) -> None:
    """Raise SubjectFolderError naming extension ``i + 1`` of ``path`` and the field, when
    a field its cause's correction reads is missing or of the wrong kind
    (:attr:`Correction.fields`, :attr:`Correction.optional`)."""
    spec = CORRECTIONS[entry["cause"]]
    for name, kind in (*spec.fields.items(), *spec.optional.items()):
        if name not in entry:
            if name in spec.fields:
                raise SubjectFolderError(f"extension {i + 1} ({entry['cause']}) has no {name!r}; expected {FIELD_KINDS[kind][1]}",
                                         path=path, where=f"extensions[{i}].{name}")
            continue
        ok, expected = FIELD_KINDS[kind]
        if not ok(entry[name]):
            raise SubjectFolderError(f"extension {i + 1} ({entry['cause']}) has {name}={entry[name]!r}; expected {expected}",
                                     path=path, where=f"extensions[{i}].{name}")
    if spec.check is not None and (problem := spec.check(entry)) is not None:
        field_name, message = problem
        raise SubjectFolderError(f"extension {i + 1} ({entry['cause']}) {message}", path=path, where=f"extensions[{i}].{field_name}")


def _one_shift_per_time(entry: Mapping[str, Any]) -> tuple[str, str] | None:
    """``marker_offset``: as many ``lab_shift_m`` rows as ``time_s`` values."""
    if len(entry["time_s"]) != len(entry["lab_shift_m"]):
        return "lab_shift_m", f"has {len(entry['time_s'])} times and {len(entry['lab_shift_m'])} lab_shift_m rows; expected one row per time"
    return None


def _frames_within(entry: Mapping[str, Any]) -> tuple[str, str] | None:
    """``unmeasured_force``: every frame range within ``n_frames``."""
    if any(r[1] > entry["n_frames"] for r in entry.get("frames", [])):
        return "frames", f"has a frame range past n_frames={entry['n_frames']}"
    return None


def append_extension(subject_dir: str | Path, extension: Mapping[str, Any], *, source: str = "addb diagnose") -> Path:
    """Append one extension to the subject's file (created when missing); returns its path.

    Raises
    ------
    SubjectFolderError
        The subject folder cannot be written.
    """
    path = extensions_path(subject_dir)
    exts = read_extensions(subject_dir)
    entry = dict(extension)
    entry.setdefault("source", source)
    entry.setdefault("created", _time.strftime("%Y-%m-%dT%H:%M:%SZ", _time.gmtime()))
    exts.append(entry)
    text = json.dumps({"schema": SCHEMA, "version": VERSION, "extensions": exts}, indent=1)
    tmp = path.with_name(path.name + ".tmp")
    try:
        tmp.write_text(text + "\n", encoding="utf-8")
        tmp.replace(path)
    except OSError as exc:
        raise SubjectFolderError(f"cannot write the extensions file ({exc.strerror})", path=path) from None
    return path


# --------------------------------------------------------------------------- trials


def _map_plates(forces: ForceRecording, plate: str, fn: Any) -> ForceRecording:
    names = [p.name for p in forces.plates]
    if plate not in names:
        raise SubjectFolderError(f"extension names plate {plate!r}; the recording has {', '.join(names)}", path=forces.source or None)
    return ForceRecording(forces.time, forces.rate_hz, tuple(fn(p) if p.name == plate else p for p in forces.plates), forces.source)


def correct_forces(forces: ForceRecording, ext: Mapping[str, Any]) -> ForceRecording:
    """The recording with one extension's force correction applied (an extension that does
    not correct forces leaves it unchanged; :data:`CORRECTIONS`).

    Raises
    ------
    SubjectFolderError
        The extension names a plate the recording lacks.
    ValueError
        The extension's cause has no correction (:func:`correction`).
    """
    fn = correction(ext["cause"]).forces
    return forces if fn is None else fn(forces, ext)


def _delay_forces(forces: ForceRecording, ext: Mapping[str, Any]) -> ForceRecording:
    """``force_time_offset``: the force samples move to ``time - delay_s``."""
    return ForceRecording(np.asarray(forces.time) - float(ext["delay_s"]), forces.rate_hz, forces.plates, forces.source)


def _offset_forces(forces: ForceRecording, ext: Mapping[str, Any]) -> ForceRecording:
    """``plate_force_offset``: the plate's force minus ``offset_N`` acting at ``centre_m``
    (:func:`offset_plate`); entries without ``centre_m`` subtract it at the centre of pressure."""
    off = np.asarray(ext["offset_N"], dtype=float)
    if "centre_m" not in ext:  # entries saved before 2026-11-22 (fourth session): at the CoP
        return _map_plates(forces, ext["plate"], lambda p: ForcePlate(p.name, p.force - off, p.cop, p.free_moment, p.corners))
    centre = np.asarray(ext["centre_m"], dtype=float)
    return _map_plates(forces, ext["plate"], lambda p: offset_plate(p, -off, centre))


def _gain_forces(forces: ForceRecording, ext: Mapping[str, Any]) -> ForceRecording:
    """``plate_force_gain``: the plate's force and free moment divided by ``gain``."""
    g = float(ext["gain"])
    return _map_plates(forces, ext["plate"], lambda p: ForcePlate(p.name, p.force / g, p.cop, p.free_moment / g, p.corners))


def _shift_forces(forces: ForceRecording, ext: Mapping[str, Any]) -> ForceRecording:
    """``plate_position_offset``: the plate's centre of pressure minus ``shift_m``."""
    s = np.asarray(ext["shift_m"], dtype=float)
    return _map_plates(forces, ext["plate"], lambda p: ForcePlate(p.name, p.force, p.cop - s, p.free_moment, p.corners))


def turn_about_vertical(angle: float) -> FloatArray:
    """``(3, 3)`` rotation by ``angle`` rad about the vertical (y) axis of the ground frame."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def register_plates(forces: ForceRecording, shift: FloatArray, rotation: float, centre: FloatArray) -> ForceRecording:
    """Every plate's readings moved rigidly: turned by ``rotation`` rad about the vertical
    axis through ``centre`` (3,) m, then shifted by ``shift`` (3,) m, ground frame.

    What a plate misregistered that way against the motion-capture frame reports, from what
    it measures: centre of pressure ``centre + R (cop - centre) + shift``, force, free moment
    and corners turned alike (``R`` :func:`turn_about_vertical`; the corners move as the
    centre of pressure). ``plate_registration`` extensions apply the inverse
    (:func:`_register_forces`); the diagnosis' tests hide one with this.
    """
    r = turn_about_vertical(float(rotation))
    o, s = np.asarray(centre, dtype=float), np.asarray(shift, dtype=float)

    def move(p: ForcePlate) -> ForcePlate:
        corners = None if p.corners is None else (np.asarray(p.corners, dtype=float) - o) @ r.T + o + s
        return ForcePlate(p.name, np.asarray(p.force) @ r.T, (np.asarray(p.cop) - o) @ r.T + o + s, np.asarray(p.free_moment) @ r.T, corners)

    return ForceRecording(forces.time, forces.rate_hz, tuple(move(p) for p in forces.plates), forces.source)


def _register_forces(forces: ForceRecording, ext: Mapping[str, Any]) -> ForceRecording:
    """``plate_registration``: every plate's readings moved back, the inverse of
    :func:`register_plates` with the entry's ``shift_m``, ``rotation_rad`` (0 when absent)
    and ``centre_m`` o: ``cop = o + Rᵀ (cop_read - o - shift_m)``, force and free moment
    turned by ``Rᵀ`` (that is, turned by ``-rotation_rad`` about ``o + shift_m``, then
    shifted by ``-shift_m``)."""
    o = np.asarray(ext["centre_m"], dtype=float)
    s = np.asarray(ext["shift_m"], dtype=float)
    return register_plates(forces, -s, -float(ext.get("rotation_rad", 0.0)), o + s)


#: Below this vertical force (N) a plate's corrected centre of pressure is not recomputed
#: (:func:`offset_plate`): the recorded one is kept, where a near-zero force acts.
COP_MIN_FORCE_N = 20.0


def offset_plate(plate: ForcePlate, offset: FloatArray, centre: FloatArray) -> ForcePlate:
    """A plate whose readings gain a constant force ``offset`` (3,) N acting at ``centre``
    (3,) m, ground frame: the zero drift of its force channels.

    A plate measures force and moment about its own reference point; a drift of its force
    channels leaves that moment as it was, so the offset acts at the plate (its centre), not
    at the foot's centre of pressure, and the centre of pressure the lab software derives
    from the drifted force moves. Here the moment about the ground
    origin gains ``centre x offset`` and the centre of pressure and vertical free moment are
    derived again from the new force and moment (on the plane of ``centre``), where the new
    vertical force exceeds :data:`COP_MIN_FORCE_N`; elsewhere the recorded ones are kept.

    ``offset`` = -(a drift) corrects a drifting plate; + (a drift) hides one.
    """
    f = np.asarray(plate.force, dtype=float)
    cop = np.asarray(plate.cop, dtype=float)
    free = np.asarray(plate.free_moment, dtype=float)
    m_o = moment_about_origin(np.nan_to_num(f), np.nan_to_num(cop), np.nan_to_num(free)) + np.cross(centre, offset)
    f_new = f + offset
    cop_new, free_new = cop_from_wrench(np.nan_to_num(f_new), m_o, float(centre[1]), COP_MIN_FORCE_N)
    keep = ~np.isfinite(cop_new).all(axis=1)
    cop_new[keep] = cop[keep]
    free_new[keep] = free[keep]
    return ForcePlate(plate.name, f_new, cop_new, free_new, plate.corners)


def correct_markers(markers: MarkerTrajectories, ext: Mapping[str, Any]) -> MarkerTrajectories:
    """The markers with one extension's marker correction applied (an extension that does
    not correct markers leaves them unchanged; :data:`CORRECTIONS`).

    Raises
    ------
    ValueError
        The extension's cause has no correction (:func:`correction`).
    """
    fn = correction(ext["cause"]).markers
    return markers if fn is None else fn(markers, ext)


def _shift_marker(markers: MarkerTrajectories, ext: Mapping[str, Any]) -> MarkerTrajectories:
    """``marker_offset``: the marker's recorded positions minus ``lab_shift_m`` (interpolated
    from ``time_s`` onto the marker frames); a marker the recording lacks: unchanged."""
    if ext["marker"] not in markers.names:
        return markers
    j = markers.names.index(ext["marker"])
    t_ext = np.asarray(ext["time_s"], dtype=float)
    shift = np.asarray(ext["lab_shift_m"], dtype=float).reshape(-1, 3)
    lab = np.stack([np.interp(markers.time, t_ext, shift[:, a]) for a in range(3)], axis=1)
    pos = np.array(markers.positions)
    pos[:, j] -= lab
    return MarkerTrajectories(markers.names, pos, markers.time, markers.rate_hz, markers.source)


def apply_extensions(subject: Subject, trials: Sequence[Trial]) -> tuple[Trial, ...]:
    """The subject's loaded raw trials with its saved extensions applied, in file order.

    Parameters
    ----------
    subject
        The subject (its folder holds ``addb_extensions.json``, or nothing to apply).
    trials
        Its loaded trials (:func:`solver.io.subject.load_trial`).

    Returns
    -------
    tuple of Trial
        The same trials, with corrected forces and markers where an extension names them.

    Raises
    ------
    SubjectFolderError
        A damaged extensions file, or an extension naming a plate the trial lacks.
    """
    exts = read_extensions(subject.path)
    if not exts:
        return tuple(trials)
    out = []
    for trial in trials:
        markers, forces = trial.markers, trial.forces
        for ext in exts:
            if ext.get("trial") != trial.name:
                continue
            markers = correct_markers(markers, ext)
            if forces is not None:
                forces = correct_forces(forces, ext)
        out.append(Trial(trial.name, markers, forces))
    return tuple(out)


def unmeasured_mask(ext: Mapping[str, Any]) -> BoolArray:
    """``(n_frames,)`` marker frames of an ``unmeasured_force`` extension."""
    mask = np.zeros(int(ext["n_frames"]), dtype=bool)
    for a, b in ext.get("frames", []):
        mask[int(a) : int(b)] = True
    return mask


def extend_subject(subject: Subject) -> Subject:
    """The subject with the mass and model of its saved extensions.

    Returns
    -------
    Subject
        ``mass_kg`` plus every ``body_mass`` change, ``model_path`` the last
        ``segment_mass_distribution`` model.
    """
    for ext in read_extensions(subject.path):
        fn = correction(ext["cause"]).subject
        if fn is not None:
            subject = fn(subject, ext)
    return subject


def _change_mass(subject: Subject, ext: Mapping[str, Any]) -> Subject:
    """``body_mass``: the subject's mass plus ``mass_change_kg``.

    Raises
    ------
    SubjectFolderError
        The changed mass is not positive (naming the extensions file).
    """
    mass = subject.mass_kg + float(ext["mass_change_kg"])
    if not mass > 0:
        raise SubjectFolderError(f"a body_mass extension changes the subject's {subject.mass_kg:g} kg by "
                                 f"{float(ext['mass_change_kg']):g} kg to {mass:g} kg; expected a positive mass",
                                 path=subject.path / FILE_NAME)
    return replace(subject, mass_kg=mass)


def _redistributed_model(subject: Subject, ext: Mapping[str, Any]) -> Subject:
    """``segment_mass_distribution``: the subject's model replaced by the entry's ``model``
    (beside the extensions file)."""
    return replace(subject, model_path=subject.path / str(ext["model"])) if ext.get("model") else subject


def extension_masks(subject: Subject) -> dict[str, BoolArray]:
    """Trial -> ``(T_markers,)`` bool, at the trial's marker frames, of the frames that saved
    ``unmeasured_force`` extensions mark as unmeasured (several extensions of one trial
    joined by :func:`solver.masks.join_masks`); {} when there are none.

    The dynamics stage resamples them onto its frames and joins them to the reviewer's
    flags, or to its automatic proposals when the reviewer gave none, so a later step off
    the plates is still proposed.

    Raises
    ------
    SubjectFolderError
        A damaged extensions file.
    DynamicsError
        Two extensions of one trial with different frame counts (naming the file and trial).
    """
    masks: dict[str, BoolArray] = {}
    for ext in read_extensions(subject.path):
        if ext["cause"] == "unmeasured_force":
            masks = join_masks(masks, {str(ext["trial"]): unmeasured_mask(ext)}, path=subject.path / FILE_NAME) or {}
    return masks


def save_extension(subject_dir: str | Path, entry: Mapping[str, Any]) -> Path:
    """Save a diagnosis' extension entry for the next processing of the subject.

    ``segment_mass_distribution`` also writes ``addb_extensions.osim``: the subject's
    current model (the generic one, or the last saved redistribution) with each body
    group's mass changed by the entry's ``fraction`` of that group's mass.

    Returns
    -------
    Path
        The extensions file.

    Raises
    ------
    SubjectFolderError
        The subject folder is not writable.
    """
    from solver.io.subject import folder_is_writable

    folder = Path(subject_dir)
    if not folder_is_writable(folder):
        raise SubjectFolderError(
            "the subject folder is read-only; copy the subject to a folder you can write to and apply there", path=folder
        )
    entry = dict(entry)
    prepare = correction(entry["cause"]).prepare
    if prepare is not None:
        entry = prepare(folder, entry)
    return append_extension(folder, entry)


def _write_redistributed_model(folder: Path, entry: dict[str, Any]) -> dict[str, Any]:
    """``segment_mass_distribution`` on saving: write ``addb_extensions.osim``, the subject's
    current model (the generic one, or the last saved redistribution) with each body group's
    mass changed by the entry's ``fraction`` of that group's mass; the entry names it."""
    from solver.io.subject import load_subject
    from solver.model.mass_groups import group_masses, redistribute
    from solver.model.osim import read_osim
    from solver.model.osim_writer import write_osim

    subject = extend_subject(load_subject(folder))
    model = read_osim(subject.model_path)
    group_mass = group_masses(model)
    change = {g: float(f) * group_mass.get(g, 0.0) for g, f in entry.get("fraction", {}).items()}
    write_osim(redistribute(model, change), folder / MODEL_NAME)
    return {**entry, "model": MODEL_NAME}


# --------------------------------------------------------------------------- the table


@dataclass(frozen=True)
class Correction:
    """How a saved extension of one cause corrects the raw recordings or the subject (each
    part None when the cause does not touch it).

    Attributes
    ----------
    forces
        ``(recording, entry) -> recording`` (:func:`correct_forces`).
    markers
        ``(markers, entry) -> markers`` (:func:`correct_markers`).
    subject
        ``(subject, entry) -> subject``: its mass or model (:func:`extend_subject`).
    prepare
        ``(subject folder, entry) -> entry`` on saving (:func:`save_extension`): writes the
        files the entry refers to.
    fields, optional
        The entry's fields these read, name -> kind (:data:`FIELD_KINDS`): required, and
        checked when present; :func:`read_extensions` refuses an entry that lacks one or
        holds the wrong kind.
    check
        ``entry -> (field, problem)`` or None: a check across the entry's fields, after
        theirs (:func:`read_extensions` refuses the entry with the problem).

    ``unmeasured_force`` extensions have no function: their frames join the masks
    (:func:`extension_masks`); only their fields and check.
    """

    forces: Callable[[ForceRecording, Mapping[str, Any]], ForceRecording] | None = None
    markers: Callable[[MarkerTrajectories, Mapping[str, Any]], MarkerTrajectories] | None = None
    subject: Callable[[Subject, Mapping[str, Any]], Subject] | None = None
    prepare: Callable[[Path, dict[str, Any]], dict[str, Any]] | None = None
    fields: Mapping[str, str] = field(default_factory=dict)
    optional: Mapping[str, str] = field(default_factory=dict)
    check: Callable[[Mapping[str, Any]], tuple[str, str] | None] | None = None


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and bool(np.isfinite(v))


def _is_vector(v: Any) -> bool:
    return isinstance(v, list) and len(v) == 3 and all(_is_number(x) for x in v)


#: Kind of an extension field -> (test of its JSON value, what is expected, for the error).
FIELD_KINDS: dict[str, tuple[Callable[[Any], bool], str]] = {
    "text": (lambda v: isinstance(v, str) and bool(v), "a name (text)"),
    "number": (_is_number, "a number"),
    "positive": (lambda v: _is_number(v) and v > 0, "a positive number"),
    "count": (lambda v: isinstance(v, int) and not isinstance(v, bool) and v > 0, "a positive whole number"),
    "vector": (_is_vector, "3 numbers [x, y, z]"),
    "numbers": (lambda v: isinstance(v, list) and len(v) > 0 and all(_is_number(x) for x in v), "a list of numbers"),
    "vectors": (lambda v: isinstance(v, list) and len(v) > 0 and all(_is_vector(x) for x in v), "a list of [x, y, z] rows"),
    "masses": (lambda v: isinstance(v, dict) and all(isinstance(k, str) and _is_number(x) for k, x in v.items()),
               "an object of group name -> kg"),
    "frames": (lambda v: isinstance(v, list) and all(
        isinstance(r, list) and len(r) == 2 and all(isinstance(x, int) and not isinstance(x, bool) for x in r) and 0 <= r[0] <= r[1]
        for r in v), "a list of [start, stop] frame ranges (whole numbers, start <= stop)"),
}


#: Cause name -> its correction. Every diagnosis cause has an entry here (the diagnosis'
#: registry refuses one that has not, :func:`solver.diagnose.causes.base.check`); the
#: diagnosis' cause module says how the entry is written, this table how it is applied.
CORRECTIONS: dict[str, Correction] = {
    "unmeasured_force": Correction(fields={"trial": "text", "n_frames": "count"}, optional={"frames": "frames"}, check=_frames_within),
    "body_mass": Correction(subject=_change_mass, fields={"mass_change_kg": "number"}),
    "force_time_offset": Correction(forces=_delay_forces, fields={"trial": "text", "delay_s": "number"}),
    "plate_force_offset": Correction(forces=_offset_forces, fields={"trial": "text", "plate": "text", "offset_N": "vector"},
                                     optional={"centre_m": "vector"}),
    "plate_force_gain": Correction(forces=_gain_forces, fields={"trial": "text", "plate": "text", "gain": "positive"}),
    "plate_position_offset": Correction(forces=_shift_forces, fields={"trial": "text", "plate": "text", "shift_m": "vector"}),
    "segment_mass_distribution": Correction(subject=_redistributed_model, prepare=_write_redistributed_model,
                                            optional={"model": "text", "mass_change_kg": "masses"}),
    "marker_offset": Correction(markers=_shift_marker, fields={"trial": "text", "marker": "text", "time_s": "numbers",
                                                               "lab_shift_m": "vectors"}, optional={"shift_m": "vector"},
                                 check=_one_shift_per_time),
    "plate_registration": Correction(forces=_register_forces, fields={"trial": "text", "shift_m": "vector", "centre_m": "vector"},
                                     optional={"rotation_rad": "number"}),
}


def correction(cause: str) -> Correction:
    """The correction of extensions of ``cause``.

    Raises
    ------
    ValueError
        No correction is known for ``cause`` (the message lists the known causes).
    """
    try:
        return CORRECTIONS[cause]
    except (KeyError, TypeError):
        raise ValueError(f"no correction is known for extensions of cause {cause!r}; known: {', '.join(CORRECTIONS)}") from None
