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
