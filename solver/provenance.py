"""What made an output: addb's version and a digest of the solver's source code.

Both the kinematics cache of :mod:`solver.pipeline` and the dataset manifest
(:mod:`solver.dataset.manifest`) key their outputs on these, so that a code update
invalidates them even when the version number (``0.1.0`` across commits) does not change.
"""

from __future__ import annotations

import hashlib
from functools import cache
from pathlib import Path


def addb_version() -> str:
    """The installed addb version (``importlib.metadata``), ``"unknown"`` outside an install."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("addb")
    except PackageNotFoundError:
        return "unknown"


def code_digest(package: str | Path | None = None) -> str:
    """Hex SHA-256 of a package's Python source: every ``*.py`` file under ``package``
    (default: the ``solver`` package, computed once per process), its relative path and its
    bytes, in path order. Other files (caches, data) do not count."""
    if package is None:
        return _solver_code_digest()
    base = Path(package)
    h = hashlib.sha256()
    for path in sorted(base.rglob("*.py"), key=lambda p: p.relative_to(base).as_posix()):
        h.update(path.relative_to(base).as_posix().encode() + b"\0")
        h.update(path.read_bytes() + b"\0")
    return h.hexdigest()


@cache
def _solver_code_digest() -> str:
    return code_digest(Path(__file__).resolve().parent)
