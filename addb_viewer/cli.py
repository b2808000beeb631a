"""The ``addb`` command line.

Each subcommand lives in its own module of :mod:`addb_viewer.commands` (listed in
:data:`COMMANDS`); heavy modules are imported inside the handlers so that ``addb --help``
starts fast. Exit codes: 0 success, 1 bad input (a clear message on stderr), 2 usage.
"""

from __future__ import annotations

import argparse
import atexit
import gc
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


# mallopt(3) parameters (glibc's malloc.h)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
#: glibc's mmap threshold and trim threshold for :func:`run_to_completion`, bytes.
MMAP_THRESHOLD, TRIM_THRESHOLD = 8 << 20, 128 << 20
#: Generation-2 threshold of the garbage collector for :func:`run_to_completion` (Python's default 10).
FULL_COLLECTION_THRESHOLD = 1000


def run_to_completion() -> bool:
    """Settings for a console process that runs one command and exits (not a server).

    * glibc's malloc: a fixed mmap threshold (:data:`MMAP_THRESHOLD`) and trim threshold
      (:data:`TRIM_THRESHOLD`), set together with ``mallopt(3)``. A fresh process starts
      with glibc's adaptive mmap threshold at 128 kB, so the pipeline's numpy temporaries
      over that size are mapped, faulted in page by page and unmapped again until the
      threshold has adapted; from the heap they reuse pages already faulted in. Setting
      either alone turns the adaptation off and is slower (mallopt(3); the same effect as
      Dask's ``MALLOC_TRIM_THRESHOLD_``, which the dataset runner removes). The threshold is
      8 MB, not higher: at 32 MB a 2,000-frame trial's many arrays of 8-32 MB shared the heap
      and fragmented it: its peak memory moved by tens of MB from one run to the next, close
      to issue 29's 500 MB, where at 8 MB it is lower and repeats, CPU time the same
      within the host's noise (tests/benchmarks/RESULTS.md, blocks ``growth-mmap-32`` and
      ``growth``, each the whole trial run three times in fresh processes; README note 7).
    * Full garbage collections (generation 2) once every :data:`FULL_COLLECTION_THRESHOLD`
      collections of generation 1 instead of 10: each traverses every object the imports
      made (numpy, scipy, pinocchio), some 20 ms apiece, and a command's own cycles are few.
    * :func:`gc.freeze` at exit (an atexit function): the interpreter's finalization then
      skips its last collection over all those objects (about 0.1 s after ``addb
      process``'s imports); every other step of a normal exit still runs.

    What this saves a whole ``addb process`` is measured in tests/benchmarks/RESULTS.md
    (block ``startup``). The malloc settings apply on glibc only (elsewhere mallopt is
    missing and they are skipped).

    Returns
    -------
    Whether the malloc settings were applied.
    """
    gc.set_threshold(*gc.get_threshold()[:2], FULL_COLLECTION_THRESHOLD)
    atexit.register(gc.freeze)
    try:
        import ctypes

        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # not glibc
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) & bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))


class Terminated(KeyboardInterrupt):
    """Raised in the main thread on SIGTERM (:func:`stop_on_sigterm`): what ``timeout``, SLURM
    at the end of a job's time and ``kill`` send. A KeyboardInterrupt, so that every clean-up
    of Ctrl-C runs (a dataset run keeps its finished subjects and writes its summary, listing
    the others as cancelled); the command then exits with 143 (128 + SIGTERM)."""


def stop_on_sigterm() -> None:
    """Make SIGTERM stop the command as Ctrl-C does, raising :class:`Terminated` in the main
    thread, instead of ending the process at once (Python's default): without it a dataset
    run ended by ``timeout`` left no summary and its work folders behind
    (docs/audits/2026-12-02-dataset.md, finding 9). Call from the main thread only."""
    import signal

    def terminate(signum: int, frame: object) -> None:
        raise Terminated()

    signal.signal(signal.SIGTERM, terminate)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``addb`` console script; returns the process exit code.

    Called with no ``argv`` (the console script, ``python -m addb_viewer.cli``), the
    process is the command's own: a command that runs to completion gets
    :func:`run_to_completion`, one that serves until stopped (its parser's default
    ``serves=True``: ``addb view``) does not. Called with an ``argv`` (from Python, as the
    tests do), the interpreter's settings are left alone.
    """
    import warnings

    one_blas_thread()
    warnings.showwarning = _show_warning
    parser = build_parser()
    args = parser.parse_args(argv)
    handler: Handler | None = getattr(args, "handler", None)
    if handler is None:
        parser.print_help()
        return 2
    if argv is None and not getattr(args, "serves", False):
        run_to_completion()
        stop_on_sigterm()
    try:
        return handler(args)
    except Terminated:  # SIGTERM: as Ctrl-C
        print(f"addb {args.command}: terminated (SIGTERM)", file=sys.stderr)
        return 143
    except KeyboardInterrupt:  # Ctrl-C: no traceback; outputs are put in place whole or not at all
        print(f"addb {args.command}: interrupted", file=sys.stderr)
        return 130
    except AddbError as exc:
        print(f"addb {args.command}: {exc}", file=sys.stderr)
        return 1
    except FileNotFoundError as exc:
        print(f"addb {args.command}: no such file or folder: {exc.filename}", file=sys.stderr)
        return 1
    except BrokenPipeError:  # the reader of stdout left (addb info ... | head): no traceback, as other tools
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # the exit's flush has nowhere to fail
        return 141  # 128 + SIGPIPE, what a shell reports for a command its pipe's reader left
    except OSError as exc:  # a folder named where a file is expected, no permission, disk full
        if exc.filename is None:
            raise
        target = exc.filename if exc.filename2 is None else f"{exc.filename} -> {exc.filename2}"
        print(f"addb {args.command}: cannot use {target}: {exc.strerror or exc}", file=sys.stderr)
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
