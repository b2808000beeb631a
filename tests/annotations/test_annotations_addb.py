"""Export of the review record to AddBiomechanics review files (the import and the reader are the
app's and the solver's: tests/viewer/test_review_masks.py, tests/io)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from annotations import AnnotationStore, export_addb_review


def test_export_can_include_excluded_frames(subject: Path, tmp_path: Path) -> None:
    store = AnnotationStore.open(subject, reviewer="ana")
    store.set_unmeasured("t", [1, 2])
    store.set_excluded("t", 4)
    out = tmp_path / "review.json"
    export_addb_review(store, "t", out, n_frames=6)
    assert out.read_bytes() == b'{"missing_grf_data":[false,true,true,false,false,false]}'
    mask = export_addb_review(store, "t", out, start_frame=2, n_frames=3, include_excluded=True)
    np.testing.assert_array_equal(mask, [True, False, True])
    assert out.read_bytes() == b'{"missing_grf_data":[true,false,true]}'
    store.close()
