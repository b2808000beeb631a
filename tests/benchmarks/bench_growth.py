"""Growth of ``addb process`` with the trial's length, and its peak memory (run on demand).

    .venv/bin/python tests/benchmarks/bench_growth.py [--cuts 500 1000 1534] [--rate-for-memory 130.4] [--memory-runs N] [--mmap-threshold-mb MB] [--fit band]

The Camargo level-ground circuit (``scripts/make_example_subject.py camargo2021_levelground``,
1534 frames at the default 100 Hz) is cut to its first N frames' worth of time (the TRC's
and the MOT's rows up to N / 100 s after the first sample; every cut keeps the static-free,
one-trial subject as it is) and each cut is processed by ``process_subject`` in a fresh
Python process (addb's bytecode compiled first, as an install has it: ``user_env.py``;
OpenBLAS started with one thread and the malloc and garbage-collector settings of
:func:`addb_viewer.cli.run_to_completion`, as the ``addb`` console script starts). Last, the whole trial is processed at ``--rate-for-memory`` Hz (130.4 Hz:
about 2,000 frames; the recording is at 200 Hz) for the issue's memory target (under
500 MB for a 2,000-frame trial). Prints per run: frames, wall time, CPU time (user + sys)
and peak resident memory of the child (``os.wait4``), the dynamics' frames (trial.npz),
CPU milliseconds per frame (flat
when the cost is linear in the length), and the dynamics fit's own time from subject.json.
``--fit band`` runs every process with ``addb process --fit band``'s options (the older
fixed-rounds fit; the default is the converged fit). ``--memory-runs N`` processes the whole
trial N times (a row each: its peak memory moves from one fresh process to the next with the
heap's fragmentation); ``--mmap-threshold-mb MB`` sets glibc's mmap threshold in every child
after the console script's settings (default: theirs, :data:`addb_viewer.cli.MMAP_THRESHOLD`),
to compare another threshold. ``--cuts`` with no number leaves out the cuts.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from user_env import compile_sources, user_environment  # this folder: the script's own

REPO = Path(__file__).resolve().parents[2]
NAME = "camargo2021_levelground"
CHILD = (
    "import sys; from pathlib import Path; sys.path.insert(0, {repo!r});"
    "from addb_viewer.cli import one_blas_thread, run_to_completion; one_blas_thread(); run_to_completion();"  # as the addb console script starts
    "import ctypes; {mmap!r} and ctypes.CDLL(None).mallopt(-3, {mmap!r});"  # M_MMAP_THRESHOLD, when asked for
    "from dataclasses import replace; from solver.dynamics.stage import DynamicsOptions;"
    "from solver.pipeline import options_for_fit, process_subject; o = options_for_fit({fit!r});"
    "o = replace(o, dynamics=replace(o.dynamics or DynamicsOptions(), rate_hz={rate!r}));"
    "process_subject(Path({subject!r}), Path({out!r}), options=o)"
)


def _cut_subject(src: Path, dst: Path, frames: int) -> None:
    """``src`` subject with its trial cut to ``frames`` frames at 100 Hz (by time)."""
    trial = src / "trials" / "levelground"
    out = dst / "trials" / "levelground"
    out.mkdir(parents=True)
    for f in ("_subject.json", "markers.yaml", "unscaled_generic.osim"):
        (dst / f).write_bytes((src / f).read_bytes())
    trc = (trial / "markers.trc").read_text().splitlines()
    t0 = float(trc[5].split("\t")[1]) if trc[5].strip() else float(trc[6].split("\t")[1])
    t_end = t0 + frames / 100.0 + 1e-9
    body_start = 5 if trc[5].strip() else 6
    rows = [r for r in trc[body_start:] if r.strip() and float(r.split("\t")[1]) <= t_end]
    names, values = trc[1].split("\t"), trc[2].split("\t")
    for key in ("NumFrames", "OrigNumFrames"):
        values[names.index(key)] = str(len(rows))
    (out / "markers.trc").write_text("\n".join(trc[:2] + ["\t".join(values)] + trc[3:body_start] + rows) + "\n")
    mot = (trial / "grf.mot").read_text().splitlines()
    end = mot.index("endheader")
    rows = [r for r in mot[end + 2 :] if r.strip() and float(r.split("\t")[0]) <= t_end]
    head = [f"nRows={len(rows)}" if h.startswith("nRows=") else h for h in mot[: end + 2]]
    (out / "grf.mot").write_text("\n".join(head + rows) + "\n")


def _run(subject: Path, out: Path, rate: float, fit: str, mmap: int) -> tuple[float, float, float]:
    """One fresh process: (wall s, CPU s, peak resident MB); ``mmap``: glibc's mmap threshold,
    bytes (0: the console script's)."""
    code = CHILD.format(repo=str(REPO), subject=str(subject), out=str(out), rate=rate, fit=fit, mmap=mmap)
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=user_environment())
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    if status != 0:
        raise SystemExit(f"process_subject of {subject} failed: {proc.stderr.read().decode()[-2000:]}")
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cuts", type=int, nargs="*", default=[500, 1000, 1534])
    ap.add_argument("--rate-for-memory", type=float, default=130.4)
    ap.add_argument("--memory-runs", type=int, default=1, help="process the whole trial this many times")
    ap.add_argument("--mmap-threshold-mb", type=int, default=0, help="glibc's mmap threshold in the children (0: the console script's)")
    ap.add_argument("--fit", default="default", choices=["default", "converged", "rounds", "band"])
    args = ap.parse_args()
    compile_sources()
    from addb_viewer.cli import MMAP_THRESHOLD

    mmap = args.mmap_threshold_mb << 20
    print(f"glibc mmap threshold in each process: {(mmap or MMAP_THRESHOLD) >> 20} MB{'' if mmap else ' (the addb console script)'}\n")
    print("| run | frames | wall (s) | CPU (s) | CPU ms per frame | dynamics fit (s) | peak memory (MB) |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    with tempfile.TemporaryDirectory() as tmp:
        whole = Path(tmp) / NAME
        subprocess.run([sys.executable, str(REPO / "scripts" / "make_example_subject.py"), NAME, str(whole)], check=True, capture_output=True)
        whole_label = f"whole trial at {args.rate_for_memory:g} Hz"
        runs = [(f"first {n} frames at 100 Hz", n, 100.0) for n in args.cuts]
        runs += [(whole_label + (f", run {k + 1}" if args.memory_runs > 1 else ""), None, args.rate_for_memory) for k in range(args.memory_runs)]
        for label, frames, rate in runs:
            subject = whole
            if frames is not None:
                subject = Path(tmp) / f"cut{frames}"
                _cut_subject(whole, subject, frames)
            out = Path(tmp) / f"out_{label.replace(' ', '_').replace(',', '')}"
            wall, cpu, peak = _run(subject, out, rate, args.fit, mmap)
            with np.load(out / "levelground" / "trial.npz") as z:
                n = int(z["time"].size)  # the dynamics' frames (results.json's n_frames counts marker frames)
            fit_s = (json.loads((out / "subject.json").read_text()).get("dynamics_seconds") or {}).get("dynamics_fit", float("nan"))
            print(f"| {label} | {n} | {wall:.1f} | {cpu:.1f} | {1000 * cpu / max(n, 1):.2f} | {fit_s:.1f} | {peak:.0f} |", flush=True)


if __name__ == "__main__":
    main()
