"""Where bone meshes are found: one search path for the review app and both recorders.

An OpenSim model names its meshes by file name only (``<mesh_file>r_femur.vtp``); OpenSim
looks for them beside the model, in its ``Geometry`` folder and in its installation's
geometry folder. An AddBiomechanics subject folder usually has no ``Geometry`` folder, so
addb ships OpenSim's standard meshes as package data (``addb_viewer/geometry_data``, see
the README there) and looks, in this order, in

1. the subject's ``Geometry`` folder,
2. the folder recorded when the trial was processed (``ProcessedTrial.geometry_dir``: the
   ``Geometry`` folder beside the subject's model, else the model's folder),
3. the model's folder's ``Geometry`` and the model's folder (also those of the file a
   linked model points to),
4. ``--geometry DIR`` or, when not given, ``$ADDB_GEOMETRY`` (folders separated by
   ``os.pathsep``),
5. the bundled set.

Folders that do not exist are left out. A file is taken only inside the folder it is
looked up in (:func:`~addb_viewer.app.paths.confine`).
"""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from addb_viewer.app.paths import UnsafePathError, confine
from solver.errors import AddbError

#: The bone meshes shipped with addb (a subset of opensim-models' Geometry folder).
BUNDLED_GEOMETRY = Path(__file__).resolve().parent / "geometry_data"

#: Environment variable naming extra mesh folders (``os.pathsep``-separated), used when
#: no ``--geometry`` is given.
GEOMETRY_ENV = "ADDB_GEOMETRY"

SearchPath = tuple[Path, ...]


class GeometryPathError(AddbError):
    """A mesh folder given by the user (``--geometry`` or ``$ADDB_GEOMETRY``) is not a folder."""


def _user_folders(geometry: str | os.PathLike[str] | Sequence[str | os.PathLike[str]] | None) -> list[Path]:
    if geometry is None:
        text = os.environ.get(GEOMETRY_ENV, "").strip()
        items = [p for p in text.split(os.pathsep) if p.strip()]
        source = f"${GEOMETRY_ENV}"
    else:
        items = [geometry] if isinstance(geometry, (str, os.PathLike)) else list(geometry)
        source = "--geometry"
    out = []
    for item in items:
        p = Path(item).expanduser()
        if not p.is_dir():
            raise GeometryPathError(f"{source} must name a folder of mesh files (.vtp); this is not a folder", path=p)
        out.append(p)
    return out


def _unique_dirs(candidates: Iterable[Path | None]) -> SearchPath:
    seen: set[Path] = set()
    out: list[Path] = []
    for c in candidates:
        if c is None:
            continue
        try:
            if not c.is_dir():
                continue
            key = c.resolve()
        except OSError:
            continue
        if key not in seen:
            seen.add(key)
            out.append(c.absolute())
    return tuple(out)


def mesh_search_path(
    subject_dir: str | os.PathLike[str] | None,
    model_path: str | os.PathLike[str] | None,
    geometry: str | os.PathLike[str] | Sequence[str | os.PathLike[str]] | None = None,
    *,
    recorded: str | os.PathLike[str] | None = None,
    bundled: bool = True,
) -> SearchPath:
    """The folders a model's mesh files are looked up in, first match wins.

    Parameters
    ----------
    subject_dir
        The AddBiomechanics subject folder (its ``Geometry`` folder comes first), or None.
    model_path
        The model file (``.osim``) whose meshes are drawn, or None.
    geometry
        The user's mesh folder(s) (``--geometry DIR``); None: ``$ADDB_GEOMETRY`` if set.
    recorded
        The mesh folder recorded with a processed trial (``ProcessedTrial.geometry_dir``),
        looked up right after the subject's ``Geometry`` folder.
    bundled
        Append the bundled standard set (:data:`BUNDLED_GEOMETRY`).

    Returns
    -------
    tuple of Path
        Existing folders, absolute, without duplicates, in the order of the module
        docstring.

    Raises
    ------
    GeometryPathError
        ``geometry`` (or a folder of ``$ADDB_GEOMETRY``) is not an existing folder.
    """
    user = _user_folders(geometry)
    candidates: list[Path | None] = []
    if subject_dir is not None and str(subject_dir):
        candidates.append(Path(subject_dir) / "Geometry")
    if recorded is not None and str(recorded):
        candidates.append(Path(recorded))
    if model_path is not None and str(model_path):
        m = Path(model_path)
        for base in (m.absolute().parent, m.resolve().parent):
            candidates += [base / "Geometry", base]
    candidates += user
    if bundled:
        candidates.append(BUNDLED_GEOMETRY)
    return _unique_dirs(candidates)


def trial_search_path(
    trial: Any,
    subject_dir: str | os.PathLike[str] | None = None,
    geometry: str | os.PathLike[str] | Sequence[str | os.PathLike[str]] | None = None,
) -> SearchPath:
    """:func:`mesh_search_path` of a :class:`~solver.results.ProcessedTrial`: its recorded
    geometry folder and model file, the subject folder if known, ``geometry``, the bundled set.

    Raises
    ------
    GeometryPathError
        As :func:`mesh_search_path`.
    """
    return mesh_search_path(
        subject_dir, trial.model_path or None, geometry, recorded=trial.geometry_dir or None
    )


def find_mesh(name: str, search_path: Sequence[str | os.PathLike[str]]) -> Path | None:
    """The first file called ``name`` in the folders of ``search_path``.

    Parameters
    ----------
    name
        The mesh file as the model names it (``r_femur.vtp``; a relative path without
        ``..`` such as ``Geometry/r_femur.vtp`` is also tried by its last component).
    search_path
        Folders, in order (:func:`mesh_search_path`).

    Returns
    -------
    Path or None
        The resolved file, or None when no folder has it.

    Raises
    ------
    UnsafePathError
        ``name`` is empty, or every folder refuses it because it leads outside the folder
        (``..``, an absolute path).
    """
    names = [name]
    parts = Path(name.replace("\\", "/")).parts
    if len(parts) > 1 and not Path(name).is_absolute() and ".." not in parts:
        names.append(parts[-1])  # "Geometry/r_femur.vtp" is also looked up as "r_femur.vtp"
    refused: UnsafePathError | None = None
    tried = 0
    for folder in search_path:
        for n in names:
            try:
                p = confine(folder, n)
            except UnsafePathError as exc:
                refused = exc
                continue
            tried += 1
            if p.is_file():
                return p
    if refused is not None and tried == 0:
        raise refused
    return None


_reported: set[str] = set()
_reported_lock = threading.Lock()


def report_missing(problems: Iterable[str], *, stream: Any = None) -> list[str]:
    """Print each mesh problem to ``stream`` (default stderr) the first time this process
    sees it, so that a missing mesh is named once, not per trial or frame.

    Returns
    -------
    list of str
        The problems printed now (those not reported before).
    """
    new = []
    with _reported_lock:
        for p in problems:
            if p not in _reported:
                _reported.add(p)
                new.append(p)
    out = stream if stream is not None else sys.stderr
    for p in new:
        print(f"addb: bone mesh not shown: {p}", file=out, flush=True)
    return new
