"""Benchmark of ``addb diagnose``: detection rate and parameter error per hidden cause, and
the false-alarm rate on consistent synthetic trials.

For each cause, ``--draws`` random draws (seeded) are hidden in neutral copies of real
trials (:mod:`tests.diagnose.harness`; the draws alternate between the ``--trials``), and
the public ``addb diagnose --json`` is run on each. A draw is *detected* when the chosen
cause (and plate or marker) is the hidden one; its parameter error is measured against the
unmodified trial's own estimate (tolerances of :data:`tests.diagnose.effects.TOLERANCE`).
``--synthetic`` consistent trials per real trial (:mod:`tests.diagnose.synthetic`) give the
false-alarm rate (a cause named where none exists).

Run (about 20 s per draw on this machine)::

    .venv/bin/python tests/benchmarks/bench_diagnose.py --draws 20 --synthetic 10 \
        --json docs/diagnose/results.json --markdown docs/diagnose/RESULTS.md
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from tests.diagnose.effects import CAUSES, TOLERANCE, check
from tests.diagnose.harness import SUBJECTS, TRIALS, diagnose_json, hidden_run, neutral_base
from tests.diagnose.harness import draw as draw_of
from tests.diagnose.synthetic import consistent_subject

UNITS = {
    "force_time_offset": ("ms", 1000.0),
    "body_mass": ("kg", 1.0),
    "plate_force_offset": ("N", 1.0),
    "plate_force_gain": ("%", 100.0),
    "plate_position_offset": ("cm", 100.0),
    "marker_offset": ("cm", 100.0),
    "segment_mass_distribution": ("kg", 1.0),
    "unmeasured_force": ("% of the erased step missed", 100.0),
    "plate_registration": ("cm", 100.0),
}


def _summary(rows: list[dict[str, Any]], synthetic: list[dict[str, Any]], bases: dict[str, Any], draws: int, keys: list[str]) -> dict[str, Any]:
    return {"rows": rows, "synthetic": synthetic, "bases": {k: {"applied": [e["cause"] for e in b.applied], "left": b.report["chosen"]} for k, b in bases.items()},
            "draws": draws, "trials": keys}


def run(args: argparse.Namespace) -> dict[str, Any]:
    """Every draw and synthetic trial; with ``--json`` the results so far are written after
    each of them (``"complete": false`` until the end), so an interrupted run keeps its rows."""
    work = Path(tempfile.mkdtemp(prefix="addb-bench-diagnose-"))
    rows: list[dict[str, Any]] = []
    synthetic: list[dict[str, Any]] = []
    bases = {}

    def save() -> None:
        if args.json:
            args.json.parent.mkdir(parents=True, exist_ok=True)
            args.json.write_text(json.dumps({**_summary(rows, synthetic, bases, args.draws, list(bases)), "complete": False}, indent=1, default=str) + "\n")
    causes = args.causes.split(",") if args.causes else list(CAUSES)
    try:
        for key in args.trials.split(","):
            t0 = time.perf_counter()
            bases[key] = neutral_base(key, work / f"base-{key}")
            print(f"base {key}: applied {[e['cause'] for e in bases[key].applied]}, "
                  f"left: {bases[key].report['chosen']} ({time.perf_counter() - t0:.0f} s)", flush=True)
        keys = list(bases)
        for ci, cause in enumerate(causes):
            for draw in range(args.first, args.first + args.draws):
                key, seed = draw_of(cause, draw, tuple(keys))
                dst = work / f"{cause}-{draw}"
                t0 = time.perf_counter()
                try:
                    hidden, report = hidden_run(bases[key], cause, seed, dst)
                    res = check(hidden, report, bases[key].report)
                    res["diagnose_seconds"] = (report.get("seconds") or {}).get("total")
                except Exception as exc:  # noqa: BLE001 - a failed draw is a result too
                    res = {"cause": cause, "detected": False, "within_tolerance": False, "error": None, "failure": repr(exc)}
                res.update(trial=key, seed=seed, wall_seconds=time.perf_counter() - t0)
                rows.append(res)
                print(f"{cause:<26s} {key:<9s} seed {seed}: chosen {res.get('chosen')}, detected {res['detected']}, "
                      f"error {res['error']}, within {res['within_tolerance']} ({res['wall_seconds']:.0f} s)", flush=True)
                shutil.rmtree(dst, ignore_errors=True)
                save()
        for key in keys:
            folder, trial = TRIALS[key]
            for seed in range(args.synthetic):
                dst = work / f"synthetic-{key}-{seed}"
                consistent_subject(bases[key].processed, SUBJECTS / folder, dst, seed=seed, base=bases[key].subject)
                report = diagnose_json(dst, trial)
                synthetic.append({"trial": key, "seed": seed, "chosen": report["chosen"], "reason": report["reason"],
                                  "diagnose_seconds": report["seconds"]["total"]})
                print(f"synthetic {key} seed {seed}: chosen {report['chosen']}", flush=True)
                shutil.rmtree(dst, ignore_errors=True)
                save()
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return {**_summary(rows, synthetic, bases, args.draws, keys), "complete": True}


def markdown(result: dict[str, Any], command: str) -> str:
    lines = [
        "# `addb diagnose`: detection of hidden causes",
        "",
        f"Made by `{command}` (see the script's docstring for the protocol).",
        f"Trials: {', '.join(result['trials'])} (neutral bases; their own findings applied first: "
        + "; ".join(f"{k}: {', '.join(v['applied']) or 'none'}" + (f", still named: {v['left']}" if v["left"] else "") for k, v in result["bases"].items())
        + ").",
        "",
        "| cause | draws | detected | within tolerance | median parameter error | tolerance | median diagnose time (s) |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    by: dict[str, list[dict[str, Any]]] = {}
    for r in result["rows"]:
        by.setdefault(r["cause"], []).append(r)
    for cause, rs in by.items():
        unit, scale = UNITS[cause]
        errs = [r["error"] for r in rs if r.get("error") is not None]
        secs = [r["diagnose_seconds"] for r in rs if r.get("diagnose_seconds")]
        med = f"{scale * float(np.median(errs)):.2f} {unit}" if errs else "—"
        lines.append(
            f"| {cause} | {len(rs)} | {sum(r['detected'] for r in rs)} ({100 * np.mean([r['detected'] for r in rs]):.0f} %) | "
            f"{sum(bool(r['within_tolerance']) for r in rs)} ({100 * np.mean([bool(r['within_tolerance']) for r in rs]):.0f} %) | {med} | "
            f"{scale * TOLERANCE[cause]:g} {unit} | {f'{np.median(secs):.1f}' if secs else '—'} |"
        )
    syn = result["synthetic"]
    if syn:
        alarms = sum(s["chosen"] is not None for s in syn)
        lines += ["", f"False alarms on consistent synthetic trials: {alarms} of {len(syn)} ({100 * alarms / len(syn):.0f} %)"
                  + (": " + ", ".join(f"{s['trial']}/{s['seed']} -> {s['chosen']}" for s in syn if s["chosen"]) if alarms else "") + "."]
    missed: dict[str, dict[str, int]] = {}
    for r in result["rows"]:
        if not r["detected"]:
            missed.setdefault(r["cause"], {})
            key = str(r.get("chosen") or r.get("failure", "none"))
            missed[r["cause"]][key] = missed[r["cause"]].get(key, 0) + 1
    if missed:
        lines += ["", "What was named instead when a draw was missed:", ""]
        lines += [f"- {c}: " + ", ".join(f"{k} x{v}" for k, v in m.items()) for c, m in missed.items()]
    return "\n".join(lines) + "\n"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--draws", type=int, default=20)
    p.add_argument("--first", type=int, default=0, help="index of the first draw (draws are numbered per cause; see tests.diagnose.harness.draw)")
    p.add_argument("--synthetic", type=int, default=10, help="consistent synthetic trials per real trial")
    p.add_argument("--trials", default="walk,run")
    p.add_argument("--causes", default="", help="comma-separated subset (default: all)")
    p.add_argument("--json", type=Path)
    p.add_argument("--markdown", type=Path)
    p.add_argument(
        "--from-json", type=Path, nargs="+",
        help="only merge earlier --json results into one table (a later file's rows of a cause replace the earlier files'; the trials and bases named are the last file's)",
    )
    p.add_argument(
        "--pool", action="store_true",
        help="with --from-json: pool the files' rows of a cause (a later file's row of the same seed replaces an earlier one), for draws measured in parts with --first",
    )
    args = p.parse_args()
    if args.from_json:
        parts = [json.loads(f.read_text()) for f in args.from_json]
        # a later file's rows of a cause (and its synthetic trials, if any) replace the
        # earlier files' (a cause re-measured after a change to it)
        rows: list[dict[str, Any]] = []
        synthetic: list[dict[str, Any]] = []
        # what a later file's row replaces: the rows of its cause, or with --pool of its seed
        key = (lambda r: (r["cause"], r["seed"])) if args.pool else (lambda r: r["cause"])
        for x in parts:
            redone = {key(r) for r in x["rows"]}
            rows = [r for r in rows if key(r) not in redone] + list(x["rows"])
            synthetic = list(x["synthetic"]) if x["synthetic"] else synthetic
        rows.sort(key=lambda r: (CAUSES.index(r["cause"]) if r["cause"] in CAUSES else len(CAUSES), r.get("seed", 0)))
        result = {
            "rows": rows,
            "synthetic": synthetic,
            "bases": parts[-1]["bases"],
            "draws": parts[-1]["draws"],
            "trials": parts[-1]["trials"],
        }
    else:
        result = run(args)
    command = "python tests/benchmarks/bench_diagnose.py " + " ".join(sys.argv[1:])
    text = markdown(result, command)
    print(text)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=1, default=str) + "\n")
    if args.markdown:
        args.markdown.parent.mkdir(parents=True, exist_ok=True)
        args.markdown.write_text(text)


if __name__ == "__main__":
    main()
