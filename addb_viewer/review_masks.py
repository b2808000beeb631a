"""The reviewer's unmeasured-force flags as the solver takes them: the one conversion from
a review record (or an AddBiomechanics ``review.json``) to ``unmeasured_force``.

``unmeasured_force`` is trial name -> ``(T,)`` bool at the trial's processed frames (those
of ``OUT/<trial>/trial.npz``; :mod:`solver.masks`). :func:`unmeasured_force` is the only
function that turns a review record into it; the review app's Reprocess and Diagnose
(:mod:`addb_viewer.app.reprocess`), ``addb process`` (one subject with ``--annotations``:
:func:`masks_from_file`; a dataset: :func:`subject_masks`) and ``addb diagnose`` all call it.

Which trials
    A trial enters when the reviewer has flagged at least one of its frames with
    ``unmeasured_force`` or marked it reviewed; its mask then replaces the solver's own
    proposals. Any other trial keeps the proposals (a trial opened but not looked at does
    not lose them). Trials without force plates have no dynamics and are left out.

Which frames
    The record stores flags on the frames of the trial it was made on, with their count
    and rate (``n_frames``, ``rate_hz``); the review app records the processed frames, so
    those flags are passed as they are (``addb convert`` of a ``.b3d`` records them there
    too, since 2026-11-24). A record at another rate (an older ``addb convert``'s, on the
    ``.b3d``'s own frames) is put on the processed frames by the one
    resampling rule, :func:`solver.masks.resample_mask`, both starting at the trial's first
    processed frame. A record at the processed rate with another frame count was made on
    another version of the trial and is refused (AnnotationError naming the trial and both
    counts). A ``review.json`` (one entry per marker frame) is resampled from the marker
    frames.

:func:`review_digest` enters each subject's manifest so that a changed review reprocesses
the subject in a dataset run; :func:`import_addb_review` reads a ``review.json`` into a
record.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from addb_viewer.locations import annotations_path
from solver.sampling import frame_interval

if TYPE_CHECKING:
    from annotations import AnnotationStore, Edit
    from solver.io.subject import Subject

BoolArray = NDArray[np.bool_]


def review_record(subject_dir: str, out_dir: str) -> Path | None:
    """The subject's review record file, or None when it has none."""
    path = annotations_path(subject_dir, out_dir)
    return path if path.is_file() else None


def _selected(store: AnnotationStore, name: str) -> bool:
    """Whether the reviewer's flags of ``name`` replace the solver's proposals."""
    return bool(store.ranges(name)) or store.is_reviewed(name)


def review_digest(subject_dir: str, out_dir: str) -> str | None:
    """SHA-256 of the subject's unmeasured-force flags (trial -> frame runs and feet, for
    the trials :func:`unmeasured_force` passes), or None when it has no record or none;
    what a dataset run's manifest keys on.

    Raises
    ------
    annotations.AnnotationError
        The record is damaged (names the file).
    """
    import hashlib
    import json

    from annotations import AnnotationStore

    path = review_record(subject_dir, out_dir)
    if path is None:
        return None
    with AnnotationStore.open(path, reviewer="addb process") as store:
        flags = {
            name: [[r.start, r.stop, r.foot] for r in store.review(name).unmeasured_force]
            for name in store.trials()
            if _selected(store, name)
        }
    return hashlib.sha256(json.dumps(flags, sort_keys=True).encode()).hexdigest() if flags else None


def processed_frames(subject: Subject, trial: str, rate_hz: float | None = None) -> NDArray[np.float64] | None:
    """``(T,)`` times, s, of the trial's processed frames as the dynamics stage will make
    them (saved extensions applied: a corrected force delay moves them), or None when the
    trial has no dynamics (no force plates, or dynamics disabled).

    Raises
    ------
    KeyError
        The subject has no trial ``trial``.
    solver.errors.AddbError
        A trial file cannot be read, or markers and forces do not overlap.
    """
    from solver.corrections import apply_extensions
    from solver.dynamics.stage import DynamicsOptions, trial_frames
    from solver.io.subject import load_trial

    if subject.disable_dynamics:
        return None
    raw = apply_extensions(subject, (load_trial(subject.trial(trial)),))[0]
    if raw.forces is None or not raw.forces.plates:
        return None
    rate = DynamicsOptions().rate_hz if rate_hz is None else float(rate_hz)
    return trial_frames(raw.markers, raw.forces, rate, trial)


def unmeasured_force(
    store: AnnotationStore,
    subject_dir: str | os.PathLike[str],
    trials: Iterable[str] | None = None,
    *,
    rate_hz: float | None = None,
) -> dict[str, BoolArray]:
    """The reviewer's unmeasured-force flags of a subject as the solver takes them.

    Parameters
    ----------
    store
        The subject's open review record.
    subject_dir
        The subject folder (its trials give the processed frames).
    trials
        Only these trials (default: every trial of the record).
    rate_hz
        The dynamics stage's rate (default: ``DynamicsOptions().rate_hz``, 100 Hz).

    Returns
    -------
    dict
        Trial name -> ``(T,)`` bool at the trial's processed frames, for the trials the
        module docstring says (flagged or marked reviewed, with force plates).

    Raises
    ------
    annotations.AnnotationError
        A flag lies beyond the frames the record has for its trial, or the record's frame
        count differs from the trial's processed frames at the same rate (naming the trial).
    solver.errors.AddbError
        A trial file of the subject cannot be read.
    """
    from annotations import AnnotationError
    from solver.io.subject import load_subject
    from solver.masks import resample_mask

    subject = load_subject(subject_dir)
    names = {t.name for t in subject.trials}
    wanted = store.trials() if trials is None else [t for t in trials if t in store.trials()]
    out: dict[str, BoolArray] = {}
    for name in wanted:
        if name not in names or not _selected(store, name):
            continue  # a trial the subject no longer has, or left to the proposals
        time = processed_frames(subject, name, rate_hz)
        if time is None:
            continue
        review = store.review(name)
        n, rate = review.n_frames, review.rate_hz
        step = frame_interval(time, default=1.0 / (rate or 100.0))
        if rate is None or abs(rate * step - 1.0) < 1e-6:  # the processed rate
            if n is not None and n != time.size:
                raise AnnotationError(
                    f"the review record has {n} frames for this trial but it has {time.size} processed frames "
                    f"now ({1 / step:g} Hz, {time[0]:.3f}-{time[-1]:.3f} s): the flags were made on another "
                    "version of the trial; review it again",
                    where=name,
                )
            out[name] = store.mask(name, time.size)
            continue
        mask = store.mask(name, n)
        out[name] = resample_mask(mask, time[0] + np.arange(mask.size) / rate, time)
    return out


def subject_masks(subject_dir: str, out_dir: str) -> dict[str, BoolArray] | None:
    """:func:`unmeasured_force` of the subject's review record (where ``addb view`` keeps
    it, :func:`addb_viewer.locations.annotations_path`): trial name -> ``(T,)`` flags at the
    trial's processed frames, or None when it has no record or no trial enters; the dataset
    runner's mask loader (``addb process DATASET_DIR``). Review work on trials the subject no
    longer has is named in a warning.

    Raises
    ------
    annotations.AnnotationError
        As :func:`unmeasured_force`; also a damaged record (names the file).
    """
    from annotations import AnnotationStore

    path = review_record(subject_dir, out_dir)
    if path is None:
        return None
    with AnnotationStore.open(path, reviewer="addb process") as store:
        _warn_orphaned_review(store, path, subject_dir)
        return unmeasured_force(store, subject_dir) or None


def _trials_lacking(named: list[str], subject_dir: str | os.PathLike[str]) -> tuple[list[str], list[str]]:
    """The subject's trial names (sorted), and those of the record's trials ``named`` that
    the subject does not have (in their order)."""
    from solver.io.subject import load_subject

    have = sorted(t.name for t in load_subject(subject_dir).trials)
    return have, [t for t in named if t not in have]


def _warn_orphaned_review(store: AnnotationStore, path: Path, subject_dir: str) -> None:
    """Warn (UserWarning) naming the trials of the subject's own record ``store`` (at ``path``)
    that hold review work (flags, a reviewed mark or notes) and that the subject no longer
    has (a trial folder renamed or removed since): their flags are not used."""
    import warnings

    _, lacking = _trials_lacking(store.trials(), subject_dir)
    orphans = [t for t in lacking if _selected(store, t) or store.notes(t)]
    if orphans:
        many = len(orphans) > 1
        warnings.warn(f"{path.name} holds review work on {'trials' if many else 'a trial'} this subject no longer has "
                      f"({', '.join(orphans)}): {'their' if many else 'its'} flags are not used", stacklevel=3)  # fmt: skip


def is_addb_review(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is an AddBiomechanics ``review.json`` (a JSON object with
    ``missing_grf_data``) rather than a review record."""
    import json

    from solver.io.review import KEY

    p = Path(path)
    if not p.is_file():
        return False
    try:
        data = json.loads(p.read_bytes())
    except (ValueError, OSError):
        return False
    return isinstance(data, dict) and KEY in data


def masks_from_file(
    path: str | os.PathLike[str], subject_dir: str | os.PathLike[str], *, reviewer: str, trials: tuple[str, ...] | None = None,
    given: bool = True,
) -> dict[str, BoolArray]:
    """``unmeasured_force`` from an ``--annotations`` file: a review record
    (:func:`unmeasured_force`) or an AddBiomechanics ``review.json`` of one trial (one entry
    per marker frame, resampled onto the processed frames): the subject's only trial, or
    the one trial of ``trials`` (``--trial``). Trial name -> ``(T,)`` flags at the trial's
    processed frames.

    A record the user ``given`` (``--annotations``, not the subject's own) must name one of
    the subject's trials when it names any: another subject's record is refused, and the
    trials of the record the subject lacks are named in a warning (their flags are not used).

    Raises
    ------
    solver.errors.SubjectFolderError
        A ``review.json`` given for a subject with more than one trial and not one trial
        in ``trials`` (or a trial the subject lacks); a ``given`` record that names trials,
        none of them the subject's (naming both lists).
    solver.errors.FileFormatError
        A damaged ``review.json``, or one with fewer entries than the trial's marker frames.
    annotations.AnnotationError
        A damaged record, or flags that do not fit the trial (:func:`unmeasured_force`).
    """
    from annotations import AnnotationStore

    if is_addb_review(path):
        from solver.errors import SubjectFolderError
        from solver.io.review import read_review
        from solver.io.subject import load_subject, load_trial
        from solver.masks import resample_mask

        subject = load_subject(subject_dir)
        if trials is not None and len(trials) == 1:
            files = subject.trial(trials[0])  # SubjectFolderError naming the subject's trials
        elif len(subject.trials) == 1:
            files = subject.trials[0]
        else:
            raise SubjectFolderError(
                "an AddBiomechanics review.json covers one trial; this subject has "
                f"{len(subject.trials)} ({', '.join(t.name for t in subject.trials)}): name it with --trial",
                path=Path(path),
            )
        name = files.name
        time = processed_frames(subject, name)
        if time is None:
            return {}
        markers = load_trial(files).markers
        mask = read_review(path, n_frames=markers.n_frames)
        return {name: resample_mask(mask, np.asarray(markers.time), time)}
    with AnnotationStore.open(path, reviewer=reviewer) as store:
        if given:
            _check_record_trials(store.trials(), Path(path), Path(subject_dir))
        return unmeasured_force(store, subject_dir)


def _check_record_trials(named: list[str], path: Path, subject_dir: Path) -> None:
    """Refuse the review record ``path`` given for ``subject_dir`` when it names trials and
    none of the subject's (another subject's record); warn naming those the subject lacks."""
    import warnings

    from solver.errors import SubjectFolderError

    have, unknown = _trials_lacking(named, subject_dir)
    if not unknown:
        return
    if len(unknown) == len(named):
        listed = f"the trial{'s' if len(named) > 1 else ''} {', '.join(named)}"
        raise SubjectFolderError(
            f"names {listed} and none of this subject's ({', '.join(have)}): it is the review record of another "
            f"subject, or of this one before its trials were renamed; give the subject's own record",
            path=path,
        )
    warnings.warn(f"{path.name} names trials that {subject_dir.name} does not have ({', '.join(unknown)}); their "
                  "flags are not used", stacklevel=2)  # fmt: skip


def import_addb_review(
    store: AnnotationStore,
    trial: str,
    path: str | os.PathLike[str],
    *,
    start_frame: int = 0,
    n_frames: int | None = None,
    source: str = "imported",
) -> Edit:
    """Set a trial's ``unmeasured_force`` flags on one segment from a ``review.json``.

    Frames ``[start_frame, start_frame + T)`` of the record become exactly the file's
    flags, in one edit (one undo step): frames marked ``true`` are flagged (frames already
    flagged keep their foot and author), frames marked ``false`` are cleared. The file is
    read by the one reader, :func:`solver.io.review.read_review`; the record's frames are
    taken as the file's (no resampling).

    Parameters
    ----------
    store
        Open store.
    trial
        Trial name.
    path
        The AddBiomechanics review file of the segment.
    start_frame
        Trial frame of the segment's first frame.
    n_frames
        Segment length, if known (extra trailing entries dropped with a warning, fewer is
        an error).
    source
        Provenance source of the new flags.

    Returns
    -------
    annotations.Edit
        The durable edit.

    Raises
    ------
    solver.errors.FileFormatError
        A damaged file (naming it).
    """
    from annotations import UNMEASURED_FORCE
    from solver.io.review import read_review

    mask = read_review(path, n_frames=n_frames)
    return store.set_mask(trial, mask, kind=UNMEASURED_FORCE, start_frame=start_frame, source=source)
