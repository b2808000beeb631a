"""What made an output: addb's version and a digest of the solver's source code.

Both the kinematics cache of :mod:`solver.pipeline` and the dataset manifest
(:mod:`solver.dataset.manifest`) key their outputs on these, so that a code update
invalidates them even when the version number (``0.1.0`` across commits) does not change.
The digest covers the modules processing runs (:func:`processing_modules`, the imports of
:mod:`solver.pipeline` followed through the solver package), not the whole package: an
edit to the .b3d export or the dataset runner does not make a dataset's finished subjects
stale (dataset audit 2026-12-02, finding 8).
"""

from __future__ import annotations

import hashlib
import re
from functools import cache
from pathlib import Path

#: An absolute import of the solver package in Python source (at any indent: the imports
#: inside functions count, as processing runs them): ``from solver.x import a, b``, the same
#: with the names in parentheses over several lines, or ``import solver.x``.
_IMPORT = re.compile(
    r"^\s*(?:from\s+(solver(?:\.\w+)*)\s+import\s+(\([^)]*\)|[^#\n(]+)|import\s+(solver(?:\.\w+)*))", re.MULTILINE
)


def addb_version() -> str:
    """The installed addb version (``importlib.metadata``), ``"unknown"`` outside an install."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("addb")
    except PackageNotFoundError:
        return "unknown"


def code_digest(package: str | Path | None = None) -> str:
    """Hex SHA-256 of the source of the modules processing runs (:func:`processing_modules`):
    each file's path relative to the package folder and its bytes, in path order. Other
    files (caches, data, modules processing does not import) do not count.

    Parameters
    ----------
    package
        A copy of the solver package's folder; None: this package (computed once per process).
    """
    if package is None:
        return _solver_code_digest()
    base = Path(package)
    return _digest(base, processing_modules(package=base))


def _digest(base: Path, files: list[Path]) -> str:
    h = hashlib.sha256()
    for path in sorted(files, key=lambda p: p.relative_to(base).as_posix()):
        h.update(path.relative_to(base).as_posix().encode() + b"\0")
        h.update(path.read_bytes() + b"\0")
    return h.hexdigest()


def processing_modules(root: str = "solver.pipeline", package: str | Path | None = None) -> list[Path]:
    """The source files of the solver modules that ``root`` imports, directly or through
    each other, at module level or inside functions (every ``from solver... import`` and
    ``import solver...`` line, read as text, not run), with each package's ``__init__.py``
    on the way: what processing a subject can run.

    Parameters
    ----------
    root
        The module to start from.
    package
        The solver package's folder (default: this module's).

    Returns
    -------
    The files, sorted; ``root``'s own among them.

    Raises
    ------
    FileNotFoundError
        ``root`` names no module of the solver package.
    """
    package = Path(__file__).resolve().parent if package is None else Path(package)  # solver/
    todo, seen = [root], set()
    files: set[Path] = set()
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        found = _module_files(package, name)
        if not found and name == root:
            raise FileNotFoundError(f"{root}: no such module in {package}")
        files.update(found)
        for path in found:
            for module, names, plain in _IMPORT.findall(path.read_text(encoding="utf-8")):
                if plain:
                    todo.append(plain)
                    continue
                todo.append(module)
                for item in re.sub(r"#[^\n]*", "", names).strip("()").replace("\\", " ").split(","):
                    word = item.split()[0] if item.split() else ""
                    if word.isidentifier():  # ``from solver.io import b3d_schema``: a submodule, when one
                        todo.append(f"{module}.{word}")
    return sorted(files)


def _module_files(package: Path, name: str) -> list[Path]:
    """The files an import of ``name`` (``solver...``) runs: the ``__init__.py`` of each
    package on its path and the module's own file ([] when ``name`` is no module, such as a
    function imported from a module)."""
    parts = name.split(".")[1:]
    leaf = package.joinpath(*parts)
    own = leaf / "__init__.py" if leaf.is_dir() else leaf.with_suffix(".py")
    if not own.is_file():
        return []
    inits = [package.joinpath(*parts[:i], "__init__.py") for i in range(len(parts))]
    return [f for f in (*inits, own) if f.is_file()]


@cache
def _solver_code_digest() -> str:
    return _digest(Path(__file__).resolve().parent, processing_modules())
