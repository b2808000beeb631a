"""``addb info [PATH]``: summarize a lab file, a model, a subject folder, a dataset folder or an output folder."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from addb_viewer.commands import FIT_CHOICES, fit_settings


def run(args: argparse.Namespace) -> int:
    """``addb info [PATH]``: print the summary of a lab file, model, .b3d file, subject folder,
    folder of .b3d files (default: the demo subject), or output folder: a subject's (given and
    fitted mass, each trial's frames, marker RMS error, residual forces and Hicks verdicts, from
    its JSON files), a dataset run's (its totals, in the report's terms) or a folder inside one
    (the totals of the subjects below it), a trial's output folder (its results.json), or a dataset folder
    (its subjects, trials, frames and hours, what the search leaves out and the state of its
    output tree, ``--out`` or ``addb view``'s default place: what the run left, and which
    subjects a new run (with ``--fit``) processes again: :mod:`solver.dataset.inventory`).

    Returns
    -------
    The exit code: 0.

    Bad input raises, as in every subcommand (:mod:`addb_viewer.commands`).
    """
    from solver.io.summary import format_summary, summarize

    path = args.path
    if path is None:
        from addb_viewer.demo import DEMO_SUBJECT

        path = DEMO_SUBJECT
    from solver.dataset.discover import SUMMARY_NAME

    if (Path(path) / SUMMARY_NAME).is_file():  # a dataset run's output tree
        from solver.dataset.report import run_text

        _dataset_options_only(args, path)
        print(run_text(path))
        return 0
    part = _output_tree_part(Path(path))
    if part is not None:
        _dataset_options_only(args, path)
        print(part)
        return 0
    scan = _dataset_scan(Path(path))
    if scan is not None:
        from addb_viewer.app.queue import dataset_output_dir
        from addb_viewer.progress import ProgressBar
        from addb_viewer.review_masks import review_digest
        from solver.dataset.inventory import dataset_inventory, inventory_text

        bar = ProgressBar() if sys.stderr.isatty() else None  # every trial file is read: a while on a large dataset
        tree = args.out if getattr(args, "out", None) else dataset_output_dir(path)
        settings = fit_settings(getattr(args, "fit", "default"))  # as addb process DATASET_DIR --fit records it
        inventory = dataset_inventory(path, tree, scan=scan, progress=bar, review_digest=review_digest, settings=settings)
        print(inventory_text(inventory, "addb process DATASET_DIR --out OUT (or addb view DATASET_DIR)"))
        return 0
    _dataset_options_only(args, path)
    print(format_summary(summarize(path)))
    return 0


def _dataset_options_only(args: argparse.Namespace, path: str | Path) -> None:
    """Refuse ``--out`` and ``--fit`` for a path that is not a dataset folder.

    Raises
    ------
    DatasetError
        Naming ``path`` and what the options are for.
    """
    given = [f"--{name}" for name, unset in (("out", None), ("fit", "default")) if getattr(args, name, unset) != unset]
    if given:
        from solver.errors import DatasetError

        raise DatasetError(f"is not a dataset folder; {' and '.join(given)} of addb info {'apply' if len(given) > 1 else 'applies'} "
                           "only to a dataset folder (they name its output tree and the run to compare it with; addb "
                           "info OUT alone summarizes an output tree)", path=Path(path))  # fmt: skip


def _output_tree_part(path: Path) -> str | None:
    """The text of a folder inside a dataset run's output tree that is neither the tree nor a
    subject's output folder (``OUT/labA``: :func:`solver.dataset.report.part_text`); None for
    any other path."""
    from solver.dataset.discover import is_subject_folder
    from solver.outputs import tree_part

    found = None if is_subject_folder(path) else tree_part(path)
    if found is None:
        return None
    from solver.dataset.report import part_text

    return part_text(*found)


def _dataset_scan(path: Path):
    """The dataset search of ``path`` when it is a dataset folder: a folder without
    ``_subject.json`` with subject folders below it (:func:`solver.dataset.discover.scan_dataset`,
    which does not enter subject, output or hidden folders); else None."""
    from solver.dataset.discover import is_subject_folder, scan_dataset

    if not path.is_dir() or is_subject_folder(path):
        return None
    scan = scan_dataset(path)
    return scan if scan.subjects else None


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``info`` subcommand's parser to ``sub`` (its ``handler``: :func:`run`)."""
    p = sub.add_parser(
        "info",
        help="summarize a TRC/MOT/STO/C3D/.osim/ExternalLoads .xml/.b3d file, a subject folder, a folder of .b3d files "
        "a dataset folder or an output folder of addb (a subject's or a dataset run's)",
    )
    p.add_argument(
        "path", nargs="?",
        help="file, subject folder, folder of .b3d files, dataset folder or output folder (default: the bundled demo subject)",
    )
    p.add_argument(
        "--out", default=None, metavar="OUT",
        help="for a dataset folder: its output tree (--out of addb process DATASET_DIR; default: where addb view "
        "DATASET_DIR writes), whose run is compared with the dataset now",
    )  # fmt: skip
    p.add_argument(
        "--fit", choices=FIT_CHOICES, default="default",
        help="for a dataset folder: the --fit of the new run to compare its output tree with (a run with another fit "
        "processes every subject again; default: default)",
    )  # fmt: skip
    p.set_defaults(handler=run)
