"""Benchmark of the recording writers and the MCAP reader (run on demand, not a test).

    .venv/bin/python tests/benchmarks/bench_recordings.py [--frames 2000] [--out DIR]

Targets (issue "recordings"): writing a 2,000-frame trial under 5 s for each of the
Rerun (.rrd) and MCAP files; reading frame 1,000 of the MCAP file under 20 ms.

The trial is the bundled demo walk processed by the full pipeline (kinematics and
dynamics, ~15 s, or reused from ``--out``), its frames repeated to ``--frames`` at the
same rate (41 markers, 22 bodies with 81 bone meshes, 2 plates, 39 coordinates).
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from solver.results import ProcessedTrial, load_processed, processed_trials

PER_FRAME = (
    "q", "qd", "qdd", "observed", "modeled", "body_position", "body_wxyz", "com", "com_acc",
    "residual_force", "residual_moment", "tau", "unobserved", "proposed",
)  # fmt: skip


def tiled(trial: ProcessedTrial, n_frames: int) -> ProcessedTrial:
    """``trial`` with its frames repeated to ``n_frames`` frames at the same rate."""
    idx = np.arange(n_frames) % trial.n_frames
    plates = tuple(
        dataclasses.replace(
            p, force=p.force[idx], cop=p.cop[idx], free_moment=p.free_moment[idx], body=p.body[idx]
        )
        for p in trial.plates
    )
    return dataclasses.replace(
        trial,
        time=np.arange(n_frames) / trial.rate_hz,
        plates=plates,
        proposal_reasons=tuple(trial.proposal_reasons[i] for i in idx),
        **{k: getattr(trial, k)[idx] for k in PER_FRAME},
    )


def timed(fn, repeat: int) -> tuple[float, float]:
    """(first call, median of the next ``repeat`` calls), seconds."""
    t0 = time.perf_counter()
    fn()
    first = time.perf_counter() - t0
    runs = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        runs.append(time.perf_counter() - t0)
    return first, statistics.median(runs)


def main() -> None:
    """Run the benchmark and print the figures."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=2000)
    ap.add_argument(
        "--out", type=Path, help="processed demo output to reuse (processed there if empty)"
    )
    args = ap.parse_args()

    from addb_viewer.demo import DEMO_SUBJECT
    from solver.pipeline import process_subject

    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        out = args.out or tmp / "out"
        if "walk" not in processed_trials(out):
            t0 = time.perf_counter()
            process_subject(DEMO_SUBJECT, out)
            print(f"processed the demo subject in {time.perf_counter() - t0:.1f} s")
        base = load_processed(out, "walk")
        trial = tiled(base, args.frames)
        n_mesh = sum(len(m) for m in trial.body_meshes.values())
        print(
            f"trial: {trial.n_frames} frames at {trial.rate_hz:.0f} Hz, {len(trial.marker_names)} markers, "
            f"{len(trial.body_names)} bodies ({n_mesh} meshes), {len(trial.plates)} plates, "
            f"{len(trial.coordinate_names)} coordinates, dynamics {'yes' if trial.has_dynamics else 'no'}"
        )
        bench_files(trial, tmp)


def bench_files(trial: ProcessedTrial, tmp: Path) -> None:
    """Write both files, then time the MCAP reads."""
    from addb_viewer.recording.mcap_writer import write_mcap
    from addb_viewer.recording.rerun_writer import write_rerun
    from solver.io.mcap_file import open_recording

    rrd, mcap = tmp / "trial.rrd", tmp / "trial.mcap"
    first, warm = timed(lambda: write_rerun(trial, rrd), 3)
    print(
        f"write .rrd : first {first:6.2f} s (imports rerun, reads meshes), then {warm:6.2f} s   (target < 5 s)"
    )
    print(f"             size {rrd.stat().st_size / 1e6:6.2f} MB")
    first, warm = timed(lambda: write_mcap(trial, mcap), 3)
    print(f"write .mcap: first {first:6.2f} s, then {warm:6.2f} s   (target < 5 s)")
    print(f"             size {mcap.stat().st_size / 1e6:6.2f} MB")

    k = min(1000, trial.n_frames - 1)

    def open_and_read() -> None:
        with open_recording(mcap) as rec:
            rec.frame(k)

    first, warm = timed(open_and_read, 20)
    print(
        f"open + read frame {k}: first {first * 1e3:6.2f} ms (imports mcap), then {warm * 1e3:6.2f} ms   (target < 20 ms)"
    )
    with open_recording(mcap) as rec:
        _, frame_only = timed(lambda: rec.frame(k), 50)
        print(f"read frame {k} of an open recording: {frame_only * 1e3:6.2f} ms (median of 50)")
        t0 = time.perf_counter()
        rec.to_arrays()
        print(f"read all frames (to_arrays): {time.perf_counter() - t0:6.2f} s")


if __name__ == "__main__":
    main()
