"""AddBiomechanics review files: which frames have unmeasured ground reaction force.

Format (``review.json``, ``<trial>/segment_<k>/review.json`` or
``addb_review_segment_<k>.json``), compact JSON without a trailing newline, one boolean per
marker frame of the trial or segment, ``true`` where the ground reaction force is missing
(the frame is left out of the dynamic fit)::

    {"missing_grf_data":[true,true,false,...]}

:func:`read_review` is the project's one reader of these files (``addb info``, ``addb
process --annotations review.json``, :func:`addb_viewer.review_masks.import_addb_review`);
the writer is :func:`annotations.addb.write_addb_review` (AddBiomechanics' formatting
byte for byte), since the review record exports them. Marker frames are put on a trial's
processed frames by :func:`solver.masks.resample_mask`.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from solver.errors import FileFormatError

KEY = "missing_grf_data"


def read_review(path: str | Path, *, n_frames: int | None = None) -> NDArray[np.bool_]:
    """``(T,)`` bool: True where the frame's ground reaction force was not measured.

    Parameters
    ----------
    path
        The review file.
    n_frames
        Expected number of marker frames of the trial or segment. Extra trailing entries
        (written by an old AddBiomechanics UI) are dropped with a warning; fewer entries
        is an error. None: as many as the file has.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist.
    FileFormatError
        Not UTF-8 or not JSON (with its line), not an object, no ``missing_grf_data`` key,
        a value that is not a list of booleans (naming the first bad index), or fewer
        entries than ``n_frames``.
    """
    path = Path(path)
    try:
        raw = json.loads(path.read_bytes().decode("utf-8"))
    except UnicodeDecodeError:
        raise FileFormatError("not UTF-8 text", path=path) from None
    except json.JSONDecodeError as exc:
        raise FileFormatError(f"not valid JSON: {exc.msg}", path=path, line=exc.lineno) from None
    if not isinstance(raw, dict) or KEY not in raw:
        raise FileFormatError(f"expected a JSON object with the key {KEY!r}", path=path, where=KEY)
    values = raw[KEY]
    if not isinstance(values, list):
        raise FileFormatError(
            f"{KEY} must be a list of true/false, found {type(values).__name__}",
            path=path,
            where=KEY,
        )
    for i, v in enumerate(values):
        if not isinstance(v, bool):
            raise FileFormatError(
                f"{KEY}[{i}] is {v!r}; expected true or false", path=path, where=f"{KEY}[{i}]"
            )
    if n_frames is not None:
        if len(values) < n_frames:
            raise FileFormatError(
                f"{len(values)} entries for a trial or segment of {n_frames} marker frames", path=path, where=KEY
            )
        if len(values) > n_frames:
            warnings.warn(f"{path}: {len(values) - n_frames} extra trailing entries dropped", stacklevel=2)
            values = values[:n_frames]
    return np.array(values, dtype=bool).reshape(len(values))
