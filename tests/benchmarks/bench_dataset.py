"""Dataset processing on this machine: the six shared and example subjects, serial (one
Dask worker) against two workers, as whole ``addb process DATASET_DIR`` runs (run on demand).

    .venv/bin/python tests/benchmarks/bench_dataset.py [--workers 1 2] [--dask-defaults]

Builds a dataset tree in a temporary folder: the three shared subjects under ``shared/``
and the three examples of scripts/make_example_subject.py (Camargo circuit, stair descent,
opensim-core's C3D walks) under ``examples/``; then runs the command once per worker
count with ``--force`` into a fresh output tree. Prints per run the wall time, speed-up,
frames (all trials), frames per second, frames per core-second (frames / wall / workers),
the peak resident memory of each worker process (from the subjects' outcomes), and the
projection for the AddBiomechanics Dataset's 24 million frames on 8, 64 and 512 cores at
the best measured frames per core-second. ``--host-reference`` also times OpenSim's IK tool
on the walk before and after the runs, as block ``process`` does (the host's speed drifts
from one day to the next; two blocks' references say by how much).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_kinematics import (  # this folder; the reference needs ``pip install opensim``
    host_reference_line,
    opensim_reference,
)

REPO = Path(__file__).resolve().parents[2]
SHARED = REPO.parent / "shared" / "data" / "subjects"
SHARED_SUBJECTS = ("rajagopal2016_walk", "rajagopal2016_run", "opencap_uhlrich2023")
EXAMPLES = ("camargo2021_levelground", "stairdown", "opensim_c3d_walking")
DATASET_FRAMES = 24_000_000


def build(root: Path) -> Path:
    for name in SHARED_SUBJECTS:
        shutil.copytree(SHARED / name, root / "shared" / name)
    for p in root.rglob("*"):
        p.chmod(0o755 if p.is_dir() else 0o644)
    for name in EXAMPLES:
        subprocess.run([sys.executable, str(REPO / "scripts" / "make_example_subject.py"), name,
                        str(root / "examples" / name)], check=True, capture_output=True)  # fmt: skip
    return root


def run(tree: Path, out: Path, workers: int, scheduler: str | None = None) -> dict:
    addb = Path(sys.executable).parent / "addb"
    where = ["--scheduler", scheduler] if scheduler else ["--workers", str(workers)]
    t0 = time.perf_counter()
    proc = subprocess.run([str(addb), "process", str(tree), "--out", str(out), *where, "--force"],
                          capture_output=True, text=True, check=False)  # fmt: skip
    wall = time.perf_counter() - t0
    summary = json.loads((out / "dataset_summary.json").read_text())
    if proc.returncode != 0:
        print(proc.stdout[-3000:], proc.stderr[-3000:], file=sys.stderr)
    peaks: dict[int, float] = {}
    for s in summary["subjects"]:
        if s.get("worker_pid") is not None and s.get("worker_peak_rss_mb") is not None:
            peaks[s["worker_pid"]] = max(peaks.get(s["worker_pid"], 0.0), s["worker_peak_rss_mb"])
    frames = summary["totals"]["frames"]
    return {
        "workers": workers, "wall": wall, "frames": frames, "subjects": summary["totals"]["subjects"],
        "fps": frames / wall, "fpcs": frames / wall / workers, "peaks": sorted(peaks.values()),
        "per_subject": {s["rel"]: s.get("seconds") for s in summary["subjects"]},
        "label": f"{workers}" if scheduler is None else f"{workers}, `dask worker` with Dask's defaults",
    }  # fmt: skip


def run_on_dask_defaults(tree: Path, out: Path, tmp: Path) -> dict:
    """:func:`run` on one hand-started worker with Dask's default configuration."""
    bindir = Path(sys.executable).parent
    env = dict(os.environ, DASK_CONFIG=str(tmp / "no_dask_config"))  # no user configuration
    file = tmp / "scheduler.json"
    scheduler = subprocess.Popen([str(bindir / "dask"), "scheduler", "--scheduler-file", str(file), "--port", "0",
                                  "--dashboard-address", ":0"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    worker = None
    try:
        for _ in range(300):
            if file.is_file() and file.stat().st_size:
                break
            time.sleep(0.1)
        address = json.loads(file.read_text())["address"]
        worker = subprocess.Popen([str(bindir / "dask"), "worker", address, "--nworkers", "1", "--nthreads", "1"],
                                  env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
        return run(tree, out, 1, scheduler=address)
    finally:
        for p in (worker, scheduler):
            if p is not None:
                p.terminate()
                p.wait(timeout=60)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--dask-defaults", action="store_true", help="add a run on one hand-started worker with Dask's defaults")
    parser.add_argument("--host-reference", action="store_true", help="also time OpenSim's IK tool on the walk (the host's speed)")
    args = parser.parse_args()
    before = opensim_reference(3) if args.host_reference else []
    with tempfile.TemporaryDirectory() as tmp:
        tree = build(Path(tmp) / "dataset")
        rows = [run(tree, Path(tmp) / f"out{w}", w) for w in args.workers]
        own = len(rows)
        if args.dask_defaults:
            rows.append(run_on_dask_defaults(tree, Path(tmp) / "out_dask_defaults", Path(tmp)))
    base = rows[0]["wall"]
    print(f"dataset: {len(SHARED_SUBJECTS) + len(EXAMPLES)} subjects, {rows[0]['frames']} frames; {time.strftime('%Y-%m-%d')}")
    print("| workers | wall (s) | speed-up | frames/s | frames per core-second | peak memory per worker (MB) | subjects |")
    print("| ---: | ---: | ---: | ---: | ---: | --- | --- |")
    for r in rows:
        print(f"| {r['label']} | {r['wall']:.1f} | {base / r['wall']:.2f} | {r['fps']:.1f} | {r['fpcs']:.1f} | "
              f"{', '.join(f'{p:.0f}' for p in r['peaks'])} | {r['subjects']} |")  # fmt: skip
    print("\nper subject (s):", json.dumps({k: round(v, 1) if v else v for k, v in rows[0]["per_subject"].items()}))
    if args.dask_defaults:
        print("per subject (s), Dask's defaults:", json.dumps({k: round(v, 1) if v else v for k, v in rows[-1]["per_subject"].items()}))
    best = max(r["fpcs"] for r in rows[:own])
    print(f"\nprojection for {DATASET_FRAMES / 1e6:.0f} million frames at {best:.1f} frames per core-second:")
    print("| cores | hours | days |")
    print("| ---: | ---: | ---: |")
    for cores in (8, 64, 512):
        hours = DATASET_FRAMES / best / cores / 3600
        print(f"| {cores} | {hours:.1f} | {hours / 24:.2f} |")
    if args.host_reference:
        print("\n" + host_reference_line(before, opensim_reference(3), "dataset runs"))


if __name__ == "__main__":
    main()
