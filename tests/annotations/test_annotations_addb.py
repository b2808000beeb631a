"""Exchange with AddBiomechanics review files, on the real files of opencap_uhlrich2023."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from annotation_support import UHLRICH

from annotations import (
    AnnotationFileError,
    AnnotationStore,
    export_addb_review,
    import_addb_review,
    read_addb_review,
)

REVIEW_FILES = sorted(UHLRICH.glob("*/addb_review_segment_*.json"))


def test_the_shared_review_files_are_there() -> None:
    assert [p.parent.name for p in REVIEW_FILES] == ["DJ1", "walking1"]


@pytest.mark.parametrize("review", REVIEW_FILES, ids=lambda p: p.parent.name)
@pytest.mark.parametrize("start_frame", [0, 109])
def test_import_then_export_is_byte_exact(
    subject: Path, tmp_path: Path, review: Path, start_frame: int
) -> None:
    original = review.read_bytes()
    n = len(read_addb_review(review))
    trial = review.parent.name
    store = AnnotationStore.open(subject, reviewer="ana")
    store.set_unmeasured(
        trial, range(start_frame + n, start_frame + n + 5)
    )  # outside: not exported
    import_addb_review(store, trial, review, start_frame=start_frame, n_frames=n)
    out = tmp_path / "review.json"
    export_addb_review(store, trial, out, start_frame=start_frame, n_frames=n)
    assert out.read_bytes() == original
    store.close()
    # and from what was saved on disk
    reopened = AnnotationStore.open(subject, reviewer="bob")
    out2 = tmp_path / "review_again.json"
    export_addb_review(reopened, trial, out2, start_frame=start_frame, n_frames=n)
    assert out2.read_bytes() == original
    reopened.close()


def test_walking1_flags_are_imported_as_unmeasured_force(subject: Path) -> None:
    review = UHLRICH / "walking1" / "addb_review_segment_1.json"
    store = AnnotationStore.open(subject, reviewer="ana")
    edit = import_addb_review(store, "walking1", review)
    assert edit.changed == 24
    assert store.ranges("walking1") == [(0, 24)]  # foot off the plates at the start
    flag = store.flag("walking1", 0)
    assert flag.foot is None and flag.provenance.source == "imported"
    assert flag.provenance.reviewer == "ana"
    np.testing.assert_array_equal(store.mask("walking1", 136), read_addb_review(review))
    store.close()


def test_import_keeps_agreeing_manual_flags_clears_the_others_and_undoes(subject: Path) -> None:
    review = UHLRICH / "walking1" / "addb_review_segment_1.json"
    store = AnnotationStore.open(subject, reviewer="ana")
    store.set_unmeasured("walking1", 5, foot="left")  # agrees with the file: kept as is
    store.set_unmeasured("walking1", 50, foot="right")  # file says false: cleared
    before = store.snapshot()
    import_addb_review(store, "walking1", review)
    assert store.flag("walking1", 5).foot == "left"
    assert store.flag("walking1", 50) is None
    assert store.ranges("walking1") == [(0, 24)]
    store.undo()  # one edit, one undo step
    assert store.snapshot() == before
    store.close()


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


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b'{"missing_grf_data":[true,fal', "not a JSON review file"),
        (b"[true, false]", "expected a JSON object"),
        (b'{"missing": [true]}', 'no "missing_grf_data"'),
        (b'{"missing_grf_data": "true"}', "must be a list"),
        (b'{"missing_grf_data": [true, 1, false]}', "entry 1 is 1"),
    ],
)
def test_bad_review_files_name_the_file(tmp_path: Path, content: bytes, message: str) -> None:
    bad = tmp_path / "review.json"
    bad.write_bytes(content)
    with pytest.raises(AnnotationFileError, match=message) as info:
        read_addb_review(bad)
    assert info.value.path == str(bad)
    assert bad.read_bytes() == content


def test_extra_trailing_flags_of_old_addb_ui_are_dropped(tmp_path: Path) -> None:
    f = tmp_path / "review.json"
    f.write_bytes(b'{"missing_grf_data":[true,false,false,true]}')
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mask = read_addb_review(f, n_frames=3)
    np.testing.assert_array_equal(mask, [True, False, False])
    assert any("extra trailing" in str(w.message) for w in caught)
    with pytest.raises(AnnotationFileError, match="4 entries for a segment of 5 frames"):
        read_addb_review(f, n_frames=5)
