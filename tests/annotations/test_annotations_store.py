"""The store's edits, reads, provenance, persistence and argument checks."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from annotations import (
    EXCLUDED,
    UNMEASURED_FORCE,
    AnnotationError,
    AnnotationStore,
    FlagRun,
    Provenance,
)
from annotations.model import format_timestamp


def test_flags_are_recorded_with_provenance(subject: Path, clock) -> None:
    store = AnnotationStore.open(subject, reviewer="ana", clock=clock)
    edit = store.set_unmeasured("walk", range(10, 20), foot="left")
    assert (edit.seq, edit.op, edit.trial, edit.changed) == (1, "flags", "walk", 10)
    assert edit.provenance == Provenance("ana", format_timestamp(clock.now), "manual")
    assert edit.provenance.timestamp.startswith("2026-01-01T00:00:00.0")
    store.set_excluded("walk", [30, 31, 33], source="proposal_accepted")
    flag = store.flag("walk", 15)
    assert flag is not None and flag.foot == "left" and flag.provenance == edit.provenance
    assert store.flag("walk", 20) is None
    assert store.flag("walk", 31, EXCLUDED).provenance.source == "proposal_accepted"
    assert store.ranges("walk") == [(10, 20)]
    assert store.ranges("walk", EXCLUDED) == [(30, 32), (33, 34)]
    runs = store.flag_runs("walk", EXCLUDED)
    assert [(r.start, r.stop) for r in runs] == [(30, 32), (33, 34)]
    store.close()


def test_later_flag_replaces_earlier_and_runs_split_by_provenance(subject: Path, clock) -> None:
    store = AnnotationStore.open(subject, reviewer="ana", clock=clock)
    first = store.set_unmeasured("walk", range(10), foot="left")
    second = store.set_unmeasured("walk", range(5, 8), foot="right")
    store.set_unmeasured("walk", 9, False)
    runs = store.flag_runs("walk")
    assert runs == [
        FlagRun(0, 5, UNMEASURED_FORCE, "left", first.provenance),
        FlagRun(5, 8, UNMEASURED_FORCE, "right", second.provenance),
        FlagRun(8, 9, UNMEASURED_FORCE, "left", first.provenance),
    ]
    assert store.ranges("walk", foot="right") == [(5, 8)]
    assert store.ranges("walk", foot="left") == [(0, 5), (8, 9)]
    store.close()


def test_mask_is_bool_T_and_foot_both_counts_for_each_foot(subject: Path) -> None:
    store = AnnotationStore.open(subject, reviewer="ana")
    store.set_unmeasured("walk", [1, 2], foot="left")
    store.set_unmeasured("walk", 4, foot="both")
    store.set_unmeasured("walk", 6)
    mask = store.mask("walk", 8)
    assert mask.dtype == np.bool_ and mask.shape == (8,)
    np.testing.assert_array_equal(mask, [0, 1, 1, 0, 1, 0, 1, 0])
    np.testing.assert_array_equal(store.mask("walk", 8, foot="left"), [0, 1, 1, 0, 1, 0, 0, 0])
    np.testing.assert_array_equal(store.mask("walk", 8, foot="right"), [0, 0, 0, 0, 1, 0, 0, 0])
    np.testing.assert_array_equal(store.mask("walk", 8, kind=EXCLUDED), np.zeros(8, bool))
    np.testing.assert_array_equal(store.mask("unknown_trial", 3), np.zeros(3, bool))
    with pytest.raises(AnnotationError, match="only 6 frames"):
        store.mask("walk", 6)
    with pytest.raises(AnnotationError, match="n_frames not given"):
        store.mask("walk")
    store.close()


def test_set_mask_is_the_reverse_of_mask(subject: Path) -> None:
    store = AnnotationStore.open(subject, reviewer="ana")
    store.set_unmeasured("run", 3, foot="right")  # kept: already flagged, mask True there
    store.set_unmeasured("run", 9)  # cleared: mask False there
    proposal = np.zeros(12, dtype=bool)
    proposal[[2, 3, 4, 10]] = True
    edit = store.set_mask("run", proposal)
    np.testing.assert_array_equal(store.mask("run", 12), proposal)
    assert edit.changed == 4  # frames 2, 4, 10 flagged, 9 cleared
    assert store.flag("run", 3).foot == "right"
    assert store.flag("run", 2).provenance.source == "proposal_accepted"
    shifted = store.set_mask("run", np.array([True, False]), start_frame=20, kind=EXCLUDED)
    assert shifted.changed == 1 and store.ranges("run", EXCLUDED) == [(20, 21)]
    store.close()


def test_trial_info_gives_default_length_and_bounds(subject: Path) -> None:
    store = AnnotationStore.open(subject, reviewer="ana")
    store.set_unmeasured("walk", 50)
    with pytest.raises(AnnotationError, match="frame 50 is annotated"):
        store.set_trial_info("walk", n_frames=40)
    store.set_trial_info("walk", n_frames=136, rate_hz=100.0)
    assert store.mask("walk").shape == (136,)
    review = store.review("walk")
    assert (review.n_frames, review.rate_hz) == (136, 100.0)
    with pytest.raises(AnnotationError, match="past the end"):
        store.set_unmeasured("walk", 136)
    with pytest.raises(AnnotationError, match="past the end"):
        store.add_activity("walk", 100, 137, "overground_walking")
    store.close()


def test_activities_notes_and_reviewed(subject: Path, clock) -> None:
    store = AnnotationStore.open(subject, reviewer="ana", clock=clock)
    a = store.add_activity("dj", 10, 120, "drop_jump", note="second landing")
    b = store.add_activity("dj", 0, 10, "standing")
    store.update_activity("dj", a.item_id, label="jump")
    n = store.add_note("dj", "plate 2 saturates", start=40, stop=45)
    store.add_note("dj", "whole trial: marker swap on RASI")
    store.set_reviewed("dj")
    acts = store.activities("dj")
    assert [(x.id, x.start, x.stop, x.label, x.note) for x in acts] == [
        (b.item_id, 0, 10, "standing", ""),
        (a.item_id, 10, 120, "jump", "second landing"),
    ]
    notes = store.notes("dj")
    assert [x.text for x in notes] == ["whole trial: marker swap on RASI", "plate 2 saturates"]
    assert notes[1].id == n.item_id and (notes[1].start, notes[1].stop) == (40, 45)
    assert store.is_reviewed("dj") and store.review("dj").reviewed_provenance.reviewer == "ana"
    store.remove_activity("dj", b.item_id)
    store.remove_note("dj", n.item_id)
    assert [x.id for x in store.activities("dj")] == [a.item_id]
    assert len(store.notes("dj")) == 1
    with pytest.raises(AnnotationError, match="no activity"):
        store.remove_activity("dj", b.item_id)
    store.set_reviewed("dj", False)
    assert not store.is_reviewed("dj")
    store.close()


def test_edits_are_durable_without_close_and_replayed_on_open(subject: Path, clock) -> None:
    writer = AnnotationStore.open(subject, reviewer="ana", clock=clock, compact_every=10**6)
    for f in range(0, 40, 3):
        writer.set_unmeasured("walk", f, foot="left")
    writer.add_activity("walk", 0, 40, "overground_walking")
    main_before = json.loads((subject / "annotations.json").read_bytes())
    assert main_before["last_seq"] == 0  # nothing compacted: everything is only in the journal
    reader = AnnotationStore.open(subject, reviewer="bob")
    assert reader.snapshot() == writer.snapshot()
    assert reader.seq == writer.seq == 15
    reader.close()
    writer.close()


def test_older_subject_file_plus_newer_journal_is_replayed(subject: Path, clock) -> None:
    store = AnnotationStore.open(subject, reviewer="ana", clock=clock)
    store.set_unmeasured("walk", range(5))
    store.compact()
    older = (subject / "annotations.json").read_bytes()
    store.set_excluded("walk", 7)
    store.set_reviewed("walk")
    store.close()
    expected = store.snapshot()
    (subject / "annotations.json").write_bytes(older)  # e.g. the last compaction was lost
    again = AnnotationStore.open(subject, reviewer="ana")
    assert again.snapshot() == expected
    assert again.is_reviewed("walk")
    again.close()


def test_close_writes_a_human_readable_versioned_file(subject: Path, clock) -> None:
    with AnnotationStore.open(subject, reviewer="ana", clock=clock) as store:
        store.set_unmeasured("walking1", range(24))
        second = store.set_unmeasured("walking1", 60, foot="left")
        store.set_excluded("walking1", range(100, 104))
    text = (subject / "annotations.json").read_text()
    data = json.loads(text)
    assert (data["schema"], data["version"]) == ("addb.annotations", 1)
    trial = data["trials"]["walking1"]
    assert trial["unmeasured_force"] == [[0, 24, None, 0], [60, 61, "left", 1]]
    assert trial["excluded"] == [[100, 104, 2]]
    assert data["provenance"][1] == ["ana", second.provenance.timestamp, "manual"]
    assert '      "unmeasured_force": [\n        [0, 24, null, 0],\n' in text  # one run per line
    reopened = AnnotationStore.open(subject, reviewer="bob")
    assert reopened.snapshot() == store.snapshot()
    reopened.close()


def test_store_accepts_a_json_path_and_keeps_files_side_by_side(tmp_path: Path) -> None:
    """The record goes to the named file (its journal and lock beside it), and reopening
    that path reads it back."""
    store = AnnotationStore.open(tmp_path / "S01_review.json", reviewer="ana")
    store.set_reviewed("t1")
    store.set_unmeasured("t1", range(3, 6), foot="left")
    store.close()
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "S01_review.journal",
        "S01_review.json",
        "S01_review.lock",
    ]
    trial = json.loads((tmp_path / "S01_review.json").read_bytes())["trials"]["t1"]
    assert trial["reviewed"][0] is True and trial["unmeasured_force"] == [[3, 6, "left", 0]]
    again = AnnotationStore.open(tmp_path / "S01_review.json", reviewer="bob")
    assert again.snapshot() == store.snapshot()
    assert again.is_reviewed("t1") and again.ranges("t1", foot="left") == [(3, 6)]
    again.close()


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda s: s.set_unmeasured("t", -1), ">= 0"),
        (lambda s: s.set_unmeasured("t", []), "no frames"),
        (lambda s: s.set_unmeasured("t", np.ones(3, dtype=bool)), "set_mask"),
        (lambda s: s.set_unmeasured("t", [1.5]), "integer"),
        (lambda s: s.set_unmeasured("t", 1, foot="middle"), "unknown foot"),
        (lambda s: s.set_unmeasured("t", 1, False, foot="left"), "only given when flagging"),
        (lambda s: s.set_unmeasured("t", 1, source="guess"), "unknown source"),
        (lambda s: s.set_unmeasured("", 1), "trial must be"),
        (lambda s: s.set_unmeasured("t", range(0, 10, 2)), "step 1"),
        (lambda s: s.mask("t", 3, kind="bad"), "unknown flag kind"),
        (lambda s: s.add_activity("t", 5, 5, "squat"), "empty or reversed"),
        (lambda s: s.add_activity("t", 0, 5, "skipping"), "unknown activity label"),
        (lambda s: s.add_note("t", "x", start=3), "both start and stop"),
        (lambda s: s.update_note("t", "nope", "x"), "no note"),
        (lambda s: s.set_mask("t", np.array([0, 1])), "bool array"),
        (lambda s: s.set_mask("t", np.array([True]), kind=EXCLUDED, foot="left"), "no foot"),
    ],
)
def test_bad_arguments_raise_and_write_nothing(subject: Path, call, message: str) -> None:
    store = AnnotationStore.open(subject, reviewer="ana")
    journal_before = (subject / "annotations.journal").read_bytes()
    with pytest.raises(AnnotationError, match=message):
        call(store)
    assert (subject / "annotations.journal").read_bytes() == journal_before
    store.close()


def test_open_checks_reviewer_folder_and_closed_store(tmp_path: Path) -> None:
    with pytest.raises(AnnotationError, match="reviewer"):
        AnnotationStore.open(tmp_path, reviewer="  ")
    with pytest.raises(AnnotationError, match="does not exist"):
        AnnotationStore.open(tmp_path / "missing", reviewer="ana")
    store = AnnotationStore.open(tmp_path, reviewer="ana")
    store.close()
    store.close()  # idempotent
    with pytest.raises(AnnotationError, match="closed"):
        store.set_reviewed("t")


def test_naive_clock_is_rejected(subject: Path) -> None:
    from datetime import datetime

    with pytest.raises(AnnotationError, match="timezone"):
        AnnotationStore.open(subject, reviewer="ana", clock=lambda: datetime(2026, 1, 1))


def test_error_to_dict_for_the_ui(subject: Path) -> None:
    store = AnnotationStore.open(subject, reviewer="ana")
    with pytest.raises(AnnotationError) as info:
        store.mask("walk")
    d = info.value.to_dict()
    assert d["type"] == "AnnotationError" and d["where"] == "walk" and "n_frames" in d["message"]
    store.close()


def test_trial_info_is_not_undone(tmp_path) -> None:
    """Recording a trial's length is bookkeeping: Undo skips it and undoes the last flag."""
    from annotations import AnnotationStore

    with AnnotationStore.open(tmp_path, reviewer="ana") as store:
        store.set_unmeasured("walk", [3, 4])
        store.set_trial_info("walk", n_frames=100, rate_hz=100.0)
        store.undo()
        assert store.flag("walk", 3) is None
        assert store.review("walk").n_frames == 100
