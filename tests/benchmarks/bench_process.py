"""End-to-end ``addb process`` timing on the shared subjects (run on demand).

    .venv/bin/python tests/benchmarks/bench_process.py [--repeat N] [--src DIR | --against DIR [--against-fit NAME]] [--fit NAME] [SUBJECT ...]

Runs the command in a fresh process per subject (as a user would), ``--repeat`` times each
(default 3; the table shows the median and the range of the wall times), and prints the
frames processed (every trial's frames, as in the trials' results.json), frames per
wall-clock second, the child's CPU time (user + sys, from ``getrusage``; median) and
frames per CPU-second (the issue's "frames per core-second"; the machine's other load
does not count in it), the per-stage times of the median run from subject.json / results.json
and the quality metrics. ``--src DIR`` runs another source tree's ``solver`` package (e.g.
an export of an earlier commit) with this venv, for before/after figures on one machine.
addb's bytecode is compiled first, outside the timed runs, as an install has it
(``user_env.py``). ``--fit NAME`` passes ``--fit NAME`` to ``addb process`` (``band``: the
older fixed-rounds dynamics fit; ``rounds``: the alternation, the default until 2026-11-26;
the default runs the joint fit to convergence). SUBJECT is a folder of ../shared/data/subjects or
``camargo2021_levelground`` (the Camargo circuit, assembled once into the temporary folder
by scripts/make_example_subject.py, outside the timed runs).
``--against DIR`` times this tree and DIR's (as ``--src``) alternately, run by run (which
runs first alternates too), and prints their CPU times side by side: on a host whose speed
drifts 10-30 % from one hour to the next, the way to see a change of a few per cent (both
trees meet the same drift). ``--against-fit NAME`` gives the other tree's ``addb process``
its own ``--fit`` (default: ``--fit``'s), so that the same fit runs in both when the
default changed between them (``default`` passes no option, which an older tree may not know).
``--host-reference`` also times OpenSim's IK tool on the walk as ``bench_kinematics.py`` does
(a whole process, best of ``--repeat``, before and after the subjects): code that does not
change between two blocks, so the ratio of two blocks' references says how much faster or
slower the host ran (timings drift 10-30 % with the host from one day to the next).
Target (issue): 200 frames per core-second.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from importlib import metadata
from pathlib import Path

from bench_kinematics import (  # this folder; the reference needs ``pip install opensim``
    host_reference_line,
    opensim_reference,
)
from example_subjects import subject_folder  # this folder: the script's own
from user_env import compile_sources, user_environment  # this folder: the script's own


def _run(subject: Path, out: Path, src: str | None, fit: str) -> tuple[float, float]:
    """One ``addb process`` of ``subject``: (wall s, CPU s user + sys of the child)."""
    env = user_environment()
    cmd = [str(Path(sys.executable).parent / "addb"), "process", str(subject), "--out", str(out)]
    if fit != "default":  # an older tree (--src) may not know the option
        cmd += ["--fit", fit]
    cwd = None
    if src:  # the other tree's `solver` first on the path; run outside the repo so '' does not shadow it
        env["PYTHONPATH"] = os.pathsep.join([src, env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
        cwd = tempfile.gettempdir()
    return timed_child(cmd, env, cwd)


def timed_child(cmd: list[str], env: dict[str, str], cwd: str | None = None) -> tuple[float, float]:
    """Run ``cmd`` as a child process to its end: (wall s, CPU s user + sys of the child,
    from ``getrusage(RUSAGE_CHILDREN)`` before and after). Raises CalledProcessError when it
    fails."""
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True, env=env, cwd=cwd)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)


def _interleaved(args: argparse.Namespace) -> None:
    """``--against``: this tree and the other alternately, CPU seconds side by side."""
    print(f"this tree against {args.against}, alternately (this first in even runs, the other in odd), {args.repeat} runs each (CPU s: median [min-max])\n")
    print("| subject | frames | CPU, this tree | CPU, other tree | this / other | frames per CPU-s: this, other |")
    print("| --- | ---: | ---: | ---: | ---: | ---: |")
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.subjects:
            folder = subject_folder(name, Path(tmp))
            cpus: dict[str | None, list[float]] = {None: [], args.against: []}
            for i in range(args.repeat):
                for src in list(cpus)[:: 1 if i % 2 == 0 else -1]:  # the order alternates too
                    out = Path(tmp) / f"{name}_{i}_{'other' if src else 'this'}"
                    cpus[src].append(_run(folder, out, src, args.fit if src is None else (args.against_fit or args.fit))[1])
            frames = sum(int(json.loads(r.read_text()).get("n_frames", 0)) for r in out.glob("*/results.json"))
            this, other = (statistics.median(v) for v in cpus.values())
            cells = [f"{statistics.median(v):.2f} [{min(v):.2f}-{max(v):.2f}]" for v in cpus.values()]
            print(f"| {name} | {frames} | {cells[0]} | {cells[1]} | {this / other:.3f} | {frames / this:.0f}, {frames / other:.0f} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("subjects", nargs="*", default=["rajagopal2016_walk", "rajagopal2016_run", "opencap_uhlrich2023"])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--src", default=None, help="source tree whose solver package to run")
    ap.add_argument("--fit", default="default", choices=["default", "converged", "rounds", "band"], help="addb process --fit")
    ap.add_argument("--host-reference", action="store_true", help="also time OpenSim's IK tool on the walk (the host's speed)")
    ap.add_argument("--against", default=None, help="source tree to time alternately with this one (CPU side by side)")
    ap.add_argument("--against-fit", default=None, choices=["default", "converged", "rounds", "band"], help="the other tree's addb process --fit (default: --fit's)")
    args = ap.parse_args()
    if args.src and args.against:
        ap.error("--src and --against exclude each other (--against times this tree against DIR)")
    compile_sources()
    if args.src:
        compile_sources(args.src)
    if args.against:
        compile_sources(args.against)
        _interleaved(args)
        return
    reference = opensim_reference(args.repeat) if args.host_reference else []
    versions = ", ".join(f"{p} {metadata.version(p)}" for p in ("numpy", "scipy", "pin"))
    print(f"{versions}; Python {sys.version.split()[0]}\n")
    print(
        "| subject | frames | wall (s): median [min-max] | frames/s | CPU (s) | frames per CPU-s | kinematics (s) | dynamics (s): preprocess / CoM fit / fit / ID "
        "| trial: measured frames, marker RMS (cm), linear residual (N, BW), angular residual (N·m, BW·h) |"
    )
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | --- | --- |")
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.subjects:
            walls, cpus = [], []
            for i in range(args.repeat):
                w, c = _run(subject_folder(name, Path(tmp)), Path(tmp) / f"{name}_{i}", args.src, args.fit)
                walls.append((w, i))
                cpus.append(c)
            wall, i_med = sorted(walls)[len(walls) // 2]
            cpu = statistics.median(cpus)
            out = Path(tmp) / f"{name}_{i_med}"
            subj = json.loads((out / "subject.json").read_text())
            dyn = subj.get("dynamics_seconds") or {}
            trials, frames = [], 0
            for res in sorted(out.glob("*/results.json")):
                r = json.loads(res.read_text())
                frames += int(r.get("n_frames", 0))
                if "linear_residual_rms_N" in r:
                    trials.append(
                        f"{res.parent.name}: {r['n_observed_frames']}/{r['n_frames']}, {r['marker_rms_m'] * 100:.2f}, "
                        f"{r['linear_residual_rms_N']:.1f} ({r['linear_residual_rms_BW']:.3f}), "
                        f"{r['angular_residual_rms_Nm']:.1f} ({r['angular_residual_rms_BWh']:.3f})"
                    )
            stages = subj["stage_seconds"]
            dyn_s = " / ".join(f"{dyn.get(k, 0):.1f}" for k in ("preprocess", "com_fit", "dynamics_fit", "inverse_dynamics"))
            ws = [w for w, _ in walls]
            print(
                f"| {name} | {frames} | {statistics.median(ws):.1f} [{min(ws):.1f}-{max(ws):.1f}] | {frames / wall:.0f} "
                f"| {cpu:.1f} | {frames / cpu:.0f} "
                f"| {stages['kinematics']:.1f} | {dyn_s} | {'; '.join(trials)} |",
                flush=True,
            )
    if args.host_reference:
        print("\n" + host_reference_line(reference, opensim_reference(args.repeat)))


if __name__ == "__main__":
    main()
