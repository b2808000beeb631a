"""Export of the review record to AddBiomechanics review files.

AddBiomechanics splits each trial into segments and stores the reviewer's decisions for
a segment in ``<trial>/segment_<k>/review.json``: a single JSON object
``{"missing_grf_data":[true,false,...]}`` with one boolean per frame of the segment,
``true`` where the ground reaction force is missing (the frame is left out of the
dynamic fit). The file is written compactly (no spaces, no trailing newline). Frame ``i``
of the file is trial frame ``start_frame + i``.

These flags map to ``unmeasured_force`` without a foot. This module writes them
(:func:`export_addb_review`, :func:`write_addb_review`: the project's one writer of the
format); the one reader is :func:`solver.io.review.read_review`, and the app imports a
file into a record with :func:`addb_viewer.review_masks.import_addb_review` (this package
imports nothing of the solver). An import followed by an export with the same
``start_frame`` and ``n_frames`` reproduces the file byte for byte.
"""

from __future__ import annotations

import os
import uuid
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from annotations.errors import AnnotationError
from annotations.journal import atomic_write
from annotations.model import EXCLUDED, UNMEASURED_FORCE

if TYPE_CHECKING:
    from annotations.store import AnnotationStore

KEY = "missing_grf_data"


def encode_addb_review(mask: NDArray[np.bool_]) -> bytes:
    """The bytes AddBiomechanics writes for a segment's mask (compact, no newline).

    Raises
    ------
    AnnotationError
        If ``mask`` is not a ``(T,)`` bool array.
    """
    arr = np.asarray(mask)
    if arr.ndim != 1 or (arr.size and arr.dtype != np.bool_):
        raise AnnotationError(f"mask must be a (T,) bool array, got {arr.dtype} {arr.shape}")
    body = ",".join("true" if v else "false" for v in arr.tolist())
    return f'{{"{KEY}":[{body}]}}'.encode("ascii")


def write_addb_review(path: str | os.PathLike[str], mask: NDArray[np.bool_]) -> None:
    """Write a segment's ``(T,)`` bool mask as an AddBiomechanics ``review.json``, atomically."""
    atomic_write(Path(path), encode_addb_review(mask), tmp_tag=uuid.uuid4().hex[:8])


def export_addb_review(
    store: AnnotationStore,
    trial: str,
    path: str | os.PathLike[str],
    *,
    start_frame: int = 0,
    n_frames: int,
    include_excluded: bool = False,
) -> NDArray[np.bool_]:
    """Write frames ``[start_frame, start_frame + n_frames)`` of a trial as a ``review.json``.

    Parameters
    ----------
    store
        Open store.
    trial
        Trial name.
    path
        Output file (written atomically, AddBiomechanics' exact formatting).
    start_frame
        Trial frame of the segment's first frame.
    n_frames
        Segment length.
    include_excluded
        Also mark frames flagged ``excluded`` as missing ground force (AddBiomechanics has
        no other way to leave a frame out of the dynamic fit).

    Returns
    -------
    numpy.ndarray
        The ``(n_frames,)`` bool mask written.

    Raises
    ------
    AnnotationError
        If ``start_frame`` or ``n_frames`` is negative or a bool.
    AnnotationFileError
        If the folder is not writable or the disk is full; ``path`` is then unchanged.
    """
    if (
        isinstance(start_frame, bool)
        or start_frame < 0
        or isinstance(n_frames, bool)
        or n_frames < 0
    ):
        raise AnnotationError(
            f"start_frame and n_frames must be >= 0, got {start_frame}, {n_frames}"
        )
    stop = start_frame + n_frames
    mask = np.zeros(n_frames, dtype=bool)
    kinds = (UNMEASURED_FORCE, EXCLUDED) if include_excluded else (UNMEASURED_FORCE,)
    for kind in kinds:
        for s, e in store.ranges(trial, kind):
            lo, hi = max(s, start_frame), min(e, stop)
            if lo < hi:
                mask[lo - start_frame : hi - start_frame] = True
    write_addb_review(path, mask)
    return mask
