"""Where a subject's processed output and its review record live by default.

Shared by every command that takes a subject folder (``addb view``, ``addb record``,
``addb export``) so that they find each other's files.

* A subject folder the user can write to: output in ``<subject>/addb_out``, review record
  ``<subject>/annotations.json`` (beside the lab data it describes).
* The bundled demo subject, or a folder the user cannot write to: output in the user's
  cache, ``$XDG_CACHE_HOME/addb/<name>-<hash>`` (default ``~/.cache/addb/...``, the hash
  is of the resolved folder path so two subjects with the same name do not collide), and
  the review record beside that folder, ``<output>.annotations.json``.

The review record is never inside the output folder, because the pipeline replaces that
folder as a whole on every (re)process.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from solver.io.subject import folder_is_writable

#: Name of the output folder inside a writable subject folder.
OUTPUT_NAME = "addb_out"

#: Name of the review record inside a writable subject folder.
ANNOTATIONS_NAME = "annotations.json"


def cache_root() -> Path:
    """``$XDG_CACHE_HOME/addb`` or ``~/.cache/addb``."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "addb"


def is_bundled_demo(subject: Path) -> bool:
    """Whether ``subject`` (a resolved path) is the demo subject shipped inside the package
    (package data: addb writes nothing there)."""
    from addb_viewer.demo import DEMO_SUBJECT

    return subject == DEMO_SUBJECT.resolve()


def uses_subject_folder(subject_dir: str | os.PathLike[str]) -> bool:
    """True when outputs go inside ``subject_dir`` (writable and not the bundled demo)."""
    subject = Path(subject_dir).resolve()
    return not is_bundled_demo(subject) and folder_is_writable(subject)


def default_output_dir(subject_dir: str | os.PathLike[str]) -> Path:
    """The output folder used when the user gives none (see the module docstring).

    Parameters
    ----------
    subject_dir
        AddBiomechanics subject folder (need not be processed yet).

    Returns
    -------
    Path
        Absolute path; the folder may not exist yet.
    """
    subject = Path(subject_dir).resolve()
    if uses_subject_folder(subject):
        return subject / OUTPUT_NAME
    digest = hashlib.sha1(str(subject).encode()).hexdigest()[:8]
    return cache_root() / f"{subject.name}-{digest}"


def annotations_path(subject_dir: str | os.PathLike[str], out_dir: str | os.PathLike[str]) -> Path:
    """The review record (``annotations.json``) of a subject processed into ``out_dir``.

    Parameters
    ----------
    subject_dir
        AddBiomechanics subject folder.
    out_dir
        Its output folder (default or given with ``--out``).

    Returns
    -------
    Path
        ``<subject>/annotations.json`` for a writable subject folder, else
        ``<out_dir>.annotations.json`` beside the output folder (never inside it). Give it
        to ``AnnotationStore.open``; the file may not exist yet.
    """
    if uses_subject_folder(subject_dir):
        return Path(subject_dir).resolve() / ANNOTATIONS_NAME
    out = Path(out_dir).resolve()
    return out.parent / f"{out.name}.annotations.json"
