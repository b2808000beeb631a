"""Exchange with AddBiomechanics review files.

AddBiomechanics splits each trial into segments and stores the reviewer's decisions for
a segment in ``<trial>/segment_<k>/review.json``: a single JSON object
``{"missing_grf_data":[true,false,...]}`` with one boolean per frame of the segment,
``true`` where the ground reaction force is missing (the frame is left out of the
dynamic fit). The file is written compactly (no spaces, no trailing newline), and the
reader here is strict where AddBiomechanics only asserts: every entry must be a JSON
boolean. Frame ``i`` of the file is trial frame ``start_frame + i``.

These flags map to ``unmeasured_force`` without a foot. ``import_addb_review`` followed
by ``export_addb_review`` with the same ``start_frame`` and ``n_frames`` reproduces the
file byte for byte.
"""

from __future__ import annotations

import json
import os
import uuid
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from annotations.errors import AnnotationError, AnnotationFileError
from annotations.journal import atomic_write
from annotations.model import EXCLUDED, UNMEASURED_FORCE, Edit

if TYPE_CHECKING:
    from annotations.store import AnnotationStore

KEY = "missing_grf_data"


def read_addb_review(
    path: str | os.PathLike[str], *, n_frames: int | None = None
) -> NDArray[np.bool_]:
    """Read an AddBiomechanics ``review.json``.

    Parameters
    ----------
    path
        The review file.
    n_frames
        Expected number of frames of the segment. Extra trailing entries (written by an
        old AddBiomechanics UI) are dropped with a warning; fewer entries is an error.

    Returns
    -------
    numpy.ndarray
        ``(T,)`` bool, ``True`` where the ground reaction force is missing.

    Raises
    ------
    AnnotationFileError
        Naming the file: not JSON, not an object, no ``missing_grf_data`` list, an entry
        that is not ``true``/``false``, or fewer entries than ``n_frames``.
    """
    p = Path(path)
    try:
        obj = json.loads(p.read_bytes())
    except OSError as exc:
        raise AnnotationFileError(f"cannot read the review file: {exc.strerror}", path=p) from exc
    except ValueError as exc:
        raise AnnotationFileError(f"not a JSON review file ({exc})", path=p) from None
    if type(obj) is not dict:
        raise AnnotationFileError(f"expected a JSON object, got {type(obj).__name__}", path=p)
    if KEY not in obj:
        raise AnnotationFileError(f'no "{KEY}" list in the review file', path=p)
    flags = obj[KEY]
    if type(flags) is not list:
        raise AnnotationFileError(
            f'"{KEY}" must be a list, got {type(flags).__name__}', path=p, where=KEY
        )
    for i, value in enumerate(flags):
        if type(value) is not bool:
            raise AnnotationFileError(
                f"entry {i} is {value!r}; expected true or false", path=p, where=f"{KEY}[{i}]"
            )
    others = sorted(set(obj) - {KEY})
    if others:
        warnings.warn(f"{p}: fields {others} are not kept (only {KEY} is)", stacklevel=2)
    if n_frames is not None:
        if len(flags) < n_frames:
            raise AnnotationFileError(
                f"{len(flags)} entries for a segment of {n_frames} frames", path=p, where=KEY
            )
        if len(flags) > n_frames:
            warnings.warn(
                f"{p}: {len(flags) - n_frames} extra trailing entries dropped", stacklevel=2
            )
            flags = flags[:n_frames]
    return np.array(flags, dtype=bool)


def encode_addb_review(mask: NDArray[np.bool_]) -> bytes:
    """The bytes AddBiomechanics writes for a segment's mask (compact, no newline)."""
    arr = np.asarray(mask)
    if arr.ndim != 1 or (arr.size and arr.dtype != np.bool_):
        raise AnnotationError(f"mask must be a (T,) bool array, got {arr.dtype} {arr.shape}")
    body = ",".join("true" if v else "false" for v in arr.tolist())
    return f'{{"{KEY}":[{body}]}}'.encode("ascii")


def write_addb_review(path: str | os.PathLike[str], mask: NDArray[np.bool_]) -> None:
    """Write a segment's ``(T,)`` bool mask as an AddBiomechanics ``review.json``, atomically."""
    atomic_write(Path(path), encode_addb_review(mask), tmp_tag=uuid.uuid4().hex[:8])


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

    Frames ``[start_frame, start_frame + T)`` become exactly the file's flags, in one
    edit (one undo step): frames marked ``true`` are flagged (frames already flagged keep
    their foot and author), frames marked ``false`` are cleared.

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
        Segment length, if known (see :func:`read_addb_review`).
    source
        Provenance source of the new flags.

    Returns
    -------
    Edit
        The durable edit.
    """
    mask = read_addb_review(path, n_frames=n_frames)
    return store.set_mask(
        trial, mask, kind=UNMEASURED_FORCE, start_frame=start_frame, source=source
    )


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
