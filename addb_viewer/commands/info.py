"""``addb info [PATH]``: summarize a lab file, a model, a subject folder or an output folder."""

from __future__ import annotations

import argparse
from pathlib import Path


def run(args: argparse.Namespace) -> int:
    """``addb info [PATH]``: print the summary of a lab file, model, .b3d file, subject folder,
    folder of .b3d files (default: the demo subject), or output folder: a subject's (given and
    fitted mass, each trial's frames, marker RMS error, residual forces and Hicks verdicts, from
    its JSON files) or a dataset run's (its totals, in the report's terms). A dataset folder is
    refused, naming its subject folders.

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

        print(run_text(path))
        return 0
    _refuse_dataset_folder(Path(path))
    print(format_summary(summarize(path)))
    return 0


def _refuse_dataset_folder(path: Path) -> None:
    """Raise SubjectFolderError when ``path`` is a dataset folder: a folder without
    ``_subject.json`` with subject folders below it (:func:`solver.dataset.discover.scan_dataset`,
    which does not enter subject, output or hidden folders). The message names some of them and
    the ``.b3d`` files beside them, if any."""
    from solver.dataset.discover import is_subject_folder, scan_dataset
    from solver.errors import SubjectFolderError, counted, listed

    if not path.is_dir() or is_subject_folder(path):
        return
    scan = scan_dataset(path)
    if not scan.subjects:
        return
    rels = [s.rel for s in scan.subjects]
    message = (
        f"is a dataset folder ({len(rels)} subject folder{'s' if len(rels) != 1 else ''}: {listed(rels, 3)}), not a subject folder; "
        "addb info SUBJECT_FOLDER summarizes one subject, addb process FOLDER processes them all"
    )
    if scan.b3d_files:
        message += f"; it also holds {counted(len(scan.b3d_files), '.b3d file')} ({listed(scan.b3d_files, 3)}): addb info FILE.b3d summarizes one"
    raise SubjectFolderError(message, path=path)


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``info`` subcommand's parser to ``sub`` (its ``handler``: :func:`run`)."""
    p = sub.add_parser(
        "info",
        help="summarize a TRC/MOT/STO/C3D/.osim/ExternalLoads .xml/.b3d file, a subject folder, a folder of .b3d files "
        "or an output folder of addb (a subject's or a dataset run's)",
    )
    p.add_argument(
        "path", nargs="?",
        help="file, subject folder, folder of .b3d files or output folder (default: the bundled demo subject)",
    )
    p.set_defaults(handler=run)
