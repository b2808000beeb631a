"""The subject folders of a dataset folder, and where each one's output goes.

A *subject folder* is a folder holding ``_subject.json`` (the AddBiomechanics layout,
:mod:`solver.io.subject`). A *dataset folder* holds subject folders at any depth, for
example one folder per lab::

    DATASET/labA/s01/_subject.json  ->  OUT/labA/s01/   (the one-subject output layout)
    DATASET/labA/s02/_subject.json  ->  OUT/labA/s02/
    DATASET/labB/p7/_subject.json   ->  OUT/labB/p7/

The search does not descend into a subject folder (its ``trials/`` are not subjects),
into hidden folders, into addb's own output folders (``addb_out``), Python's or npm's
(``__pycache__``, ``node_modules``), or into the output folder of the run itself when it
lies inside the dataset folder (:func:`scan_dataset` says which excluded folders it met,
so that the run can refuse one holding subject folders: addb never writes
``_subject.json`` into an output). It follows symbolic links (a dataset may link subjects
in from elsewhere) except one leading back to a folder above it, a loop
(:attr:`DatasetScan.loops`). The rule of which folders it enters is
:func:`solver.files.folders_to_search`.

AddBiomechanics ``.b3d`` files are not subject folders: the search lists those it meets
outside subject folders (:attr:`DatasetScan.b3d_files`) so that the run can say they are
not processed and how to make them subject folders (``addb convert``).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from solver.errors import DatasetError, FileFormatError, SubjectFolderError, counted, listed
from solver.files import folders_to_search
from solver.io.subject import (
    SUBJECT_JSON,
    output_folder_note,
    output_tree_part_note,
    trial_output_note,
)
from solver.outputs import SUMMARY_NAME, read_summary, summary_subjects, tree_part

#: Its HTML report, beside it (:mod:`solver.dataset.report`).
REPORT_NAME = "dataset_report.html"

@dataclass(frozen=True)
class DatasetSubject:
    """One subject folder of a dataset.

    Attributes
    ----------
    rel
        Its path relative to the dataset folder, with ``/`` separators (``labA/s01``);
        also the subject's key in the summary and its output folder below OUT.
    path
        The subject folder (absolute).
    """

    rel: str
    path: Path

    def out_dir(self, out_root: str | Path) -> Path:
        """Its output folder below ``out_root`` (the mirrored relative path)."""
        return Path(out_root).resolve().joinpath(*PurePosixPath(self.rel).parts)


def is_subject_folder(path: str | Path) -> bool:
    """True when ``path`` is a folder holding ``_subject.json``."""
    return (Path(path) / SUBJECT_JSON).is_file()


@dataclass(frozen=True)
class DatasetScan:
    """What the search below a dataset folder met (:func:`scan_dataset`).

    Attributes
    ----------
    subjects
        The subject folders, sorted by relative path (possibly none).
    excluded
        The excluded folders the search met and did not enter (as reached from the
        dataset folder, not resolved).
    b3d_files
        Relative paths (``/`` separators) of the ``.b3d`` files outside subject folders,
        which a dataset run does not process.
    loops
        Relative paths of the symbolic links the search did not follow because they lead
        back to a folder above them (:func:`solver.files.links_back`); following them searched the same
        folders again and again, and the folders above the dataset.
    """

    subjects: tuple[DatasetSubject, ...]
    excluded: tuple[Path, ...]
    b3d_files: tuple[str, ...]
    loops: tuple[str, ...] = ()

    def require_subjects(self, root: str | Path) -> tuple[DatasetSubject, ...]:
        """The subject folders of the scan of ``root``: at least one.

        Raises
        ------
        DatasetError
            There is none below ``root``; the message names the ``.b3d`` files met instead,
            which are not subject folders, and how to make them ones, or says that ``root`` is
            an output folder of addb (:func:`solver.io.subject.output_folder_note`), a trial's
            (:func:`~solver.io.subject.trial_output_note`), a dataset run's output tree or a
            folder inside one (:func:`~solver.io.subject.output_tree_part_note`).
        """
        if not self.subjects:
            note = output_folder_note(root) or trial_output_note(root) or _output_tree_note(Path(root)) or output_tree_part_note(root)
            if note is not None:  # an output folder given as the dataset: say so, not "no subject folder"
                raise DatasetError(note, path=Path(root).resolve())
            message = f"no subject folder (a folder holding {SUBJECT_JSON}) below this folder"
            if self.b3d_files:
                message += f"; it holds {_b3d_note(self.b3d_files)}"
            raise DatasetError(message, path=Path(root).resolve())
        return self.subjects


@dataclass(frozen=True)
class TreeSubjects:
    """The subjects a dataset run's output tree, or a folder inside it, stands for
    (:func:`tree_subjects`).

    Attributes
    ----------
    tree
        The output tree (it holds :data:`SUMMARY_NAME`).
    processed
        Relative paths (``labA/s01``) of the subjects its summary lists below the folder whose
        output folder holds processed trials, in the summary's order.
    left_out
        Those listed there without processed trials (failed or cancelled).
    part
        The folder's path relative to ``tree`` (``labA``), None for the tree itself.
    """

    tree: Path
    processed: tuple[str, ...]
    left_out: tuple[str, ...]
    part: str | None = None

    def below_folder(self, rel: str) -> str:
        """``rel`` relative to the folder given (``labA/s01`` -> ``s01`` for ``OUT/labA``)."""
        return rel if self.part is None else rel[len(self.part) + 1 :]

    def require_processed(self, folder: str | Path, tell: Callable[[str], object]) -> tuple[str, ...]:
        """:attr:`processed`, after passing ``tell`` the line naming the subjects left out
        ("left out 2 subjects without processed trials (labA/s03, labB/p7)"), if any.

        Raises
        ------
        SubjectFolderError
            No subject below ``folder`` (the folder given) has processed trials.
        """
        if not self.processed:
            raise SubjectFolderError(
                "a dataset output tree (or a folder of one) without a processed subject (every subject failed or "
                "was cancelled, or none is below it)", path=folder)  # fmt: skip
        if self.left_out:
            tell(f"left out {counted(len(self.left_out), 'subject')} without processed trials ({listed(list(self.left_out), 3)})")
        return self.processed


def tree_subjects(folder: str | Path) -> TreeSubjects | None:
    """The subjects of ``folder`` when it is a dataset run's output tree (``OUT``: every subject
    its summary lists) or a folder inside one that is not a subject's output folder
    (``OUT/labA``: those below it); None for any other folder. ``addb benchmark`` and ``addb
    export --format b3d`` take these.

    Raises
    ------
    FileFormatError
        The tree's summary is damaged (:func:`solver.outputs.read_summary`).
    """
    from solver.results import processed_trials

    p = Path(folder)
    if (p / SUMMARY_NAME).is_file():
        tree, part = p, None
    elif (found := tree_part(p)) is not None:
        tree, part = found
    else:
        return None
    rels = [s["rel"] for s in summary_subjects(read_summary(tree), part)]
    done = {rel: bool(processed_trials(tree / rel)) for rel in rels}
    return TreeSubjects(tree, tuple(r for r in rels if done[r]), tuple(r for r in rels if not done[r]), part)


def _output_tree_note(root: Path) -> str | None:
    """What to tell a user who gave a dataset run's output tree (it holds
    :data:`SUMMARY_NAME`) where the dataset folder was expected, naming the dataset folder
    the summary records; None for any other folder."""
    if not (root / SUMMARY_NAME).is_file():
        return None
    try:
        dataset = read_summary(root)["dataset"]
    except (OSError, FileFormatError):
        dataset = None  # a damaged summary: the folder is still an output tree
    where = f": here probably {dataset}" if dataset else ""
    return (
        f"is the output tree of a dataset run (it holds {SUMMARY_NAME}), not a dataset folder; expected the "
        f"folder of subject folders{where}, with this folder given as --out"
    )


def _walk(base: Path, top: Path, skip: set[Path]) -> DatasetScan:
    """The search of :func:`scan_dataset` from ``top`` (``base`` or a folder below it);
    relative paths are taken from ``base``."""
    found: list[DatasetSubject] = []
    excluded: list[Path] = []
    b3d: list[str] = []
    loops: list[str] = []
    for folder, dirs, files in os.walk(top, followlinks=True):
        here = Path(folder)
        if SUBJECT_JSON in files and here != base:
            found.append(DatasetSubject(here.relative_to(base).as_posix(), here))
            dirs[:] = []  # a subject's trials are not subjects
            continue
        b3d += [(here / f).relative_to(base).as_posix() for f in sorted(files) if f.lower().endswith(".b3d") and not f.startswith(".")]
        entered, back = folders_to_search(here, dirs)
        loops += [(here / d).relative_to(base).as_posix() for d in back]
        excluded += [here / d for d in entered if (here / d).resolve() in skip]
        dirs[:] = [d for d in entered if (here / d).resolve() not in skip]
    return DatasetScan(tuple(sorted(found, key=lambda s: s.rel)), tuple(excluded), tuple(sorted(b3d)), tuple(sorted(loops)))


def scan_dataset(root: str | Path, *, exclude: tuple[str | Path, ...] = ()) -> DatasetScan:
    """Search ``root`` for subject folders (see the module docstring), without requiring any.

    Parameters
    ----------
    root
        The dataset folder.
    exclude
        Folders not to search (the run's output folder when it lies inside ``root``).

    Returns
    -------
    DatasetScan
        The subject folders, the excluded folders met and the ``.b3d`` files outside
        subject folders.

    Raises
    ------
    DatasetError
        ``root`` is not a folder.
    """
    base = Path(root).resolve()
    if not base.is_dir():
        raise DatasetError("not a folder; expected a dataset folder of subject folders", path=root)
    return _walk(base, base, {Path(p).resolve() for p in exclude})


def subjects_below(root: str | Path, folder: str | Path) -> tuple[DatasetSubject, ...]:
    """The subject folders at or below ``folder`` (a folder below the dataset folder ``root``,
    as reached from it: an excluded folder of :class:`DatasetScan`), named relative to ``root``.

    Returns
    -------
    tuple of DatasetSubject
        Possibly none; ``folder`` itself when it is a subject folder.
    """
    base = Path(root).resolve()
    top = Path(folder)
    if is_subject_folder(top):
        return (DatasetSubject(top.relative_to(base).as_posix(), top),)
    return _walk(base, top, set()).subjects


def _b3d_note(b3d_files: tuple[str, ...]) -> str:
    return (
        f"{counted(len(b3d_files), '.b3d file')} ({listed(b3d_files, 5)}), which a dataset run does not process: convert each into a subject "
        "folder of the dataset with `addb convert FILE.b3d --out SUBJECT_DIR` (a folder holding one .b3d file can "
        "become that subject folder: --out that folder), or review a folder of .b3d files with `addb view FOLDER`"
    )


def b3d_note(scan: DatasetScan) -> str | None:
    """A message for the user naming the ``.b3d`` files of ``scan`` that a dataset run does not
    process and what it expects instead, or None when there are none."""
    return f"the dataset folder holds {_b3d_note(scan.b3d_files)}" if scan.b3d_files else None


def loop_note(scan: DatasetScan) -> str | None:
    """A message for the user naming the links of ``scan`` that lead back to a folder above
    them (not followed), or None when there are none."""
    if not scan.loops:
        return None
    return f"did not follow {counted(len(scan.loops), 'symbolic link')} leading back to a folder above it (a loop): {listed(list(scan.loops), 3)}"


def find_subjects(root: str | Path, *, exclude: tuple[str | Path, ...] = ()) -> tuple[DatasetSubject, ...]:
    """Every subject folder below ``root``, sorted by relative path.

    Parameters
    ----------
    root
        The dataset folder (not itself a subject folder).
    exclude
        Folders not to search (the run's output folder when it lies inside ``root``).

    Returns
    -------
    tuple of DatasetSubject
        At least one.

    Raises
    ------
    DatasetError
        ``root`` is not a folder, or holds no subject folder (the message names the
        ``.b3d`` files found instead, if any).
    """
    return scan_dataset(root, exclude=exclude).require_subjects(root)
