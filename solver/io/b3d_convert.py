"""Between .b3d files and addb's folders.

* :func:`b3d_to_subject`: a .b3d file -> an AddBiomechanics subject folder that
  ``addb process`` solves (``_subject.json``, the embedded model as
  ``unscaled_generic.osim``, ``trials/<trial>/markers.trc`` and ``grf.mot``), plus the
  file's missing-GRF labels per trial for the caller to store as a review record (this
  module does not write review records: :mod:`solver` does not import ``annotations``).
* :func:`processed_to_b3d`: a processed output folder -> a .b3d file (sensor data, a
  kinematics pass and a dynamics pass, the scaled model).

Format reference: keenon/nimblephysics ``dart/proto/SubjectOnDisk.proto`` and
``dart/biomechanics/SubjectOnDisk.cpp``; the raw plate torque of a sensor frame is the
free moment about the centre of pressure (checked on results.b3d: the stored contact
wrench about the origin equals CoP × force + that torque).
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from solver.errors import SubjectFolderError
from solver.io.b3d import B3dFile, open_b3d
from solver.io.mot import write_forces
from solver.io.subject import MODEL_FILE, SUBJECT_JSON
from solver.io.trc import write_trc
from solver.io.types import ForcePlate, ForceRecording, MarkerTrajectories
from solver.outputs import SUBJECT_RECORD
from solver.sampling import frame_interval, nominal_interval

#: The name of the file in a converted subject folder that says where it came from.
SOURCE_JSON = "b3d_source.json"


@dataclass(frozen=True)
class ConvertedTrial:
    """One trial written by :func:`b3d_to_subject`.

    Attributes
    ----------
    name
        Trial folder name (the .b3d trial name, with path separators replaced).
    b3d_name
        The trial name in the .b3d file.
    n_frames, rate_hz
        Frames and frame rate of the written markers and forces.
    missing_grf
        ``(N,)`` the file's missing-GRF reason per frame (``"notMissingGRF"`` = measured).
    """

    name: str
    b3d_name: str
    n_frames: int
    rate_hz: float
    missing_grf: tuple[str, ...] = field(repr=False)

    @property
    def missing_mask(self) -> np.ndarray:
        """``(N,)`` bool: frames the file marks as missing ground reaction force."""
        return np.array([r != "notMissingGRF" for r in self.missing_grf], dtype=bool)


@dataclass(frozen=True)
class ConvertedSubject:
    """Result of :func:`b3d_to_subject`: the subject folder and its trials."""

    path: Path
    source: Path
    trials: tuple[ConvertedTrial, ...]
    #: Trial folders an earlier conversion into the folder wrote that this file does not
    #: have, removed by ``overwrite``.
    removed: tuple[str, ...] = ()
    #: Such folders kept because something other than the conversion's files is in them.
    kept: tuple[str, ...] = ()


def _folder_name(name: str, used: set[str]) -> str:
    base = re.sub(r"[\\/:\s]+", "_", name).strip("._") or "trial"
    out, k = base, 1
    while out in used:
        k += 1
        out = f"{base}_{k}"
    used.add(out)
    return out


def b3d_to_subject(
    path: str | Path | B3dFile,
    out_dir: str | Path,
    *,
    pass_index: int = 0,
    overwrite: bool = False,
) -> ConvertedSubject:
    """Write a .b3d file as an AddBiomechanics subject folder.

    Markers go to ``markers.trc`` (mm, unobserved = NaN; a marker with an empty name is
    left out, as no TRC column can be named "", and so is a marker not observed on any
    frame of the trial, which ``addb process`` refuses; a position of exactly (0, 0, 0),
    which some .b3d files hold for unobserved markers, reads back from the TRC as missing,
    the TRC convention); the raw force plates of every frame to
    ``grf.mot`` (force N, centre of pressure m, free moment N·m, plates named 1..P). The
    model of processing pass ``pass_index`` (AddBiomechanics' scaled model) becomes
    ``unscaled_generic.osim``; ``_subject.json`` carries mass, height, sex, age, tags and
    the ground contact bodies as ``footBodyNames``.

    Parameters
    ----------
    path
        The .b3d file (or an open :class:`B3dFile`).
    out_dir
        The subject folder to write (created; must not already hold a ``_subject.json``
        unless ``overwrite``).
    pass_index
        Which pass's model to embed.
    overwrite
        Replace the files of an existing converted subject. Trial folders the earlier
        conversion wrote (named in its ``b3d_source.json``) that this file does not have are
        removed, so that ``addb process`` does not solve them with the new subject; such a
        folder that holds anything else, and every trial folder it did not write, is kept
        (:attr:`ConvertedSubject.kept`).

    Returns
    -------
    ConvertedSubject
        Including each trial's missing-GRF reasons, for the review record.

    Raises
    ------
    B3dFormatError
        The file is damaged.
    SubjectFolderError
        ``out_dir`` already holds a subject and ``overwrite`` is False, or the file has no
        trial with frames, no model or no subject mass, a mass or height out of range, a
        marker name twice, a trial's time step out of :data:`RATE_RANGE_HZ` or model text
        that is not XML (checked before anything is written).
    """
    b3d = path if isinstance(path, B3dFile) else open_b3d(path)
    h = b3d.header
    out = Path(out_dir)
    if (out / SUBJECT_JSON).exists() and not overwrite:
        raise SubjectFolderError(f"already holds a subject ({SUBJECT_JSON}); overwrite=True (addb convert --force) writes over it", path=out)
    if not h.passes or not (0 <= pass_index < len(h.passes)):
        raise SubjectFolderError(f"the file has {_passes(len(h.passes))}, no pass {pass_index} to take the model from", path=b3d.path)
    if not any(t.n_frames for t in h.trials):
        raise SubjectFolderError("the file has no trial with frames", path=b3d.path)
    if not (np.isfinite(h.mass_kg) and h.mass_kg > 0):  # proto3: an absent mass reads as 0
        raise SubjectFolderError(f"the file's header gives no subject mass (mass_kg {h.mass_kg!r}), which addb process "
                                 "needs; nothing was written", path=b3d.path)
    _check_before_writing(b3d, pass_index)
    earlier = _converted_trials(out) if overwrite else ()
    out.mkdir(parents=True, exist_ok=True)
    (out / MODEL_FILE).write_text(b3d.model_text(pass_index), encoding="utf-8")
    keep = [j for j, name in enumerate(h.marker_names) if name]
    used: set[str] = set()
    trials = []
    for k, t in enumerate(h.trials):
        if t.n_frames == 0:
            continue
        fr = b3d.read_trial(k)
        folder = out / "trials" / _folder_name(t.name, used)
        folder.mkdir(parents=True, exist_ok=True)
        time = np.arange(t.n_frames) * t.timestep_s
        absent = np.isnan(fr.markers).any(axis=2) | (fr.markers == 0.0).all(axis=2)  # (N, M)
        seen = [j for j in keep if not absent[:, j].all()]
        markers = MarkerTrajectories(
            tuple(h.marker_names[j] for j in seen), fr.markers[:, seen, :], time, t.rate_hz, source=str(b3d.path)
        )
        write_trc(folder / "markers.trc", markers)
        if t.n_force_plates:
            plates = tuple(
                ForcePlate(
                    name=str(p + 1),
                    force=np.nan_to_num(fr.plate_force[:, p]),
                    cop=np.nan_to_num(fr.plate_cop[:, p]),
                    free_moment=np.nan_to_num(fr.plate_moment[:, p]),
                    corners=t.force_plate_corners[p] if p < t.force_plate_corners.shape[0] else None,
                )
                for p in range(t.n_force_plates)
            )
            write_forces(folder / "grf.mot", ForceRecording(time, t.rate_hz, plates, source=str(b3d.path)))
        trials.append(ConvertedTrial(folder.name, t.name, t.n_frames, t.rate_hz, t.missing_grf))
    subject: dict[str, Any] = {
        "massKg": h.mass_kg,
        **({"heightM": h.height_m} if np.isfinite(h.height_m) and h.height_m > 0 else {}),  # optional: 0 means not given
        "sex": h.sex or "unknown",
        "subjectTags": list(h.tags),
        "footBodyNames": list(h.ground_contact_bodies) or ["calcn_r", "calcn_l"],
        "disableDynamics": False,
        "segmentedTrials": [c.name for c in trials],
    }
    if h.age_years > 0:
        subject["ageYears"] = h.age_years
    (out / SUBJECT_JSON).write_text(json.dumps(subject, indent=2) + "\n")
    source = {
        "b3d": str(Path(b3d.path).resolve()),
        "version": h.version,
        "model_from_pass": pass_index,
        "model_pass_type": h.passes[pass_index].type,
        "notes": h.notes,
        "href": h.href,
        "trials": {c.name: {"b3d_trial": c.b3d_name, "frames": c.n_frames, "rate_hz": c.rate_hz} for c in trials},
    }
    (out / SOURCE_JSON).write_text(json.dumps(source, indent=2) + "\n")
    gone = [name for name in earlier if name not in source["trials"] and (out / "trials" / name).is_dir()]
    removed = tuple(name for name in gone if _remove_converted_trial(out / "trials" / name))
    return ConvertedSubject(out, Path(b3d.path), tuple(trials), removed, tuple(n for n in gone if n not in removed))


#: Frame rates (Hz) of a trial that :func:`b3d_to_subject` converts: a motion capture's
#: (a time step outside them is a damaged or mistaken header: input audit 2026-12-02, finding 14).
RATE_RANGE_HZ = (1.0, 20000.0)


def _check_before_writing(b3d: B3dFile, pass_index: int) -> None:
    """What :func:`b3d_to_subject` would otherwise find only in the folder it writes
    (input audit 2026-12-02, finding 10): the subject's mass and height within what
    ``_subject.json`` accepts (:data:`solver.io.subject.MOST_KG`, ``MOST_M``), marker names
    unique, each trial's frame rate within :data:`RATE_RANGE_HZ`, and the model text of
    pass ``pass_index`` well-formed XML.

    Raises
    ------
    SubjectFolderError
        Naming the .b3d and the header field, trial or pass; nothing is written.
    """
    import xml.etree.ElementTree as ET

    from solver.io.subject import MOST_KG, MOST_M

    h = b3d.header
    nothing = "; nothing was written"
    if h.mass_kg > MOST_KG:
        raise SubjectFolderError(f"mass_kg {h.mass_kg:g} is more than {MOST_KG:g} kg (a unit error?){nothing}", path=b3d.path,
                                 where="header")  # fmt: skip
    if np.isfinite(h.height_m) and h.height_m > MOST_M:
        raise SubjectFolderError(f"height_m {h.height_m:g} is more than {MOST_M:g} m (a unit error?){nothing}", path=b3d.path,
                                 where="header")  # fmt: skip
    names = [n for n in h.marker_names if n]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise SubjectFolderError(f"marker names {', '.join(repeated)} appear more than once in marker_name{nothing}",
                                 path=b3d.path, where="header")  # fmt: skip
    lo, hi = RATE_RANGE_HZ
    for t in h.trials:
        if t.n_frames and not (lo <= t.rate_hz <= hi):
            raise SubjectFolderError(f"trial_timestep {t.timestep_s:g} s ({t.rate_hz:g} Hz); expected the frame interval of a "
                                     f"motion capture, {1 / hi:g} to {1 / lo:g} s{nothing}", path=b3d.path,
                                     where=f"trial {t.name!r}")  # fmt: skip
    try:
        ET.fromstring(b3d.model_text(pass_index))
    except ET.ParseError as exc:
        raise SubjectFolderError(f"the model text of pass {pass_index} is not well-formed XML ({exc}){nothing}", path=b3d.path,
                                 where=f"pass {pass_index}") from None  # fmt: skip


def converted_trial_folders(subject_dir: str | Path) -> dict[str, str]:
    """.b3d trial name -> trial folder name of a subject folder written by
    :func:`b3d_to_subject` (its ``b3d_source.json``; a trial whose name is no folder name,
    with spaces or slashes, was renamed): the ``trial_names`` of
    :func:`solver.io.b3d_compare.compare_with_b3d`.

    Raises
    ------
    SubjectFolderError
        The folder has no readable ``b3d_source.json`` (it was not converted from a .b3d).
    """
    path = Path(subject_dir) / SOURCE_JSON
    try:
        trials = json.loads(path.read_text(encoding="utf-8"))["trials"]
        return {str(v["b3d_trial"]): str(folder) for folder, v in trials.items()}
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as err:
        raise SubjectFolderError(f"no trial map of a .b3d conversion ({type(err).__name__}: {err})", path=path) from None


def _converted_trials(out: Path) -> tuple[str, ...]:
    """The trial folders an earlier conversion into ``out`` wrote (read by
    :func:`converted_trial_folders`); none when there is none or it cannot be read (a folder
    it did not write is not touched), and never a name that leaves ``out/trials``."""
    try:
        folders = converted_trial_folders(out).values()
    except SubjectFolderError:
        return ()
    return tuple(name for name in folders if name and "/" not in name and name not in (".", ".."))


def _remove_converted_trial(folder: Path) -> bool:
    """Remove ``folder`` (an existing folder) when it holds only what a conversion writes
    (``markers.trc``, ``grf.mot``). True when it was removed; a folder with anything else in it
    is kept whole."""
    if any(f.name not in ("markers.trc", "grf.mot") or not f.is_file() for f in folder.iterdir()):
        return False
    for f in folder.iterdir():
        f.unlink()
    folder.rmdir()
    return True


ReviewWriter = Callable[[ConvertedSubject], Any]


# --------------------------------------------------------------------------- processed -> .b3d


def _missing_reason(unobserved: bool, manual: bool, reason: str) -> str:
    """Our per-frame flag -> a .b3d missing-GRF reason name."""
    if manual:
        return "manualReview"
    if not unobserved:
        return "notMissingGRF"
    if reason.endswith("in contact with no plate force"):
        return "notOverForcePlate"
    if reason.startswith("measured vertical force differs"):
        return "forceDiscrepancy"
    return "unmeasuredExternalForceDetected"


def _rotation_wxyz(wxyz: np.ndarray) -> np.ndarray:
    """``(T, 4)`` unit quaternions (w, x, y, z) -> ``(T, 3, 3)`` rotation matrices."""
    w, x, y, z = (wxyz[:, i] for i in range(4))
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=1),
    ], axis=1)  # fmt: skip


def _contact(trial: Any, bodies: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per contact body the sum of the plate wrenches assigned to it: (T, B, 6) wrench
    [moment about the origin, force], (T, B, 3) CoP, free moment about it, force."""
    t, nb = trial.n_frames, len(bodies)
    force = np.zeros((t, nb, 3))
    moment_o = np.zeros((t, nb, 3))
    cop_num = np.zeros((t, nb, 3))
    cop_den = np.zeros((t, nb))
    for plate in trial.plates:
        if plate.body is None:
            continue
        f = np.nan_to_num(plate.force)
        c = np.nan_to_num(plate.cop)
        m = np.cross(c, f) + np.nan_to_num(plate.free_moment)
        for b, name in enumerate(bodies):
            if name not in trial.body_names:
                continue
            on = plate.body == trial.body_names.index(name)
            force[on, b] += f[on]
            moment_o[on, b] += m[on]
            weight = np.abs(f[on, 1])
            cop_num[on, b] += c[on] * weight[:, None]
            cop_den[on, b] += weight
    with np.errstate(invalid="ignore", divide="ignore"):
        cop = np.where(cop_den[..., None] > 0, cop_num / cop_den[..., None], 0.0)
    torque = moment_o - np.cross(cop, force)
    return np.concatenate([moment_o, force], axis=2), cop, torque, force


def processed_to_b3d(
    out_dir: str | Path,
    path: str | Path,
    *,
    manual: dict[str, np.ndarray] | None = None,
    subject_info: dict[str, Any] | None = None,
) -> Path:
    """Write a processed subject (an ``addb process`` output folder) as a .b3d file.

    Contents: per trial the sensor data addb used (observed markers, m; the plates on the
    trial's frames: force N, CoP m (0 where unloaded), free moment N·m), then two passes
    with addb's coordinates (the independent coordinates of the scaled model, in the order
    of :func:`solver.io.b3d.dof_names`; velocities and accelerations, those of a
    kinematics-only trial the central differences of its coordinates), at the time step of
    the trial's rate rounded to 1e-6 Hz:

    * ``kinematics``: coordinates, centre of mass, the contact wrenches, per-frame marker
      RMS and max; joint torques and residual wrench 0 (the kinematics pass computes
      none; every pass frame of a file must have the same size);
    * ``dynamics``: the same plus joint torques, the residual norms (linear N, angular N·m)
      per frame, and the residual wrench in the root body frame ([moment, force]) as
      ``root_frame_residual``.

    The contact wrench of a contact body is the sum of the plates addb assigned to it:
    [moment about the origin, force] in the world frame, and as CoP (vertical-force
    weighted), free moment and force. The centre of mass velocity is the central
    difference of addb's centre of mass. Missing-GRF reasons come from addb's flags:
    ``manualReview`` where ``manual`` marks the frame (reviewer flags), else
    ``notOverForcePlate`` / ``forceDiscrepancy`` / ``unmeasuredExternalForceDetected`` by
    addb's proposal reason for frames excluded from the dynamic fit, else ``notMissingGRF``.
    Both passes embed the scaled model (``<subject>_scaled.osim``), and the header's subject
    mass is that model's: the mass the dynamics fit settled on (the given mass when no trial
    has dynamics).

    Parameters
    ----------
    out_dir
        The processed output folder (``subject.json`` and ``<trial>/trial.npz``).
    path
        The .b3d file to write.
    manual
        Trial name -> ``(T,)`` bool frames a reviewer flagged (from the review record).
    subject_info
        Optional ``sex``, ``age_years``, ``tags``, ``notes``, ``foot_bodies`` (contact
        bodies, in order).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    SubjectFolderError
        ``out_dir`` holds no processed trial, or its scaled model is missing.
    """
    from solver.io.b3d import B3dFrames, B3dHeader, B3dPass, B3dPassFrames, B3dTrial, B3dTrialPass
    from solver.io.b3d_writer import write_b3d
    from solver.model.osim import read_osim
    from solver.results import load_processed, processed_trials

    out = Path(out_dir)
    names = processed_trials(out)
    if not names:
        raise SubjectFolderError("holds no processed trial (<trial>/trial.npz)", path=out)
    info = dict(subject_info or {})
    trials = [load_processed(out, n) for n in names]
    model_path = Path(trials[0].model_path)  # load_processed finds a moved folder's model in it
    if not model_path.exists():
        candidates = sorted(out.glob("*_scaled.osim"))
        if not candidates:
            raise SubjectFolderError(f"the scaled model {model_path.name} is missing", path=out)
        model_path = candidates[0]
    model_text = model_path.read_text(encoding="utf-8")
    model = read_osim(model_path)
    from solver.io.b3d import dof_names

    dofs = dof_names(model)
    bodies = tuple(info.get("foot_bodies") or ())
    if not bodies:
        assigned: set[str] = set()
        for tr in trials:
            for plate in tr.plates:
                if plate.body is not None:
                    assigned |= {tr.body_names[i] for i in np.unique(plate.body) if i >= 0}
        order = ("calcn_r", "calcn_l")
        bodies = tuple(sorted(assigned, key=lambda n: (order.index(n) if n in order else len(order), n)))
    marker_names: list[str] = []
    for tr in trials:
        marker_names += [m for m in tr.marker_names if m not in marker_names]
    header_trials, blocks = [], []
    subject_json = out / SUBJECT_RECORD
    summary = json.loads(subject_json.read_text()) if subject_json.exists() else {}
    for k, tr in enumerate(trials):
        t = tr.n_frames
        dt = nominal_interval(frame_interval(tr.time, default=0.01))
        cols = [tr.coordinate_names.index(n) for n in dofs]
        qd_all, qdd_all = _finite_rates(tr.q, tr.qd, tr.qdd, tr.time)
        q, qd, qdd = tr.q[:, cols], qd_all[:, cols], qdd_all[:, cols]
        has_dyn = tr.has_dynamics
        tau = np.nan_to_num(tr.tau[:, cols]) if has_dyn else np.zeros_like(q)
        markers = np.full((t, len(marker_names), 3), np.nan)
        for j, m in enumerate(tr.marker_names):
            markers[:, marker_names.index(m)] = tr.observed[:, j]
        plates = tr.plates
        pf = np.stack([np.nan_to_num(p.force) for p in plates], axis=1) if plates else np.zeros((t, 0, 3))
        pc = np.stack([np.nan_to_num(p.cop) for p in plates], axis=1) if plates else np.zeros((t, 0, 3))
        pm = np.stack([np.nan_to_num(p.free_moment) for p in plates], axis=1) if plates else np.zeros((t, 0, 3))
        wrench, cop, torque, force = _contact(tr, bodies)
        com = np.nan_to_num(tr.com)
        com_vel = np.gradient(com, tr.time, axis=0) if t > 1 else np.zeros_like(com)
        com_acc = np.nan_to_num(tr.com_acc)
        rms = np.nan_to_num(tr.marker_rms_per_frame)
        err = tr.marker_errors
        mmax = np.where(np.isfinite(err), err, 0.0).max(axis=1) if err.size else np.zeros(t)
        lin = np.nan_to_num(np.linalg.norm(tr.residual_force, axis=1)) if has_dyn else np.zeros(t)
        ang = np.nan_to_num(np.linalg.norm(tr.residual_moment, axis=1)) if has_dyn else np.zeros(t)
        rot = [i for i, c in enumerate(model.coordinates) if c.name in dofs and c.motion_type != "translational"]
        rot_cols = [tr.coordinate_names.index(model.coordinates[i].name) for i in rot]
        max_vel = np.abs(qd_all[:, rot_cols]).max(axis=1) if rot_cols else np.zeros(t)
        flagged = np.zeros(t, bool) if manual is None or tr.trial not in manual else np.asarray(manual[tr.trial], bool)[:t]
        if flagged.size < t:
            flagged = np.concatenate([flagged, np.zeros(t - flagged.size, bool)])
        reasons = tuple(
            # no force data (no plates, or kinematics only): no frame's ground reaction force is
            # measured, so none may pass as a measured zero (a reader would take the subject for
            # airborne); AddBiomechanics' reason for a foot no plate measures
            "notOverForcePlate" if not has_dyn
            else _missing_reason(bool(tr.unobserved[i]), bool(flagged[i]), tr.proposal_reasons[i] if i < len(tr.proposal_reasons) else "")
            for i in range(t)
        )
        root = tr.body_names.index(model.joints[0].child.body) if model.joints and model.joints[0].child.body in tr.body_names else 0
        r = _rotation_wxyz(tr.body_wxyz[:, root])
        res_f = np.einsum("tji,tj->ti", r, np.nan_to_num(tr.residual_force))
        res_m = np.einsum("tji,tj->ti", r, np.nan_to_num(tr.residual_moment))
        ones = np.ones(len(dofs), bool)

        common_pass = {
            "marker_rms": rms, "marker_max": mmax, "joints_max_velocity": max_vel,
            "dof_positions_observed": ones, "dof_velocities_finite_differenced": ones,
            "dof_accelerations_finite_differenced": ones,
        }  # fmt: skip
        kin_pass = B3dTrialPass(type="kinematics", linear_residual=np.zeros(t), angular_residual=np.zeros(t), **common_pass)
        dyn_pass = B3dTrialPass(type="dynamics", linear_residual=lin, angular_residual=ang, **common_pass)
        common_frames = {
            "pos": q, "vel": qd, "acc": qdd, "ground_contact_wrench": wrench, "ground_contact_cop": cop,
            "ground_contact_torque": torque, "ground_contact_force": force, "com_pos": com, "com_vel": com_vel,
            "com_acc": com_acc,
        }  # fmt: skip
        kin_frames = B3dPassFrames(
            type="kinematics", tau=np.zeros_like(q), extra={"root_frame_residual": np.zeros((t, 6))}, **common_frames
        )
        dyn_frames = B3dPassFrames(
            type="dynamics", tau=tau, extra={"root_frame_residual": np.concatenate([res_m, res_f], axis=1)}, **common_frames
        )
        corners = (
            np.stack([p.corners for p in plates])
            if plates and all(p.corners is not None for p in plates)
            else np.zeros((0, 4, 3))
        )
        header_trials.append(
            B3dTrial(
                name=tr.trial, original_name=tr.trial, split_index=0, timestep_s=dt, n_frames=t, tags=(),
                missing_grf=reasons, n_force_plates=len(plates), force_plate_corners=corners,
                marker_names_guessed=False, passes=(kin_pass, dyn_pass),
            )
        )
        blocks.append(
            B3dFrames(
                trial=k, start=0, time_s=np.arange(t) * dt, missing_grf=reasons, markers=markers,
                plate_force=pf, plate_cop=pc, plate_moment=pm, passes=(kin_frames, dyn_frames),
            )
        )
    header = B3dHeader(
        version=4,
        n_dofs=len(dofs),
        mass_kg=_model_mass(trials),
        height_m=float(trials[0].height_m or summary.get("height_m") or 0.0),
        sex=str(info.get("sex", "unknown")),
        age_years=int(info.get("age_years", -1)),
        tags=tuple(info.get("tags", ())),
        notes=str(info.get("notes", f"Written by addb from {out.name}")),
        href="",
        ground_contact_bodies=bodies,
        marker_names=tuple(marker_names),
        passes=(B3dPass("kinematics", model_text), B3dPass("dynamics", model_text)),
        trials=tuple(header_trials),
    )
    write_b3d(path, header, blocks)
    return Path(path)


def _model_mass(trials: list[Any]) -> float:
    """The subject mass (kg) of the scaled model a processed subject's .b3d embeds: the mass
    the dynamics fit settled on, which every trial with dynamics holds (a kinematics-only
    trial, such as a static one, holds the given mass); the given mass when no trial has
    dynamics (the model is then scaled to it)."""
    return float(next((tr.mass_kg for tr in trials if tr.has_dynamics), trials[0].mass_kg))


def _finite_rates(q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, time: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Velocities and accelerations of a processed trial for a .b3d pass, ``(T, n)`` each.

    A trial with dynamics has them from its fit's spline; a kinematics-only trial (a static
    trial) has none (NaN). Where a value is not finite it is replaced by the central
    difference of ``q`` ``(T, n)`` over ``time`` ``(T,)`` (s) (of the velocities for the
    accelerations; zero for a trial of one frame), as the passes' flags
    ``dof_velocities_finite_differenced`` say: a reader that filters frames on the joint
    velocities would otherwise get NaN.
    """
    if np.isfinite(qd).all() and np.isfinite(qdd).all():
        return qd, qdd
    if q.shape[0] > 1:
        fd_v = np.gradient(q, time, axis=0)
        fd_a = np.gradient(fd_v, time, axis=0)
    else:
        fd_v = fd_a = np.zeros_like(q)
    return np.where(np.isfinite(qd), qd, fd_v), np.where(np.isfinite(qdd), qdd, fd_a)


def _passes(n: int) -> str:
    """The processing passes of a file, for a message: "no processing pass", "one processing
    pass (pass 0)", "3 processing passes (0 to 2)"."""
    if n == 0:
        return "no processing pass"
    return "one processing pass (pass 0)" if n == 1 else f"{n} processing passes (0 to {n - 1})"
