"""Scaling + IK from the command line against OpenSim's InverseKinematicsTool, side by side.

    .venv/bin/python tests/benchmarks/bench_kinematics.py [--repeats 3]

OpenSim (``pip install opensim``, benchmark only) runs the working IK setup of
shared/oracles (the study's scaled model, 39 weighted markers) on the walk trial in a
fresh process; we time that whole process (interpreter start, ``import opensim``, the
tool's setup, ``InverseKinematicsTool.run()``, its output) and, inside it,
``run()`` alone. addb runs ``addb kinematics`` on the
rajagopal2016_walk subject folder in a fresh process (interpreter start, imports, reading,
scaling from the generic model over walk + static, IK of both trials, writing the outputs)
and we time the whole command, with addb's bytecode compiled first as an install has it
(``user_env.py``). It also runs ``addb kinematics --model SCALED --trial walk``, inverse
kinematics alone of the walk with the model the first ``addb kinematics`` run scaled and
wrote: the job OpenSim's tool does (a scaled model and one trial in, coordinates out); and
the same with OpenSim's own input model (the study-scaled model, every marker weighted 1,
where OpenSim's setup weights 39 markers its own way). All
marker RMS values are evaluated the same way: our forward kinematics, over every
observation of the 39 markers OpenSim's setup weights.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
from user_env import compile_sources, user_environment  # this folder: the script's own

REPO = Path(__file__).resolve().parents[2]
SHARED = REPO.parent / "shared"
ORACLES = SHARED / "oracles"
SUBJECT = SHARED / "data" / "subjects" / "rajagopal2016_walk"

OPENSIM_SCRIPT = """
import sys, time, opensim as osim
osim.Logger.setLevelString("error")
tool = osim.InverseKinematicsTool(sys.argv[1])
t0 = time.perf_counter()
tool.run()
print(time.perf_counter() - t0)
"""


def weighted_markers() -> set[str]:
    root = ET.parse(ORACLES / "opensim_ik_setup_walk.xml").getroot()
    return {
        e.get("name")
        for e in root.iter("IKMarkerTask")
        if e.findtext("apply").strip() == "true" and float(e.findtext("weight")) > 0
    }


def rms(model_file: Path, mot: Path, names: set[str]) -> float:
    from solver.io.mot import read_coordinates
    from solver.io.trc import read_trc
    from solver.model.osim import read_osim
    from solver.model.skeleton import Skeleton

    sk = Skeleton(read_osim(model_file))
    rot = [c.name for c in sk.osim.coordinates if c.motion_type == "rotational"]
    table = read_coordinates(mot, rotational=rot)
    q = sk.cmap.complete(np.column_stack([table.column(c) for c in sk.coordinate_names]))
    trc = read_trc(SUBJECT / "trials" / "walk" / "markers.trc")
    use = [n for n in trc.names if n in names and n in sk.marker_names]
    frames = np.array([int(np.argmin(np.abs(trc.time - t))) for t in table.time])
    y = trc.positions[frames][:, [trc.names.index(n) for n in use]]
    e = np.linalg.norm(sk.marker_positions(q, sk.marker_index(use)) - y, axis=2)
    return float(np.sqrt(np.nanmean(e**2))), len(use)


def opensim_reference(repeat: int) -> list[float]:
    """Whole-process times (s) of OpenSim's IK tool on the walk (:func:`run_opensim`), ``repeat``
    runs: the host reference of the whole-process timing blocks (code that does not change
    between two blocks, so two blocks' references say how much faster the host ran)."""
    times = []
    for _ in range(repeat):
        with tempfile.TemporaryDirectory() as tmp:
            times.append(run_opensim(Path(tmp))[0])
    return times


def host_reference_line(before: list[float], after: list[float], what: str = "subjects") -> str:
    """The host reference's line of a block: the best of the runs before and after ``what``."""
    return (
        f"host reference, OpenSim 4.6 IK tool on the walk (whole process, as block `kinematics`): best {min(before + after):.2f} s "
        f"(runs before the {what} {', '.join(f'{t:.2f}' for t in before)}; after {', '.join(f'{t:.2f}' for t in after)})"
    )


def run_opensim(work: Path) -> tuple[float, float, Path]:
    """OpenSim's IK of the walk in a fresh process: (whole process s, ``run()`` s, .mot)."""
    setup = ET.parse(ORACLES / "opensim_ik_setup_walk.xml")
    root = setup.getroot()
    tool = root.find("InverseKinematicsTool")
    tool.find("model_file").text = str(ORACLES / "opensim_scaled_walk.osim")
    tool.find("marker_file").text = str(SUBJECT / "trials" / "walk" / "markers.trc")
    tool.find("results_directory").text = str(work)
    tool.find("output_motion_file").text = str(work / "opensim_ik.mot")
    setup.write(work / "setup.xml")
    (work / "run.py").write_text(OPENSIM_SCRIPT)
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, str(work / "run.py"), str(work / "setup.xml")], capture_output=True, text=True, check=True, cwd=work)
    whole = time.perf_counter() - t0
    return whole, float(out.stdout.strip().splitlines()[-1]), work / "opensim_ik.mot"


def run_addb(work: Path, scaled_model: Path | None = None) -> tuple[float, Path]:
    """``addb kinematics`` of the walk subject in a fresh process: (whole process s, output
    folder). With ``scaled_model``: IK alone of the walk with that model (``--model``)."""
    addb = Path(sys.executable).parent / "addb"
    out = work / ("addb" if scaled_model is None else f"addb_ik_{scaled_model.stem}")
    extra = [] if scaled_model is None else ["--model", str(scaled_model), "--trial", "walk"]
    t0 = time.perf_counter()
    subprocess.run([str(addb), "kinematics", str(SUBJECT), "--out", str(out), *extra], check=True, capture_output=True, env=user_environment())
    return time.perf_counter() - t0, out


def row(label: str, times: list[float], rms_m: float) -> None:
    """Print one table row: the best of the whole-process ``times`` (s), all of them, and the
    marker RMS (``rms_m``, m, printed in cm)."""
    print(f"| {label} | {min(times):.2f} s | {', '.join(f'{t:.2f}' for t in times)} | {rms_m * 100:.2f} |")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    names = weighted_markers()
    compile_sources()
    os_times, os_run_times, ad_times, ik_times, same_times = [], [], [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        scaled = work / "rajagopal2016_walk_scaled.osim"  # the first addb run's scaled model
        for _ in range(args.repeats):  # interleaved, so all see the same machine load
            t_os, t_run, os_mot = run_opensim(work)
            os_times.append(t_os)
            os_run_times.append(t_run)
            t_ad, ad_out = run_addb(work)
            ad_times.append(t_ad)
            if not scaled.exists():
                shutil.copyfile(ad_out / scaled.name, scaled)
            t_ik, ik_out = run_addb(work, scaled)
            ik_times.append(t_ik)
            t_same, same_out = run_addb(work, ORACLES / "opensim_scaled_walk.osim")
            same_times.append(t_same)
        os_rms, n = rms(ORACLES / "opensim_scaled_walk.osim", os_mot, names)
        ad_rms, n2 = rms(ad_out / "rajagopal2016_walk_scaled.osim", ad_out / "walk" / "walk_ik.mot", names)
        ik_rms, _ = rms(scaled, ik_out / "walk" / "walk_ik.mot", names)
        same_rms, _ = rms(ORACLES / "opensim_scaled_walk.osim", same_out / "walk" / "walk_ik.mot", names)
        shutil.rmtree(work / "addb", ignore_errors=True)
    best_os, best_ad, best_ik, best_same = min(os_times), min(ad_times), min(ik_times), min(same_times)
    best_run = min(os_run_times)
    print(f"markers evaluated: {n} (OpenSim) / {n2} (addb), all observations of the walk (238 frames)")
    print(f"| | wall time (best of {args.repeats}) | all runs (s) | marker RMS (cm) |")
    print("| --- | ---: | --- | ---: |")
    row("OpenSim 4.6 IK, whole process (start, import, setup, run, output), walk only, study-scaled model", os_times, os_rms)
    print(f"| of which InverseKinematicsTool.run() | {best_run:.2f} s | {', '.join(f'{t:.2f}' for t in os_run_times)} | |")
    row("`addb kinematics` command: start-up + scaling + IK of walk and static + files", ad_times, ad_rms)
    row("`addb kinematics --model SCALED --trial walk`: start-up + IK of the walk with the model the row above scaled + files", ik_times, ik_rms)
    row("`addb kinematics --model opensim_scaled_walk.osim --trial walk`: the same with OpenSim's input model (every marker weight 1)", same_times, same_rms)
    print(
        f"\nspeed-up, whole process against whole process (issue: at least 10x): IK alone, the same job as OpenSim's tool, {best_os / best_ik:.1f}x; "
        f"on OpenSim's model {best_os / best_same:.1f}x; scaling + IK of both trials {best_os / best_ad:.1f}x; OpenSim's run() alone against IK alone {best_run / best_ik:.1f}x, against scaling + IK {best_run / best_ad:.1f}x"
    )


if __name__ == "__main__":
    main()
