"""Probe: does the centre of pressure's place in the foot tell a shift of one belt from the
plates' registration on the walk?

    .venv/bin/python tests/benchmarks/probe_cop_symmetry.py [--sigma 0.1] [--draws 40]

A probe for issue 29's second gap, not a change of ``addb diagnose``. On the joint fit the
diagnosis names a hidden shift of one of the walk's two belts as the plates' registration in
some draws (docs/diagnose/JUDGED_FIT.md): the residuals do not resolve the other belt's
displacement, so both causes explain them alike. The centre of pressure's place relative to
the foot on it is information the rule does not read: a registration moves both belts'
centres of pressure relative to both feet, a shift of one belt those of one foot only.

The walk's neutral base is built with the joint fit at ``mass_sigma`` ``--sigma`` in the
alternation's place (``bench_diagnose_joint.py``), and the draws of block
``diagnose-walk-two-rows-compare`` are hidden in it and diagnosed (seeds 5000 + i of
``plate_position_offset`` and 9000 + i of ``plate_registration``, i < ``--draws``). For every
draw, each candidate of the two causes (the shift of each belt, the registration) is undone
on the hidden recording and the corrected centres of pressure are put in the frame of the
foot on their belt (``calcn_r`` on belt ``r``, ``calcn_l`` on ``l``; the base's processed
motion; samples above 20 % of body weight): the *asymmetry* is the distance between the two
feet's mean centre of pressure (forward and lateral, the left foot's lateral axis mirrored),
cm. The tie-break tried: where the diagnosis names one of the two causes, the candidate of
the smaller asymmetry instead. Prints one row per draw and, per row, the draws within
tolerance as diagnosed and under the tie-break (:func:`tests.diagnose.effects.check`).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import shutil
import sys
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(Path(__file__).resolve().parent))

#: Belt -> the foot on it (the walk's split-belt treadmill).
FOOT = {"r": "calcn_r", "l": "calcn_l"}
#: Samples of a belt used: its vertical force above this share of body weight.
LOADED_BW = 0.2
#: The two causes and the first seed of their draws (as in block ``diagnose-walk-two-rows-compare``).
SEEDS = {"plate_position_offset": 5000, "plate_registration": 9000}


class FootFrames:
    """The foot's frame at each force sample of a belt's loaded samples (the base's motion)."""

    def __init__(self, processed: Any, recording: Any, bw: float) -> None:
        from solver.diagnose.data import wxyz_to_matrix

        t = np.asarray(recording.time)
        inside = (t >= processed.time[0]) & (t <= processed.time[-1])
        idx = np.clip(np.searchsorted(processed.time, t), 0, processed.n_frames - 1)
        self.frames = {}
        for p in recording.plates:
            b = processed.body_names.index(FOOT[p.name])
            loaded = inside & (np.asarray(p.force)[:, 1] > LOADED_BW * bw)
            self.frames[p.name] = (loaded, wxyz_to_matrix(processed.body_wxyz[idx[loaded], b]),
                                   processed.body_position[idx[loaded], b])  # fmt: skip

    def means(self, recording: Any) -> dict[str, np.ndarray]:
        """Belt -> (2,) mean centre of pressure in its foot's frame (forward, lateral; the
        left foot's lateral axis mirrored), m."""
        out = {}
        for p in recording.plates:
            loaded, rot, pos = self.frames[p.name]
            local = np.einsum("tji,tj->ti", rot, np.asarray(p.cop)[loaded] - pos).mean(axis=0)
            out[p.name] = np.array([local[0], local[2] if p.name == "r" else -local[2]])
        return out

    def asymmetry(self, recording: Any) -> float:
        """Distance between the two feet's mean centres of pressure, m."""
        m = self.means(recording)
        return float(np.linalg.norm(m["r"] - m["l"]))


def shifted(recording: Any, plate: str, shift: Any) -> Any:
    """``recording`` with belt ``plate``'s centre of pressure moved by ``shift`` (3,) m (as the
    harness hides a shift: the ``plate_position_offset`` correction of ``-shift``)."""
    from solver.corrections import correct_forces

    return correct_forces(recording, {"cause": "plate_position_offset", "plate": plate, "shift_m": -np.asarray(shift)})


def hidden_recording(recording: Any, cause: str, plate: str | None, truth: dict[str, Any]) -> Any:
    """The base's recording with the draw's effect hidden as the harness hides it."""
    from solver.corrections import register_plates

    if cause == "plate_position_offset":
        return shifted(recording, plate or "", truth["shift_m"])
    return register_plates(recording, np.array(truth["shift_m"]), truth["rotation_rad"], np.array(truth["centre_m"]))


def undone(recording: Any, candidate: dict[str, Any]) -> Any:
    """``recording`` with a candidate's estimate undone, as its extension would apply it
    (:func:`solver.corrections.correct_forces`: its parameters are the extension's fields)."""
    from solver.corrections import correct_forces

    return correct_forces(recording, {"cause": candidate["cause"], **candidate["parameters"]})


def tie_break(row: dict[str, Any], report: dict[str, Any], base_report: dict[str, Any], scored: dict[tuple[str, str | None], float],
              candidates: dict[tuple[str, str | None], dict[str, Any]]) -> tuple[tuple[str, str | None] | None, bool]:
    """(the candidate the tie-break names instead, or None when it keeps the diagnosis'
    choice; whether the draw is then within tolerance)."""
    from tests.diagnose.effects import TOLERANCE, Hidden, error

    if row["chosen"] not in SEEDS or not scored:
        return None, row["within_tolerance"]
    pick = min(scored, key=lambda k: scored[k])
    chosen = (row["chosen"], row["chosen_choice"] if row["chosen"] == "plate_position_offset" else None)
    if pick == chosen:
        return None, row["within_tolerance"]
    if pick[0] != row["cause"] or (row["choice"] is not None and pick[1] != row["choice"]):
        return pick, False
    hidden = Hidden(row["cause"], row["choice"], row["truth"])
    modified = {**report, "chosen": pick[0], "chosen_parameters": candidates[pick]["parameters"]}
    return pick, error(hidden, modified, base_report) <= TOLERANCE[row["cause"]]


def main() -> None:
    """Build the base, run the draws, print the table."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sigma", type=float, default=0.1, help="mass_sigma of the joint fit (default 0.1, as block diagnose-walk-two-rows-compare)")
    ap.add_argument("--draws", type=int, default=40, help="draws of each cause (default 40)")
    args = ap.parse_args()

    import bench_diagnose_joint

    import solver.dynamics.stage as stage_module
    from solver.results import load_processed
    from tests.diagnose.effects import _forces_path, check, read_forces
    from tests.diagnose.harness import hidden_run, probe_walk_base

    stage_module.fit_dynamics = bench_diagnose_joint.joint_in_place(args.sigma)  # type: ignore[assignment]
    work, base = probe_walk_base(None, "addb-probe-cop-symmetry-")
    try:
        processed = load_processed(base.subject / "addb_out", base.trial)
        recording = read_forces(_forces_path(base.subject, base.trial))
        feet = FootFrames(processed, recording, 9.80665 * processed.mass_kg)
        m = feet.means(recording)
        print(f"walk, joint fit at mass_sigma {args.sigma:g}; the base's own asymmetry {100 * feet.asymmetry(recording):.1f} cm "
              f"(mean centre of pressure in the foot's frame, forward and lateral: right foot {100 * m['r'][0]:.1f}, "
              f"{100 * m['r'][1]:.1f} cm; left foot {100 * m['l'][0]:.1f}, {100 * m['l'][1]:.1f} cm)\n")
        print("| cause | seed | hidden shift (forward, lateral; cm) | named | within | asymmetry: hidden, undone by each candidate (cm) | tie-break names | within |")
        print("| --- | ---: | --- | --- | --- | --- | --- | --- |")
        counts = {c: [0, 0, 0] for c in SEEDS}
        for cause, first in SEEDS.items():
            for seed in range(first, first + args.draws):
                dst = work / f"{cause}-{seed}"
                with contextlib.redirect_stderr(io.StringIO()):
                    hidden, report = hidden_run(base, cause, seed, dst)
                shutil.rmtree(dst, ignore_errors=True)
                row = check(hidden, report, base.report)
                cands = {(c["cause"], c["choice"]): c for c in report["candidates"] if c["cause"] in SEEDS}
                hid = hidden_recording(recording, cause, hidden.choice, hidden.truth)
                scored = {k: feet.asymmetry(undone(hid, c)) for k, c in cands.items()}
                pick, ok = tie_break(row, report, base.report, scored, cands)
                counts[cause][0] += 1
                counts[cause][1] += bool(row["within_tolerance"])
                counts[cause][2] += bool(ok)
                shift = 100 * np.asarray(hidden.truth["shift_m"])
                named = row["chosen"] if row["chosen"] != "plate_position_offset" else f"plate_position_offset {row['chosen_choice']}"
                each = ", ".join(f"{'shift ' + k[1] if k[1] else 'registration'} {100 * v:.1f}" for k, v in sorted(scored.items(), key=lambda kv: kv[0][1] or ""))
                print(f"| {cause}{' ' + hidden.choice if hidden.choice else ''} | {seed} | {shift[0]:.1f}, {shift[2]:.1f} | {named} | "
                      f"{'yes' if row['within_tolerance'] else 'no'} | {100 * feet.asymmetry(hid):.1f}; {each} | "
                      f"{'(as named)' if pick is None else (pick[0] + (' ' + pick[1] if pick[1] else ''))} | {'yes' if ok else 'no'} |", flush=True)
        print("\n| cause | draws | within tolerance as diagnosed | with the tie-break |\n| --- | ---: | ---: | ---: |")
        for cause, (n, before, after) in counts.items():
            print(f"| {cause} | {n} | {before} | {after} |")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
