"""Benchmark of the model conversion (run on demand, not a test).

    OPENBLAS_NUM_THREADS=1 python tests/benchmarks/bench_model.py

Targets (issue "foundation"): conversion < 0.5 s; marker forward kinematics < 20 µs per
frame; inverse dynamics < 50 µs per frame, one core.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

from solver.model.osim import read_osim
from solver.model.skeleton import ExternalWrench, Skeleton

MODEL = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "models" / "Rajagopal2016.osim"


def best_of(fn, repeats: int = 5) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    t_conv = best_of(lambda: Skeleton(read_osim(MODEL)))
    sk = Skeleton(read_osim(MODEL))
    rng = np.random.default_rng(0)
    n_frames = 1000
    lo, hi = np.clip(sk.ranges[:, 0], -1, 1), np.clip(sk.ranges[:, 1], -1, 1)
    q = sk.cmap.complete(rng.uniform(lo, hi, (n_frames, sk.n)))
    qd, qdd = rng.uniform(-2, 2, q.shape), rng.uniform(-10, 10, q.shape)
    t_fk = best_of(lambda: sk.marker_positions(q))
    t_com = best_of(lambda: sk.center_of_mass(q))
    grf = [
        ExternalWrench(b, rng.normal(0, 300, (n_frames, 3)), rng.normal(0, 0.3, (n_frames, 3)), rng.normal(0, 5, (n_frames, 3)))
        for b in ("calcn_r", "calcn_l")
    ]
    t_id = best_of(lambda: sk.inverse_dynamics(q, qd, qdd), repeats=3)
    t_id_grf = best_of(lambda: sk.inverse_dynamics(q, qd, qdd, grf), repeats=3)
    print(f"model: {MODEL.name}: {sk.n} coordinates, {sk.nv} pinocchio joints, {len(sk.marker_names)} markers")
    print(f"load + convert:                      {t_conv * 1e3:8.1f} ms   (target < 500 ms)")
    print(f"marker FK, {n_frames} frames:              {t_fk / n_frames * 1e6:8.2f} us/frame (target < 20)")
    print(f"centre of mass, {n_frames} frames:         {t_com / n_frames * 1e6:8.2f} us/frame")
    print(f"inverse dynamics, no GRF:            {t_id / n_frames * 1e6:8.2f} us/frame (target < 50)")
    print(f"inverse dynamics, 2 plate wrenches:  {t_id_grf / n_frames * 1e6:8.2f} us/frame (target < 50)")


if __name__ == "__main__":
    main()
