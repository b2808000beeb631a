"""``addb benchmark SUBJECT_DIR... --method analytical|mlp|hybrid``: the seed paper's benchmark.

Estimating dynamics from motion (Werling et al. 2024, §5) on our own processed subjects:
prints the paper's table (method x four metrics) with a dataset summary and writes both as
``benchmark.json`` and ``benchmark.md``. Each argument is a processed output folder or a
subject folder; a subject folder not processed yet is processed first into its default
output folder (:mod:`addb_viewer.locations`: ``<subject>/addb_out``, or the user's cache
for a read-only folder). An argument may also be an AddBiomechanics ``.b3d`` file (the
published dataset's format): its dynamics pass's frames with measured force are the
ground truth, its kinematics pass the input. A folder of ``.b3d`` files or a dataset run's
output tree stands for its subjects (:func:`dataset_entries`).
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from addb_viewer.commands import whole_number


def dataset_entries(path: str) -> list[tuple[str, str | None]]:
    """The subjects one command-line argument stands for, each as (path, name or None).

    A dataset run's output tree (``dataset_summary.json``) stands for every subject output
    folder its summary lists with processed trials, named by their relative paths
    (``labA/s01``: two labs' ``s01`` are two subjects), a folder inside it (``OUT/labA``) for
    those below that folder; a folder of ``.b3d`` files (no
    subject folder in it) for each file, named by its relative path without the suffix; any
    other argument for itself, under its recorded name (None).

    Raises
    ------
    FileFormatError
        The output tree's summary is damaged (:func:`solver.outputs.read_summary`).
    SubjectFolderError
        The argument is a dataset folder of subject folders (processed by ``addb process
        DATASET_DIR --out OUT``, whose output tree is what to give), or an output tree with no
        processed subject.
    """
    from solver.dataset.discover import SUMMARY_NAME, scan_dataset, tree_subjects
    from solver.errors import SubjectFolderError, counted
    from solver.io.subject import SUBJECT_JSON
    from solver.results import processed_trials

    p = Path(path)
    found = tree_subjects(p)
    if found is not None:
        processed = found.require_processed(p, lambda line: print(f"addb benchmark: {p}: {line}", file=sys.stderr))
        return [(str(found.tree / rel), rel) for rel in processed]
    if not p.is_dir() or (p / SUBJECT_JSON).is_file() or processed_trials(p):
        return [(path, None)]
    scan = scan_dataset(p)
    if scan.subjects:
        out = p / "addb_out"
        hint = f" (here probably {out}, where addb view DATASET_DIR writes)" if (out / SUMMARY_NAME).is_file() else ""
        raise SubjectFolderError(
            f"is a dataset folder ({counted(len(scan.subjects), 'subject folder')}); the benchmark reads processed subjects: "
            f"process it with addb process DATASET_DIR --out OUT and give the output tree OUT{hint}",
            path=p,
        )
    if scan.b3d_files:
        return [(str(p / f), str(Path(f).with_suffix("").as_posix())) for f in scan.b3d_files]
    return [(path, None)]


def resolve_output(path: str, progress=None) -> tuple[Path, Path | None]:
    """(processed output folder, subject folder or None) of a command-line argument.

    Raises
    ------
    SubjectFolderError
        The argument is neither a .b3d file nor a folder, or a folder that is neither a
        processed output folder nor a subject folder (no ``_subject.json``).
    """
    from addb_viewer.recording.jobs import ensure_processed
    from solver.errors import SubjectFolderError
    from solver.io.subject import SUBJECT_JSON
    from solver.results import processed_trials

    p = Path(path)
    if p.suffix.lower() == ".b3d" and p.is_file():
        return p, None  # an AddBiomechanics binary subject: read as is (solver.benchmark.b3d_trials)
    if not p.is_dir():
        raise SubjectFolderError("not a folder", path=p)
    if processed_trials(p):
        return p, None
    if not (p / SUBJECT_JSON).is_file():
        raise SubjectFolderError("neither a processed output folder nor a subject folder (no _subject.json)", path=p)
    return ensure_processed(p, progress=progress), p


def activity_seconds(pairs: list[tuple[Path, Path | None]]) -> dict[str, float] | None:
    """Seconds per activity label over the subjects' review records (None: no record)."""
    from addb_viewer.locations import annotations_path
    from annotations import AnnotationStore
    from solver.results import load_processed, processed_trials

    total: dict[str, float] = {}
    found = False
    for out, subject in pairs:
        if subject is None:
            continue
        path = annotations_path(subject, out)
        if not path.exists():
            continue
        found = True
        trials = set(processed_trials(out))
        with AnnotationStore.open(path, reviewer="addb benchmark") as store:
            for name in store.trials():
                review = store.review(name)
                rate = review.rate_hz or (load_processed(out, name).rate_hz if name in trials else 100.0)
                for a in review.activities:
                    total[a.label] = total.get(a.label, 0.0) + (a.stop - a.start) / rate
    return total if found else None


def _command(args: argparse.Namespace) -> str:
    """The command line that reproduces this run (recorded in the report)."""
    parts = ["addb", "benchmark", *args.subjects]
    for m in args.method or ["analytical"]:
        parts += ["--method", m]
    for c in args.contact or ["measured"]:
        parts += ["--contact", c]
    for t in args.train or []:
        parts += ["--train", t]
    if not args.train:
        parts += ["--split", args.split]
    parts += ["--seed", str(args.seed), "--inputs", args.inputs, "--epochs", str(args.epochs)]
    if args.filtering:
        parts.append("--filtering")
    parts += ["-o", args.output]
    return " ".join(shlex.quote(p) for p in parts)


def run(args: argparse.Namespace) -> int:
    """``addb benchmark SUBJECT_DIR|FILE.b3d... --method ...``: the seed paper's benchmark (Werling
    et al. 2024, §5) on the given subjects; prints the table and writes benchmark.json/.md
    under ``-o``.

    Returns
    -------
    The exit code: 0 when the table was written.

    Bad input raises, as in every subcommand (:mod:`addb_viewer.commands`).
    """
    from addb_viewer.progress import ProgressBar, table
    from solver.benchmark.dataset import load_dataset
    from solver.benchmark.filtering import filtering_markdown, filtering_study, plot_filtering
    from solver.benchmark.mlp import MlpOptions
    from solver.benchmark.report import (
        dataset_summary,
        summary_lines,
        table_header,
        table_rows,
        write_report,
    )
    from solver.benchmark.run import run_benchmark

    command = _command(args)
    bar = ProgressBar()
    entries = [e for s in args.subjects for e in dataset_entries(s)]
    train_entries = [e for s in (args.train or []) for e in dataset_entries(s)]
    pairs = [resolve_output(s, bar) for s, _ in entries]
    train_pairs = [resolve_output(s, bar) for s, _ in train_entries]
    print(f"loading {len(pairs)} subject(s) (inverse kinematics of the markers)" if args.inputs == "kinematic" else f"loading {len(pairs)} subject(s)", file=sys.stderr)
    dataset = load_dataset([o for o, _ in pairs], inputs=args.inputs, names=[n for _, n in entries])
    train = load_dataset([o for o, _ in train_pairs], inputs=args.inputs, names=[n for _, n in train_entries]) if train_pairs else None
    methods = tuple(dict.fromkeys(args.method or ["analytical"]))
    contacts = tuple(dict.fromkeys(args.contact or ["measured"]))
    result = run_benchmark(
        dataset,
        methods=methods,
        contacts=contacts,
        split=args.split,
        seed=args.seed,
        train=train,
        mlp_options=MlpOptions(epochs=args.epochs, seed=args.seed),
        progress=bar,
    )
    summary = dataset_summary(dataset, activities=activity_seconds(pairs + train_pairs))
    print(table(table_rows(result), table_header()))
    print(f"protocol: {result.protocol}")
    for row in result.rows:
        if "train_seconds" in row.notes:
            print(f"{row.method} training: {row.notes['train_seconds']:.1f} s over {len(row.notes['folds'])} fold(s)")
    for line in summary_lines(summary):
        print(line)
    js, md = write_report(args.output, result, summary, command=command)
    if args.filtering:
        rows = filtering_study(dataset, contact=contacts[0])
        (Path(args.output) / "filtering_study.md").write_text(filtering_markdown(rows))
        png = Path(args.output) / "filtering_study.png"
        plotted = plot_filtering(rows, png, title=f"analytical baseline ({contacts[0]} contact), {dataset.n_frames} frames")
        print(filtering_markdown(rows), end="")
        print(f"wrote {Path(args.output) / 'filtering_study.md'}" + (f" and {png}" if plotted else " (no plot: matplotlib is not installed; pip install 'addb[plot]')"))
    print(f"wrote {js} and {md}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``benchmark`` subcommand's parser to ``sub`` (its ``handler``: :func:`run`)."""
    p = sub.add_parser(
        "benchmark",
        help="the seed paper's benchmark: estimate dynamics from motion (analytical / MLP baselines, hybrid)",
        description=(
            "Score methods that estimate the centre-of-mass acceleration, ground reaction forces and "
            "moments and joint torques from motion alone (Werling et al. 2024, section 5) on processed "
            "subjects; prints the table and writes benchmark.json and benchmark.md."
        ),
    )
    p.add_argument(
        "subjects", nargs="+", metavar="SUBJECT_DIR",
        help="subject folder, processed output folder, AddBiomechanics .b3d file or folder of them, or a dataset "
        "run's output tree (each processed subject, named by its path in the tree)",
    )
    p.add_argument("--method", action="append", choices=("analytical", "mlp", "hybrid"), help="method to score (repeatable; default analytical): the paper's analytical and MLP baselines, or the hybrid (analytical total force split between the feet by a network)")
    p.add_argument("--train", action="append", metavar="SUBJECT_DIR", help="train the networks (mlp, hybrid) on these subjects only (repeatable)")
    p.add_argument("--split", choices=("loso", "seeded"), default="loso", help="protocol without --train: leave-one-subject-out (default) or one seeded train/dev/test split")
    p.add_argument("--seed", type=int, default=0, help="seed of the split and of the networks (default 0)")
    p.add_argument("--contact", action="append", choices=("measured", "kinematic"), help="analytical baseline's contact rule (repeatable; default measured)")
    p.add_argument("--inputs", choices=("kinematic", "processed"), default="kinematic", help="input coordinates: IK of the markers (default) or the dynamics-fitted ones")
    p.add_argument("--epochs", type=whole_number(1), default=10, help="training epochs of the networks (default 10, the paper's)")
    p.add_argument("--filtering", action="store_true", help="also run the filtering study (error against low-pass cut-off)")
    p.add_argument("-o", "--output", default="addb_benchmark", help="folder for benchmark.json/.md (default ./addb_benchmark)")
    p.set_defaults(handler=run)
