"""Benchmark of the .b3d reader and writer (run on demand, not a test).

    .venv/bin/python tests/benchmarks/bench_b3d.py [--frames 12000] [--processed OUT_DIR]

Targets (issue 27): reading frame 10,000 of a large written file under 5 ms; reading a
whole 2,000-frame trial; writing a processed subject.

The large file is results.b3d's subject (33 DOFs, 52 markers, 2 plates) with its first
trial's frames repeated to ``--frames`` frames in one trial and a second (dynamics) pass
copied from the first, written with :func:`solver.io.b3d_writer.write_b3d`. The processed
subject is results.b3d converted and processed by addb (``--processed`` reuses an output
folder; otherwise it is made, ~20 s).
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

from solver.io.b3d import B3dFrames, B3dHeader, open_b3d
from solver.io.b3d_convert import processed_to_b3d
from solver.io.b3d_writer import write_b3d

B3D = REPO.parent / "shared" / "data" / "b3d" / "results.b3d"


def big_subject(n: int) -> tuple[B3dHeader, list[B3dFrames]]:
    src = open_b3d(B3D)
    info = src.header.trials[0]
    fr = src.read_trial(0)
    idx = np.arange(n) % info.n_frames
    tp = info.passes[0]
    tp = dataclasses.replace(tp, **{k: getattr(tp, k)[idx] for k in ("marker_rms", "marker_max", "linear_residual", "angular_residual", "joints_max_velocity")})
    dyn_tp = dataclasses.replace(tp, type="dynamics")
    trial = dataclasses.replace(info, n_frames=n, missing_grf=tuple(info.missing_grf[i] for i in idx), passes=(tp, dyn_tp))
    p0 = fr.passes[0]
    fields = {f.name: getattr(p0, f.name)[idx] for f in dataclasses.fields(p0) if f.name not in ("type", "extra")}
    passes = (dataclasses.replace(p0, **fields), dataclasses.replace(p0, type="dynamics", **fields))
    frames = dataclasses.replace(
        fr, time_s=np.arange(n) * info.timestep_s, missing_grf=trial.missing_grf, markers=fr.markers[idx],
        plate_force=fr.plate_force[idx], plate_cop=fr.plate_cop[idx], plate_moment=fr.plate_moment[idx], passes=passes,
        acc_obs=fr.acc_obs[idx], gyro_obs=fr.gyro_obs[idx], emg=fr.emg[idx], exo=fr.exo[idx], custom=fr.custom[idx],
    )  # fmt: skip
    header = dataclasses.replace(src.header, passes=(src.header.passes[0], dataclasses.replace(src.header.passes[0], type="dynamics")), trials=(trial,))
    return header, [frames]


def timed(fn, repeat: int) -> list[float]:
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return out


def line(label: str, times: list[float], target: str = "") -> str:
    return f"{label:<44} best {1e3 * min(times):9.2f} ms  median {1e3 * statistics.median(times):9.2f} ms  {target}"


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=12_000)
    ap.add_argument("--processed", help="an addb output folder of results.b3d converted (reused)")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench_b3d_"))
    header, frames = big_subject(args.frames)
    big = tmp / "big.b3d"
    w = timed(lambda: write_b3d(big, header, frames), 3)
    print(f"large file: {args.frames} frames, 2 passes, {big.stat().st_size / 1e6:.1f} MB")
    print(line(f"write {args.frames} frames (write_b3d)", w))
    f = open_b3d(big)
    print(line("open (header, 1.2 MB model text)", timed(lambda: open_b3d(big), 20)))
    k = min(10_000, args.frames - 1)  # frame 10,000 of the default 12,000 (the last one of a smaller file)
    a = max(0, k - 2_000)
    print(line(f"read frame {k:,} (open file)", timed(lambda: f.read_frame(0, k), 50), "(target < 5 ms)"))
    print(line(f"open + read frame {k:,}", timed(lambda: open_b3d(big).read_frame(0, k), 20)))
    print(line(f"read frames {a:,}..{k:,} ({k - a:,}-frame range)", timed(lambda: f.read_frames(0, a, k), 5)))
    # a whole 2,000-frame trial
    h2, fr2 = big_subject(2_000)
    t2 = tmp / "t2000.b3d"
    write_b3d(t2, h2, fr2)
    f2 = open_b3d(t2)
    print(line("read a whole 2,000-frame trial (read_trial)", timed(lambda: f2.read_trial(0), 5)))
    print(line("write a 2,000-frame trial (write_b3d)", timed(lambda: write_b3d(t2, h2, fr2), 3)))
    # a processed subject
    out = Path(args.processed) if args.processed else None
    if out is None:
        out = tmp / "out"
        addb = str(REPO / ".venv" / "bin" / "addb")
        subprocess.run([addb, "convert", str(B3D), "--out", str(tmp / "subject")], check=True, capture_output=True)
        subprocess.run([addb, "process", str(tmp / "subject"), "--out", str(out)], check=True, capture_output=True)
    target = tmp / "processed.b3d"
    times = timed(lambda: processed_to_b3d(out, target), 5)
    n = sum(t.n_frames for t in open_b3d(target).header.trials)
    print(line(f"write a processed subject ({n} frames, processed_to_b3d)", times))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
