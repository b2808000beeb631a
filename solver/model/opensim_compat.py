"""Reproduce a known inexactness of OpenSim 4.6's CustomJoint dynamics, for comparisons.

OpenSim builds a CustomJoint as Simbody's function-based mobilizer. Its velocity-
dependent acceleration term (H-dot times u) differentiates the rotation axes
w2 = R1 a2 and w3 = R1 R2 a3 with the angular velocity contributed by the *first
mobility* (for w2) and by every mobility *but the third* (for w3), which equals the
exact rates w1 θ1' and w1 θ1' + w2 θ2' only when rotation i is driven by mobility i.
In the walker knee one coordinate drives all three rotations, so w2 is differentiated
with the whole angular velocity and the term (w3 θ3') x w2 θ2' is added that the exact
kinematics do not have. The mass matrix and gravity terms are unaffected.

We compute the exact dynamics (checked against the Lagrangian built from OpenSim's own
mass matrix in tests/model). This module computes the difference, expressed as extra
accelerations of the expanded rotation joints, so that tests can reproduce OpenSim's
numbers to round-off and quantify the difference.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def _rotate(axis: FloatArray, angle: FloatArray, vec: FloatArray) -> FloatArray:
    """Rodrigues rotation of ``vec`` (..., 3) about unit ``axis`` (3,) by ``angle`` (...)."""
    c, s = np.cos(angle)[..., None], np.sin(angle)[..., None]
    return vec * c + np.cross(axis, vec) * s + axis * (vec @ axis)[..., None] * (1 - c)


def simbody_hdot_error(skeleton: object, q_pin: FloatArray, v_pin: FloatArray) -> FloatArray:
    """Extra expanded-joint accelerations that make exact RNEA equal OpenSim's ID.

    Parameters
    ----------
    skeleton
        A :class:`solver.model.skeleton.Skeleton`.
    q_pin, v_pin
        ``(T, nv)`` expanded joint positions and velocities.

    Returns
    -------
    ``(T, nv)`` accelerations (rad/s²) to add to the exact expanded accelerations.
    """
    out = np.zeros_like(q_pin)
    for joint, rots in skeleton.joint_rotations:  # type: ignore[attr-defined]
        if joint.type != "CustomJoint" or len(rots) != 3:
            continue
        mobility = {c: i for i, c in enumerate(joint.coordinates)}
        rot_axes = [a for a in joint.axes if a.kind == "rotation"]
        n_mob = len(joint.coordinates)
        theta, rate, mob = [], [], []
        for (axis, dof, const), ta in zip(rots, rot_axes):
            theta.append(q_pin[:, dof] if dof is not None else np.full(q_pin.shape[0], const))
            rate.append(v_pin[:, dof] if dof is not None else np.zeros(q_pin.shape[0]))
            mob.append(-1 if ta.coordinate is None else mobility[ta.coordinate])
        a1, a2, a3 = (r[0] for r in rots)
        w1 = np.broadcast_to(a1, q_pin.shape[:1] + (3,))
        w2 = _rotate(a1, theta[0], np.broadcast_to(a2, w1.shape))
        w3 = _rotate(a1, theta[0], _rotate(a2, theta[1], np.broadcast_to(a3, w1.shape)))
        w = (w1, w2, w3)
        omega = [w[i] * rate[i][:, None] for i in range(3)]
        v1 = sum(omega[i] for i in range(3) if mob[i] == 0)
        v2 = sum(omega[i] for i in range(3) if (n_mob <= 2 or mob[i] != 2) and mob[i] >= 0)
        v1 = v1 if isinstance(v1, np.ndarray) else np.zeros_like(w1)
        v2 = v2 if isinstance(v2, np.ndarray) else np.zeros_like(w1)
        simbody = np.cross(v1, w2) * rate[1][:, None] + np.cross(v2, w3) * rate[2][:, None]
        exact = np.cross(omega[0], w2) * rate[1][:, None] + np.cross(omega[0] + omega[1], w3) * rate[2][:, None]
        delta = simbody - exact  # (T, 3) angular acceleration in the joint parent frame
        if not np.any(delta):
            continue
        wmat = np.stack(w, axis=-1)  # (T, 3, 3) columns w1 w2 w3
        dtheta = np.linalg.solve(wmat, delta[..., None])[..., 0]
        for i, (_, dof, _) in enumerate(rots):
            if dof is not None:
                out[:, dof] += dtheta[:, i]
    return out
