"""The seed paper's benchmark on all shared subjects (run on demand).

    .venv/bin/python tests/benchmarks/bench_benchmark.py [--work DIR] [--docs docs/benchmark]

Processes the three subjects of ../shared/data/subjects and the examples assembled by
``scripts/make_example_subject.py`` (the Camargo circuit, the stair descent, opensim-core's
two C3D walks) into ``DIR`` (skipped when already processed there), then runs, each in a fresh process as a user would:

    addb benchmark DIR/out/* --method analytical --method mlp --method hybrid --contact measured --contact kinematic --filtering
    addb benchmark DIR/out/* --method analytical --method mlp --method hybrid --contact measured --contact kinematic --inputs processed

and copies the tables (Markdown) and the filtering-study plot into ``--docs``. Prints the
wall times and the networks' (MLP, hybrid) training times. Needs PyTorch (``pip install torch==2.13.0``)
and matplotlib.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
SUBJECTS = REPO.parent / "shared" / "data" / "subjects"
NAMES = ("rajagopal2016_walk", "rajagopal2016_run", "opencap_uhlrich2023")
EXAMPLES = ("camargo2021_levelground", "stairdown", "opensim_c3d_walking")


def _process(addb: Path, work: Path) -> list[Path]:
    outs = []
    examples = [work / "subjects" / n for n in EXAMPLES]
    for example in examples:
        if not example.exists():
            subprocess.run([sys.executable, str(REPO / "scripts" / "make_example_subject.py"), example.name, str(example)], check=True, capture_output=True)
    for subject in [SUBJECTS / n for n in NAMES] + examples:
        out = work / "out" / subject.name
        if not any(out.glob("*/trial.npz")):
            t0 = time.perf_counter()
            subprocess.run([str(addb), "process", str(subject), "--out", str(out)], check=True, capture_output=True)
            print(f"processed {subject.name} in {time.perf_counter() - t0:.0f} s")
        outs.append(out)
    return outs


def _run(addb: Path, args: list[str]) -> float:
    t0 = time.perf_counter()
    proc = subprocess.run([str(addb), "benchmark", *args], check=True, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    print(proc.stdout)
    return wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--work", type=Path, default=Path("/tmp/addb_bench_benchmark"))
    parser.add_argument("--docs", type=Path, default=REPO / "docs" / "benchmark")
    args = parser.parse_args()
    addb = Path(sys.executable).parent / "addb"
    outs = [str(o) for o in _process(addb, args.work)]
    runs = {
        "kinematic": ["--method", "analytical", "--method", "mlp", "--method", "hybrid", "--contact", "measured", "--contact", "kinematic", "--filtering"],
        "processed": ["--method", "analytical", "--method", "mlp", "--method", "hybrid", "--contact", "measured", "--contact", "kinematic",
                      "--inputs", "processed"],
    }
    args.docs.mkdir(parents=True, exist_ok=True)
    for name, extra in runs.items():
        report = args.work / f"report_{name}"
        wall = _run(addb, [*outs, *extra, "-o", str(report)])
        data = json.loads((report / "benchmark.json").read_text())
        print(f"[{name} inputs] addb benchmark wall time {wall:.1f} s")
        for row in data["rows"]:
            if "train_seconds" in row["notes"]:
                folds = row["notes"]["folds"]
                print(f"  {row['method']}: training {row['notes']['train_seconds']:.1f} s over {len(folds)} folds "
                      f"({sum(f['train_frames'] for f in folds)} training frames in all)")
        shutil.copy(report / "benchmark.md", args.docs / f"benchmark_{name}_inputs.md")
        shutil.copy(report / "benchmark.json", args.docs / f"benchmark_{name}_inputs.json")
        if (report / "filtering_study.png").exists():
            shutil.copy(report / "filtering_study.png", args.docs / "filtering_study.png")
            shutil.copy(report / "filtering_study.md", args.docs / "filtering_study.md")


if __name__ == "__main__":
    main()
