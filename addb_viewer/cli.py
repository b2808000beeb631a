"""The ``addb`` command line.

Each subcommand lives in its own module of :mod:`addb_viewer.commands` (listed in
:data:`COMMANDS`); heavy modules are imported inside the handlers so that ``addb --help``
starts fast. Exit codes: 0 success, 1 bad input (a clear message on stderr), 2 usage.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Callable, Sequence

from solver.errors import AddbError

Handler = Callable[[argparse.Namespace], int]

#: Subcommand modules, in the order ``addb --help`` lists them.
COMMANDS = (
    "addb_viewer.commands.info",
    "addb_viewer.commands.kinematics",
    "addb_viewer.commands.view",
    "addb_viewer.commands.process",
    "addb_viewer.commands.record",
    "addb_viewer.commands.export",
    "addb_viewer.commands.benchmark",
    "addb_viewer.commands.diagnose",
    "addb_viewer.commands.convert",
)


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
    for name in COMMANDS:
        importlib.import_module(name).register(sub)
    return parser


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Warnings from the readers are messages for the user: one line, no source excerpt."""
    print(f"addb: warning: {message}", file=sys.stderr)


def one_blas_thread() -> None:
    """Make OpenBLAS start with one thread unless the user set ``OPENBLAS_NUM_THREADS``.

    Every stage already runs its linear algebra single-threaded
    (:func:`solver.single_threaded_blas`), but that limit comes after numpy and scipy have
    loaded their OpenBLAS libraries, and each library's extra thread spins at load: CPU
    time that buys no wall time (tests/test_cli_blas.py checks the thread count, not the
    time). Only before numpy is imported (as in the
    console script): in a process that has numpy already (``main`` called from Python) the
    environment is left as it is, and the threadpoolctl limit still applies.
    """
    if "numpy" not in sys.modules:
        os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``addb`` console script; returns the process exit code."""
    import warnings

    one_blas_thread()
    warnings.showwarning = _show_warning
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
    except Exception as exc:
        from annotations import (
            AnnotationError,  # the review record's own errors (no solver base class)
        )

        if isinstance(exc, AnnotationError):
            print(f"addb {args.command}: {exc}", file=sys.stderr)
            return 1
        raise


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
