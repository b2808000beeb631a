"""A third method: the analytical baseline's total force, split between the feet by a network.

Not one of the paper's baselines; added because, on our handful of subjects, the paper's
MLP baseline (:mod:`solver.benchmark.mlp`) stays well behind the analytical baseline (GRF
error 3.48 against 1.09 N/kg with the plates' contact and 1.76 with contact from foot
height, docs/benchmark), while the analytical baseline's error has two parts that can be
attacked separately (kinematic inputs, tests/benchmarks/RESULTS.md): its total force,
differentiated twice from noisy kinematics (given the measured split instead, its error is
0.83 N/kg), and its split between the feet (given the measured total force instead, 0.41).
Its motion-only version adds misjudged contact (1.76). So this method keeps the physics of
the total force, learns how much to smooth it, and learns the split.

1. Total external force ``F = m (a_com - g)`` by inverse dynamics without external loads,
   and the centre-of-mass acceleration, as the analytical baseline
   (:func:`~solver.benchmark.analytical.analytical_baseline`) computes them, from q̃
   low-passed once more at a cut-off chosen on the training subjects (:func:`select_cutoff`:
   the candidate whose total force best matches their measured one; 30 Hz leaves q̃ as it
   is). The paper's filtering study, repeated on our data (docs/benchmark/filtering_study.md),
   shows the analytical baseline's error falling from 30 Hz to about 6 Hz; the filter is a
   choice of the method, learned like its weights, not a change of the benchmark's input.
2. A network of the MLP baseline's shape and training (``Linear -> 512 sigmoid ->
   Linear``, RMSprop 1e-4, batches of 32, 10 epochs; :func:`~solver.benchmark.mlp.fit_network`)
   predicts per frame the shares ``(s_r, s_l, s_air)`` (a softmax) of ``F`` borne by the
   right foot, the left foot and neither, from the same 50-frame history sampled every 5
   frames. Each history sample holds per foot (:func:`contact_features`): the height of the
   foot origin and of its toe body above their own lowest point within 0.5 s centred on
   the frame (m), their horizontal speed and vertical velocity (m/s), the horizontal
   distance from the whole-body centre of mass to the foot origin (m), and the analytical
   baseline's kinematic contact indicator (1 when the foot origin is within 0.1 m of that
   lowest point). None of these depend on where the lab's horizontal axes point or on
   which foot is which, so every training frame is also used mirrored (feet swapped,
   shares swapped).
3. Training targets: the measured vertical-force shares ``(F_r,y, F_l,y) / ΣF_y``, or
   "neither" where ``ΣF_y`` is under 2 % of body weight; squared error of the shares,
   weighted by ``max(measured ΣF_y, |analytical F_y|) / BW`` so that frames carrying
   little force count little (their split barely changes the error in newtons).
4. Prediction: ``GRF_k = s_k c_k F`` with ``c_k`` the kinematic contact indicator (a foot
   the rule calls airborne bears nothing: on the run held out, the network alone, trained on
   walking, stairs and a drop jump, put force on airborne feet); the ground reaction moment
   about each foot origin is zero; joint torques by inverse dynamics of q̃ with these
   forces at the foot origins (the re-filtered coordinates, as for the force).

The inputs are the motion alone (no force plate, no measured contact), as for the paper's
MLP. ``torch`` is needed (the ``mlp`` extra).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import minimum_filter1d

from solver.benchmark.analytical import Prediction, kinematic_contact, torques_from_feet
from solver.benchmark.dataset import BenchmarkError, BenchmarkTrial, benchmark_input, skeleton_for
from solver.benchmark.mlp import MlpOptions, _import_torch, _std, fit_network, history_index
from solver.constants import GRAVITY

FloatArray = NDArray[np.float64]

#: Features per foot and history sample (see :func:`contact_features`).
FEATURES_PER_FOOT = 8
#: Below this total vertical force (fraction of body weight) a training frame is airborne.
AIRBORNE_BW = 0.02
#: Window of the lowest-point reference of the heights, s (as the kinematic contact rule).
WINDOW_S = 0.5
#: Candidate cut-offs (Hz) of the extra low-pass filter of the total force, chosen on the
#: training subjects (:func:`select_cutoff`); 30 Hz is the input q̃ as it is.
CUTOFFS_HZ = (4.0, 6.0, 8.0, 10.0, 12.0, 15.0, 20.0, 30.0)


def toe_body(trial: BenchmarkTrial, foot: str) -> str:
    """The body attached to ``foot`` by a joint (the toes), or ``foot`` itself if none."""
    sk = skeleton_for(trial.model_path)
    children = [j.child.body for j in sk.osim.joints if j.parent.body == foot]
    return children[0] if children else foot


def contact_features(trial: BenchmarkTrial, q: FloatArray | None = None) -> FloatArray:
    """``(T, FEATURES_PER_FOOT, 2)`` per-frame contact features of the right and left foot.

    Per foot, in this order: height of the foot origin and of the toe body's origin above
    their own lowest point within ``WINDOW_S`` centred on the frame (m); horizontal speed
    and vertical velocity of the foot origin, then of the toe origin (m/s, central
    differences); horizontal distance from the whole-body centre of mass to the foot
    origin (m); the kinematic contact indicator of the analytical baseline (0 or 1).
    Ground frame with +y up; ``q`` ``(T, n)`` defaults to ``trial.q``.
    """
    from solver.dynamics.preprocess import derivatives

    sk = skeleton_for(trial.model_path)
    q = trial.q if q is None else q
    _, pos = sk.body_poses(q)
    foot = pos[:, [sk.body_index(f) for f in trial.feet]]  # (T, 2, 3)
    toe = pos[:, [sk.body_index(toe_body(trial, f)) for f in trial.feet]]
    width = max(1, round(WINDOW_S / trial.dt)) | 1
    parts = []
    for p in (foot, toe):
        parts.append(p[..., 1] - minimum_filter1d(p[..., 1], width, axis=0, mode="nearest"))
    for p in (foot, toe):
        v, _ = derivatives(p, trial.dt)
        parts += [np.linalg.norm(v[..., [0, 2]], axis=-1), v[..., 1]]
    com = sk.center_of_mass(q)
    parts.append(np.linalg.norm(com[:, None, [0, 2]] - foot[..., [0, 2]], axis=-1))
    parts.append(kinematic_contact(trial, q).astype(float))
    return np.stack(parts, axis=1)


def _windows(trial: BenchmarkTrial, frames: NDArray[np.intp], options: MlpOptions) -> FloatArray:
    """``(K, S * FEATURES_PER_FOOT * 2)`` network inputs (feet the fastest-varying axis)."""
    feats = contact_features(trial)
    return feats[history_index(trial.n_frames, frames, options)].reshape(len(frames), -1)


def _mirror(x: FloatArray) -> FloatArray:
    """Inputs with the right and left foot swapped."""
    return x.reshape(len(x), -1, 2)[:, :, ::-1].reshape(len(x), -1)


def smoothed_input(trial: BenchmarkTrial, cutoff_hz: float | None) -> FloatArray:
    """``(T, n)`` the input q̃ low-passed once more at ``cutoff_hz`` (the benchmark's 3rd-order
    zero-phase Butterworth); q̃ itself for None or a cut-off at or above the input's own."""
    if cutoff_hz is None or cutoff_hz >= trial.cutoff_hz:
        return trial.q
    return benchmark_input(trial.q, cutoff_hz=cutoff_hz)


def total_force(trial: BenchmarkTrial, cutoff_hz: float | None = None) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """``(T, 3)`` total external force ``m (a_com - g)`` (N, ground frame) by inverse dynamics
    without external loads of the input q̃ low-passed at ``cutoff_hz`` (:func:`smoothed_input`),
    with the coordinates, velocities and accelerations ``(T, n)`` it used (central
    differences)."""
    from solver.dynamics.preprocess import derivatives

    q = smoothed_input(trial, cutoff_hz)
    qd, qdd = derivatives(q, trial.dt)
    return skeleton_for(trial.model_path).inverse_dynamics(q, qd, qdd).root_force, q, qd, qdd


def select_cutoff(trials: Sequence[BenchmarkTrial], candidates: Sequence[float] = CUTOFFS_HZ) -> tuple[float, dict[float, float]]:
    """The cut-off (Hz) of :func:`total_force` that best reproduces the measured total ground
    reaction force on the benchmark frames of ``trials`` (the training subjects), and the
    error of every candidate: ``|ΣF - F_total| / m`` (N/kg) averaged over each subject's
    frames, then over the subjects, so that every subject counts the same (pooled by frames,
    the Camargo circuit's noisy kinematics, 388 frames best filtered at 4 Hz, chose 4 Hz for
    the fold that holds out the run, whose own best is 8 Hz: the run's GRF error 0.96 N/kg,
    against 0.88 with the 6 Hz chosen subject by subject).

    Raises
    ------
    BenchmarkError
        No trial or no candidate.
    """
    if not trials or not candidates:
        raise BenchmarkError("no training trial or no cut-off to choose the hybrid's filter from")
    errors = {}
    for fc in candidates:
        per_subject: dict[str, list[FloatArray]] = {}
        for t in trials:
            f = total_force(t, fc)[0][t.frames]
            per_subject.setdefault(t.subject, []).append(np.linalg.norm(t.grf[t.frames].sum(axis=1) - f, axis=1) / t.mass_kg)
        errors[float(fc)] = float(np.mean([np.concatenate(e).mean() for e in per_subject.values()]))
    return min(errors, key=errors.__getitem__), errors


def split_targets(trial: BenchmarkTrial, frames: NDArray[np.intp], cutoff_hz: float | None = None) -> FloatArray:
    """``(K, 4)`` training targets: the measured shares (right, left, airborne) of the
    vertical ground reaction force and the frame's loss weight (see the module docstring;
    the analytical force of the weight is :func:`total_force` at ``cutoff_hz``)."""
    fy = np.clip(trial.grf[frames, :, 1], 0.0, None)
    measured = fy.sum(axis=1)
    body_weight = trial.mass_kg * GRAVITY
    analytical = np.abs(total_force(trial, cutoff_hz)[0][frames, 1])
    air = measured < AIRBORNE_BW * body_weight
    shares = np.zeros((len(frames), 3))
    shares[~air, :2] = fy[~air] / measured[~air, None]
    shares[air, 2] = 1.0
    weight = np.maximum(measured, analytical) / body_weight
    return np.column_stack([shares, weight])


@dataclass
class TrainedContactSplit:
    """A trained contact-split network with its input standardization.

    Attributes
    ----------
    net
        The ``torch.nn.Sequential`` (3 outputs: right, left, airborne logits).
    options
        Hyper-parameters.
    x_mean, x_std
        ``(D,)`` input standardization.
    cutoff_hz
        Cut-off of the total force's extra low-pass filter, chosen on the training subjects
        (:func:`select_cutoff`).
    cutoff_errors
        The training subjects' total-force error (N/kg) of every candidate cut-off.
    history
        Per epoch ``{"epoch", "train_loss", "dev_loss"}`` (weighted squared share error).
    seconds
        Training wall time, s.
    n_train
        Training samples (mirrored copies included).
    """

    net: Any
    options: MlpOptions
    x_mean: FloatArray
    x_std: FloatArray
    cutoff_hz: float | None = None
    cutoff_errors: dict[float, float] = field(default_factory=dict)
    history: list[dict[str, float]] = field(default_factory=list)
    seconds: float = 0.0
    n_train: int = 0

    def shares(self, trial: BenchmarkTrial) -> FloatArray:
        """``(T, 3)`` predicted shares (right, left, airborne) on every frame (rows sum to 1)."""
        torch = _import_torch()
        x = _windows(trial, np.arange(trial.n_frames, dtype=np.intp), self.options)
        with torch.no_grad():
            out = self.net(torch.as_tensor((x - self.x_mean) / self.x_std, dtype=torch.float32))
            return torch.softmax(out, dim=1).numpy().astype(float)

    def predict(self, trial: BenchmarkTrial) -> Prediction:
        """The method's :class:`~solver.benchmark.analytical.Prediction` on every frame."""
        total, q, qd, qdd = total_force(trial, self.cutoff_hz)
        sk = skeleton_for(trial.model_path)
        com_acc = total / sk.total_mass + np.asarray(sk.model.gravity.linear, dtype=float)
        share = self.shares(trial)[:, :2] * kinematic_contact(trial, trial.q)
        grf = share[:, :, None] * total[:, None, :]
        grm = np.zeros_like(grf)
        tau = torques_from_feet(trial, q, qd, qdd, grf, grm)
        return Prediction(com_acc=com_acc, grf=grf, grm=grm, tau=tau)


def _stack(trials: Sequence[BenchmarkTrial], options: MlpOptions, cutoff_hz: float | None) -> tuple[FloatArray, FloatArray]:
    xs = [_windows(t, t.frames, options) for t in trials]
    ys = [split_targets(t, t.frames, cutoff_hz) for t in trials]
    if not xs:
        return np.zeros((0, options.samples * FEATURES_PER_FOOT * 2)), np.zeros((0, 4))
    x, y = np.concatenate(xs), np.concatenate(ys)
    return np.concatenate([x, _mirror(x)]), np.concatenate([y, y[:, [1, 0, 2, 3]]])


def train_contact_split(
    train: Sequence[BenchmarkTrial],
    dev: Sequence[BenchmarkTrial] = (),
    *,
    options: MlpOptions | None = None,
    cutoffs_hz: Sequence[float] = CUTOFFS_HZ,
    progress: Callable[[str, float], None] | None = None,
) -> TrainedContactSplit:
    """Choose the total force's filter and train the contact-split network on the benchmark
    frames of ``train``.

    Parameters
    ----------
    train, dev
        Benchmark trials of the training and development subjects (dev: loss per epoch).
    options
        Hyper-parameters (default: the paper's MLP values).
    cutoffs_hz
        Candidate cut-offs of the total force's filter (:func:`select_cutoff`); one value
        fixes it (``(30.0,)``: the input q̃ as it is, the analytical baseline's force).
    progress
        Called with (message, fraction) after each epoch.

    Raises
    ------
    BenchmarkError
        PyTorch is not installed, or no training frame.
    """
    _import_torch()
    opts = options or MlpOptions()
    t0 = time.perf_counter()
    if not train or not any(len(t.frames) for t in train):
        raise BenchmarkError("no training frame for the contact-split network")
    cutoff, cutoff_errors = select_cutoff(train, cutoffs_hz)
    x, y = _stack(train, opts, cutoff)
    xd, yd = _stack(dev, opts, cutoff)
    x_mean, x_std = x.mean(axis=0), _std(x)

    def loss(out: Any, target: Any) -> Any:
        import torch

        err = (torch.softmax(out, dim=1) - target[:, :3]) ** 2
        return (target[:, 3:] * err).sum(dim=1).mean()

    net, history = fit_network(
        (x - x_mean) / x_std, y, 3, loss, opts, dev=((xd - x_mean) / x_std, yd), progress=progress, name="contact split"
    )
    return TrainedContactSplit(net, opts, x_mean, x_std, cutoff, cutoff_errors, history, time.perf_counter() - t0, len(x))
