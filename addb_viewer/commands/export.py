"""``addb export SUBJECT_DIR --trial NAME --format mcap -o FILE.mcap``."""

from __future__ import annotations

import argparse
from pathlib import Path


def run(args: argparse.Namespace) -> int:
    from addb_viewer.progress import ProgressBar
    from addb_viewer.recording.jobs import FORMATS, record_subject_trial

    fmt = args.format
    if fmt is None:
        suffix = Path(args.output).suffix.lower()
        fmt = next((name for name, s in FORMATS.items() if s == suffix), "mcap")
    path = record_subject_trial(
        args.subject, args.trial, args.output, fmt=fmt, out_dir=args.out, progress=ProgressBar()
    )
    print(f"wrote {path} ({fmt}, {path.stat().st_size / 1e6:.1f} MB)")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "export",
        help="export a processed trial for other tools (MCAP with Foxglove transforms, or Rerun)",
        description=(
            "Write one trial as MCAP (JSON channels: markers, plate wrenches, body poses as "
            "foxglove.FrameTransforms, residuals, joint torques, flags and annotations; zstd "
            "chunks with summary and index) or as a Rerun .rrd. The subject is processed first "
            "if it has no output yet."
        ),
    )
    p.add_argument("subject", help="AddBiomechanics subject folder")
    p.add_argument("--trial", required=True, help="trial name")
    p.add_argument(
        "--format",
        choices=("mcap", "rrd"),
        help="file format (default: from the output suffix, else mcap)",
    )
    p.add_argument("-o", "--output", required=True, help="the file to write")
    p.add_argument(
        "--out",
        help="processed output folder (default: <subject>/addb_out, or the user cache for read-only subjects)",
    )
    p.set_defaults(handler=run)
