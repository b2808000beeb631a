"""Everything the diagnosis needs about one processed trial, computed once.

The diagnosis holds the trial's kinematics fixed (``q``, ``qd``, ``qdd`` of ``trial.npz``)
and recomputes the root residual wrench from its parts, so that each candidate cause
changes one part:

    r(t) = I(t) - E(t)

* ``I`` is the root wrench of gravity and inertia (inverse dynamics without external
  loads) of the processed model scaled to the subject's *stated* mass: the diagnosis'
  reference is the subject as stated, so that a wrong stated mass shows up (the pipeline
  fits the total mass from the forces; ``body_mass`` reports the difference);
* ``E`` is the total wrench of *every* plate on *every* frame, recomputed from the raw
  force file with the stage's filter (plates are not assigned to feet: the root residual
  depends on the total external wrench only, and a plate that reads force with no foot
  on it is part of what is wrong).

Both are ``(T, 6)``: force (N) and moment about the pelvis (root body) origin (N·m), in
the ground frame, as :attr:`solver.results.ProcessedTrial.residual_force` and
``residual_moment``. Frames flagged by the reviewer as unmeasured are left out of the
residual terms; every frame keeps its marker terms.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from solver.dynamics.preprocess import lowpass, moment_about_origin, resample, true_runs
from solver.io.types import ForcePlate, ForceRecording
from solver.model.mass_groups import BODY_GROUPS, body_group, group_masses  # noqa: F401 (re-exported)
from solver.model.osim import Body, OsimModel, read_osim
from solver.model.skeleton import Skeleton
from solver.outputs import SUBJECT_RECORD
from solver.results import ProcessedTrial
from solver.sampling import frame_interval

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class RawPlates:
    """Plate wrenches from the raw force file, low-passed at their own rate (as the stage does).

    Attributes
    ----------
    names
        Plate names.
    time
        ``(R,)`` raw sample times, s.
    force, moment
        ``(P, R, 3)`` filtered force (N) and moment about the ground origin (N·m), ground frame.
    centre
        ``(P, 3)`` where a plate's zero drift acts, m (:func:`plate_centre`: its corners'
        centre, or the median centre of pressure of its loaded samples).
    idle
        ``(P, R)`` samples where nobody stands on the plate (:func:`idle_samples`): its true
        force is zero there, whatever it reads.
    """

    names: tuple[str, ...]
    time: FloatArray
    force: FloatArray
    moment: FloatArray
    centre: FloatArray
    idle: BoolArray

    def on(self, time: FloatArray, delay: float = 0.0) -> tuple[FloatArray, FloatArray, BoolArray]:
        """Force and moment about the ground origin on ``time`` + ``delay``, ``(P, T, 3)``
        each, and the idle mask ``(P, T)`` there.

        ``delay`` > 0 reads later samples (forces recorded ``delay`` s late); times outside
        the recording take its first or last sample.
        """
        t = np.clip(np.asarray(time, dtype=float) + delay, self.time[0], self.time[-1])
        f = np.stack([resample(self.time, p, t) for p in self.force])
        m = np.stack([resample(self.time, p, t) for p in self.moment])
        near = np.clip(np.searchsorted(self.time, t), 0, self.time.size - 1)
        return f, m, self.idle[:, near]


#: A plate is idle where its filtered force stays below IDLE_BW body weights for at least
#: IDLE_SECONDS (a swing or flight phase, or a plate nobody uses), trimmed by IDLE_TRIM_SECONDS
#: at both ends (the filter spreads each contact over a few samples).
IDLE_BW = 0.15
#: A plate bears load when its vertical force exceeds this fraction of body weight (where
#: its centre of pressure is defined and a shift of it acts).
LOADED_BW = 0.02
IDLE_SECONDS = 0.1
IDLE_TRIM_SECONDS = 0.03


def idle_samples(force: FloatArray, rate_hz: float, bw: float) -> BoolArray:
    """``(R,)`` samples of one plate (``force`` ``(R, 3)``, filtered) where nobody stands on it.

    A drifting plate reads its offset there (up to a tenth of body weight or so), a
    healthy one reads zero; a loaded plate reads far more than IDLE_BW for most of a
    stance, so short dips do not count.
    """
    low = np.linalg.norm(force, axis=1) < IDLE_BW * bw
    out = np.zeros_like(low)
    trim = round(IDLE_TRIM_SECONDS * rate_hz)
    for a, b in true_runs(low):
        if (b - a) / rate_hz >= IDLE_SECONDS:
            out[a + (trim if a > 0 else 0) : b - (trim if b < low.size else 0)] = True
    return out


def plate_centre(plate: ForcePlate, bw: float) -> FloatArray:
    """``(3,)`` the point a plate refers its readings to, ground frame, m: the centre of its
    corners when the recording gives them (C3D), otherwise the median centre of pressure of
    its samples loaded above LOADED_BW body weights (``bw`` N), the origin if none is."""
    if plate.corners is not None:
        return np.asarray(plate.corners, dtype=float).mean(axis=0)
    cop = np.asarray(plate.cop, dtype=float)
    loaded = np.nan_to_num(np.asarray(plate.force, dtype=float)[:, 1]) > LOADED_BW * bw
    return np.nan_to_num(np.nanmedian(cop[loaded], axis=0)) if loaded.any() else np.zeros(3)


def raw_plates(forces: ForceRecording, cutoff_hz: float, order: int, bw: float) -> RawPlates:
    """Filter every plate of a raw recording (zero-phase Butterworth, as the dynamics stage).

    Parameters
    ----------
    forces
        The raw recording (after any saved extensions).
    cutoff_hz, order
        The stage's filter settings.
    bw
        Body weight, N (a plate is loaded above LOADED_BW of it).
    """
    f_all, m_all, centres, idle = [], [], [], []
    for p in forces.plates:
        f = np.nan_to_num(np.asarray(p.force, dtype=float))
        cop = np.asarray(p.cop, dtype=float)
        m_o = moment_about_origin(f, cop, np.nan_to_num(np.asarray(p.free_moment, dtype=float)))
        centre = plate_centre(p, bw)
        f_all.append(lowpass(f, forces.rate_hz, cutoff_hz, order))
        m_all.append(lowpass(m_o, forces.rate_hz, cutoff_hz, order))
        centres.append(np.nan_to_num(centre))
        idle.append(idle_samples(f_all[-1], forces.rate_hz, bw))
    return RawPlates(
        tuple(p.name for p in forces.plates),
        np.asarray(forces.time, dtype=float),
        np.array(f_all).reshape(len(f_all), -1, 3),
        np.array(m_all).reshape(len(m_all), -1, 3),
        np.array(centres).reshape(-1, 3),
        np.array(idle, dtype=bool).reshape(len(idle), -1),
    )


@dataclass(frozen=True)
class MarkerData:
    """Marker errors of the processed trial.

    Attributes
    ----------
    names
        ``(M,)`` marker names.
    error
        ``(T, M, 3)`` model minus observed position, m, ground frame (NaN where missing).
    rotation
        ``(T, M, 3, 3)`` rotation of each marker's body (columns: body axes in ground).
    bodies
        ``(M,)`` body of each marker.
    fixed
        ``(M,)`` the generic model marks the marker as placed on a landmark (``<fixed>``).
    fitted_offset
        ``(M, 3)`` body-fixed offset the kinematics stage fitted for each marker, m (zero
        when unknown).
    retained
        ``(T, M, 3, 3)`` ground frame: the part of a displacement of each landmark
        (``fixed``) marker's model position that stays in that marker's own error once the
        pose is solved again (:func:`retained_displacement`); identity for other markers.
    scale_response
        ``(M, 3, 3)`` body frame: how far the kinematics stage's scale fit moved each
        landmark marker's scaled landmark per metre of misplacement in this trial
        (:func:`solver.kinematics.fit.landmark_scale_response`); zero when unknown.
    """

    names: tuple[str, ...]
    error: FloatArray
    rotation: FloatArray
    bodies: tuple[str, ...]
    fixed: BoolArray
    fitted_offset: FloatArray
    retained: FloatArray
    scale_response: FloatArray

    @property
    def seen(self) -> BoolArray:
        """``(T, M)`` marker observed."""
        return np.isfinite(self.error).all(axis=2)

    @property
    def landmark(self) -> BoolArray:
        """``(M,)`` landmark markers: ``fixed`` and on a body of the model."""
        return self.fixed & np.array([b != "ground" for b in self.bodies], dtype=bool)

    def mean_error(self) -> tuple[FloatArray, FloatArray]:
        """``(T, 3)`` mean error over the seen markers (m; zero where none) and ``(T,)`` their count."""
        seen = self.seen
        n = seen.sum(axis=1)
        total = np.where(seen[..., None], self.error, 0.0).sum(axis=1)
        return total / np.maximum(n, 1)[:, None], n.astype(float)


@dataclass(frozen=True)
class DiagnosisData:
    """One processed trial prepared for the diagnosis (see the module docstring).

    Attributes
    ----------
    trial
        The processed trial.
    dt
        Frame interval, s.
    stated_mass, fitted_mass
        The subject's stated mass and the pipeline's fitted mass, kg.
    gravity
        ``(3,)`` m/s².
    pelvis
        ``(T, 3)`` root body origin, m.
    com
        ``(T, 3)`` centre of mass, m.
    inertial
        ``(T, 6)`` gravity + inertia root wrench at the *fitted* mass (force N, moment
        about the pelvis origin N·m).
    groups
        Group name -> ``(T, 6)`` the part of ``inertial`` due to that group's bodies.
    group_mass
        Group name -> mass of the group in the processed model, kg.
    plates
        Raw plates, filtered.
    flagged
        ``(T,)`` frames the reviewer flagged as unmeasured (left out of residual terms).
    proposed
        ``(T,)`` frames the pipeline proposed as unmeasured, with ``reasons``.
    markers
        Marker errors.
    feet
        ``(F,)`` foot body names, with ``foot_contact`` ``(F, T)`` their contact (kinematic
        contact or a loaded plate under them) and ``foot_loaded`` ``(F, T)`` whether a
        loaded plate is under them (:func:`solver.dynamics.contact.assign_contacts` on the
        raw plates).
    model
        The model the trial was prepared with (the processed, mass-fitted one, or a
        refit's), or None (then ``trial.model_path``'s).
    """

    trial: ProcessedTrial
    dt: float
    stated_mass: float
    fitted_mass: float
    gravity: FloatArray
    pelvis: FloatArray
    com: FloatArray
    inertial: FloatArray
    groups: dict[str, FloatArray]
    group_mass: dict[str, float]
    plates: RawPlates
    flagged: BoolArray
    markers: MarkerData
    feet: tuple[str, ...] = ()
    foot_contact: BoolArray | None = None
    foot_loaded: BoolArray | None = None
    model: OsimModel | None = None

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.trial.n_frames)

    @property
    def time(self) -> FloatArray:
        """``(T,)`` frame times, s."""
        return self.trial.time

    @property
    def left_out(self) -> BoolArray:
        """``(T,)`` frames the solver left out of its dynamic fit on its own (its unmeasured
        force proposals; reviewer flags not included): their motion had free
        centre-of-mass accelerations."""
        return self.trial.unobserved & ~self.flagged

    @property
    def bw(self) -> float:
        """Stated body weight, N."""
        return self.stated_mass * float(np.linalg.norm(self.gravity))

    def external(self, delay: float = 0.0) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Plate wrenches with forces read ``delay`` s later.

        Returns
        -------
        per
            ``(P, T, 6)`` each plate's wrench (force; moment about the pelvis origin), zero
            where the plate is idle.
        total
            ``(T, 6)`` their sum.
        idle_force
            ``(P, T, 3)`` what each plate reads where it is idle (zero elsewhere), N.
        """
        f, m_o, idle = self.plates.on(self.time, delay)
        m_p = m_o - np.cross(self.pelvis[None], f)
        per = np.where(idle[..., None], 0.0, np.concatenate([f, m_p], axis=2))
        return per, per.sum(axis=0), np.where(idle[..., None], f, 0.0)

    def residual(self, delay: float = 0.0, mass: float | None = None) -> FloatArray:
        """``(T, 6)`` root residual at ``mass`` (default: the stated mass) with every plate
        that is not idle."""
        m = self.stated_mass if mass is None else mass
        return self.inertial * (m / self.fitted_mass) - self.external(delay)[1]


def _scaled_bodies(model: OsimModel, factors: Mapping[str, float]) -> OsimModel:
    bodies = tuple(
        Body(b.name, b.mass * factors.get(b.name, 0.0), b.com, tuple(map(tuple, np.array(b.inertia) * factors.get(b.name, 0.0))), b.meshes)
        for b in model.bodies
    )
    return replace(model, bodies=bodies)


def generic_mass_distribution(model: OsimModel, generic: OsimModel) -> OsimModel:
    """``model`` (scaled, mass-fitted) with the mass distribution of ``generic``, total kept.

    The dynamics stage fits each body's mass factor to the measured forces, so a force
    error leaves part of itself in the processed model's masses (a shifted centre of
    pressure moves mass sideways, for example). The marker-only motion of the diagnosis
    is evaluated with masses the forces did not touch: each body gets the generic model's
    share of the processed total, and its inertia scales with its mass (the scaling keeps
    inertia proportional to mass, :func:`solver.model.scaling.scale_model`). Bodies the
    generic model lacks, or that have no mass in the processed model, keep theirs.

    Parameters
    ----------
    model
        The processed (scaled, mass-fitted) model.
    generic
        The subject's unscaled model, with any saved mass redistribution applied.

    Returns
    -------
    OsimModel
        Same geometry, markers and total mass as ``model``.
    """
    share = {b.name: b.mass for b in generic.bodies}
    known = [b for b in model.bodies if b.name in share and b.mass > 0]
    generic_total = sum(share[b.name] for b in known)
    if generic_total <= 0:
        return model
    k = sum(b.mass for b in known) / generic_total  # the known bodies keep their total
    factors = {b.name: 1.0 for b in model.bodies} | {b.name: share[b.name] * k / b.mass for b in known}
    return _scaled_bodies(model, factors)


def root_wrench(sk: Skeleton, trial: ProcessedTrial) -> FloatArray:
    """``(T, 6)`` gravity + inertia root wrench of ``trial``'s motion (no external load)."""
    idr = sk.inverse_dynamics(trial.q, trial.qd, trial.qdd)
    return np.concatenate([idr.root_force, idr.root_moment], axis=1)


def group_wrenches(model: OsimModel, trial: ProcessedTrial) -> tuple[dict[str, FloatArray], dict[str, float]]:
    """Per body group, ``(T, 6)`` the gravity + inertia root wrench of its bodies alone
    (force N; moment about the pelvis origin N·m; ground frame; they sum to the whole
    body's), and the group's mass, kg."""
    out = {}
    by_group: dict[str, list[str]] = {}
    for b in model.bodies:
        by_group.setdefault(body_group(b.name), []).append(b.name)
    for group, names in by_group.items():
        sub = _scaled_bodies(model, dict.fromkeys(names, 1.0))
        out[group] = root_wrench(Skeleton(sub), trial)
    return out, group_masses(model)


def retained_displacement(sk: Skeleton, q: FloatArray, marker_names: Sequence[str], seen: BoolArray, which: BoolArray) -> FloatArray:
    """How much of a shift of one marker's model position inverse kinematics leaves in
    that marker's error.

    Inverse kinematics minimizes the sum of squared marker errors e over the coordinates:
    moving marker j's model position by d (error e + B d) moves the pose by
    dq = -(JᵀJ + λI)⁻¹ Jᵀ B d, so the errors change by P B d with
    P = I - J (JᵀJ + λI)⁻¹ Jᵀ (J: ``(3M, n)`` Jacobian of the seen markers' positions
    over the coordinates the solver moves, λ the solver's pull toward the previous frame,
    :class:`solver.kinematics.ik.IkSettings`; coordinate bounds are ignored).
    Marker j's own error keeps P_jj d: the joints take up the rest, spread over the other
    markers. A body-fixed marker offset fitted with the pose held fixed therefore
    underestimates a misplacement by the share the pose absorbed.

    Parameters
    ----------
    sk
        Skeleton of the trial's model.
    q
        ``(T, n)`` coordinates of the motion.
    marker_names
        ``(M,)`` marker names (those not in the model keep the identity).
    seen
        ``(T, M)`` marker observed (the unseen take no part in the pose).
    which
        ``(M,)`` markers whose block is computed (the others keep the identity).

    Returns
    -------
    ``(T, M, 3, 3)`` diagonal blocks P_jj, ground frame (identity where not computed or
    the marker is unseen).
    """
    from solver.kinematics.ik import IkSettings

    t_frames, m = seen.shape
    out = np.broadcast_to(np.eye(3), (t_frames, m, 3, 3)).copy()
    known = np.array([n in sk.marker_names for n in marker_names])
    if not (which & known).any():
        return out
    cols = np.flatnonzero(known)
    idx = sk.marker_index([marker_names[c] for c in cols])
    lam = IkSettings().temporal_weight
    free = np.flatnonzero(sk.is_independent & ~sk.locked)  # what the solver moves
    for t in range(t_frames):
        use = seen[t, cols]
        if not (use & which[cols]).any():
            continue
        jk = sk.marker_jacobian(q[t], idx[use])[1][:, :, free]  # (k, 3, n_free)
        jf = jk.reshape(-1, free.size)
        h_inv = np.linalg.inv(jf.T @ jf + lam * np.eye(free.size))
        for k, c in enumerate(cols[use]):
            if which[c]:
                out[t, c] = np.eye(3) - jk[k] @ h_inv @ jk[k].T
    return out


def marker_data(
    trial: ProcessedTrial,
    model: OsimModel,
    generic: OsimModel | None,
    offsets: Mapping[str, Sequence[float]],
    sk: Skeleton | None = None,
    scale_response: Mapping[str, Sequence[Sequence[float]]] | None = None,
) -> MarkerData:
    """Marker errors, body rotations and placement information of a processed trial
    (``sk``: the model's skeleton, built when not given; ``scale_response``: marker name ->
    ``(3, 3)`` L of :func:`load_scale_response`)."""
    mk = {m.name: m for m in model.markers}
    fixed_generic = {m.name: m.fixed for m in generic.markers} if generic is not None else {}
    bodies = tuple(mk[n].body if n in mk else "ground" for n in trial.marker_names)
    quat = trial.body_wxyz  # (T, B, 4)
    rot_b = wxyz_to_matrix(quat)
    bidx = {b: i for i, b in enumerate(trial.body_names)}
    rot = np.stack([rot_b[:, bidx[b]] if b in bidx else np.broadcast_to(np.eye(3), (trial.n_frames, 3, 3)) for b in bodies], axis=1)
    fixed = np.array([bool(fixed_generic.get(n, mk[n].fixed if n in mk else False)) for n in trial.marker_names])
    fitted = np.array([np.asarray(offsets.get(n, (0.0, 0.0, 0.0)), dtype=float) for n in trial.marker_names]).reshape(-1, 3)
    identity = np.broadcast_to(np.eye(3), (*rot.shape[:2], 3, 3))
    response = scale_response or {}
    absorbed = np.array([np.asarray(response.get(n, np.zeros((3, 3))), dtype=float) for n in trial.marker_names]).reshape(-1, 3, 3)
    md = MarkerData(trial.marker_names, trial.modeled - trial.observed, rot, bodies, fixed, fitted, identity, absorbed)
    return replace(md, retained=retained_displacement(sk or Skeleton(model), trial.q, md.names, md.seen, md.landmark))


def wxyz_to_matrix(q: FloatArray) -> FloatArray:
    """``(..., 4)`` unit quaternions (w, x, y, z) -> ``(..., 3, 3)`` rotation matrices."""
    w, x, y, z = (q[..., k] for k in range(4))
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=-2,
    )


def _subject_summary(out_dir: str | Path) -> dict[str, Any]:
    """``OUT/subject.json`` (the kinematics stage's summary), or {} when there is none."""
    path = Path(out_dir) / SUBJECT_RECORD
    return json.loads(path.read_text()) if path.is_file() else {}


def load_offsets(out_dir: str | Path) -> dict[str, list[float]]:
    """Body-fixed marker offsets the kinematics stage fitted (``OUT/subject.json``), m."""
    return dict(_subject_summary(out_dir).get("marker_offsets_m", {}) or {})


def load_scale_response(out_dir: str | Path, trial: str) -> dict[str, list[list[float]]]:
    """Landmark marker name -> ``(3, 3)`` scale response L of ``trial`` (``OUT/subject.json``,
    :attr:`solver.kinematics.result.KinematicsResult.landmark_scale_response`); empty for an
    output written before 2026-11-25, whose misplacements are then reported without it."""
    return dict((_subject_summary(out_dir).get("landmark_scale_response") or {}).get(trial, {}) or {})


def prepare(
    trial: ProcessedTrial,
    forces: ForceRecording,
    *,
    stated_mass: float,
    flagged: BoolArray,
    generic_model: OsimModel | None = None,
    marker_offsets: Mapping[str, Sequence[float]] | None = None,
    feet: Sequence[str] = ("calcn_r", "calcn_l"),
    model: OsimModel | None = None,
    scale_response: Mapping[str, Sequence[Sequence[float]]] | None = None,
) -> DiagnosisData:
    """Build the :class:`DiagnosisData` of a processed trial.

    Parameters
    ----------
    trial
        The processed trial (with dynamics).
    forces
        Its raw force recording (saved extensions applied).
    stated_mass
        The subject's stated mass, kg.
    flagged
        ``(T,)`` reviewer flags on the trial's frames.
    generic_model
        The subject's unscaled model (for the ``fixed`` flags of markers).
    marker_offsets
        Marker name -> fitted body-fixed offset, m (``OUT/subject.json``).
    feet
        Foot body names.
    model
        The trial's (mass-fitted) model; default: read from ``trial.model_path``.
    scale_response
        Marker name -> ``(3, 3)`` scale response of the trial (:func:`load_scale_response`).
    """
    model = read_osim(trial.model_path) if model is None else model
    sk = Skeleton(model)
    settings = trial.settings or {}
    cutoff = float(settings.get("cutoff_hz", 30.0))
    order = int(settings.get("filter_order", 3))
    g = np.asarray(model.gravity, dtype=float)
    plates = raw_plates(forces, cutoff, order, stated_mass * float(np.linalg.norm(g)))
    groups, group_mass = group_wrenches(model, trial)
    pelvis = trial.body_position[:, trial.body_names.index(sk.root_body)]
    contact = _contact(sk, trial, plates, feet, stated_mass, cutoff)
    return DiagnosisData(
        trial=trial,
        dt=frame_interval(trial.time),
        stated_mass=float(stated_mass),
        fitted_mass=float(sk.total_mass),
        gravity=g,
        pelvis=pelvis,
        com=trial.com,
        inertial=root_wrench(sk, trial),
        groups=groups,
        group_mass=group_mass,
        plates=plates,
        flagged=np.asarray(flagged, dtype=bool),
        markers=marker_data(trial, model, generic_model, marker_offsets or {}, sk, scale_response),
        feet=tuple(feet),
        foot_contact=None if contact is None else contact.foot_in_contact | contact.foot_loaded,
        foot_loaded=None if contact is None else contact.foot_loaded,
        model=model,
    )


def _contact(sk: Skeleton, trial: ProcessedTrial, plates: RawPlates, feet: Sequence[str], mass: float, cutoff: float):
    """Contact assignment of the raw plates on the trial's frames (None without feet)."""
    from solver.dynamics.contact import assign_contacts
    from solver.dynamics.preprocess import cop_from_wrench
    from solver.results import PlateData

    feet = [f for f in feet if f in sk.body_names]
    if not feet:
        return None
    f, m_o, _ = plates.on(trial.time)
    bw = mass * float(np.linalg.norm(sk.osim.gravity))
    data = []
    for i, name in enumerate(plates.names):
        cop, free = cop_from_wrench(f[i], m_o[i], float(plates.centre[i][1]), LOADED_BW * bw)
        data.append(PlateData(name, f[i], cop, free))
    return assign_contacts(sk, trial.q, data, feet, mass, frame_interval(trial.time), None)


def marker_kinematics(trial: ProcessedTrial, model: OsimModel) -> ProcessedTrial:
    """``trial`` with its motion replaced by inverse kinematics of its observed markers.

    The dynamics fit absorbs part of any force error into the motion (the root follows the
    centre-of-mass path the forces imply, joints move to cancel moments); the motion that
    only the markers decide carries none of it. Same model, same 30 Hz zero-phase
    low-pass and spline derivatives as the dynamics stage; the solve starts at the frame
    that sees the most markers (a subject walking into the capture volume would otherwise
    leave the poses of its first, barely observed frames in every later one). No frame of
    this motion came from the dynamic fit, so none is marked ``unobserved`` (left out of it).
    Every frame is solved in time order (``keyframe_stride=1``, whatever the default), the
    solve every rule and threshold of the diagnosis was calibrated on: with keyframes every
    4 frames the directions no marker pins move otherwise, and two of the run's hidden mass
    redistributions (draws 7001, 7003) were no longer named.
    """
    from solver.dynamics.preprocess import lowpass
    from solver.dynamics.spline import differentiate
    from solver.kinematics.ik import FrameSolver, IkSettings, solve_trajectory_from_best_frame
    from solver.model.rotations import rotations_to_wxyz

    sk = Skeleton(model)
    idx = sk.marker_index(list(trial.marker_names))
    solver = FrameSolver(sk, idx, np.ones(idx.size), IkSettings(keyframe_stride=1))
    q = solve_trajectory_from_best_frame(solver, trial.observed, trial.q)
    settings = trial.settings or {}
    dt = frame_interval(trial.time)
    q = lowpass(q, 1.0 / dt, float(settings.get("cutoff_hz", 30.0)), int(settings.get("filter_order", 3)))
    q = sk.cmap.complete(q)
    qd, qdd = differentiate(q, dt, str(settings.get("derivative", "spline")))
    rot, pos = sk.body_poses(q)
    return replace(
        trial,
        q=q,
        qd=qd,
        qdd=qdd,
        modeled=sk.marker_positions(q, idx),
        body_position=pos,
        body_wxyz=rotations_to_wxyz(rot),
        com=sk.center_of_mass(q),
        com_acc=differentiate(sk.center_of_mass(q), dt, str(settings.get("derivative", "spline")))[1],
        unobserved=np.zeros(trial.n_frames, dtype=bool),
    )
