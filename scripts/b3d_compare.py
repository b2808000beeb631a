"""AddBiomechanics' result in a .b3d file beside addb's, as a markdown table (docs/b3d/comparison.md).

Run from the repository root::

    .venv/bin/python scripts/b3d_compare.py [FILE.b3d] [--work DIR] [--md docs/b3d/comparison.md]

Steps: ``addb convert FILE.b3d --out WORK/subject`` (the same code), ``addb process
WORK/subject --out WORK/out``, then :func:`solver.io.b3d_compare.compare_with_b3d`.
Default FILE: ../shared/data/b3d/results.b3d.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DEFAULT_B3D = REPO.parent / "shared" / "data" / "b3d" / "results.b3d"


def main(argv: list[str] | None = None) -> int:
    """The command line (the module docstring); returns the exit code."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("b3d", nargs="?", default=str(DEFAULT_B3D))
    ap.add_argument("--work", help="working folder (default: a temporary one)")
    ap.add_argument("--md", default=str(REPO / "docs" / "b3d" / "comparison.md"))
    args = ap.parse_args(argv)
    sys.path.insert(0, str(REPO))
    from solver.io.b3d_compare import compare_with_b3d
    from solver.io.b3d_convert import converted_trial_folders

    work = Path(args.work or tempfile.mkdtemp(prefix="addb_b3d_compare_"))
    subject, out = work / "subject", work / "out"
    addb = [sys.executable, "-m", "addb_viewer.cli"] if not (REPO / ".venv" / "bin" / "addb").exists() else [str(REPO / ".venv" / "bin" / "addb")]
    subprocess.run([*addb, "convert", args.b3d, "--out", str(subject), "--force"], check=True, cwd=REPO)
    t0 = time.perf_counter()
    subprocess.run([*addb, "process", str(subject), "--out", str(out)], check=True, cwd=REPO)
    seconds = time.perf_counter() - t0
    rows = compare_with_b3d(args.b3d, out, trial_names=converted_trial_folders(subject))  # renamed trial folders
    (work / "comparison.json").write_text(json.dumps(rows, indent=2))
    b3d_name = Path(args.b3d).name
    cmd = f"`.venv/bin/python scripts/b3d_compare.py {'' if args.b3d == str(DEFAULT_B3D) else args.b3d}`".replace(" `", "`")
    lines = [
        f"# {b3d_name}: AddBiomechanics' pass beside addb",
        "",
        f"Made by {cmd} on {dt.date.today().isoformat()} (every figure below comes from that command;",
        f"addb process took {seconds:.0f} s). Marker RMS is over every observed (frame, marker) pair of the",
        "markers addb used, the same observed positions for both; AddBiomechanics' markers are our forward",
        "kinematics of the file's coordinates with the model embedded in the file (that FK reproduces the",
        "file's centre of mass within 1 mm: tests/io/test_b3d_convert.py). Residuals are addb's, on the frames",
        "the file marks measured (notMissingGRF) that addb also treated as measured.",
        "",
        (
            "| trial | frames | markers | AddB pass | AddB marker RMS (cm) | addb marker RMS (cm) | AddB reported RMS, mean (cm) "
            "| measured frames (file / addb) | addb linear residual RMS N (Hicks) | addb angular residual RMS N·m (Hicks) |"
        ),
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lin_ok = r["linear_residual_rms_N"] <= r["hicks_linear_threshold_N"]
        ang_ok = r["angular_residual_rms_Nm"] <= r["hicks_angular_threshold_Nm"]
        lines.append(
            f"| {r['trial']} | {r['frames']} | {r['markers']} | {r['b3d_pass']} | {100 * r['b3d_marker_rms_m']:.2f} | "
            f"{100 * r['addb_marker_rms_m']:.2f} | {100 * r['b3d_reported_marker_rms_m']:.1f} | "
            f"{r['measured_frames']} / {r['addb_observed_frames']} | "
            f"{r['linear_residual_rms_N']:.1f} (≤ {r['hicks_linear_threshold_N']:.1f}: {'yes' if lin_ok else 'no'}) | "
            f"{r['angular_residual_rms_Nm']:.1f} (≤ {r['hicks_angular_threshold_Nm']:.1f}: {'yes' if ang_ok else 'no'}) |"
        )
    lines += [
        "",
        f"Mass: file {rows[0]['b3d_mass_kg']:.2f} kg, addb fitted {rows[0]['addb_mass_kg']:.2f} kg." if rows else "",
        "",
    ]
    text = "\n".join(lines)
    Path(args.md).parent.mkdir(parents=True, exist_ok=True)
    Path(args.md).write_text(text)
    print(text)
    print(f"wrote {args.md} (work folder {work})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
