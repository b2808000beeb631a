"""``addb info [PATH]``: summarize a lab file, a model or a subject folder."""

from __future__ import annotations

import argparse


def run(args: argparse.Namespace) -> int:
    """``addb info [PATH]``: print the summary of a lab file, model, .b3d file or subject folder
    (default: the demo subject).

    Returns
    -------
    The exit code: 0.

    Bad input raises, as in every subcommand (:mod:`addb_viewer.commands`).
    """
    from solver.io.summary import format_summary, summarize

    path = args.path
    if path is None:
        from addb_viewer.demo import DEMO_SUBJECT

        path = DEMO_SUBJECT
    print(format_summary(summarize(path)))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``info`` subcommand's parser to ``sub`` (its ``handler``: :func:`run`)."""
    p = sub.add_parser("info", help="summarize a TRC/MOT/STO/C3D/.osim/ExternalLoads .xml/.b3d file or a subject folder")
    p.add_argument("path", nargs="?", help="file or subject folder (default: the bundled demo subject)")
    p.set_defaults(handler=run)
