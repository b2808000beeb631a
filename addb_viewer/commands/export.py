"""``addb export SUBJECT_DIR --trial NAME --format mcap -o FILE.mcap``, and
``addb export DIR --format b3d -o FILE.b3d`` (a whole processed subject as an
AddBiomechanics binary file; on a dataset output tree, one file per subject)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any


def _manual_masks(record: Path | None, out_dir: Path) -> dict[str, Any] | None:
    """Trial -> (T,) bool: frames a reviewer flagged (review record flags not imported)."""
    if record is None or not record.is_file():
        return None
    import numpy as np

    from annotations import AnnotationStore
    from solver.results import load_processed, processed_trials

    masks = {}
    with AnnotationStore.open(record, reviewer="addb export") as store:
        known = set(store.trials())
        for name in processed_trials(out_dir):
            if name not in known:
                continue
            n = load_processed(out_dir, name).n_frames
            mask = np.zeros(n, dtype=bool)
            for run in store.flag_runs(name):
                if run.provenance.source != "imported":
                    mask[run.start:min(run.stop, n)] = True
            masks[name] = mask
    return masks


def _subject_info(subject_dir: Path | None) -> dict[str, Any]:
    if subject_dir is None or not (subject_dir / "_subject.json").is_file():
        return {}
    from solver.io.subject import load_subject

    s = load_subject(subject_dir)
    info: dict[str, Any] = {"sex": s.sex, "foot_bodies": list(s.foot_body_names), "tags": list(s.raw.get("subjectTags", []))}
    age = s.raw.get("ageYears")
    if isinstance(age, (int, float)) and age > 0:
        info["age_years"] = int(age)
    return info



def _recorded_path(out_dir: Path, summary: dict[str, Any], key: str) -> Path | None:
    """``summary[key]`` as a path (relative ones from ``out_dir``); None when null.

    Raises
    ------
    FileFormatError
        The value is neither a non-empty string nor null (names ``subject.json`` and the key).
    """
    value = summary[key]
    if value is None:
        return None
    if not isinstance(value, str) or not value:
        from solver.errors import FileFormatError
        from solver.outputs import SUBJECT_RECORD

        raise FileFormatError(f"{key}={value!r}: expected a path, or null", path=out_dir / SUBJECT_RECORD, where=key)
    return out_dir / value  # an absolute value stays as it is


def recorded_inputs(out_dir: str | Path) -> tuple[Path | None, Path | None]:
    """The subject folder and review record of a processed output folder given on its own.

    The subject folder ``out_dir/subject.json`` records (:data:`solver.outputs.SUBJECT_DIR_KEY`,
    written by every run since 2026-12-02), else ``<subject>`` for a folder named
    ``<subject>/addb_out``. The review record: ``<out_dir>.annotations.json`` beside the
    folder (a review of this very output, :command:`addb view OUT`), else the one
    subject.json records (:data:`solver.outputs.REVIEW_RECORD_KEY`: the flags the run took;
    null: it took none), else, when it records none, the subject's where ``addb view`` and
    ``addb convert`` keep it (:func:`addb_viewer.locations.annotations_path`, then
    ``<subject>/annotations.json``). A subject folder is taken only when it holds
    ``_subject.json``, and a review record only when it is a file; a recorded one that is
    gone is named on stderr and left out.

    Returns
    -------
    (subject folder or None, review record or None)

    Raises
    ------
    FileFormatError
        ``subject.json`` is not a JSON object, or records a path that is not a string
        (names the file).
    """
    import json

    from addb_viewer.locations import ANNOTATIONS_NAME, OUTPUT_NAME, annotations_path
    from solver.outputs import REVIEW_RECORD_KEY, SUBJECT_DIR_KEY, SUBJECT_RECORD

    out = Path(out_dir)
    summary: dict[str, Any] = {}
    record_file = out / SUBJECT_RECORD
    if record_file.is_file():
        try:
            summary = json.loads(record_file.read_text(encoding="utf-8"))
        except (ValueError, UnicodeDecodeError) as exc:
            from solver.errors import FileFormatError

            raise FileFormatError(f"is not readable JSON ({exc})", path=record_file) from None
        if not isinstance(summary, dict):
            from solver.errors import FileFormatError

            raise FileFormatError(f"holds a JSON {type(summary).__name__}, expected an object", path=record_file)

    def kept(path: Path | None, what: str, ok: bool) -> Path | None:
        if path is not None and not ok:
            print(f"addb export: {record_file}: the {what} it records, {path}, is gone; exported without it", file=sys.stderr)
            return None
        return path

    subject_dir = None
    if SUBJECT_DIR_KEY in summary:
        subject_dir = _recorded_path(out, summary, SUBJECT_DIR_KEY)
        subject_dir = kept(subject_dir, "subject folder", subject_dir is not None and (subject_dir / "_subject.json").is_file())
    elif out.name == OUTPUT_NAME and (out.parent / "_subject.json").is_file():
        subject_dir = out.parent
    beside = out.parent / f"{out.name}.annotations.json"  # the record kept for this very folder
    if beside.is_file():
        return subject_dir, beside
    if REVIEW_RECORD_KEY in summary:
        record = _recorded_path(out, summary, REVIEW_RECORD_KEY)
        return subject_dir, kept(record, "review record", record is not None and record.is_file())
    guesses = []
    if subject_dir is not None:
        guesses += [annotations_path(subject_dir, out), subject_dir / ANNOTATIONS_NAME]
    return subject_dir, next((g for g in guesses if g.is_file()), None)


def export_b3d(args: argparse.Namespace) -> int:
    """``--format b3d``: a processed output folder, a subject folder, or a dataset output tree.

    Raises
    ------
    OutputFolderError
        For one subject, ``args.output`` is a folder instead of the name of the .b3d file to
        write.
    """
    from solver.dataset.discover import tree_subjects
    from solver.errors import counted
    from solver.io.b3d_convert import processed_to_b3d
    from solver.outputs import SUBJECT_RECORD
    from solver.results import processed_trials

    src = Path(args.subject)
    output = Path(args.output)
    found = tree_subjects(src)
    if found is not None:  # a dataset output tree, or a folder of one: a .b3d file per processed subject
        processed = found.require_processed(src, lambda line: print(f"addb export: {src}: {line}", file=sys.stderr))
        for rel in processed:
            out_dir = found.tree / rel
            target = output / Path(found.below_folder(rel)).parent / f"{out_dir.name}.b3d"  # the given folder's layout
            target.parent.mkdir(parents=True, exist_ok=True)
            subject_dir, record = recorded_inputs(out_dir)
            processed_to_b3d(out_dir, target, manual=_manual_masks(record, out_dir), subject_info=_subject_info(subject_dir))
            print(f"wrote {target} ({target.stat().st_size / 1e6:.1f} MB)")
        print(f"{counted(len(processed), 'subject')} written under {output}")
        return 0
    if output.is_dir():
        from solver.errors import OutputFolderError

        raise OutputFolderError(f"is a folder; expected the name of the .b3d file to write (e.g. {output / (src.name + '.b3d')})", path=output)
    if (src / SUBJECT_RECORD).is_file() and processed_trials(src):
        out_dir = src
        subject_dir, record = recorded_inputs(out_dir)
    else:
        from addb_viewer.locations import annotations_path
        from addb_viewer.progress import ProgressBar
        from addb_viewer.recording.jobs import ensure_processed

        out_dir = ensure_processed(src, args.out, progress=ProgressBar())
        subject_dir, record = src, annotations_path(src, out_dir)
    output.parent.mkdir(parents=True, exist_ok=True)
    processed_to_b3d(out_dir, output, manual=_manual_masks(record, out_dir), subject_info=_subject_info(subject_dir))
    print(f"wrote {output} (b3d, {output.stat().st_size / 1e6:.1f} MB)")
    return 0


def _format_without_suffix(src: Path) -> str:
    """The format of an output name without suffix: b3d for a dataset output tree or a folder
    of one (the only format it exports to), else mcap."""
    from solver.dataset.discover import tree_subjects

    return "b3d" if tree_subjects(src) is not None else "mcap"


def run(args: argparse.Namespace) -> int:
    """``addb export ... --format mcap|b3d``: a trial as MCAP, or a processed subject (one file per
    subject of a dataset output tree) as .b3d.

    Returns
    -------
    The exit code: 0 when every file was written.

    Bad input raises, as in every subcommand (:mod:`addb_viewer.commands`); an output name
    whose suffix is not .mcap, .rrd or .b3d (no suffix: MCAP, or .b3d files for a dataset output tree), or that disagrees with
    ``--format``, is refused before anything is processed.
    """
    from addb_viewer.recording.jobs import FORMATS

    by_suffix = {".b3d": "b3d", **{s: name for name, s in FORMATS.items()}}
    suffix = Path(args.output).suffix.lower()
    fmt = args.format
    if fmt is None:
        if suffix and suffix not in by_suffix:  # it wrote MCAP under that name
            raise SystemExit(
                f"addb export: cannot tell the format from -o {args.output} (a {suffix} file); "
                f"name it {', '.join(by_suffix)} or give --format"
            )
        fmt = by_suffix.get(suffix) or _format_without_suffix(Path(args.subject))
    elif by_suffix.get(suffix, fmt) != fmt:  # it wrote the --format under the other format's suffix
        raise SystemExit(f"addb export: --format {fmt}, but -o {args.output} names a {by_suffix[suffix]} file; give one that agrees")
    if fmt == "b3d":
        return export_b3d(args)
    if not args.trial:
        raise SystemExit(f"addb export: --trial is required for --format {fmt}")
    from addb_viewer.commands.record import refuse_output_folder
    from addb_viewer.progress import ProgressBar
    from addb_viewer.recording.jobs import record_subject_trial

    # the output folder itself is taken by --format b3d only
    given_format = ["--format", fmt] if args.format else []
    refuse_output_folder(args.subject, args.out, ["export", "SUBJECT_DIR", "--trial", args.trial, *given_format, "-o", args.output])
    path = record_subject_trial(
        args.subject, args.trial, args.output, fmt=fmt, out_dir=args.out, progress=ProgressBar(),
        geometry=args.geometry,
    )
    print(f"wrote {path} ({fmt}, {path.stat().st_size / 1e6:.1f} MB)")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``export`` subcommand's parser to ``sub`` (its ``handler``: :func:`run`)."""
    p = sub.add_parser(
        "export",
        help="export a processed trial (MCAP, Rerun) or a processed subject (.b3d) for other tools",
        description=(
            "Write one trial as MCAP (JSON channels: markers, plate wrenches, body poses as "
            "foxglove.FrameTransforms, residuals, joint torques, flags and annotations; zstd "
            "chunks with summary and index) or as a Rerun .rrd; or, with --format b3d, a whole "
            "processed subject as an AddBiomechanics .b3d file (sensor data, a kinematics and a "
            "dynamics pass, missing-GRF reasons from addb's flags, the scaled model). DIR is a "
            "subject folder (processed first if it has no output yet), a processed output folder, "
            "or for b3d a dataset output tree (dataset_summary.json): then -o is a folder and each "
            "subject output folder REL/NAME becomes OUT/REL/NAME.b3d."
        ),
    )
    p.add_argument(
        "subject",
        help="subject folder (mcap, rrd, b3d); for b3d also a processed output folder or a dataset output tree",
    )
    p.add_argument("--trial", help="trial name (mcap, rrd)")
    p.add_argument(
        "--format",
        choices=("mcap", "rrd", "b3d"),
        help="file format (default: from the output suffix .mcap, .rrd or .b3d; when it has none, b3d for a dataset "
        "output tree and mcap otherwise)",
    )
    p.add_argument("-o", "--output", required=True, help="the file to write (a folder for a dataset tree)")
    p.add_argument(
        "--out",
        help="processed output folder (default: <subject>/addb_out, or the user cache for read-only subjects)",
    )
    p.add_argument(
        "--geometry",
        metavar="DIR",
        help="folder of bone meshes (.vtp) for mcap/rrd when the subject has no Geometry folder "
        "(default: $ADDB_GEOMETRY, then the meshes bundled with addb)",
    )
    p.set_defaults(handler=run)
