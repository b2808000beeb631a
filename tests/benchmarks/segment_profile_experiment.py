"""Experiment (not a test, not yet in ``addb diagnose``): is a segment mass redistribution
identifiable once the *whole* motion is profiled out?

``segment_mass_distribution`` fails its hidden-effect draws (docs/diagnose/RESULTS.md): the
dynamics fit bends the motion to balance a wrong mass distribution, and the diagnosis,
which profiles out only a translation of the whole body (:mod:`solver.diagnose.profile`),
then finds about 0.2-0.5 kg of a 5-6 kg redistribution on the fitted motion. This script
estimates the group masses with every coordinate at every frame profiled out instead: the
linearized joint fit of motion and masses around the processed motion,

    min over (dq, theta)   sum_evaluated |(r_t + A_t dq + G_t theta) / s_r|²
                         + sum_markers   |(e_tm + J_tm dq_t) / s_m|²
                         + sum_t         |D2 dq / s_a|²

with r the root residual (force; moment about the pelvis origin) and e the marker errors
of the processed trial, A the root wrench's derivative with respect to the coordinates
(through central-difference velocities and accelerations; finite differences of
:meth:`solver.model.skeleton.Skeleton.inverse_dynamics`), J the marker Jacobians, G the
group wrench per kg (:attr:`solver.diagnose.data.DiagnosisData.groups`; total mass kept)
and s the dynamics fit's standard deviations (its weak acceleration prior s_a included).
theta is the Gauss-Newton step in the masses of a joint refit that starts at the
processed motion (the motion's own step eliminated, the Schur complement).

For each draw the estimate is compared with the neutral base's own estimate: the hidden
legs share must come back, ``-legs_fraction x fitted mass`` kg (tests/diagnose/effects.py).

Run (bases and draws are processed once and kept in ``--work``)::

    .venv/bin/python tests/benchmarks/segment_profile_experiment.py --draws 4 --work /tmp/segment-profile

``--synthetic N`` first estimates on N consistent synthetic trials per base
(:mod:`tests.diagnose.synthetic`: the base's processed motion and masses with forces computed
from them, plus noise), where the estimate should be 0.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from addb_viewer.cli import main as cli
from solver.diagnose.core import build_context, frame_flags, load_inputs
from solver.diagnose.data import prepare
from solver.model.osim import read_osim
from solver.model.skeleton import Skeleton
from solver.results import load_processed
from tests.diagnose.effects import copy_subject, hide
from tests.diagnose.harness import SUBJECTS, TRIALS, draw, neutral_base
from tests.diagnose.synthetic import consistent_subject

CAUSE = "segment_mass_distribution"


def _wrench_about_ground(sk: Skeleton, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(T, 6)`` gravity + inertia root wrench (moment about the ground origin), pelvis origin."""
    idr = sk.inverse_dynamics(q, qd, qdd)
    pos = sk.body_poses(q)[1][:, sk.body_names.index(sk.root_body)]
    return np.concatenate([idr.root_force, idr.root_moment + np.cross(pos, idr.root_force)], axis=1), pos


def profiled_estimate(subject: Path, trial: str, accel_sigma: float = 500.0, legs_only: bool = False) -> dict[str, Any]:
    """Group mass changes (kg, total kept) with the whole motion profiled out; with
    ``legs_only`` one parameter: mass moved from the rest of the body (each group in
    proportion to its mass) to the legs."""
    inputs = load_inputs(subject, trial, subject / "addb_out")
    processed = load_processed(subject / "addb_out", trial)
    model = read_osim(processed.model_path)
    marker_time = np.asarray(inputs.raw.markers.time)
    data = prepare(
        processed, inputs.raw.forces, stated_mass=inputs.subject.mass_kg,
        flagged=frame_flags(inputs.flags, marker_time, processed.time), generic_model=read_osim(inputs.subject.model_path),
        marker_offsets=inputs.marker_offsets, feet=inputs.subject.foot_body_names, model=model,
    )
    ctx, _ = build_context(data)
    sk = Skeleton(model)
    q, qd, qdd = processed.q, processed.qd, processed.qdd
    t_n, n = q.shape
    h = data.dt
    w0, pelvis = _wrench_about_ground(sk, q, qd, qdd)
    eps = 1e-5
    jac = np.empty((3, t_n, 6, n))  # d wrench / d (q, qd, qdd)
    for k in range(n):
        for which in range(3):
            args = [q.copy(), qd.copy(), qdd.copy()]
            args[which][:, k] += eps
            jac[which, :, :, k] = (_wrench_about_ground(sk, *args)[0] - w0) / eps
    # back to moments about the (fixed) pelvis origin: dM_p = dM_g - p x dF
    jac[:, :, 3:, :] -= np.cross(pelvis[None, :, None, :], jac[:, :, :3, :].transpose(0, 1, 3, 2)).transpose(0, 1, 3, 2)
    s = ctx.sigmas
    sig = np.array([s.force] * 3 + [s.moment] * 3)
    residual = data.inertial - data.external()[1]
    evaluated = ctx.evaluated.copy()
    evaluated[[0, -1]] = False
    rows: list[np.ndarray] = []
    cols: list[np.ndarray] = []
    vals: list[np.ndarray] = []
    rhs: list[np.ndarray] = []
    r = 0
    for t in np.flatnonzero(evaluated):
        dq, dv, da = jac[0, t], jac[1, t], jac[2, t]
        for tt, coef in ((t - 1, -dv / (2 * h) + da / h**2), (t, dq - 2 * da / h**2), (t + 1, dv / (2 * h) + da / h**2)):
            rows.append(np.repeat(np.arange(r, r + 6), n))
            cols.append(np.tile(tt * n + np.arange(n), 6))
            vals.append((coef / sig[:, None]).ravel())
        rhs.append(residual[t] / sig)
        r += 6
    n_residual = r
    markers = sk.marker_index(list(data.markers.names))
    for t in range(t_n):
        _, jm = sk.marker_jacobian(q[t], markers)
        err = data.markers.error[t]
        seen = np.all(np.isfinite(err), axis=1)
        m = int(seen.sum())
        rows.append(np.repeat(np.arange(r, r + 3 * m), n))
        cols.append(np.tile(t * n + np.arange(n), 3 * m))
        vals.append((jm[seen] / s.marker).ravel())
        rhs.append(err[seen].ravel() / s.marker)
        r += 3 * m
    for t in range(1, t_n - 1):  # the dynamics fit's acceleration prior
        for tt, coef in ((t - 1, 1.0), (t, -2.0), (t + 1, 1.0)):
            rows.append(r + np.arange(n))
            cols.append(tt * n + np.arange(n))
            vals.append(np.full(n, coef / h**2 / accel_sigma))
        rhs.append(np.zeros(n))
        r += n
    a = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(r, t_n * n))
    z0 = np.concatenate(rhs)
    groups = [g for g in data.groups if data.group_mass[g] > 0]
    g_cols = np.zeros((r, len(groups)))
    for j, g in enumerate(groups):
        g_cols[:n_residual, j] = ((data.groups[g] / data.group_mass[g])[evaluated] / sig).ravel()
    basis = np.linalg.svd(np.ones((1, len(groups))))[2][1:].T  # total mass kept
    if legs_only:
        rest = np.array([0.0 if g == "legs" else data.group_mass[g] for g in groups])
        basis = (np.array([1.0 if g == "legs" else 0.0 for g in groups]) - rest / rest.sum())[:, None]
    g_cols = g_cols @ basis
    ata = (a.T @ a).tocsc()
    lu = splu(ata + sp.identity(t_n * n, format="csc") * 1e-6 * float(ata.diagonal().mean()))

    def profiled(z: np.ndarray) -> np.ndarray:
        return z - a @ lu.solve(np.asarray(a.T @ z))

    z0p = profiled(z0)
    gp = np.stack([profiled(g_cols[:, j]) for j in range(g_cols.shape[1])], axis=1)
    beta = np.linalg.lstsq(gp, -z0p, rcond=None)[0]
    return {
        "mass_change_kg": {g: float(v) for g, v in zip(groups, basis @ beta)},
        "cost_before": float(z0p @ z0p),
        "cost_after": float(np.sum((z0p + gp @ beta) ** 2)),
        "fitted_mass_kg": float(data.fitted_mass),
    }


def processed_copy(src: Path, dst: Path, key: str, seed: int) -> tuple[Path, dict[str, Any]]:
    """A copy of the base with the draw hidden, processed (kept in ``dst`` for reruns)."""
    trial = TRIALS[key][1]
    truth_file = dst / "hidden.txt"
    if not (dst / "addb_out").is_dir():
        subject = copy_subject(src, dst)
        hidden = hide(CAUSE, subject, trial, seed, load_processed(src / "addb_out", trial))
        truth_file.write_text(repr(hidden.truth["legs_fraction"]))
        if cli(["process", str(subject), "--out", str(subject / "addb_out")]) != 0:
            raise RuntimeError(f"addb process failed on {subject}")
    return dst, {"legs_fraction": float(truth_file.read_text())}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--draws", type=int, default=4)
    p.add_argument("--work", type=Path, required=True)
    p.add_argument("--legs-only", action="store_true", help="one parameter: mass moved between the legs and the rest")
    p.add_argument("--synthetic", type=int, default=0, help="consistent synthetic trials per base (their estimate should be 0)")
    args = p.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    for key in ("walk", "run"):
        folder, trial = TRIALS[key]
        for seed in range(args.synthetic):
            base_dir, dst = args.work / f"base-{key}", args.work / f"synthetic-{key}-{seed}"
            if not (base_dir / "addb_out").is_dir():
                neutral_base(key, base_dir)
            if not (dst / "addb_out").is_dir():
                consistent_subject(load_processed(base_dir / "addb_out", trial), SUBJECTS / folder, dst, seed=seed)
                if cli(["process", str(dst), "--out", str(dst / "addb_out")]) != 0:
                    raise RuntimeError(f"addb process failed on {dst}")
            est = profiled_estimate(dst, trial, legs_only=args.legs_only)
            gain = 100 * (1 - est["cost_after"] / est["cost_before"])
            print(f"synthetic {key} {seed}: {({g: round(v, 2) for g, v in est['mass_change_kg'].items()})} kg, cost gain {gain:.1f} %", flush=True)
    bases: dict[str, dict[str, Any]] = {}
    print("| trial | seed | hidden: legs kg to move back | estimate, relative to the base | error (kg) | cost gain, draw | cost gain, base |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for i in range(args.draws):
        key, seed = draw(CAUSE, i)
        trial = TRIALS[key][1]
        base_dir = args.work / f"base-{key}"
        if not (base_dir / "addb_out").is_dir():
            neutral_base(key, base_dir)
        if key not in bases:
            bases[key] = profiled_estimate(base_dir, trial, legs_only=args.legs_only)
        t0 = time.perf_counter()
        subject, truth = processed_copy(base_dir, args.work / f"{key}-{seed}", key, seed)
        est = profiled_estimate(subject, trial, legs_only=args.legs_only)
        legs = est["mass_change_kg"]["legs"] - bases[key]["mass_change_kg"]["legs"]
        expected = -truth["legs_fraction"] * est["fitted_mass_kg"]

        def gain(e: dict[str, Any]) -> str:
            return f"{100 * (1 - e['cost_after'] / e['cost_before']):.1f} %"

        print(f"| {key} | {seed} | {expected:+.2f} | {legs:+.2f} | {abs(legs - expected):.2f} | {gain(est)} | {gain(bases[key])} |"
              f"  ({time.perf_counter() - t0:.0f} s; base: {({g: round(v, 1) for g, v in bases[key]['mass_change_kg'].items()})})", flush=True)


if __name__ == "__main__":
    main()
