"""The ``addb`` command line.

Each subcommand lives in its own small function; heavy modules (viser, rerun, the
solver) are imported inside it so that ``addb --help`` and ``addb info`` start fast.
Exit codes: 0 success, 1 bad input (a clear message on stderr), 2 usage error.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence

from solver.errors import AddbError

Handler = Callable[[argparse.Namespace], int]


def _cmd_info(args: argparse.Namespace) -> int:
    from solver.io.summary import format_summary, summarize

    path = args.path
    if path is None:
        from addb_viewer.demo import DEMO_SUBJECT

        path = DEMO_SUBJECT
    print(format_summary(summarize(path)))
    return 0


def _cmd_kinematics(args: argparse.Namespace) -> int:
    from addb_viewer.progress import ProgressBar, table
    from solver.pipeline import ProcessOptions, process_kinematics

    opts = ProcessOptions(trials=tuple(args.trial) if args.trial else None)
    result = process_kinematics(args.subject, args.out, options=opts, progress=ProgressBar())
    rows = [
        [t.name, str(t.q.shape[0]), f"{t.marker_rms * 100:.2f}", f"{t.marker_max * 100:.2f}", t.worst_marker]
        for t in result.kinematics.trials
        if not opts.trials or t.name in opts.trials
    ]
    print(table(rows, ["trial", "frames", "marker RMS (cm)", "max (cm)", "worst marker"]))
    print(f"wrote {args.out}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every subcommand registered."""
    parser = argparse.ArgumentParser(
        prog="addb",
        description=(
            "Raw motion capture + force plates + an OpenSim model -> scaled skeleton, "
            "motion, joint torques and residual forces, reviewed in the browser."
        ),
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    p = sub.add_parser(
        "info", help="summarize a TRC/MOT/STO/C3D/.osim file or an AddBiomechanics subject folder"
    )
    p.add_argument("path", nargs="?", help="file or subject folder (default: the bundled demo subject)")
    p.set_defaults(handler=_cmd_info)
    p = sub.add_parser("kinematics", help="scale the model and solve inverse kinematics for a subject")
    p.add_argument("subject", help="AddBiomechanics subject folder")
    p.add_argument("--out", required=True, help="output folder (replaced atomically)")
    p.add_argument("--trial", action="append", help="write only this trial (repeatable); all trials are used for scaling")
    p.set_defaults(handler=_cmd_kinematics)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``addb`` console script; returns the process exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    handler: Handler | None = getattr(args, "handler", None)
    if handler is None:
        parser.print_help()
        return 2
    try:
        return handler(args)
    except AddbError as exc:
        print(f"addb {args.command}: {exc}", file=sys.stderr)
        return 1
    except FileNotFoundError as exc:
        print(f"addb {args.command}: no such file or folder: {exc.filename}", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
