"""From a subject folder to a recording file: used by ``addb record``, ``addb export``
and the review app's "Record" button.

The subject is processed into its default output folder (:mod:`addb_viewer.locations`)
when it has not been processed yet; the review state comes from the subject's review
record when there is one.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from addb_viewer.locations import annotations_path, default_output_dir
from solver.errors import SubjectFolderError
from solver.results import ProcessedTrial, load_processed, processed_trials

Progress = Callable[[str, float], None]

#: Recording formats: name -> file suffix.
FORMATS = {"mcap": ".mcap", "rrd": ".rrd"}


def ensure_processed(
    subject_dir: str | os.PathLike[str],
    out_dir: str | os.PathLike[str] | None = None,
    *,
    progress: Progress | None = None,
    trial: str | None = None,
) -> Path:
    """The output folder of a subject, processing the subject first if it holds no
    processed trial.

    Parameters
    ----------
    subject_dir
        AddBiomechanics subject folder.
    out_dir
        Output folder; default :func:`addb_viewer.locations.default_output_dir`.
    progress
        Called with (message, fraction) while processing.
    trial
        The trial the caller needs: when the subject must be processed first and has no
        trial of that name, SubjectFolderError is raised before processing.

    Returns
    -------
    Path
        The output folder.

    Raises
    ------
    SubjectFolderError
        The subject must be processed and ``subject_dir`` is not a folder, or has no trial
        ``trial``.
    """
    from solver.io.subject import load_subject
    from solver.pipeline import process_subject

    out = Path(out_dir) if out_dir is not None else default_output_dir(subject_dir)
    if not processed_trials(out):
        if not Path(subject_dir).is_dir():
            raise SubjectFolderError("not a folder", path=subject_dir)
        if trial is not None:  # a typo costs no processing
            load_subject(subject_dir).trial(trial)  # SubjectFolderError naming the trials
        process_subject(subject_dir, out, progress=progress)
    return out


def review_state_of(
    subject_dir: str | os.PathLike[str], out_dir: str | os.PathLike[str], trial: str
) -> dict[str, Any] | None:
    """The review state of ``trial`` from the subject's review record, or None when the
    subject has no review record yet (nothing is created)."""
    from addb_viewer.recording.metadata import review_state
    from annotations import AnnotationStore

    path = annotations_path(subject_dir, out_dir)
    if not path.exists():
        return None
    with AnnotationStore.open(path, reviewer="addb-recorder") as store:
        return review_state(store.review(trial))


def load_trial(out_dir: str | os.PathLike[str], trial: str) -> ProcessedTrial:
    """The processed trial ``trial`` of ``out_dir``.

    Raises
    ------
    SubjectFolderError
        No such processed trial (the message lists those there are).
    """
    available = processed_trials(out_dir)
    if trial not in available:
        raise SubjectFolderError(
            f"no processed trial {trial!r}; processed trials: {', '.join(available) or 'none'}",
            path=out_dir,
        )
    return load_processed(out_dir, trial)


def write_recording(
    trial: ProcessedTrial,
    output: str | os.PathLike[str],
    fmt: str,
    *,
    annotations: dict[str, Any] | None = None,
    mesh_path: Sequence[str | os.PathLike[str]] | None = None,
) -> Path:
    """Write ``trial`` as ``fmt`` (``"rrd"`` or ``"mcap"``) to ``output``.

    Bone meshes are looked up along ``mesh_path`` (default: the trial's own search path,
    see :func:`addb_viewer.geometry.trial_search_path`).

    Raises
    ------
    ValueError
        ``fmt`` is neither ``"rrd"`` nor ``"mcap"``.
    """
    if fmt == "rrd":
        from addb_viewer.recording.rerun_writer import write_rerun

        return write_rerun(trial, output, annotations=annotations, mesh_path=mesh_path)
    if fmt == "mcap":
        from addb_viewer.recording.mcap_writer import write_mcap

        return write_mcap(trial, output, annotations=annotations, mesh_path=mesh_path)
    raise ValueError(f"unknown recording format {fmt!r}; expected one of {', '.join(FORMATS)}")


def record_subject_trial(
    subject_dir: str | os.PathLike[str],
    trial: str,
    output: str | os.PathLike[str],
    *,
    fmt: str = "rrd",
    out_dir: str | os.PathLike[str] | None = None,
    progress: Progress | None = None,
    geometry: str | os.PathLike[str] | None = None,
) -> Path:
    """Process the subject if needed and write one trial's recording with its review state.

    Parameters
    ----------
    subject_dir
        AddBiomechanics subject folder.
    trial
        Trial name.
    output
        Recording file to write.
    fmt
        ``"rrd"`` (Rerun) or ``"mcap"``.
    out_dir
        Output folder of the subject (default location if None).
    progress
        Progress callback while processing.
    geometry
        Extra folder of bone meshes (``--geometry``); None: ``$ADDB_GEOMETRY`` if set.
        Meshes are looked up in the subject's ``Geometry``, the model's folders, this
        folder, then the bundled set (:func:`addb_viewer.geometry.mesh_search_path`).

    Returns
    -------
    Path
        ``output``.

    Raises
    ------
    GeometryPathError
        ``geometry`` is not a folder (checked before any processing).
    SubjectFolderError
        The subject has no trial ``trial`` (checked before any processing), or it was not
        processed.
    OutputFolderError
        ``output`` is a folder (checked before any processing).
    """
    from addb_viewer.geometry import mesh_search_path, trial_search_path
    from solver.errors import OutputFolderError

    if Path(output).is_dir():
        raise OutputFolderError(f"is a folder; expected the name of the file to write (e.g. {Path(output) / (trial + '.' + fmt)})", path=output)
    mesh_search_path(None, None, geometry, bundled=False)  # a wrong --geometry fails first
    out = ensure_processed(subject_dir, out_dir, progress=progress, trial=trial)
    processed = load_trial(out, trial)
    return write_recording(
        processed,
        output,
        fmt,
        annotations=review_state_of(subject_dir, out, trial),
        mesh_path=trial_search_path(processed, subject_dir, geometry),
    )
