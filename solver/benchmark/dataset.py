"""The benchmark's dataset: inputs and ground truth per frame, from processed trials.

Werling et al. 2024, "AddBiomechanics Dataset: Capturing the Physics of Human Motion at
Scale", §5 proposes the task *estimating dynamics from motion*: given the coordinates
q̃ of a subject's scaled model over time, predict per frame

* the centre-of-mass acceleration (m/s², ground frame),
* per foot, the ground reaction force (GRF) and the ground reaction moment (GRM) about
  the foot body's origin (ground frame),
* the joint torques (generalized forces of the non-root coordinates).

:func:`benchmark_trial` turns one :class:`~solver.results.ProcessedTrial` into a
:class:`BenchmarkTrial`:

1. resampled to 100 Hz (linear interpolation; boolean masks by nearest frame) when the
   trial was processed at another rate;
2. the input q̃ is the motion as a pose estimator would give it: by default
   (``inputs="kinematic"``) inverse kinematics of the trial's observed markers (raw, at
   the trial's frames) with the subject's scaled model (:func:`kinematic_coordinates`),
   then the paper's 3rd-order zero-phase Butterworth filter at 30 Hz
   (:func:`benchmark_input`). As in the paper, whose inputs come from the dataset's
   kinematics pass and whose labels from its dynamics pass, the input is *not* the
   dynamics stage's coordinates: those were fitted to the measured forces, and would hand
   the force plates to every method. ``inputs="processed"`` uses them anyway (filtered at
   30 Hz once more), as an upper bound of what a method can reach. The filtering study
   (:mod:`solver.benchmark.filtering`) filters the same unfiltered input at other cut-offs;
3. ground truth: the trial's centre-of-mass acceleration and generalized forces, and
   per foot the sum of the plate wrenches the dynamics stage applied to that foot,
   moved to the foot origin: ``F_b = Σ F_p``, ``M_b = Σ (cop_p - o_b) × F_p + τ_free,p``;
4. benchmark frames: force measured (not ``unobserved``), every loaded plate's wrench
   applied to one of the two feet (at most two contact bodies; a load on any other body,
   or a loaded plate applied to no body, drops the frame), at least
   :data:`MARGIN_FRAMES` frames away from a frame that fails these rules, and finite
   ground truth. The margin exists because the ground-truth accelerations are spline
   derivatives of the fitted motion, which at frame t depend on neighbouring frames; next
   to frames with unmeasured force (whose motion the dynamics fit leaves free) they can be
   inconsistent with the measured force (on the Camargo circuit, 10 of 668 such frames
   had more than 5 N/kg between m (a_com - g) and the plates, up to 135 m/s²).
   A trial with fewer than :data:`MIN_TRIAL_FRAMES` benchmark frames is skipped.

Splits are by subject (:func:`split_subjects`, seeded; or :func:`leave_one_subject_out`
folds for datasets of a handful of subjects), so no subject is in two splits.

Contact: a foot is in contact on a frame when a loaded plate's wrench is applied to it
(the plates' body assignment of the dynamics stage: the measured, "ground truth" contact).
"""

from __future__ import annotations

import random
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from solver.benchmark.models import BenchmarkError, skeleton_for
from solver.constants import GRAVITY_VECTOR
from solver.results import ProcessedTrial, load_processed, processed_trials

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Frame rate of the benchmark, Hz (the paper's).
RATE_HZ = 100.0
#: Low-pass cut-off of the input coordinates, Hz (the paper's 30 Hz) ...
CUTOFF_HZ = 30.0
#: ... of a Butterworth filter of this order, applied forward and backward.
FILTER_ORDER = 3
#: Trials with fewer benchmark frames than this are skipped.
MIN_TRIAL_FRAMES = 12
#: Benchmark frames keep this many frames (30 ms) away from a frame with unmeasured force.
MARGIN_FRAMES = 3
#: The two contact bodies, in the order of every per-foot array (right, left).
DEFAULT_FEET = ("calcn_r", "calcn_l")
#: A plate whose vertical force exceeds this fraction of body weight is loaded (the
#: dynamics stage's default threshold of contact assignment).
LOADED_BW = 0.02
#: Standard gravity, m/s² (OpenSim's ground frame, Y up).
GRAVITY = np.array(GRAVITY_VECTOR)
#: The splits, in order.
SPLITS = ("train", "dev", "test")
#: Sources of the input coordinates (see the module docstring).
INPUTS = ("kinematic", "processed")


@dataclass(frozen=True)
class BenchmarkTrial:
    """One trial of the benchmark on its 100 Hz frames (all frames of the trial are kept,
    because baselines need neighbouring frames; :attr:`frames` selects those scored).

    Attributes
    ----------
    subject, trial
        Names.
    model_path
        The subject's scaled (and mass-fitted) model, ``.osim``.
    mass_kg
        Subject mass, kg (the dynamics stage's fitted mass; normalizes the metrics).
    coordinate_names
        ``(n,)`` OpenSim coordinate names; the first six are the root (pelvis) coordinates.
    feet
        The two contact bodies (right, left).
    time
        ``(T,)`` s, 100 Hz.
    inputs
        Where the input comes from: ``"kinematic"`` (inverse kinematics of the markers) or
        ``"processed"`` (the dynamics stage's coordinates).
    q_unfiltered
        ``(T, n)`` the input coordinates (rad or m) before the benchmark's filter.
    q
        ``(T, n)`` the input q̃: ``q_unfiltered`` low-passed at ``cutoff_hz``.
    cutoff_hz
        Cut-off of the filter that made ``q``.
    frames
        ``(K,)`` indices of the benchmark frames (sorted).
    contact
        ``(T, 2)`` ground-truth contact of each foot (a loaded plate applied to it).
    com_acc
        ``(T, 3)`` ground-truth centre-of-mass acceleration, m/s², ground frame.
    grf
        ``(T, 2, 3)`` ground-truth ground reaction force on each foot, N, ground frame.
    grm
        ``(T, 2, 3)`` ground-truth ground reaction moment on each foot about the foot body's
        origin, N·m, ground frame.
    tau
        ``(T, n)`` ground-truth generalized forces (N·m or N); the first six are the root
        residuals.
    hicks_ok
        Whether the trial meets both Hicks residual thresholds (None when unknown).
    """

    subject: str
    trial: str
    model_path: str
    mass_kg: float
    coordinate_names: tuple[str, ...]
    feet: tuple[str, str]
    time: FloatArray
    inputs: str
    q_unfiltered: FloatArray
    q: FloatArray
    cutoff_hz: float
    frames: NDArray[np.intp]
    contact: BoolArray
    com_acc: FloatArray
    grf: FloatArray
    grm: FloatArray
    tau: FloatArray
    hicks_ok: bool | None = None

    @property
    def n_frames(self) -> int:
        """Number of frames T of the whole trial."""
        return int(self.time.size)

    @property
    def dt(self) -> float:
        """Frame interval, s."""
        return 1.0 / RATE_HZ


@dataclass(frozen=True)
class Skipped:
    """A trial left out of the dataset, and why."""

    subject: str
    trial: str
    reason: str


@dataclass(frozen=True)
class Dataset:
    """The benchmark trials of several subjects.

    Attributes
    ----------
    trials
        Benchmark trials, in subject then trial order.
    skipped
        Trials left out, with the reason.
    """

    trials: tuple[BenchmarkTrial, ...]
    skipped: tuple[Skipped, ...] = ()

    @property
    def subjects(self) -> list[str]:
        """Subject names, in order of first appearance."""
        return list(dict.fromkeys(t.subject for t in self.trials))

    def of_subjects(self, names: Iterable[str]) -> Dataset:
        """The trials of the named subjects (skipped trials are kept)."""
        keep = set(names)
        return Dataset(tuple(t for t in self.trials if t.subject in keep), self.skipped)

    @property
    def n_frames(self) -> int:
        """Number of benchmark frames."""
        return int(sum(t.frames.size for t in self.trials))


def torque_columns(trial: BenchmarkTrial) -> NDArray[np.intp]:
    """``(n_scored,)`` indices, into the model's n coordinates, of the coordinates scored by
    the joint torque metric: every coordinate but the six root coordinates (their
    generalized forces are residuals) and the dependent (coupled) ones, whose force is
    carried by their independent coordinate."""
    sk = skeleton_for(trial.model_path)
    root = set(sk.root_transform_axes())
    return np.array([i for i in range(sk.n) if i not in root and sk.is_independent[i]], dtype=np.intp)


# ---------------------------------------------------------------------------------- building


def benchmark_input(q: FloatArray, *, cutoff_hz: float = CUTOFF_HZ, order: int = FILTER_ORDER) -> FloatArray:
    """The benchmark input q̃: ``(T, n)`` coordinates at 100 Hz low-passed with a zero-phase
    Butterworth filter (3rd order, 30 Hz by default; a cut-off at or above 50 Hz, the
    Nyquist frequency, leaves ``q`` as is)."""
    from solver.dynamics.preprocess import lowpass

    return lowpass(np.asarray(q, dtype=float), RATE_HZ, cutoff_hz, order)


def kinematic_coordinates(trial: ProcessedTrial) -> FloatArray:
    """``(T, n)`` inverse kinematics of the trial's observed markers ``(T, M, 3)`` (raw,
    on the trial's frames) with its scaled model: the motion without the dynamics fit.

    Per frame, the kinematics stage's least-squares solver (equal marker weights), warm
    started along time, forwards and backwards, from the processed pose of the frame that
    sees the most markers (:func:`solver.kinematics.ik.solve_trajectory_from_best_frame`).

    A trial read from a .b3d file with a kinematics pass carries that pass's coordinates as
    ``settings["kinematic_q"]`` (:mod:`solver.benchmark.b3d_trials`): they are the input, as
    in the paper.

    Raises
    ------
    BenchmarkError
        No observed marker on any frame (and no ``kinematic_q`` given), naming the trial.
    """
    given = trial.settings.get("kinematic_q") if isinstance(trial.settings, dict) else None
    if given is not None:
        return np.asarray(given, dtype=float)
    from solver.kinematics.ik import FrameSolver, IkSettings, solve_trajectory_from_best_frame

    sk = skeleton_for(trial.model_path)
    idx = sk.marker_index(list(trial.marker_names))
    obs = np.asarray(trial.observed, dtype=float)
    if not np.isfinite(obs).all(axis=2).any():
        raise BenchmarkError("no observed marker on any frame", where=f"{trial.subject}/{trial.trial}")
    solver = FrameSolver(sk, idx, np.ones(idx.size), IkSettings())
    return solve_trajectory_from_best_frame(solver, obs, np.asarray(trial.q, dtype=float))


def foot_wrenches(
    trial: ProcessedTrial, feet: Sequence[str]
) -> tuple[FloatArray, FloatArray, BoolArray, BoolArray]:
    """Per-foot ground reaction force and moment about the foot origin, from the plates.

    Parameters
    ----------
    trial
        A processed trial with its plates' body assignment.
    feet
        The contact bodies, e.g. ``("calcn_r", "calcn_l")``.

    Returns
    -------
    grf, grm
        ``(T, F, 3)`` force (N) and moment about each foot's origin (N·m), ground frame:
        sums over the plates applied to the foot of ``F`` and ``(cop - origin) × F +
        free moment``.
    contact
        ``(T, F)`` whether a loaded plate is applied to the foot.
    foreign
        ``(T,)`` frames where a loaded plate is applied to no body or to a body that is not
        one of ``feet`` (more contact bodies than the benchmark's two feet).

    Raises
    ------
    BenchmarkError
        The model has no body of ``feet`` (naming the missing ones and the trial).
    """
    t = trial.n_frames
    nf = len(feet)
    grf = np.zeros((t, nf, 3))
    grm = np.zeros((t, nf, 3))
    contact = np.zeros((t, nf), dtype=bool)
    foreign = np.zeros(t, dtype=bool)
    body_index = {b: i for i, b in enumerate(trial.body_names)}
    missing = [f for f in feet if f not in body_index]
    if missing:
        raise BenchmarkError(f"the model has no body {', '.join(missing)} (feet of the benchmark)", where=f"{trial.subject}/{trial.trial}")
    weight = trial.mass_kg * float(np.linalg.norm(GRAVITY))
    for plate in trial.plates:
        body = np.full(t, -1) if plate.body is None else np.asarray(plate.body)
        force = np.nan_to_num(np.asarray(plate.force, dtype=float))
        loaded = force[:, 1] > LOADED_BW * weight
        applied = body >= 0
        cop = np.nan_to_num(np.asarray(plate.cop, dtype=float))
        free = np.nan_to_num(np.asarray(plate.free_moment, dtype=float))
        on_feet = np.zeros(t, dtype=bool)
        for k, foot in enumerate(feet):
            on = applied & (body == body_index[foot])
            on_feet |= on
            arm = cop[on] - trial.body_position[on, body_index[foot]]
            grf[on, k] += force[on]
            grm[on, k] += np.cross(arm, force[on]) + free[on]
            contact[on, k] |= loaded[on]
        foreign |= loaded & ~on_feet
    return grf, grm, contact, foreign


def _resample_trial_arrays(time: FloatArray, arrays: dict[str, np.ndarray]) -> tuple[FloatArray, dict[str, np.ndarray]]:
    """Put (T, ...) arrays on a 100 Hz grid: floats linearly, booleans by nearest frame."""
    from solver.dynamics.preprocess import common_time, resample

    new_time = common_time(float(time[0]), float(time[-1]), RATE_HZ)
    nearest = np.clip(np.rint(np.interp(new_time, time, np.arange(time.size))).astype(int), 0, time.size - 1)
    out = {}
    for name, a in arrays.items():
        out[name] = a[nearest] if a.dtype == bool else resample(time, a, new_time)
    return new_time, out


def benchmark_trial(
    trial: ProcessedTrial,
    *,
    feet: Sequence[str] = DEFAULT_FEET,
    cutoff_hz: float = CUTOFF_HZ,
    min_frames: int = MIN_TRIAL_FRAMES,
    inputs: str = "kinematic",
    margin_frames: int = MARGIN_FRAMES,
) -> BenchmarkTrial | Skipped:
    """The benchmark view of one processed trial (see the module docstring), or the reason
    it is skipped (no dynamics, fewer than ``min_frames`` benchmark frames).

    Raises
    ------
    BenchmarkError
        ``inputs`` is not one of ``INPUTS``, ``feet`` is not two bodies of the model
        (:func:`foot_wrenches`), or, with kinematic inputs, no marker is observed on any
        frame (:func:`kinematic_coordinates`).
    """
    if inputs not in INPUTS:
        raise BenchmarkError(f"inputs must be one of {INPUTS}, got {inputs!r}")
    if len(feet) != 2:
        raise BenchmarkError(f"the benchmark needs exactly two feet, got {list(feet)}")
    if not trial.has_dynamics or trial.n_frames < 3:
        return Skipped(trial.subject, trial.trial, "no dynamics (no force plates, or processed for kinematics only)")
    grf, grm, contact, foreign = foot_wrenches(trial, feet)
    finite_q = np.isfinite(np.asarray(trial.q, dtype=float)).all()
    if not finite_q:
        return Skipped(trial.subject, trial.trial, "coordinates with missing (NaN) frames")
    arrays: dict[str, np.ndarray] = {
        "q": kinematic_coordinates(trial) if inputs == "kinematic" else np.asarray(trial.q, dtype=float),
        "com_acc": np.asarray(trial.com_acc, dtype=float),
        "tau": np.asarray(trial.tau, dtype=float),
        "grf": grf,
        "grm": grm,
        "contact": contact,
        "measured": ~np.asarray(trial.unobserved, dtype=bool) & ~foreign,
    }
    time = np.asarray(trial.time, dtype=float)
    if abs(trial.rate_hz - RATE_HZ) > 1e-6 * RATE_HZ:
        time, arrays = _resample_trial_arrays(time, arrays)
    finite = np.ones(time.size, dtype=bool)
    for name in ("q", "com_acc", "tau", "grf", "grm"):
        finite &= np.isfinite(arrays[name].reshape(time.size, -1)).all(axis=1)
    usable = arrays["measured"] & finite
    if margin_frames > 0:
        bad = np.convolve((~usable).astype(int), np.ones(2 * margin_frames + 1, dtype=int), mode="same") > 0
        usable &= ~bad
    frames = np.flatnonzero(usable)
    if frames.size < min_frames:
        return Skipped(trial.subject, trial.trial, f"{frames.size} benchmark frames (fewer than {min_frames})")
    q = arrays["q"]
    m = trial.metrics
    hicks = None
    if m.get("hicks_linear_ok") is not None:
        hicks = bool(m["hicks_linear_ok"]) and m.get("hicks_angular_ok") is not False
    return BenchmarkTrial(
        subject=trial.subject,
        trial=trial.trial,
        model_path=trial.model_path,
        mass_kg=float(trial.mass_kg),
        coordinate_names=tuple(trial.coordinate_names),
        feet=(feet[0], feet[1]),
        time=time,
        inputs=inputs,
        q_unfiltered=q,
        q=benchmark_input(q, cutoff_hz=cutoff_hz),
        cutoff_hz=float(cutoff_hz),
        frames=frames.astype(np.intp),
        contact=arrays["contact"],
        com_acc=arrays["com_acc"],
        grf=arrays["grf"],
        grm=arrays["grm"],
        tau=arrays["tau"],
        hicks_ok=hicks,
    )


def build_dataset(
    trials: Iterable[ProcessedTrial],
    *,
    feet: Sequence[str] = DEFAULT_FEET,
    cutoff_hz: float = CUTOFF_HZ,
    min_frames: int = MIN_TRIAL_FRAMES,
    inputs: str = "kinematic",
    margin_frames: int = MARGIN_FRAMES,
) -> Dataset:
    """The benchmark dataset of processed trials (see :func:`benchmark_trial`)."""
    kept: list[BenchmarkTrial] = []
    skipped: list[Skipped] = []
    for trial in trials:
        b = benchmark_trial(
            trial, feet=feet, cutoff_hz=cutoff_hz, min_frames=min_frames, inputs=inputs, margin_frames=margin_frames
        )
        (kept if isinstance(b, BenchmarkTrial) else skipped).append(b)  # type: ignore[arg-type]
    return Dataset(tuple(kept), tuple(skipped))


def load_dataset(
    out_dirs: Iterable[str | Path],
    *,
    feet: Sequence[str] = DEFAULT_FEET,
    cutoff_hz: float = CUTOFF_HZ,
    min_frames: int = MIN_TRIAL_FRAMES,
    inputs: str = "kinematic",
    margin_frames: int = MARGIN_FRAMES,
    names: Sequence[str | None] | None = None,
) -> Dataset:
    """The benchmark dataset of every trial processed into the output folders ``out_dirs``
    (one per subject, as written by :func:`solver.pipeline.process_subject`); an entry may
    also be an AddBiomechanics ``.b3d`` file (one subject: its dynamics pass is the ground
    truth, :mod:`solver.benchmark.b3d_trials`). ``names``, one per entry of ``out_dirs``,
    names the subjects in place of their recorded names where not None (a dataset's
    relative paths, ``labA/s01``: two labs' ``s01`` are two subjects).

    Raises
    ------
    BenchmarkError
        An output folder holds no processed trial, one folder is given twice (under two
        paths or names), two folders hold the same subject, or a .b3d file has no dynamics
        pass.
    B3dFormatError
        A .b3d file is damaged.
    """

    folders = list(out_dirs)
    given = list(names) if names is not None else [None] * len(folders)
    if len(given) != len(folders):
        raise ValueError(f"{len(given)} names for {len(folders)} subjects")
    first_given: dict[Path, int] = {}
    for k, out in enumerate(folders):  # one folder under two paths or names (OUT and OUT/labA/s01) would be scored twice
        first = first_given.setdefault(Path(out).resolve(), k)
        if first != k:
            raise BenchmarkError(f"given twice (also as {folders[first]}): each subject is scored once", path=out)

    def trials_of(out: str | Path) -> Iterator[ProcessedTrial]:
        if Path(out).suffix.lower() == ".b3d" and Path(out).is_file():
            from solver.benchmark.b3d_trials import b3d_processed_trials

            yield from b3d_processed_trials(out)
            return
        found = processed_trials(out)
        if not found:
            raise BenchmarkError("no processed trial in this folder", path=out)
        for name in found:
            yield load_processed(out, name)

    def load_all() -> Iterator[ProcessedTrial]:
        seen: dict[str, Path] = {}
        for out, subject in zip(folders, given):
            for trial in trials_of(out):
                if subject is not None:
                    trial = replace(trial, subject=subject)
                first = seen.setdefault(trial.subject, Path(out))
                if first != Path(out):
                    raise BenchmarkError(f"subject {trial.subject!r} is also in {first}", path=out)
                yield trial

    return build_dataset(
        load_all(), feet=feet, cutoff_hz=cutoff_hz, min_frames=min_frames, inputs=inputs, margin_frames=margin_frames
    )


# ---------------------------------------------------------------------------------- splits


@dataclass(frozen=True)
class Split:
    """Subjects of each split; no subject is in two.

    Attributes
    ----------
    train, dev, test
        Subject names.
    name
        A label for reports ("seeded", "fold 2/4: test = walk", ...).
    """

    train: tuple[str, ...]
    dev: tuple[str, ...]
    test: tuple[str, ...]
    name: str = field(default="split")

    def __post_init__(self) -> None:
        for a, b in ((self.train, self.dev), (self.train, self.test), (self.dev, self.test)):
            both = sorted(set(a) & set(b))
            if both:
                raise BenchmarkError(f"subject(s) {', '.join(both)} in two splits")


def split_subjects(subjects: Sequence[str], *, seed: int = 0, dev_fraction: float = 0.1, test_fraction: float = 0.2) -> Split:
    """Seeded train/dev/test split of subjects.

    The subjects are shuffled with ``random.Random(seed)``; the test split takes
    ``round(test_fraction * N)`` subjects and the dev split ``round(dev_fraction * N)``,
    each at least one while that leaves a training subject (3 subjects: one each; 2: one
    train, one test, no dev; 1: test only).
    """
    names = sorted(dict.fromkeys(subjects))
    random.Random(seed).shuffle(names)
    n = len(names)
    n_test = min(max(1, round(test_fraction * n)), n)
    n_dev = min(max(1, round(dev_fraction * n)), max(n - n_test - 1, 0))
    test, dev, train = names[:n_test], names[n_test:n_test + n_dev], names[n_test + n_dev:]
    return Split(tuple(sorted(train)), tuple(sorted(dev)), tuple(sorted(test)), name=f"seeded (seed {seed})")


def leave_one_subject_out(subjects: Sequence[str]) -> list[Split]:
    """One fold per subject: that subject is the test split, all others train (no dev
    split). Used when the dataset has only a handful of subjects, so that every subject is
    scored by a model that never saw it."""
    names = sorted(dict.fromkeys(subjects))
    return [
        Split(tuple(s for s in names if s != test), (), (test,), name=f"fold {i + 1}/{len(names)}: test = {test}")
        for i, test in enumerate(names)
    ]
