"""Derivatives of marker positions with respect to body scale factors and marker offsets.

For fixed coordinates q, every marker position is *affine* in the scale factors: rotations
do not depend on scale, and each translation of the kinematic chain is a generic
translation multiplied element-wise by one body's factors. With the OpenSim joint
semantics (parent body P, child body C, offset frames pf and cf, joint translation
p_J(q) = sum_k a_k f_k(q) in the parent offset frame),

    o_C = o_P + R_P (s_P * t_pf) + R_P R_pf sum_k a_k (|a_k| . s_P) f_k(q) - R_C (s_C * t_cf)
    p_m = o_B + R_B (s_B * l_m + d_m)

where ``*`` is the element-wise product, t and l are the generic (unscaled) offsets and
d_m the body-fixed marker offset. Differentiating gives the Jacobians below, exact for
any scale (checked against finite differences of rebuilt models in tests).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from solver.kinematics.scale_groups import ScaleGroups
from solver.model.osim import OsimModel

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class _JointTerms:
    parent: int  # body index, -1 for ground
    child: int
    t_pf: FloatArray  # (3,) generic parent offset translation
    r_pf: FloatArray  # (3, 3) parent offset rotation
    t_cf: FloatArray  # (3,) generic child offset translation
    axes: tuple[tuple[FloatArray, object, int | None], ...]  # (axis, function, coordinate index)


class ScaleJacobian:
    """Precomputed structure of the generic model for scale derivatives.

    Parameters
    ----------
    generic
        The unscaled model the scale factors multiply.
    groups
        Body -> scale group assignment.
    """

    def __init__(self, generic: OsimModel, groups: ScaleGroups) -> None:
        self.groups = groups
        self.body_index = {b: i for i, b in enumerate(generic.body_names)}
        cidx = {c: i for i, c in enumerate(generic.coordinate_names)}
        terms = []
        for j in generic.joints:
            axes = tuple(
                (np.array(a.axis), a.function, None if a.coordinate is None else cidx[a.coordinate])
                for a in j.axes
                if a.kind == "translation"
            )
            terms.append(
                _JointTerms(
                    parent=self.body_index.get(j.parent.body, -1),
                    child=self.body_index[j.child.body],
                    t_pf=np.array(j.parent.translation),
                    r_pf=j.parent.rotation(),
                    t_cf=np.array(j.child.translation),
                    axes=axes,
                )
            )
        self._terms = terms
        self._group_of_body = np.array([groups.body_group[b] for b in generic.body_names], dtype=np.intp)

    def body_origins(self, body_rot: FloatArray, x: FloatArray) -> FloatArray:
        """d(body origin)/d(group scales).

        Parameters
        ----------
        body_rot
            ``(F, B, 3, 3)`` body rotations at the current coordinates.
        x
            ``(F, n)`` coordinates with couplers applied.

        Returns
        -------
        ``(F, B, 3, 3G)``.
        """
        f, b = body_rot.shape[:2]
        out = np.zeros((f, b, 3, self.groups.n_params))
        for t in self._terms:
            c = t.child
            gc = self._group_of_body[c]
            if t.parent >= 0:
                out[:, c] = out[:, t.parent]
                gp = self._group_of_body[t.parent]
                r_p = body_rot[:, t.parent]
                block = r_p * t.t_pf[None, None, :]
                if t.axes:
                    trans = np.zeros((f, 3, 3))
                    for axis, func, ci in t.axes:
                        val = func.value(x[:, ci]) if ci is not None else np.full(f, float(func.value(0.0)))
                        trans += val[:, None, None] * np.outer(axis, np.abs(axis))[None]
                    block = block + (r_p @ t.r_pf) @ trans
                out[:, c, :, 3 * gp : 3 * gp + 3] += block
            out[:, c, :, 3 * gc : 3 * gc + 3] -= body_rot[:, c] * t.t_cf[None, None, :]
        return out

    def markers(
        self, body_rot: FloatArray, x: FloatArray, marker_body: NDArray[np.intp], marker_generic: FloatArray
    ) -> FloatArray:
        """d(marker position)/d(group scales), ``(F, M, 3, 3G)``.

        Parameters
        ----------
        body_rot, x
            As in :meth:`body_origins`.
        marker_body
            ``(M,)`` body index of each marker.
        marker_generic
            ``(M, 3)`` generic (unscaled) marker locations in the body frame.
        """
        origins = self.body_origins(body_rot, x)
        out = origins[:, marker_body].copy()
        g = self._group_of_body[marker_body]
        local = body_rot[:, marker_body] * marker_generic[None, :, None, :]  # (F, M, 3, 3)
        for m in range(marker_body.size):
            out[:, m, :, 3 * g[m] : 3 * g[m] + 3] += local[:, m]
        return out
