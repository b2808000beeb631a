"""The rule for tests that need an optional tool (tests/conftest.py): skip on a machine
without it (reason in the skip summary), fail under ``CI=true``."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import PRETEND_MISSING, import_tool, in_ci, require_tool

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize(
    ("value", "expected"),
    [("true", True), ("TRUE", True), ("1", True), ("yes", True), ("", False), ("false", False)],
)
def test_ci_is_read_from_the_environment(
    value: str, expected: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("CI", value)
    assert in_ci() is expected


def test_missing_tool_skips_outside_ci(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception, match="needs opensim: not here"):
        require_tool("opensim", False, "not here")


def test_missing_tool_fails_under_ci(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="CI=true .* needs opensim: not here"):
        require_tool("opensim", False, "not here")


def test_present_tool_passes_unless_pretended_missing(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("CI", "true")
    monkeypatch.delenv(PRETEND_MISSING, raising=False)
    require_tool("torch", True, "unused")  # no exception
    assert import_tool("json").dumps([1]) == "[1]"
    monkeypatch.setenv(PRETEND_MISSING, "Torch, opensim")
    with pytest.raises(pytest.fail.Exception, match="needs torch"):
        require_tool("torch", True, "pretended missing")


def test_absent_module_is_reported_not_raised_as_import_error(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception, match="no_such_addb_module"):
        import_tool("no_such_addb_module.sub")


SAMPLE = """
from tests.conftest import needs_tool, require_tool

import pytest

@needs_tool("torch", False, "PyTorch is not installed")
def test_marked():
    pass

def test_called():
    require_tool("chromium", False, "/usr/bin/chromium is not installed")

def test_plain():
    pass
"""


@pytest.mark.parametrize("ci", [False, True], ids=["local", "ci"])
def test_a_test_file_skips_locally_and_fails_under_ci(tmp_path: Path, ci: bool) -> None:
    """A real pytest run (the mark goes through the conftest hook): locally two skips
    listed with their reasons by -rs and exit 0; under CI=true the same two fail."""
    folder = tmp_path / "sample"
    folder.mkdir()
    (folder / "conftest.py").write_text(
        "from tests.conftest import pytest_configure, pytest_runtest_setup  # noqa: F401\n"
    )
    (folder / "test_sample.py").write_text(SAMPLE)
    env = {k: v for k, v in os.environ.items() if k not in ("CI", PRETEND_MISSING)}
    env["PYTHONPATH"] = str(ROOT)
    if ci:
        env["CI"] = "true"
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-rfEs", "-p", "no:xdist", "-p", "no:cacheprovider",
         str(folder)],
        check=False, capture_output=True, text=True, cwd=tmp_path, env=env, timeout=120,
    )  # fmt: skip
    out = proc.stdout
    if ci:
        assert proc.returncode == 1, out
        assert "1 passed" in out and "1 failed" in out and "1 error" in out, out
        assert "CI=true and a required tool is missing: needs torch" in out
        assert "CI=true and a required tool is missing: needs chromium" in out
    else:
        assert proc.returncode == 0, out
        assert "1 passed, 2 skipped" in out, out
        assert "SKIPPED" in out and "needs torch: PyTorch is not installed" in out
        assert "needs chromium: /usr/bin/chromium is not installed" in out
