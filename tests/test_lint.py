"""The code base is clean under the pinned linter (ruff, the test extra; rules: ruff's
defaults with pyproject.toml's line length, and a docstring on every public module, class,
method and function outside tests/, pyproject.toml's ``[tool.ruff.lint]``). A finding that is meant (a library's error turned
into the user's message) carries a ``noqa`` with its reason."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_ruff_reports_nothing() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "ruff", "check", "--no-cache", "--output-format", "concise", "."],
        cwd=REPO, capture_output=True, text=True, check=False,
    )
    assert "No module named ruff" not in out.stderr, "ruff is a test dependency: pip install -e '.[test]'"
    assert out.returncode == 0, out.stdout + out.stderr
