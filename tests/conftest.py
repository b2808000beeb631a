"""Fixtures shared by every test folder, and the rule for tests that need an optional tool.

A test that needs Chromium, Playwright, OpenSim or PyTorch skips on a machine without it,
with the reason in pytest's skip summary; under ``CI=true`` (the CI machine installs
them all) it fails instead, so a missing tool cannot hide as a green run. Use
:func:`require_tool` / :func:`import_tool` inside a test, or the :func:`needs_tool` mark
on a test or module (``pytestmark``); a test marked ``opensim`` gets the OpenSim check
before its fixtures run.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import shutil
import sys
from pathlib import Path
from types import ModuleType

import pytest

#: Review apps made by the tests start no spare ("warm") solver child: each would cost about
#: 1 s of CPU and 100 MB while idle, on a 2-core machine running two test workers. The
#: warm-child tests (tests/viewer/test_solver_warm_child.py) switch spares on themselves.
os.environ.setdefault("ADDB_WARM_SOLVER", "0")

#: The read-only real lab data beside the repository: ``<repo>/../shared/data``.
SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data``: measured TRC/MOT/C3D/.osim files and subject folders."""
    return SHARED_DATA


# ---------------------------------------------------------------------------- ../shared
# The suite reads ../shared and must leave it as it found it, also where it is writable (a
# developer's copy; root, as on CI, writes through missing write bits): a test that runs
# the app or a recorder on a shared subject folder in place writes its review record there,
# and OpenSim appends to an opensim.log in the folder of a model it loads. The controlling
# process (the only one of a serial run; xdist's controller) lists every file's size and
# modification time at the start and again at the end, and a difference fails the run.
_SHARED_STATE = pytest.StashKey[dict[str, tuple[int, int]]]()


def file_states(root: Path) -> dict[str, tuple[int, int]]:
    """``relative path -> (size in bytes, modification time in ns)`` of every file below
    ``root`` (none when it does not exist)."""
    return {
        str(p.relative_to(root)): (st.st_size, st.st_mtime_ns)
        for p in sorted(root.rglob("*"))
        if p.is_file() and not p.is_symlink()
        for st in (p.stat(),)
    }


def changed_files(before: dict[str, tuple[int, int]], after: dict[str, tuple[int, int]]) -> list[str]:
    """The paths added, removed or modified between two :func:`file_states`, sorted."""
    return sorted(k for k in before.keys() | after.keys() if before.get(k) != after.get(k))


def pytest_sessionstart(session: pytest.Session) -> None:
    if not hasattr(session.config, "workerinput"):
        session.config.stash[_SHARED_STATE] = file_states(SHARED_DATA.parent)


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    before = session.config.stash.get(_SHARED_STATE, None)
    if before is None:
        return
    changed = changed_files(before, file_states(SHARED_DATA.parent))
    if changed:
        shown = ", ".join(changed[:10]) + (f" and {len(changed) - 10} more" if len(changed) > 10 else "")
        print(f"\nerror: the tests changed files of {SHARED_DATA.parent} (read-only data): {shown}",
              file=sys.stderr)  # fmt: skip
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


def writable_copy(src: Path, dst: Path, **copytree_kw: object) -> Path:
    """Copy ``src`` to ``dst`` and make the copy writable (files 0o644, folders 0o755).

    ``shutil.copytree`` keeps the mode bits of the read-only shared data, and addb treats
    a folder without write bits as read-only (outputs then go to the user's cache).
    """
    shutil.copytree(src, dst, **copytree_kw)
    dst.chmod(0o755)
    for p in dst.rglob("*"):
        p.chmod(0o644 if p.is_file() else 0o755)
    return dst


#: Environment variable that lists tools to treat as missing (comma-separated names as
#: given to :func:`require_tool`, e.g. ``ADDB_TEST_PRETEND_MISSING=opensim,torch``): lets
#: the skip/fail rule be checked on a machine that has them, without uninstalling.
PRETEND_MISSING = "ADDB_TEST_PRETEND_MISSING"


def in_ci() -> bool:
    """Whether the tests run under CI (``CI`` set to ``true``/``1``/``yes``, any case)."""
    return os.environ.get("CI", "").strip().lower() in ("true", "1", "yes")


def _pretend_missing(name: str) -> bool:
    names = {n.strip().lower() for n in os.environ.get(PRETEND_MISSING, "").split(",")}
    return name.lower() in names


def tool_available(module: str) -> bool:
    """Whether Python module ``module`` can be found (without importing it)."""
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        return False


def require_tool(name: str, available: bool, reason: str) -> None:
    """Skip the current test when tool ``name`` is missing; under ``CI=true`` fail it.

    Parameters
    ----------
    name
        Short tool name, e.g. ``"opensim"``, ``"torch"``, ``"chromium"``, ``"playwright"``
        (also the name :data:`PRETEND_MISSING` matches).
    available
        Whether the tool is present.
    reason
        What is missing and how to get it, shown in the skip summary or the failure.

    Raises
    ------
    pytest.skip.Exception
        Missing, not under CI.
    pytest.fail.Exception
        Missing under ``CI=true``.
    """
    if available and not _pretend_missing(name):
        return
    message = f"needs {name}: {reason}"
    if in_ci():
        pytest.fail(f"CI=true and a required tool is missing: {message}", pytrace=False)
    pytest.skip(message)


def import_tool(module: str, name: str | None = None, reason: str = "") -> ModuleType:
    """Import ``module`` for the current test; missing: :func:`require_tool` (skip, or fail
    under ``CI=true``). ``name`` defaults to the top-level package name."""
    name = name or module.split(".")[0]
    top = module.split(".")[0]
    require_tool(name, tool_available(top), reason or f"Python package {top!r} is not installed")
    return importlib.import_module(module)


def needs_tool(name: str, available: bool, reason: str) -> pytest.MarkDecorator:
    """Mark for a test or module (``pytestmark``) that needs tool ``name``: checked with
    :func:`require_tool` before the test's fixtures run."""
    return pytest.mark.needs_tool(name, available, reason)


OPENSIM = tool_available("opensim")
OPENSIM_REASON = "the opensim package (test extra `opensim`, OpenSim 4.6) is not installed"
TORCH = tool_available("torch")
TORCH_REASON = "PyTorch (the mlp extra) is not installed"


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers",
        "needs_tool(name, available, reason): skips without the tool, fails under CI=true",
    )


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item: pytest.Item) -> None:
    """Before a test's fixtures (some run the solver for a minute): its ``needs_tool``
    marks, and ``opensim`` marks (pyproject.toml: "needs the opensim package")."""
    for mark in item.iter_markers("needs_tool"):
        require_tool(*mark.args)
    if item.get_closest_marker("opensim") is not None:
        require_tool("opensim", OPENSIM, OPENSIM_REASON)
