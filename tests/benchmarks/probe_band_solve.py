"""Probe: the joint fit's forward substitution with many right-hand sides, in chunks that
stay in cache, against LAPACK's ``dtbtrs`` on the whole band.

    .venv/bin/python tests/benchmarks/probe_band_solve.py [--repeat 7] [SUBJECT ...]

A probe for issue 29 (throughput): since 2026-12-02 ``addb process`` solves in chunks of
8192 rows (``solver.dynamics.banded.banded_forward_solve``, the function timed here; a
system of at most that many rows is one ``dtbtrs`` call). Every step of the
joint fit (:func:`solver.dynamics.joint_fit._reduced`) solves W = L^-1 [B, g] for each
trial's banded Cholesky factor L (``(u + 1, N)`` lower band storage) and the J mass columns
of its border plus the gradient: ``dtbtrs`` runs one column at a time (level-2 BLAS), and on
the Camargo circuit the factor is 51 MB, read from memory once per column. Here the same
solve runs in row chunks of ``m``: for the chunk [s, e), the rows' dependence on the
solution above it is one dense product with the band's corner
``L[s:min(s + u, e), s - u:s]``, and ``dtbtrs`` on the chunk's own band
``L[:, s:e]`` then reads a few MB once for all columns (forward substitution by blocks;
Golub & Van Loan, Matrix Computations, 4th ed., §3.1.4 and §4.3).

The factor and right-hand sides are the fit's own: each SUBJECT is processed once (as
``addb process`` does it), the first multi-column solve of its first trial is kept, and the
number of such solves of that trial in the whole fit is counted. Prints, per subject, the
system's size, the median time of ``dtbtrs`` and of the chunked solve for each chunk size
(alternating runs), the largest difference of the solutions relative to the largest entry,
and what the best chunk size would save over that trial's solves.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from example_subjects import subject_folder

from solver.dynamics.banded import banded_forward_solve as chunked_forward_solve

#: Row chunks tried (rows of the band, not frames).
CHUNKS = (512, 1024, 2048, 4096, 8192)
SUBJECTS = ("rajagopal2016_walk", "rajagopal2016_run", "opencap_uhlrich2023", "camargo2021_levelground")


def capture(folder: Path) -> tuple[np.ndarray, np.ndarray, int]:
    """Process ``folder`` and keep the first multi-column forward solve of the joint fit:
    ``(factor, rhs, count)`` with ``count`` the fit's multi-column solves of the same trial
    (of a system of the same size)."""
    import solver.dynamics.joint_fit as jf
    from solver.pipeline import process_subject

    kept: list[tuple[np.ndarray, np.ndarray]] = []
    count = 0
    solve = jf.banded_forward_solve

    def spy(factor: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        nonlocal count
        if rhs.ndim == 2 and rhs.shape[1] > 1:
            if not kept:
                kept.append((factor.copy(order="F"), rhs.copy()))
            count += factor.shape == kept[0][0].shape
        return solve(factor, rhs)

    jf.banded_forward_solve = spy
    try:
        with tempfile.TemporaryDirectory() as out, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            process_subject(folder, out)
    finally:
        jf.banded_forward_solve = solve
    factor, rhs = kept[0]
    return factor, rhs, count


def one_time(fn) -> float:
    """Wall seconds of one call of ``fn``."""
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("subjects", nargs="*", default=list(SUBJECTS))
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args(argv)
    from scipy.linalg.lapack import dtbtrs

    from solver import single_threaded_blas

    print(f"numpy {np.__version__}; one BLAS thread, as the stages run (solver.single_threaded_blas); median of {args.repeat} runs, alternating\n")
    print("| subject | band (u + 1) x N | right-hand sides | the trial's solves in the fit | dtbtrs (ms) | " + " | ".join(f"chunks of {m} (ms)" for m in CHUNKS) + " | largest difference (relative) | saved over the trial's solves (s) |")
    print("| --- | --- | ---: | ---: | ---: | " + " | ".join("---:" for _ in CHUNKS) + " | ---: | ---: |")
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.subjects:
            factor, rhs, count = capture(subject_folder(name, Path(tmp)))
            ref = dtbtrs(factor, rhs, uplo="L")[0]
            diff = max(float(np.abs(chunked_forward_solve(factor, rhs, m) - ref).max()) for m in CHUNKS) / float(np.abs(ref).max())
            times: dict[object, list[float]] = {m: [] for m in ("dtbtrs", *CHUNKS)}
            with single_threaded_blas():
                for _ in range(args.repeat):  # alternating, so that the host's drift falls on all alike
                    times["dtbtrs"].append(one_time(lambda f=factor, b=rhs: dtbtrs(f, b, uplo="L")))
                    for m in CHUNKS:
                        times[m].append(one_time(lambda m=m, f=factor, b=rhs: chunked_forward_solve(f, b, m)))
            med = {k: float(np.median(v)) * 1e3 for k, v in times.items()}
            best = min(med[m] for m in CHUNKS)
            saved = max(med["dtbtrs"] - best, 0.0) * count / 1e3
            print(
                f"| {name} | {factor.shape[0]} x {factor.shape[1]} | {rhs.shape[1]} | {count} | {med['dtbtrs']:.1f} | "
                + " | ".join(f"{med[m]:.1f}" for m in CHUNKS)
                + f" | {diff:.1e} | {saved:.2f} |"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
