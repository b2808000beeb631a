"""Run the ``addb`` command line in the test's own process and keep what it printed."""

from __future__ import annotations

import contextlib
import io

from addb_viewer.cli import main as cli


def run_addb(argv: list[str]) -> tuple[int, str, str]:
    """``addb ARGV`` in this process: (exit code, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = cli(argv)
    return code, out.getvalue(), err.getvalue()
