"""A fresh ``addb process`` against the same work in a warm interpreter (run on demand).

    .venv/bin/python tests/benchmarks/bench_startup.py [--repeat N] [SUBJECT ...]

For each subject, the CPU time (user + sys) of

* a fresh ``addb process`` (as ``bench_process.py`` runs it, as a user would: a new
  process, addb's bytecode compiled first), median of ``--repeat`` runs;
* alternately with those, the same command with the interpreter's and glibc's defaults
  (``main`` called with its arguments, as from Python: no
  :func:`addb_viewer.cli.run_to_completion`): what that start-up step saves;
* ``solver.pipeline.process_subject`` on the same subject in one child interpreter that has
  already processed it once (``--repeat`` + 1 calls; the first, which pays the imports and
  every first-use set-up, is not counted), median: what a Dask worker of
  ``addb process DATASET_DIR`` pays per subject once it has run one (block `dataset`).

The difference between the first and the last is what one process pays besides the work:
interpreter start, imports, first-use set-up and finalization. Frames are every trial's frames (results.json, as
``bench_process.py``); frames per CPU-second both ways, and the CPU time that 200 frames
per core-second allows (issue 29's target). SUBJECT as in ``bench_process.py``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from bench_process import _run as run_addb_process  # this folder: one `addb process`, (wall, CPU)
from bench_process import timed_child  # this folder: a child process's (wall, CPU)
from example_subjects import subject_folder  # this folder: the script's own
from user_env import compile_sources, user_environment  # this folder: the script's own

#: Run in the warm child: argv = subject folder, output folder, calls; prints one JSON list
#: of the CPU seconds (user + sys of the whole process, every thread) of each call.
WARM = """
import json, shutil, sys, time
from solver.pipeline import process_subject
subject, out, calls = sys.argv[1], sys.argv[2], int(sys.argv[3])
cpu = []
for _ in range(calls):
    shutil.rmtree(out, ignore_errors=True)
    t0 = time.process_time()
    process_subject(subject, out)
    cpu.append(time.process_time() - t0)
print(json.dumps(cpu))
"""


#: ``addb process`` as ``main`` called from Python runs it: argv given, so no run_to_completion.
DEFAULTS = "import sys; from addb_viewer.cli import main; sys.exit(main(sys.argv[1:]))"


def defaults_cpu(subject: Path, out: Path) -> float:
    """CPU seconds (user + sys) of one fresh ``addb process`` with the interpreter's defaults."""
    return timed_child([sys.executable, "-c", DEFAULTS, "process", str(subject), "--out", str(out)], user_environment())[1]


def warm_cpu(subject: Path, out: Path, calls: int) -> list[float]:
    """CPU seconds of each of ``calls`` ``process_subject`` calls in one fresh child."""
    proc = subprocess.run([sys.executable, "-c", WARM, str(subject), str(out), str(calls)],
                          check=True, capture_output=True, text=True, env=user_environment())  # fmt: skip
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("subjects", nargs="*", default=["rajagopal2016_walk", "rajagopal2016_run", "opencap_uhlrich2023"])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    compile_sources()
    print(f"CPU seconds (user + sys), median of {args.repeat}; warm: calls 2 to {args.repeat + 1} in one interpreter\n")
    print("| subject | frames | fresh process (s) | fresh, interpreter defaults (s) | warm interpreter (s) | per-process cost (s) "
          "| frames per CPU-s: fresh, warm | CPU at 200 frames per CPU-s (s) |")  # fmt: skip
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.subjects:
            folder = subject_folder(name, Path(tmp))
            fresh, plain = [], []
            for i in range(args.repeat):  # alternately, the order alternating too
                for kind in ("console", "defaults")[:: 1 if i % 2 == 0 else -1]:
                    if kind == "console":
                        fresh.append(run_addb_process(folder, Path(tmp) / f"{name}_fresh", None, "default")[1])
                    else:
                        plain.append(defaults_cpu(folder, Path(tmp) / f"{name}_plain"))
            warm = warm_cpu(folder, Path(tmp) / f"{name}_warm", args.repeat + 1)[1:]
            frames = sum(int(json.loads(r.read_text()).get("n_frames", 0)) for r in (Path(tmp) / f"{name}_fresh").glob("*/results.json"))
            f, w, d = statistics.median(fresh), statistics.median(warm), statistics.median(plain)
            print(f"| {name} | {frames} | {f:.2f} [{min(fresh):.2f}-{max(fresh):.2f}] | {d:.2f} [{min(plain):.2f}-{max(plain):.2f}] "
                  f"| {w:.2f} [{min(warm):.2f}-{max(warm):.2f}] "
                  f"| {f - w:.2f} | {frames / f:.0f}, {frames / w:.0f} | {frames / 200:.2f} |", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
