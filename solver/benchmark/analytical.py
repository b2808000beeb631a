"""The analytical baseline of the benchmark (Werling et al. 2024, §5).

From the input coordinates q̃ alone:

1. generalized velocities and accelerations by central differences (second-order
   one-sided at the two end frames; :func:`solver.dynamics.preprocess.derivatives`);
2. the centre-of-mass acceleration they imply and, by Newton's law for the whole body,
   the total external force ``F = m (a_com - g)``. Both come from inverse dynamics without
   external loads: the root residual force of that solution is exactly the rate of change
   of linear momentum minus gravity, ``m a_com - m g`` (so ``a_com = F / m + g`` with no
   separate centre-of-mass differentiation);
3. ``F`` is split evenly between the feet in contact (all of it on the one foot in single
   support, half on each in double support, none in flight);
4. the ground reaction moment about each foot's origin is zero (the force acts at the
   foot origin);
5. joint torques by inverse dynamics of q̃ with these foot forces.

Which feet are in contact: ``contact="measured"`` (default) takes the ground-truth
contact of the benchmark trial (a loaded force plate applied to the foot), as the paper's
baseline is given the contact state; ``contact="kinematic"`` uses the motion alone: a foot
is in contact when its body origin is less than ``kinematic_height_m`` (0.1 m) above its
own lowest point within ``kinematic_window_s`` (0.5 s) centred on the frame: the step or
floor it stands on, so that stairs and uneven ground work (the trial's lowest foot
origin, the earlier rule, called every foot on an upper step airborne: agreement with the
measured contact on the stair descent 0.41, against 0.96; over the eight benchmark trials
0.77 against 0.84, tests/benchmarks/RESULTS.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import minimum_filter1d

from solver.benchmark.dataset import BenchmarkTrial, skeleton_for

FloatArray = NDArray[np.float64]

#: Contact rules of :func:`analytical_baseline`.
CONTACT_RULES = ("measured", "kinematic")


@dataclass(frozen=True)
class Prediction:
    """A method's estimate on every frame of a benchmark trial (ground frame, SI units).

    Attributes
    ----------
    com_acc
        ``(T, 3)`` centre-of-mass acceleration, m/s².
    grf
        ``(T, 2, 3)`` ground reaction force on each foot (right, left), N.
    grm
        ``(T, 2, 3)`` ground reaction moment on each foot about its origin, N·m.
    tau
        ``(T, n)`` generalized forces, N·m or N (the first six: root residuals).
    """

    com_acc: FloatArray
    grf: FloatArray
    grm: FloatArray
    tau: FloatArray


def kinematic_contact(
    trial: BenchmarkTrial, q: FloatArray, *, height_m: float = 0.1, window_s: float = 0.5
) -> NDArray[np.bool_]:
    """``(T, 2)`` feet whose body origin is within ``height_m`` (m) of its own lowest height
    within ``window_s`` (s) centred on the frame, from the coordinates ``q`` ``(T, n)``
    alone (see the module docstring)."""
    y = foot_origins(trial, q)[..., 1]
    width = max(1, round(window_s / trial.dt)) | 1  # odd: centred on the frame
    return (y - minimum_filter1d(y, width, axis=0, mode="nearest")) < height_m


def foot_origins(trial: BenchmarkTrial, q: FloatArray) -> FloatArray:
    """``(T, 2, 3)`` ground-frame origins of the two feet for coordinates ``q``, m."""
    sk = skeleton_for(trial.model_path)
    _, pos = sk.body_poses(q)
    return pos[:, [sk.body_index(f) for f in trial.feet]]


def torques_from_feet(
    trial: BenchmarkTrial, q: FloatArray, qd: FloatArray, qdd: FloatArray, grf: FloatArray, grm: FloatArray
) -> FloatArray:
    """``(T, n)`` generalized forces by inverse dynamics with the given per-foot wrenches:
    ``grf`` ``(T, 2, 3)`` acting at each foot's origin plus the couple ``grm`` ``(T, 2, 3)``
    (the moment about that origin), ground frame."""
    from solver.model.skeleton import ExternalWrench

    sk = skeleton_for(trial.model_path)
    origins = foot_origins(trial, q)
    wrenches = [ExternalWrench(f, grf[:, k], origins[:, k], grm[:, k]) for k, f in enumerate(trial.feet)]
    return sk.inverse_dynamics(q, qd, qdd, wrenches).tau


def analytical_baseline(
    trial: BenchmarkTrial,
    *,
    q: FloatArray | None = None,
    contact: str = "measured",
    kinematic_height_m: float = 0.1,
    kinematic_window_s: float = 0.5,
) -> Prediction:
    """The analytical baseline on every frame of ``trial`` (see the module docstring).

    Parameters
    ----------
    trial
        A benchmark trial.
    q
        ``(T, n)`` input coordinates; default ``trial.q`` (the 30 Hz-filtered q̃). The
        filtering study passes coordinates filtered at other cut-offs.
    contact
        ``"measured"`` (ground-truth contact) or ``"kinematic"`` (foot height).
    kinematic_height_m, kinematic_window_s
        Height threshold (m) and window (s) of the kinematic contact rule.

    Returns
    -------
    Prediction

    Raises
    ------
    ValueError
        ``contact`` is neither ``"measured"`` nor ``"kinematic"``.
    """
    from solver.dynamics.preprocess import derivatives

    if contact not in CONTACT_RULES:
        raise ValueError(f"contact must be one of {CONTACT_RULES}, got {contact!r}")
    q = trial.q if q is None else np.asarray(q, dtype=float)
    sk = skeleton_for(trial.model_path)
    qd, qdd = derivatives(q, trial.dt)
    total = sk.inverse_dynamics(q, qd, qdd).root_force  # (T, 3) = m (a_com - g), N
    gravity = np.asarray(sk.model.gravity.linear, dtype=float)
    com_acc = total / sk.total_mass + gravity
    on = trial.contact if contact == "measured" else kinematic_contact(trial, q, height_m=kinematic_height_m, window_s=kinematic_window_s)
    n_on = on.sum(axis=1, keepdims=True)
    share = np.where(n_on > 0, on / np.maximum(n_on, 1), 0.0)  # (T, 2)
    grf = share[:, :, None] * total[:, None, :]
    grm = np.zeros_like(grf)
    tau = torques_from_feet(trial, q, qd, qdd, grf, grm)
    return Prediction(com_acc=com_acc, grf=grf, grm=grm, tau=tau)
