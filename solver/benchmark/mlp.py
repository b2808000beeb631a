"""The MLP baseline of the benchmark (Werling et al. 2024, §5), in PyTorch (CPU).

Network: two fully connected layers, 512 hidden units, sigmoid activation
(``Linear(D, 512) -> Sigmoid -> Linear(512, 12)``), trained with RMSprop (learning rate
1e-4), batches of 32, 10 epochs, mean squared error on standardized outputs.

Input of frame t: a 50-frame history sampled every 5 frames (frames t-45, t-40, ..., t:
10 samples, as the paper's data loader reads ``window // stride`` frames ``stride`` apart;
before a trial's first frame the first frame is repeated), each sample holding

* the coordinates q̃ of the non-root independent coordinates and their accelerations
  (central differences), rad and rad/s² (m, m/s² for translational ones);
* the joint-centre positions (body origins) relative to the pelvis, in the pelvis frame, m;
* for the root, whose six coordinates depend on where the lab's axes point, the same
  information in the pelvis frame: gravity's direction, the pelvis origin's linear
  acceleration, the pelvis angular velocity and angular acceleration.

Output of frame t: per foot (right, left) the ground reaction force and the moment about
the foot origin, divided by body mass and expressed in the pelvis frame (N/kg, N·m/kg),
as the paper's network predicts contact wrenches in the root frame. The prediction is
rotated to the ground frame and scaled by the mass; the centre-of-mass acceleration
follows from the predicted force, ``a_com = ΣF / m + g``, and joint torques from inverse
dynamics of q̃ with the predicted wrenches at the feet.

Inputs and outputs are standardized with the training set's mean and standard deviation.
Subjects of different models share the coordinates and bodies they have in common
(:meth:`FeatureSpec.common`).

``torch`` is an optional dependency (``pip install 'addb[mlp]'``): it is imported only
when a network is built or trained, and :func:`torch_available` tells whether it can be.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from solver.benchmark.analytical import Prediction, torques_from_feet
from solver.benchmark.dataset import BenchmarkError, BenchmarkTrial, skeleton_for

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class MlpOptions:
    """Hyper-parameters of the MLP baseline (the paper's values by default).

    Attributes
    ----------
    hidden
        Hidden units of the single hidden layer.
    history_frames, stride
        The input covers the last ``history_frames`` frames, one sample every ``stride``.
    learning_rate, batch_size, epochs
        RMSprop learning rate, mini-batch size and number of passes over the training set.
    seed
        Seed of the weight initialization and of the shuffling.
    threads
        Torch intra-op threads (None: torch's default).
    """

    hidden: int = 512
    history_frames: int = 50
    stride: int = 5
    learning_rate: float = 1e-4
    batch_size: int = 32
    epochs: int = 10
    seed: int = 0
    threads: int | None = None

    @property
    def samples(self) -> int:
        """Number of history samples per input."""
        return max(1, self.history_frames // self.stride)


def torch_available() -> bool:
    """Whether PyTorch can be imported (the ``mlp`` extra)."""
    try:
        import torch  # noqa: F401
    except ImportError:
        return False
    return True


def _import_torch() -> Any:
    try:
        import torch
    except ImportError as exc:
        raise BenchmarkError(
            "the MLP baseline needs PyTorch: install the CPU build with "
            "`pip install torch==2.13.0` (or `pip install 'addb[mlp]'`)"
        ) from exc
    return torch


# ---------------------------------------------------------------------------------- features


@dataclass(frozen=True)
class FeatureSpec:
    """Which coordinates and bodies make up an input sample (fixed across subjects).

    Attributes
    ----------
    coordinates
        Non-root independent coordinate names.
    bodies
        Body names whose origins are joint centres (the pelvis excluded).
    """

    coordinates: tuple[str, ...]
    bodies: tuple[str, ...]

    @staticmethod
    def of_trial(trial: BenchmarkTrial) -> FeatureSpec:
        """All non-root independent coordinates and non-root bodies of the trial's model."""
        sk = skeleton_for(trial.model_path)
        root = set(sk.root_transform_axes())
        coords = tuple(c for i, c in enumerate(sk.coordinate_names) if i not in root and sk.is_independent[i])
        bodies = tuple(b for b in sk.body_names if b != sk.root_body)
        return FeatureSpec(coords, bodies)

    @staticmethod
    def common(trials: Sequence[BenchmarkTrial]) -> FeatureSpec:
        """The coordinates and bodies every trial's model has (in the first one's order).

        Raises
        ------
        BenchmarkError
            ``trials`` is empty.
        """
        if not trials:
            raise BenchmarkError("no trial to define the MLP's inputs")
        specs = [FeatureSpec.of_trial(t) for t in trials]
        coords = [c for c in specs[0].coordinates if all(c in s.coordinates for s in specs)]
        bodies = [b for b in specs[0].bodies if all(b in s.bodies for s in specs)]
        return FeatureSpec(tuple(coords), tuple(bodies))

    @property
    def per_sample(self) -> int:
        """Features per history sample."""
        return 2 * len(self.coordinates) + 3 * len(self.bodies) + 12


def _vee(skew: FloatArray) -> FloatArray:
    return np.stack([skew[..., 2, 1] - skew[..., 1, 2], skew[..., 0, 2] - skew[..., 2, 0], skew[..., 1, 0] - skew[..., 0, 1]], axis=-1) / 2


def frame_features(trial: BenchmarkTrial, spec: FeatureSpec, q: FloatArray | None = None) -> tuple[FloatArray, FloatArray]:
    """Per-frame input features and the pelvis orientation.

    Returns
    -------
    features
        ``(T, spec.per_sample)``: coordinates, their accelerations, joint centres in the
        pelvis frame, then gravity direction, pelvis linear acceleration, angular velocity
        and angular acceleration, all in the pelvis frame.
    pelvis_rot
        ``(T, 3, 3)`` pelvis orientation (columns: pelvis axes in the ground frame).

    Raises
    ------
    BenchmarkError
        The trial's model lacks a coordinate of ``spec`` (naming them).
    """
    from solver.dynamics.preprocess import derivatives

    sk = skeleton_for(trial.model_path)
    q = trial.q if q is None else q
    dt = trial.dt
    missing = [c for c in spec.coordinates if c not in sk.coordinate_names]
    if missing:
        raise BenchmarkError(f"model of {trial.subject} lacks coordinate(s) {', '.join(missing)} of the MLP's inputs")
    cidx = [sk.coordinate_index(c) for c in spec.coordinates]
    _, qdd = derivatives(q, dt)
    rot, pos = sk.body_poses(q)
    root = sk.body_index(sk.root_body)
    r_p, p_p = rot[:, root], pos[:, root]  # (T, 3, 3), (T, 3)
    to_pelvis = r_p.transpose(0, 2, 1)
    bidx = [sk.body_index(b) for b in spec.bodies]
    centres = np.einsum("tij,tbj->tbi", to_pelvis, pos[:, bidx] - p_p[:, None, :])
    gravity_dir = to_pelvis @ np.array([0.0, -1.0, 0.0])
    _, acc = derivatives(p_p, dt)
    lin_acc = np.einsum("tij,tj->ti", to_pelvis, acc)
    r_dot, _ = derivatives(r_p, dt)
    omega = _vee(np.einsum("tij,tjk->tik", to_pelvis, r_dot))  # body-frame angular velocity
    alpha, _ = derivatives(omega, dt)
    feats = np.concatenate(
        [q[:, cidx], qdd[:, cidx], centres.reshape(len(q), -1), gravity_dir, lin_acc, omega, alpha], axis=1
    )
    return feats, r_p


def history_index(n_frames: int, frames: NDArray[np.intp], options: MlpOptions) -> NDArray[np.intp]:
    """``(K, S)`` frame indices of the history samples of each frame (oldest first),
    clamped to the trial's first frame."""
    offsets = options.stride * np.arange(options.samples - 1, -1, -1)
    return np.clip(np.asarray(frames)[:, None] - offsets[None, :], 0, n_frames - 1)


def windows(trial: BenchmarkTrial, spec: FeatureSpec, frames: NDArray[np.intp], options: MlpOptions) -> tuple[FloatArray, FloatArray]:
    """Network inputs ``(K, S * spec.per_sample)`` of ``frames`` and the pelvis orientation
    ``(K, 3, 3)`` at those frames."""
    feats, r_p = frame_features(trial, spec)
    idx = history_index(trial.n_frames, frames, options)
    return feats[idx].reshape(len(frames), -1), r_p[frames]


def targets(trial: BenchmarkTrial, frames: NDArray[np.intp], pelvis_rot: FloatArray) -> FloatArray:
    """``(K, 12)`` per-kg wrenches [F_r, M_r, F_l, M_l] in the pelvis frame (the outputs)."""
    to_pelvis = pelvis_rot.transpose(0, 2, 1)
    parts = []
    for k in range(2):
        parts.append(np.einsum("tij,tj->ti", to_pelvis, trial.grf[frames, k]))
        parts.append(np.einsum("tij,tj->ti", to_pelvis, trial.grm[frames, k]))
    return np.concatenate(parts, axis=1) / trial.mass_kg


# ---------------------------------------------------------------------------------- model


@dataclass
class TrainedMlp:
    """A trained network with its input/output standardization.

    Attributes
    ----------
    net
        The ``torch.nn.Sequential``.
    spec, options
        Input layout and hyper-parameters.
    x_mean, x_std, y_mean, y_std
        Standardization of inputs ``(D,)`` and outputs ``(12,)``.
    history
        Per epoch: ``{"epoch", "train_loss", "dev_loss"}`` (standardized MSE).
    seconds
        Training wall time, s.
    n_train
        Number of training samples.
    """

    net: Any
    spec: FeatureSpec
    options: MlpOptions
    x_mean: FloatArray
    x_std: FloatArray
    y_mean: FloatArray
    y_std: FloatArray
    history: list[dict[str, float]] = field(default_factory=list)
    seconds: float = 0.0
    n_train: int = 0

    def predict_outputs(self, x: FloatArray) -> FloatArray:
        """``(K, 12)`` network outputs (per-kg pelvis-frame wrenches) for inputs ``(K, D)``."""
        torch = _import_torch()
        xs = (x - self.x_mean) / self.x_std
        self.net.eval()
        with torch.no_grad():
            ys = self.net(torch.as_tensor(xs, dtype=torch.float32)).numpy().astype(float)
        return ys * self.y_std + self.y_mean

    def predict(self, trial: BenchmarkTrial) -> Prediction:
        """The MLP baseline's :class:`~solver.benchmark.analytical.Prediction` on every frame."""
        from solver.dynamics.preprocess import derivatives

        frames = np.arange(trial.n_frames, dtype=np.intp)
        x, r_p = windows(trial, self.spec, frames, self.options)
        y = self.predict_outputs(x) * trial.mass_kg
        grf = np.stack([np.einsum("tij,tj->ti", r_p, y[:, 6 * k:6 * k + 3]) for k in range(2)], axis=1)
        grm = np.stack([np.einsum("tij,tj->ti", r_p, y[:, 6 * k + 3:6 * k + 6]) for k in range(2)], axis=1)
        sk = skeleton_for(trial.model_path)
        gravity = np.asarray(sk.model.gravity.linear, dtype=float)
        com_acc = grf.sum(axis=1) / trial.mass_kg + gravity
        qd, qdd = derivatives(trial.q, trial.dt)
        tau = torques_from_feet(trial, trial.q, qd, qdd, grf, grm)
        return Prediction(com_acc=com_acc, grf=grf, grm=grm, tau=tau)


def _stack(trials: Sequence[BenchmarkTrial], spec: FeatureSpec, options: MlpOptions) -> tuple[FloatArray, FloatArray]:
    xs, ys = [], []
    for t in trials:
        x, r_p = windows(t, spec, t.frames, options)
        xs.append(x)
        ys.append(targets(t, t.frames, r_p))
    if not xs:
        return np.zeros((0, options.samples * spec.per_sample)), np.zeros((0, 12))
    return np.concatenate(xs), np.concatenate(ys)


def _std(a: FloatArray) -> FloatArray:
    s = a.std(axis=0)
    return np.where(s > 1e-8, s, 1.0)


def train_mlp(
    train: Sequence[BenchmarkTrial],
    dev: Sequence[BenchmarkTrial] = (),
    *,
    spec: FeatureSpec | None = None,
    options: MlpOptions | None = None,
    progress: Callable[[str, float], None] | None = None,
) -> TrainedMlp:
    """Train the MLP baseline on the benchmark frames of ``train``.

    Parameters
    ----------
    train, dev
        Benchmark trials of the training and development subjects (dev: loss per epoch).
    spec
        Input layout (default: what every train and dev trial's model has in common).
    options
        Hyper-parameters (default: the paper's).
    progress
        Called with (message, fraction) after each epoch.

    Raises
    ------
    BenchmarkError
        PyTorch is not installed, or no training frame.
    """
    torch = _import_torch()
    opts = options or MlpOptions()
    spec = spec or FeatureSpec.common(list(train) + list(dev))
    t0 = time.perf_counter()
    x, y = _stack(train, spec, opts)
    if len(x) == 0:
        raise BenchmarkError("no training frame for the MLP baseline")
    xd, yd = _stack(dev, spec, opts) if dev else (np.zeros((0, x.shape[1])), np.zeros((0, y.shape[1])))
    x_mean, x_std, y_mean, y_std = x.mean(axis=0), _std(x), y.mean(axis=0), _std(y)
    mse = torch.nn.MSELoss()
    net, history = fit_network(
        (x - x_mean) / x_std, (y - y_mean) / y_std, y.shape[1], lambda out, target: mse(out, target), opts,
        dev=((xd - x_mean) / x_std, (yd - y_mean) / y_std), progress=progress, name="MLP",
    )
    return TrainedMlp(net, spec, opts, x_mean, x_std, y_mean, y_std, history, time.perf_counter() - t0, len(x))


def fit_network(
    x: FloatArray,
    y: FloatArray,
    n_outputs: int,
    loss: Callable[[Any, Any], Any],
    options: MlpOptions,
    *,
    dev: tuple[FloatArray, FloatArray] | None = None,
    progress: Callable[[str, float], None] | None = None,
    name: str = "network",
) -> tuple[Any, list[dict[str, float]]]:
    """Train the paper's network shape, ``Linear(D, hidden) -> Sigmoid -> Linear(hidden,
    n_outputs)``, with RMSprop on mini-batches (the options' learning rate, batch size,
    epochs and seed).

    Parameters
    ----------
    x, y
        ``(N, D)`` standardized inputs and ``(N, E)`` targets (any columns ``loss`` reads).
    n_outputs
        Width of the output layer.
    loss
        ``loss(output (B, n_outputs), target (B, E)) -> scalar tensor`` to minimize.
    options
        Hyper-parameters (:class:`MlpOptions`).
    dev
        Development inputs and targets, whose loss is recorded after each epoch.
    progress
        Called with (message, fraction) after each epoch.
    name
        Name of the network in progress messages.

    Returns
    -------
    net, history
        The ``torch.nn.Sequential`` (in eval mode) and per epoch ``{"epoch", "train_loss",
        "dev_loss"}`` (``dev_loss`` NaN without dev frames).
    """
    torch = _import_torch()
    if options.threads:
        torch.set_num_threads(options.threads)
    torch.manual_seed(options.seed)
    net = torch.nn.Sequential(
        torch.nn.Linear(x.shape[1], options.hidden), torch.nn.Sigmoid(), torch.nn.Linear(options.hidden, n_outputs)
    )
    optimizer = torch.optim.RMSprop(net.parameters(), lr=options.learning_rate)
    xt = torch.as_tensor(x, dtype=torch.float32)
    yt = torch.as_tensor(y, dtype=torch.float32)
    xd, yd = dev if dev is not None else (np.zeros((0, x.shape[1])), np.zeros((0, y.shape[1])))
    xdt = torch.as_tensor(xd, dtype=torch.float32)
    ydt = torch.as_tensor(yd, dtype=torch.float32)
    gen = torch.Generator().manual_seed(options.seed)
    history = []
    for epoch in range(options.epochs):
        net.train()
        order = torch.randperm(len(xt), generator=gen)
        total = 0.0
        for start in range(0, len(xt), options.batch_size):
            batch = order[start:start + options.batch_size]
            optimizer.zero_grad()
            value = loss(net(xt[batch]), yt[batch])
            value.backward()
            optimizer.step()
            total += value.item() * len(batch)
        net.eval()
        with torch.no_grad():
            dev_loss = float(loss(net(xdt), ydt)) if len(xdt) else float("nan")
        history.append({"epoch": epoch + 1, "train_loss": total / len(xt), "dev_loss": dev_loss})
        if progress:
            progress(f"{name} epoch {epoch + 1}/{options.epochs}: train loss {total / len(xt):.3f}", (epoch + 1) / options.epochs)
    return net, history
