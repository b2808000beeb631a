"""Centre-of-mass initialization with unobserved-force frames (AddBiomechanics extension).

The seed paper (Werling et al. 2024, AddBiomechanics Dataset, §3) writes the centre-of-mass
trajectory as a linear function of a path vector

    zeta = [c_1, cdot_1, 1/m, a_u (centre-of-mass accelerations on unobserved frames)]

by integrating the accelerations with semi-explicit Euler: a_t = F_t / m + g on frames
with measured external force F_t, a_t = a_u,t on the others; v_{t+1} = v_t + h a_t;
c_{t+1} = c_t + h v_{t+1}. Least squares against the kinematic centre of mass, with a
regularization alpha |a_u|^2, gives the mass and a trajectory consistent with the forces.

Semi-explicit Euler makes the second difference exact: c_{t+1} - 2 c_t + c_{t-1} = h² a_t.
We therefore solve the same problem with the positions c_t as unknowns (plus 1/m, shared
by all trials of a subject): the dynamics equations of observed frames enter with a very
large weight (they hold to round-off), the kinematic positions with weight 1 and the
unobserved accelerations with weight alpha. The normal equations are banded (plus one
column for 1/m), so long trials solve in milliseconds; eliminating c_1, cdot_1 and the
observed accelerations recovers the paper's zeta exactly.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.linalg import spsolve

from solver.errors import DynamicsError

FloatArray = NDArray[np.float64]

#: Weight of the dynamics equations on observed frames relative to the position fit (m² per
#: (m/s²)² h⁴); large enough that they hold to ~1e-9 relative, small enough for float64.
DYNAMICS_WEIGHT = 1e8


@dataclass(frozen=True)
class ComTrial:
    """Inputs of one trial.

    Attributes
    ----------
    com
        ``(T, 3)`` kinematic centre of mass, m.
    force
        ``(T, 3)`` total measured external force on the body, N (any value on unobserved frames).
    observed
        ``(T,)`` frames whose external force is fully measured.
    dt
        Frame interval, s.
    """

    com: FloatArray
    force: FloatArray
    observed: NDArray[np.bool_]
    dt: float


@dataclass(frozen=True)
class ComFit:
    """Result of :func:`fit_com`.

    Attributes
    ----------
    mass_kg
        Fitted body mass.
    com
        Per trial, ``(T, 3)`` fitted centre-of-mass trajectory, m.
    acc
        Per trial, ``(T, 3)`` its acceleration (second difference / h²; ends copied), m/s².
    rms_shift
        Per trial, RMS distance between fitted and kinematic centre of mass, m.
    """

    mass_kg: float
    com: tuple[FloatArray, ...]
    acc: tuple[FloatArray, ...]
    rms_shift: tuple[float, ...]


def fit_com(
    trials: Sequence[ComTrial], gravity: FloatArray, *, alpha: float = 1e-4, mass_prior: tuple[float, float] | None = None
) -> ComFit:
    """Fit one body mass and a force-consistent centre-of-mass path per trial.

    Parameters
    ----------
    trials
        Trials of one subject (at least one observed interior frame overall).
    gravity
        ``(3,)`` m/s².
    alpha
        Regularization of unobserved accelerations, m² per (m/s²)² per frame.
    mass_prior
        (mass kg, weight) pulling 1/m toward 1/mass (weight in m² per (1/kg)²); None: no prior.

    Raises
    ------
    DynamicsError
        No trial has an observed interior frame, or the fitted mass is not positive.
    """
    gravity = np.asarray(gravity, dtype=float)
    offsets, n = [], 0
    for tr in trials:
        offsets.append(n)
        n += 3 * tr.com.shape[0]
    m_col = n  # index of 1/m
    rows, cols, vals, rhs, weights = [], [], [], [], []
    r = 0

    def add(entries: list[tuple[int, float]], b: float, w: float) -> None:
        nonlocal r
        for c, v in entries:
            rows.append(r)
            cols.append(c)
            vals.append(v)
        rhs.append(b)
        weights.append(w)
        r += 1

    n_obs = 0
    for tr, off in zip(trials, offsets):
        t = tr.com.shape[0]
        h2 = tr.dt**2
        for k in range(t):
            for a in range(3):
                add([(off + 3 * k + a, 1.0)], float(tr.com[k, a]), 1.0)
        for k in range(1, t - 1):
            idx = [off + 3 * (k - 1), off + 3 * k, off + 3 * (k + 1)]
            if tr.observed[k]:
                n_obs += 1
                for a in range(3):
                    entries = [(idx[0] + a, 1.0), (idx[1] + a, -2.0), (idx[2] + a, 1.0), (m_col, -h2 * float(tr.force[k, a]))]
                    add(entries, h2 * float(gravity[a]), DYNAMICS_WEIGHT)
            else:
                for a in range(3):
                    add([(idx[0] + a, 1.0 / h2), (idx[1] + a, -2.0 / h2), (idx[2] + a, 1.0 / h2)], 0.0, alpha)
    if n_obs == 0:
        raise DynamicsError("no frame with measured force to fit the mass")
    if mass_prior is not None:
        add([(m_col, 1.0)], 1.0 / mass_prior[0], mass_prior[1])
    a_mat = sp.csr_matrix((vals, (rows, cols)), shape=(r, n + 1))
    w = sp.diags(np.array(weights))
    lhs = (a_mat.T @ w @ a_mat).tocsc()
    sol = spsolve(lhs, a_mat.T @ (np.array(weights) * np.array(rhs)))
    inv_m = float(sol[m_col])
    if not np.isfinite(inv_m) or inv_m <= 0:
        raise DynamicsError(f"the centre-of-mass fit gave a non-positive mass (1/m = {inv_m:.3g})")
    coms, accs, shifts = [], [], []
    for tr, off in zip(trials, offsets):
        t = tr.com.shape[0]
        c = sol[off : off + 3 * t].reshape(t, 3)
        acc = np.empty_like(c)
        acc[1:-1] = (c[2:] - 2 * c[1:-1] + c[:-2]) / tr.dt**2
        acc[0], acc[-1] = acc[1], acc[-2]
        coms.append(c)
        accs.append(acc)
        shifts.append(float(np.sqrt(np.mean(np.sum((c - tr.com) ** 2, axis=1)))))
    return ComFit(1.0 / inv_m, tuple(coms), tuple(accs), tuple(shifts))
