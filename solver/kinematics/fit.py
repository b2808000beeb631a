"""Joint fit of body scales, marker offsets and coordinates over frames of all trials.

One nonlinear least-squares problem over a subset of frames (from every trial, static
trials included):

    min  sum_f sum_m w_m |p_m(q_f, s, d) - y_fm|^2                        (markers)
       + sum_g [a |s_g - s_h|^2 + b |anisotropy(s_g)|^2]                  (scale prior)
       + sum_m c n_m |d_m|^2                                              (offset prior)
       + e sum_f |q_f - q_f^0|^2                                          (tiny pose prior)

with s the scale factors of the body groups (:mod:`solver.kinematics.scale_groups`),
s_h the height ratio, d_m a body-fixed offset of marker m, n_m the number of fit frames
that observe marker m. It is solved by Levenberg-Marquardt with analytic Jacobians:
pinocchio's marker Jacobian for q, the exact affine scale/offset Jacobian of
:mod:`solver.kinematics.scale_jacobian` for (s, d). The per-frame pose blocks are
eliminated with a Schur complement, so a step costs one small dense solve per frame
and one of size 3 G + 3 M. This is the AddBiomechanics idea (Werling et al. 2023,
"AddBiomechanics: Automating model scaling, inverse kinematics, and inverse dynamics
from human motion data through sequential optimization", PLOS ONE) solved jointly
rather than bilevel.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from solver.kinematics.ik import solver_bounds
from solver.kinematics.scale_groups import ScaleGroups, prior_residuals
from solver.kinematics.scale_jacobian import ScaleJacobian
from solver.model.osim import Marker, OsimModel
from solver.model.scaling import scale_model
from solver.model.skeleton import Skeleton

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class FitSettings:
    """Weights and stopping rules of the joint fit (see the module docstring for the terms).

    Attributes
    ----------
    scale_prior_weight
        a, per frame in the fit (so the prior keeps its relative strength), m² per unit².
    anisotropy_weight
        b, same units.
    offset_weight
        c, relative to one observation: an offset of d costs c d² per observing frame.
    pose_prior_weight
        e, m² per rad²; only conditions directions no marker observes.
    max_iterations
        Levenberg-Marquardt iterations.
    tolerance
        Stop when the relative cost decrease of an accepted step is below this.
    """

    scale_prior_weight: float = 2e-4
    anisotropy_weight: float = 1e-3
    offset_weight: float = 0.02
    pose_prior_weight: float = 1e-5
    max_iterations: int = 40
    tolerance: float = 1e-5


@dataclass(frozen=True)
class FitResult:
    """Result of :func:`fit_model`.

    Attributes
    ----------
    model
        The scaled model with fitted marker locations (generic location scaled, plus offset).
    scales
        ``(3G,)`` group scale factors.
    offsets
        ``(M, 3)`` body-fixed marker offsets, m, for the fitted markers.
    q
        ``(F, n)`` coordinates of the fit frames.
    marker_rms
        RMS marker error over all observations of the fit frames, m.
    iterations
        Accepted Levenberg-Marquardt steps.
    skeleton
        :attr:`model` built (``ScaleFitProblem.build`` of the scales and offsets), for reuse.
    """

    model: OsimModel
    scales: FloatArray
    offsets: FloatArray
    q: FloatArray
    marker_rms: float
    iterations: int
    skeleton: Skeleton


class ScaleFitProblem:
    """The least-squares problem of the module docstring, for given data.

    Parameters
    ----------
    generic
        The generic (unscaled) model; its markers are the markers to fit.
    groups
        Scale groups.
    markers
        ``(M,)`` names of the model markers the observations refer to.
    obs
        ``(F, M, 3)`` observed positions, NaN where missing.
    weights
        ``(M,)`` marker weights.
    height_scale
        s_h, the prior's target factor.
    settings
        Weights.
    """

    def __init__(
        self,
        generic: OsimModel,
        groups: ScaleGroups,
        markers: list[str],
        obs: FloatArray,
        weights: FloatArray,
        height_scale: float,
        settings: FitSettings,
    ) -> None:
        self.generic = generic
        self.groups = groups
        self.names = list(markers)
        self.obs = obs
        self.seen = np.isfinite(obs).all(axis=2)
        self.sqrt_w = np.sqrt(weights)
        self.height_scale = height_scale
        self.settings = settings
        by_name = {m.name: m for m in generic.markers}
        self.generic_markers = [by_name[n] for n in self.names]
        self.marker_local = np.array([m.location for m in self.generic_markers]).reshape(-1, 3)
        bidx = {b: i for i, b in enumerate(generic.body_names)}
        self.marker_body = np.array([bidx[m.body] for m in self.generic_markers], dtype=np.intp)
        self.sj = ScaleJacobian(generic, groups)
        n_frames = obs.shape[0]
        n_obs = self.seen.sum(axis=0).astype(float)
        fixed = np.array([m.fixed for m in self.generic_markers])
        self.offset_w = settings.offset_weight * np.maximum(n_obs, 1.0) * np.where(fixed, 20.0, 1.0)
        self.prior_w = settings.scale_prior_weight * n_frames
        self.aniso_w = settings.anisotropy_weight * n_frames
        self.n_s = groups.n_params
        self.n_z = self.n_s + 3 * len(self.names)

    def build(self, scales: FloatArray, offsets: FloatArray) -> Skeleton:
        """The skeleton for given group scales ``scales`` ``(3G,)`` (x, y, z factors of each
        group, dimensionless) and marker offsets ``offsets`` ``(M, 3)`` (body-fixed, m, added
        to the scaled generic locations)."""
        body_scales = self.groups.body_scales(scales)
        scaled = scale_model(self.generic, body_scales)
        moved = {
            m.name: Marker(m.name, m.body, tuple(np.array(m.location) * body_scales[m.body] + d), m.fixed)
            for m, d in zip(self.generic_markers, offsets)
        }
        markers = tuple(moved.get(m.name, m) for m in scaled.markers)
        return Skeleton(replace(scaled, markers=markers))

    def prior(self, scales: FloatArray, offsets: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Residuals ``(k,)`` and Jacobian ``(k, n_z)`` of the scale and offset priors."""
        rs, js = prior_residuals(scales, self.height_scale, self.prior_w, self.aniso_w)
        sw = np.repeat(np.sqrt(self.offset_w), 3)
        r = np.concatenate([rs, sw * offsets.reshape(-1)])
        j = np.zeros((r.size, self.n_z))
        j[: rs.size, : self.n_s] = js
        j[rs.size :, self.n_s :] = np.diag(sw)
        return r, j

    def z_jacobian(self, sk: Skeleton, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Derivatives of marker positions w.r.t. scales and offsets, in block form.

        Returns
        -------
        js
            ``(F, M, 3, 3G)`` d position / d group scales.
        rb
            ``(F, M, 3, 3)`` d position of marker m / d its own offset (its body's rotation);
            the offset Jacobian is block diagonal, so only these blocks are kept.
        """
        body_rot, _ = sk.body_poses(q)
        js = self.sj.markers(body_rot, q, self.marker_body, self.marker_local)
        return js, body_rot[:, self.marker_body]

    def shift(self, js: FloatArray, rb: FloatArray, dz: FloatArray) -> FloatArray:
        """``(F, M, 3)`` position change for a step ``dz`` = [d scales, d offsets]."""
        d_off = dz[self.n_s :].reshape(-1, 3)
        return js @ dz[: self.n_s] + np.einsum("fmij,mj->fmi", rb, d_off)

    def cost(self, positions: FloatArray, q: FloatArray, q_anchor: FloatArray, free: IntArray, scales: FloatArray, offsets: FloatArray) -> float:
        """Total cost for model marker positions ``(F, M, 3)``."""
        d = np.where(self.seen[..., None], positions - np.nan_to_num(self.obs), 0.0) * self.sqrt_w[None, :, None]
        rp, _ = self.prior(scales, offsets)
        e = self.settings.pose_prior_weight
        return float(np.sum(d**2) + rp @ rp + e * np.sum((q[:, free] - q_anchor[:, free]) ** 2))


@dataclass
class _Normal:
    """Gauss-Newton normal equations of :class:`ScaleFitProblem` at one point, in block
    form (pose blocks per frame, then z = [scales, offsets]); coordinates held at a bound by
    their gradient have identity rows (projected Gauss-Newton)."""

    a_blocks: FloatArray  # (F, nf, nf) pose blocks (with the pose prior)
    b_blocks: FloatArray  # (F, nf, nz) pose-z couplings
    g_f: FloatArray  # (F, nf) pose gradients
    c_mat: FloatArray  # (nz, nz) z block (with the priors)
    g_z: FloatArray  # (nz,) z gradient
    jq: FloatArray  # (F, M, 3, nf) weighted marker Jacobians over the free coordinates
    js: FloatArray  # (F, M, 3, 3G) weighted d position / d group scales
    rbw: FloatArray  # (F, M, 3, 3) weighted d position / d own offset
    rb: FloatArray  # (F, M, 3, 3) rotation of each marker's body
    held: BoolArray  # (F, nf)
    w_seen: FloatArray  # (F, M) sqrt weights, 0 where unseen


def _linearize(
    problem: ScaleFitProblem,
    sk: Skeleton,
    q: FloatArray,
    q_anchor: FloatArray,
    free: IntArray,
    lo: FloatArray,
    hi: FloatArray,
    midx: IntArray,
    scales: FloatArray,
    offsets: FloatArray,
) -> _Normal:
    """Residuals and Jacobians of all frames (weighted, 0 where unseen) -> :class:`_Normal`."""
    e = problem.settings.pose_prior_weight
    n_f, nf, nz = q.shape[0], free.size, problem.n_z
    n_m = len(problem.names)
    w_seen = problem.sqrt_w[None, :] * problem.seen  # (F, M) weights, 0 where unseen
    y = np.nan_to_num(problem.obs)
    pos, jq = sk.marker_jacobians(q, midx, free)  # (F, M, 3), (F, M, 3, nf): batched
    ww = w_seen[:, :, None]
    r = ww * (pos - y)  # (F, M, 3)
    jq *= ww[..., None]
    js, rb = problem.z_jacobian(sk, q)
    js = js * ww[..., None]
    rbw = rb * ww[..., None]
    jq_flat = jq.reshape(n_f, 3 * n_m, nf)
    a_blocks = np.transpose(jq_flat, (0, 2, 1)) @ jq_flat + e * np.eye(nf)
    b_s = np.transpose(jq_flat, (0, 2, 1)) @ js.reshape(n_f, 3 * n_m, problem.n_s)
    b_d = np.einsum("fmia,fmib->famb", jq, rbw).reshape(n_f, nf, 3 * n_m)
    b_blocks = np.concatenate([b_s, b_d], axis=2)
    g_f = np.einsum("fmia,fmi->fa", jq, r) + e * (q[:, free] - q_anchor[:, free])
    js_flat = js.reshape(-1, problem.n_s)
    c_mat = np.zeros((nz, nz))
    c_mat[: problem.n_s, : problem.n_s] = js_flat.T @ js_flat
    c_sd = np.einsum("fmia,fmib->amb", js, rbw).reshape(problem.n_s, 3 * n_m)
    c_mat[: problem.n_s, problem.n_s :] = c_sd
    c_mat[problem.n_s :, : problem.n_s] = c_sd.T
    diag = np.repeat((w_seen**2).sum(axis=0), 3)  # R^T R = I for each offset block
    c_mat[problem.n_s :, problem.n_s :] += np.diag(diag)
    g_z = np.concatenate([js_flat.T @ r.reshape(-1), np.einsum("fmia,fmi->ma", rbw, r).reshape(-1)])
    # coordinates held at a bound by their gradient do not move (projected Gauss-Newton)
    x = q[:, free]
    held = ((x <= lo[free]) & (g_f > 0)) | ((x >= hi[free]) & (g_f < 0))  # (F, nf)
    if held.any():
        a_blocks[held[:, :, None] | held[:, None, :]] = 0.0
        fi, ci = np.nonzero(held)
        a_blocks[fi, ci, ci] = 1.0
        b_blocks[held] = 0.0
        g_f[held] = 0.0
    rp, jp = problem.prior(scales, offsets)
    c_mat += jp.T @ jp
    g_z += jp.T @ rp
    return _Normal(a_blocks, b_blocks, g_f, c_mat, g_z, jq, js, rbw, rb, held, w_seen)


def fit_model(problem: ScaleFitProblem, q_init: FloatArray, scales0: FloatArray) -> FitResult:
    """Solve :class:`ScaleFitProblem` by Levenberg-Marquardt with a Schur complement.

    Parameters
    ----------
    problem
        The data and weights.
    q_init
        ``(F, n)`` starting coordinates of the fit frames.
    scales0
        ``(3G,)`` starting group scales.
    """
    st = problem.settings
    scales = np.array(scales0, dtype=float)
    offsets = np.zeros((len(problem.names), 3))
    q = np.array(q_init, dtype=float)
    q_anchor = q.copy()
    sk = problem.build(scales, offsets)
    free = np.flatnonzero(sk.is_independent & ~sk.locked)
    lo, hi = solver_bounds(sk)
    midx = sk.marker_index(problem.names)
    cost = problem.cost(sk.marker_positions(q, midx), q, q_anchor, free, scales, offsets)
    mu = None
    accepted_steps = 0
    nf, nz = free.size, problem.n_z
    for _ in range(st.max_iterations):
        lin = _linearize(problem, sk, q, q_anchor, free, lo, hi, midx, scales, offsets)
        a_blocks, b_blocks, g_f, c_mat, g_z = lin.a_blocks, lin.b_blocks, lin.g_f, lin.c_mat, lin.g_z
        if mu is None:
            mu = 1e-4 * float(np.mean(np.concatenate([np.diagonal(a_blocks, axis1=1, axis2=2).ravel(), np.diag(c_mat)])))
        # ---- damped steps until one lowers the cost
        improved = False
        for _ in range(10):
            a_d = a_blocks + mu * np.eye(nf)[None]
            ainv_b = np.linalg.solve(a_d, b_blocks)  # (F, nf, nz)
            ainv_g = np.linalg.solve(a_d, g_f[..., None])[..., 0]
            b_flat = b_blocks.reshape(-1, nz)
            schur = c_mat + mu * np.eye(nz) - b_flat.T @ ainv_b.reshape(-1, nz)
            rhs = g_z - b_flat.T @ ainv_g.reshape(-1)
            dz = -np.linalg.solve(schur, rhs)
            dq = -(ainv_g + ainv_b @ dz)
            q_new = q.copy()
            q_new[:, free] += dq
            q_new = np.clip(q_new, lo, hi)
            q_new = sk.cmap.complete(q_new)
            s_new, o_new = scales + dz[: problem.n_s], offsets + dz[problem.n_s :].reshape(-1, 3)
            # positions at the new point: affine in (s, d) at fixed q, so exact without a rebuild
            pos_new = sk.marker_positions(q_new, midx) + problem.shift(*problem.z_jacobian(sk, q_new), dz)
            cost_new = problem.cost(pos_new, q_new, q_anchor, free, s_new, o_new)
            if cost_new < cost:
                improved = True
                break
            mu *= 10.0
        if not improved:
            break
        rel = (cost - cost_new) / max(cost, 1e-30)
        q, scales, offsets, cost = q_new, s_new, o_new, cost_new
        accepted_steps += 1
        mu = max(mu / 5.0, 1e-12)
        sk = problem.build(scales, offsets)
        if rel < st.tolerance:
            break
    pos = sk.marker_positions(q, midx)
    err = np.linalg.norm(pos - problem.obs, axis=2)[problem.seen]
    return FitResult(
        model=sk.osim,
        scales=scales,
        offsets=offsets,
        q=q,
        marker_rms=float(np.sqrt(np.mean(err**2))),
        iterations=accepted_steps,
        skeleton=sk,
    )


def landmark_scale_response(
    problem: ScaleFitProblem, fit: FitResult, markers: list[str], trials: dict[str, BoolArray]
) -> dict[str, dict[str, FloatArray]]:
    """How far the scale fit moves a marker's scaled landmark when that marker is misplaced.

    A marker recorded a body-fixed ``m`` away from its landmark pulls the fit: its own
    offset takes part of ``m``, the poses another, and the body scales move the *landmark*
    (the generic location times the body's scale factors) toward the marker by ``L m``.
    The marker's fitted offset and its remaining error then show ``(I - L) m``, not ``m``,
    so a misplacement estimated from them is short by ``L m`` (0.2-0.6 cm for 2 cm
    misplacements of the walk's elbow and sacrum markers, 2026-11-25). ``L`` is the linear
    response of the fit's minimum (its Gauss-Newton normal equations at ``fit``, poses
    eliminated by the same Schur complement as :func:`fit_model`) to moving the marker's
    observations by ``R_f e_k`` on the fit frames of one trial (a marker misplaced in that
    trial only; the other trials' frames pull the scales back), for the three body axes e_k.

    Parameters
    ----------
    problem
        The problem ``fit`` solved.
    fit
        Its solution.
    markers
        Names of ``problem``'s markers whose response is wanted (others are ignored).
    trials
        Trial name -> ``(F,)`` its fit frames.

    Returns
    -------
    dict
        Trial name -> marker name -> ``(3, 3)`` L, body frame, dimensionless (column k: the
        landmark's displacement per metre of misplacement along body axis k).
    """
    wanted = [problem.names.index(n) for n in markers if n in problem.names]
    if not wanted:
        return {t: {} for t in trials}
    sk = fit.skeleton  # the model of fit.scales and fit.offsets
    free = np.flatnonzero(sk.is_independent & ~sk.locked)
    lo, hi = solver_bounds(sk)
    midx = sk.marker_index(problem.names)
    lin = _linearize(problem, sk, fit.q, fit.q, free, lo, hi, midx, fit.scales, fit.offsets)
    n_s, nz = problem.n_s, problem.n_z
    ainv_b = np.linalg.solve(lin.a_blocks, lin.b_blocks)  # (F, nf, nz)
    b_flat = lin.b_blocks.reshape(-1, nz)
    schur = lin.c_mat - b_flat.T @ ainv_b.reshape(-1, nz)
    # gradient changes for observations moved by dy: the residual r = w (p - y) changes by -w dy;
    # by linearity dz = -S^-1 (dg_z - B^T A^-1 dg_f), and A^-1 B is at hand
    out: dict[str, dict[str, FloatArray]] = {}
    for trial, frames in trials.items():
        in_trial = np.asarray(frames, dtype=bool)[:, None, None]
        reduced = np.zeros((len(wanted), 3, nz))
        for i, j in enumerate(wanted):
            dr = np.where(in_trial, -lin.w_seen[:, j, None, None] * lin.rb[:, j], 0.0)  # (F, 3 lab, 3 axes k)
            g_f = np.einsum("fia,fik->fak", lin.jq[:, j], dr)  # (F, nf, k)
            g_f[lin.held] = 0.0
            reduced[i, :, :n_s] = np.einsum("fia,fik->ka", lin.js[:, j], dr)
            reduced[i, :, n_s + 3 * j : n_s + 3 * j + 3] = np.einsum("fia,fik->ka", lin.rbw[:, j], dr)
            reduced[i] -= np.einsum("fab,fak->kb", ainv_b, g_f)  # B^T A^-1 g_f (A symmetric)
        dz = -np.linalg.solve(schur, reduced.reshape(-1, nz).T).T.reshape(len(wanted), 3, nz)
        out[trial] = {}
        for i, j in enumerate(wanted):
            group = problem.groups.body_group[problem.generic_markers[j].body]
            d_scales = dz[i, :, :n_s].reshape(3, -1, 3)[:, group, :]  # (k, 3 axes)
            out[trial][problem.names[j]] = (problem.marker_local[j][None, :] * d_scales).T  # column k
    return out
