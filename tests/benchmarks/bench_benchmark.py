"""The seed paper's benchmark on all shared subjects (run on demand).

    .venv/bin/python tests/benchmarks/bench_benchmark.py [--work DIR] [--fresh] [--docs docs/benchmark]

Processes the three subjects of ../shared/data/subjects and the examples assembled by
``scripts/make_example_subject.py`` (the Camargo circuit, the stair descent, opensim-core's
two C3D walks) with ``addb process`` into ``DIR/out`` (skipped when already processed there,
unless ``--fresh``), then runs, each in a fresh process as a user would:

    addb benchmark DIR/out/* --method analytical --method mlp --method hybrid --contact measured --contact kinematic --filtering
    addb benchmark DIR/out/* --method analytical --method mlp --method hybrid --contact measured --contact kinematic --inputs processed

(defaults: ``--inputs kinematic --split loso --seed 0 --epochs 10``), copies the reports
(Markdown, JSON) and the filtering study (table and plot) into ``--docs``, and prints in
Markdown (standard output; progress on standard error): the processing and benchmark wall
times, the networks' training times, the dataset, the table of each run, the per-trial
GRF and CoM acceleration errors of the kinematic-input run and the filtering study. Needs
PyTorch (``pip install torch==2.13.0``) and, for the plot, matplotlib (the ``plot`` extra).
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


def _process(addb: Path, work: Path, fresh: bool) -> tuple[list[Path], dict[str, float]]:
    outs: list[Path] = []
    times: dict[str, float] = {}
    examples = [work / "subjects" / n for n in EXAMPLES]
    for example in examples:
        if not example.exists():
            subprocess.run([sys.executable, str(REPO / "scripts" / "make_example_subject.py"), example.name, str(example)], check=True, capture_output=True)
    for subject in [SUBJECTS / n for n in NAMES] + examples:
        out = work / "out" / subject.name
        if fresh and out.exists():
            shutil.rmtree(out)
        if not any(out.glob("*/trial.npz")):
            t0 = time.perf_counter()
            subprocess.run([str(addb), "process", str(subject), "--out", str(out)], check=True, capture_output=True)
            times[subject.name] = time.perf_counter() - t0
            print(f"processed {subject.name} in {times[subject.name]:.0f} s", file=sys.stderr, flush=True)
        outs.append(out)
    return outs, times


def _run(addb: Path, args: list[str]) -> float:
    t0 = time.perf_counter()
    proc = subprocess.run([str(addb), "benchmark", *args], check=True, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    print(proc.stdout, file=sys.stderr, flush=True)
    return wall


def _f(x: float) -> str:
    return f"{x:.2f}"


def _table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join("---" for _ in header) + " |"]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in rows])


def _summary_table(data: dict) -> str:
    header = ["method", "frames", "CoM acc. error (m/s²)", "GRM error (N·m/kg)", "GRF error (N/kg)", "joint torque error (N·m/kg)"]
    rows = [[r["method"], str(r["frames"]), _f(r["com_acc"]), _f(r["grm"]), _f(r["grf"]), _f(r["torque"])] for r in data["rows"]]
    return _table(header, rows)


def _per_trial_table(data: dict) -> str:
    rows = data["rows"]
    body = [[t, *(f"{_f(r['per_trial'][t]['grf'])} / {_f(r['per_trial'][t]['com_acc'])}" for r in rows)] for t in rows[0]["per_trial"]]
    return _table(["trial", *(r["method"] for r in rows)], body)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--work", type=Path, default=Path("/tmp/addb_bench_benchmark"))
    parser.add_argument("--docs", type=Path, default=REPO / "docs" / "benchmark")
    parser.add_argument("--fresh", action="store_true", help="process every subject again even if DIR/out has it")
    args = parser.parse_args()
    addb = Path(sys.executable).parent / "addb"
    t0 = time.perf_counter()
    out_paths, times = _process(addb, args.work, args.fresh)
    outs = [str(o) for o in out_paths]
    if times:
        print(f"`addb process` of the subjects: {', '.join(f'{k} {v:.0f} s' for k, v in times.items())} "
              f"({time.perf_counter() - t0:.0f} s in all).\n")
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
        print(f"**{name.capitalize()} inputs** (`--inputs {name}`): `addb benchmark` wall time {wall:.1f} s, loading, inputs, "
              "every row" + (" and the filtering study" if name == "kinematic" else "") + " included.\n")
        for row in data["rows"]:
            if "train_seconds" in row["notes"]:
                folds = row["notes"]["folds"]
                cut = sorted({f["cutoff_hz"] for f in folds if f.get("cutoff_hz") is not None})
                print(f"* {row['method']}: training {row['notes']['train_seconds']:.1f} s over {len(folds)} folds "
                      f"({sum(f['train_frames'] for f in folds)} training frames in all"
                      + (f"; cut-offs chosen: {', '.join(f'{c:g}' for c in cut)} Hz" if cut else "") + ")")
        print()
        print(_summary_table(data))
        print()
        if name == "kinematic":
            print("Per trial, GRF error / CoM acc. error (N/kg / m/s²):\n")
            print(_per_trial_table(data))
            print()
            study = report / "filtering_study.md"
            if study.exists():
                print("Filtering study (analytical baseline, measured contact, same frames):\n")
                print(study.read_text().strip())
                print()
        shutil.copy(report / "benchmark.md", args.docs / f"benchmark_{name}_inputs.md")
        shutil.copy(report / "benchmark.json", args.docs / f"benchmark_{name}_inputs.json")
        if (report / "filtering_study.md").exists():
            shutil.copy(report / "filtering_study.md", args.docs / "filtering_study.md")
            if (report / "filtering_study.png").exists():
                shutil.copy(report / "filtering_study.png", args.docs / "filtering_study.png")
            else:
                plot = args.docs.resolve() / "filtering_study.png"
                shown = plot.relative_to(REPO) if plot.is_relative_to(REPO) else plot  # as the repository names it
                print(f"**The plot {shown} was not redrawn: matplotlib is not installed (the `plot` extra).**\n")


if __name__ == "__main__":
    main()
