"""AddBiomechanics review files: which frames have unmeasured ground reaction force.

Format (``review.json`` or ``addb_review_segment_<k>.json``), compact JSON without a
trailing newline, one boolean per marker frame of the trial or segment::

    {"missing_grf_data":[true,true,false,...]}

:func:`write_review` reproduces AddBiomechanics' formatting byte for byte.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from solver.errors import FileFormatError

KEY = "missing_grf_data"


def read_review(path: str | Path) -> NDArray[np.bool_]:
    """``(T,)`` bool: True where the frame's ground reaction force was not measured.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist.
    FileFormatError
        Not JSON (with its line), not an object, no ``missing_grf_data`` key, or a
        value that is not a list of booleans (naming the first bad index).
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
    return np.array(values, dtype=bool).reshape(len(values))


def write_review(path: str | Path, mask: NDArray[np.bool_]) -> None:
    """Write a ``(T,)`` bool mask in AddBiomechanics' exact review-file format.

    Raises
    ------
    ValueError
        ``mask`` is not one-dimensional.
    """
    arr = np.asarray(mask)
    if arr.ndim != 1:
        raise ValueError(f"mask must be (T,), got {arr.shape}")
    text = json.dumps({KEY: [bool(v) for v in arr.tolist()]}, separators=(",", ":"))
    Path(path).write_bytes(text.encode("utf-8"))
