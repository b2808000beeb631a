"""The environment a user's ``addb`` command runs in, for the whole-process timings.

A user's installed addb has its bytecode: ``pip install .`` compiles the package, and an
editable install writes ``__pycache__`` on the first import. This machine's shell sets
``PYTHONDONTWRITEBYTECODE=1``, so a timed ``addb`` process here compiled addb's modules
from source every time (about 56 modules for ``addb kinematics``, 0.05-0.1 s measured
2026-11-25). The benchmarks that time whole processes compile the sources first
(:func:`compile_sources`, outside the timed runs) and run their children in
:func:`user_environment`.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
#: addb's packages (pyproject.toml: solver, addb_viewer, annotations).
PACKAGES = ("solver", "addb_viewer", "annotations")


def user_environment() -> dict[str, str]:
    """This process' environment without ``PYTHONDONTWRITEBYTECODE``."""
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def compile_sources(root: str | Path = REPO) -> None:
    """Write the bytecode of addb's packages under ``root`` (this repository, or an exported
    tree given to ``--src``), as an install would.

    Raises
    ------
    subprocess.CalledProcessError
        A module does not compile.
    """
    trees = [str(Path(root) / p) for p in PACKAGES if (Path(root) / p).is_dir()]
    subprocess.run([sys.executable, "-m", "compileall", "-q", *trees], check=True, env=user_environment(), stdout=subprocess.DEVNULL)
