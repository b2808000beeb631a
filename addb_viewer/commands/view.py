"""``addb view [SUBJECT_DIR]``: review a subject in the browser (default: the bundled demo).

``addb view FILE.b3d`` converts the AddBiomechanics file into a cached subject folder
first (:func:`b3d_subject`), then reviews that; ``addb view FOLDER`` of .b3d files (and no
subject folder) converts each and reviews them as a dataset, in the workbench's queue
(:func:`b3d_dataset`). ``addb view DATASET_DIR`` (subject folders at any depth, or a dataset
output tree) opens the review workbench (:mod:`addb_viewer.app.workbench`); .b3d files beside
its subject folders are named in the queue's note, not converted.

Prints the page's address, then serves until Ctrl-C (or SIGTERM). A subject without
processed output is processed first, with the progress in the page; a subject that
fails to load shows the error in the page and on the terminal, and the server keeps
running.
"""

from __future__ import annotations

import argparse
import getpass
import os
import signal
import sys
import threading
from pathlib import Path

from addb_viewer.commands import whole_number


def default_reviewer() -> str:
    """``$ADDB_REVIEWER``, else the login name, else "reviewer"."""
    name = os.environ.get("ADDB_REVIEWER", "").strip()
    if name:
        return name
    try:
        return getpass.getuser() or "reviewer"
    except (OSError, KeyError):
        return "reviewer"


def b3d_subject(path: Path) -> Path:
    """The cached subject folder of a .b3d file, converted on first use.

    ``$XDG_CACHE_HOME/addb/b3d/<stem>-<hash>`` (the hash is of the resolved path, size and
    modification time, so a changed file converts again); the file's missing-GRF labels
    become the folder's review record (``addb convert``). A file converted again brings
    the review of its latest earlier conversion (:func:`_carry_over_review`): the reviewers'
    flags and notes stay with the file, not with one version of it.
    """
    import hashlib

    from addb_viewer.commands.convert import write_review_record
    from addb_viewer.locations import cache_root
    from solver.io.b3d_convert import b3d_to_subject
    from solver.io.subject import SUBJECT_JSON

    st = path.stat()
    key = f"{path.resolve()}:{st.st_size}:{st.st_mtime_ns}"
    folder = cache_root() / "b3d" / f"{path.stem}-{hashlib.sha1(key.encode()).hexdigest()[:10]}"
    if not (folder / SUBJECT_JSON).is_file():
        print(f"addb view: converting {path} to {folder}", flush=True)
        converted = b3d_to_subject(path, folder, overwrite=True)
        _carry_over_review(path, folder)
        write_review_record(converted)
    return folder


def _carry_over_review(path: Path, folder: Path) -> None:
    """Copy into the new cached subject ``folder`` of the .b3d file ``path`` the review record
    of the latest earlier conversion of the same file (the cached folder beside it whose
    ``b3d_source.json`` names the same resolved path and whose record changed last), when
    every trial the two conversions share has the same frames; else leave it and say where
    it is. :func:`addb_viewer.commands.convert.write_review_record` then replaces what the
    earlier conversion imported and keeps the reviewers' work."""
    import json
    import shutil

    from addb_viewer.locations import ANNOTATIONS_NAME
    from annotations import AnnotationStore

    def source(of: Path) -> dict | None:
        try:
            data = json.loads((of / "b3d_source.json").read_text())
        except (OSError, ValueError):
            return None
        return data if isinstance(data, dict) and isinstance(data.get("trials"), dict) else None

    new = source(folder)
    if new is None:
        return
    earlier = [f for f in folder.parent.glob(f"{path.stem}-*") if f != folder and (f / ANNOTATIONS_NAME).is_file()
               and (s := source(f)) is not None and s.get("b3d") == new.get("b3d")]  # fmt: skip
    if not earlier:
        return
    latest = max(earlier, key=lambda f: (f / ANNOTATIONS_NAME).stat().st_mtime_ns)
    old = source(latest) or {}
    frames = {name: t.get("frames") for name, t in old["trials"].items() if isinstance(t, dict)}
    differ = [name for name, t in new["trials"].items() if name in frames and frames[name] != t.get("frames")]
    record = latest / ANNOTATIONS_NAME
    if differ:
        print(f"addb view: not carried over: the review of the earlier conversion {record} (its trials "
              f"{', '.join(sorted(differ))} had other frames than this version of the file)", flush=True)  # fmt: skip
        return
    with AnnotationStore.open(record, reviewer="addb view"):
        pass  # replays its journal into the record file (a writer may have left it behind)
    for name in (ANNOTATIONS_NAME, Path(ANNOTATIONS_NAME).with_suffix(".journal").name):  # the record and its history
        if (latest / name).is_file():
            shutil.copyfile(latest / name, folder / name)
    print(f"addb view: carried over the review of the earlier conversion ({record})", flush=True)


def b3d_dataset(folder: Path) -> Path:
    """A dataset tree for a folder of .b3d files: each file converted once into its cached
    subject folder (:func:`b3d_subject`), linked as ``<cache>/b3d-datasets/<folder>-<hash>/<stem>``;
    the tree's outputs go to its ``addb_out``.

    Raises
    ------
    SubjectFolderError
        The folder holds no .b3d file.
    B3dFormatError
        A file is damaged (names the file and byte offset).
    """
    import hashlib

    from addb_viewer.locations import cache_root
    from solver.errors import SubjectFolderError

    files = sorted(p for p in folder.glob("*.b3d") if p.is_file())
    if not files:
        raise SubjectFolderError("no .b3d file in this folder", path=folder)
    digest = hashlib.sha1(str(folder.resolve()).encode()).hexdigest()[:8]
    root = cache_root() / "b3d-datasets" / f"{folder.resolve().name}-{digest}"
    root.mkdir(parents=True, exist_ok=True)
    for f in files:
        subject = b3d_subject(f)
        link = root / f.stem
        if link.is_symlink() and link.resolve() != subject.resolve():
            link.unlink()
        if not link.exists():
            link.symlink_to(subject, target_is_directory=True)
    return root


def is_b3d_folder(path: Path) -> bool:
    """A folder holding .b3d files that is not itself a subject folder (no ``_subject.json``).

    A folder that also holds subject folders is a dataset folder, as ``addb process`` and
    ``addb info`` take it: :func:`run` asks :func:`addb_viewer.app.queue.is_dataset` first,
    and the workbench queues the subject folders and names the .b3d files it leaves out."""
    return path.is_dir() and not (path / "_subject.json").is_file() and any(p.is_file() for p in path.glob("*.b3d"))


def open_dataset(args: argparse.Namespace, dataset: Path) -> tuple[object, object]:
    """The review app on a dataset's queue (:mod:`addb_viewer.app.workbench`), showing the
    next trial to review (or the first subject)."""
    from addb_viewer.app.paths import ReviewPaths
    from addb_viewer.app.queue import build_queue, dataset_subjects, next_to_review
    from addb_viewer.app.server import ReviewApp
    from addb_viewer.app.workbench import Workbench

    _, out, subjects = dataset_subjects(dataset, args.out)
    rows = build_queue(subjects)
    first = next_to_review(rows) or rows[0]
    app = ReviewApp(
        ReviewPaths.for_subject(first.subject.subject_dir, first.subject.out_dir),
        reviewer=args.reviewer or default_reviewer(), host=args.host, port=args.port,
        geometry=args.geometry, process_missing=False,
    )  # fmt: skip
    bench = Workbench(app, dataset, args.out, workers=args.workers)
    if first.trial is not None and app.trial is not None and app.trial.trial != first.trial:
        app.set_trial_options(first.trial)
        app.load_trial(first.trial)
    bench.current = (first.subject.rel, app.trial.trial if app.trial is not None else None)
    bench.refresh()
    print(f"addb view: dataset {dataset} ({len(subjects)} subjects, output {out})", flush=True)
    return app, bench


def run(args: argparse.Namespace) -> int:
    """``addb view [SUBJECT_DIR|FILE.b3d|DATASET_DIR]``: serve the review app (a subject, a
    converted .b3d file, or a dataset's workbench) until Ctrl-C or SIGTERM.

    Returns
    -------
    The exit code: 0 after a clean stop, 1 when the subject folder does not exist.

    Raises
    ------
    SubjectFolderError
        The path is a file other than a .b3d file, or a folder without ``_subject.json``
        (:func:`solver.io.subject.check_subject_folder`: an output folder of addb, a folder
        inside a dataset output tree, or no subject folder at all), before the server starts.
    OutputFolderError
        ``--out`` of a subject is a folder its processing would refuse
        (:func:`solver.outputs.check_output_folder`: the subject folder or a folder above
        it, a file, a folder of other files), before the server starts.

    Other bad input raises too, as in every subcommand (:mod:`addb_viewer.commands`).
    """
    from addb_viewer.app.paths import ReviewPaths
    from addb_viewer.app.queue import is_dataset
    from addb_viewer.app.server import ReviewApp
    from solver.errors import SubjectFolderError
    from solver.io.subject import check_subject_folder
    from solver.outputs import check_output_folder

    subject = Path(args.subject) if args.subject else None
    dataset = subject is not None and is_dataset(subject)  # one search of the folder
    if subject is not None and not dataset and is_b3d_folder(subject):
        subject = b3d_dataset(subject)  # a folder of published subjects: reviewed as a dataset
        dataset = True
    if dataset:
        from addb_viewer.geometry import mesh_search_path

        mesh_search_path(None, None, args.geometry, bundled=False)  # a wrong --geometry fails here
        app, _ = open_dataset(args, subject)
        return _serve(app, args)
    if subject is not None and subject.suffix.lower() == ".b3d" and subject.is_file():
        subject = b3d_subject(subject)
    if subject is None:
        from addb_viewer.demo import DEMO_SUBJECT

        subject = DEMO_SUBJECT
    if subject.is_file():
        raise SubjectFolderError(
            "is a file; addb view expects a subject folder (with _subject.json), a dataset folder (subject "
            "folders, or a dataset output tree), a .b3d file or a folder of .b3d files",
            path=subject,
        )
    if not subject.is_dir():
        print(f"addb view: no such subject folder: {subject}", file=sys.stderr)
        return 1
    check_subject_folder(subject)  # refused here, on the terminal, not in a page that cannot load it
    paths = ReviewPaths.for_subject(subject, args.out)
    # processing and Reprocess write the output folder through this check: refused here, on
    # the terminal, rather than in the page once the server runs
    check_output_folder(paths.out_dir, (paths.subject_dir,))
    from addb_viewer.geometry import mesh_search_path

    mesh_search_path(None, None, args.geometry, bundled=False)  # a wrong --geometry fails here
    app = ReviewApp(
        paths,
        reviewer=args.reviewer or default_reviewer(),
        host=args.host,
        port=args.port,
        geometry=args.geometry,
    )
    print(f"addb view: {paths.subject_dir.name}  (output {paths.out_dir})", flush=True)
    return _serve(app, args)


def _serve(app: object, args: argparse.Namespace) -> int:
    """Print the address and serve until Ctrl-C or SIGTERM."""
    print(f"addb view: {app.paths.subject_dir.name} at {app.url}  (Ctrl-C to stop)", flush=True)
    if app.token:
        print(
            f"addb view: listening on {args.host}: requests need the access token in this address "
            "(share it only with the reviewers; requests without it are refused and logged)",
            flush=True,
        )
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    announced = False
    try:
        while not stop.wait(0.2):  # a signal stops the server at any time, even while processing
            if not announced and app.ready.is_set():
                announced = True
                if app.first_frame_seconds is not None:
                    print(f"addb view: first frame shown {app.first_frame_seconds:.2f} s after start", flush=True)
    except KeyboardInterrupt:
        pass
    finally:
        app.stop()
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``view`` subcommand's parser to ``sub`` (its ``handler``: :func:`run`)."""
    p = sub.add_parser("view", help="review a subject in the browser: replay, flag frames, reprocess")
    p.add_argument(
        "subject",
        nargs="?",
        help="AddBiomechanics subject folder or .b3d file, or a dataset: a folder of subject folders "
        "or a dataset output tree, reviewed through its queue, or a folder of .b3d files (no subject "
        "folder), each converted and queued (default: the bundled demo subject)",
    )
    p.add_argument("--port", type=int, default=8080, help="port to listen on (default 8080; the next free one if busy; 0: any)")
    p.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to bind (default 127.0.0.1, this machine only); any other, e.g. 0.0.0.0 for a "
        "team on a lab server, requires the access token printed in the address",
    )
    p.add_argument("--reviewer", help="your name, recorded with every flag (default: $ADDB_REVIEWER or your login)")
    p.add_argument("--out", help="processed output folder (default: <subject>/addb_out, or the user cache for the demo; "
                   "for a dataset its output tree, default <dataset>/addb_out)")
    p.add_argument(
        "--geometry",
        metavar="DIR",
        help="folder of bone meshes (.vtp) to use when the subject has no Geometry folder "
        "(default: $ADDB_GEOMETRY, then the meshes bundled with addb)",
    )
    p.add_argument(
        "--workers",
        type=whole_number(0),
        help="dataset: worker processes that process the subjects without output in the background "
        "(default: the cores less one; 0: none)",
    )
    p.set_defaults(handler=run, serves=True)  # runs until stopped: no run_to_completion (addb_viewer.cli)
