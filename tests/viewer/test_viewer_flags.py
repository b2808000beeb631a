"""Flagging: the editor's semantics on a real AnnotationStore, and the page's controls
(driven over viser's websocket protocol, as a browser tab does) writing to the store on
disk before the page says "saved"."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from viewer_support import ProtocolClient, wait_for

from addb_viewer.app.flags import REJECTED_NOTE, TrialEditor, describe_frame, toggled_foot
from annotations import AnnotationError, AnnotationStore

T = 100


@pytest.fixture
def editor(tmp_path: Path):
    store = AnnotationStore.open(tmp_path, reviewer="ana")
    store.set_trial_info("walk", n_frames=T, rate_hz=100.0)
    proposed = np.zeros(T, bool)
    proposed[10:20] = proposed[30:35] = True
    reasons = tuple("left foot off the plates" if 10 <= i < 20 else "force mismatch" if 30 <= i < 35 else "" for i in range(T))
    yield TrialEditor(store, "walk", proposed, reasons)
    store.close()


@pytest.mark.parametrize(
    ("current", "foot", "new"),
    [
        (None, "left", "left"), (None, "both", "both"),
        ("left", "left", None), ("left", "right", "both"), ("left", "both", None),
        ("both", "left", "right"), ("both", "right", "left"), ("both", "both", None),
        ("", "left", None),  # a flag without a foot: toggling clears it
    ],
)
def test_toggle_semantics(current, foot, new) -> None:
    assert toggled_foot(current, foot) == new


def test_toggle_and_ranges_per_foot(editor: TrialEditor) -> None:
    editor.toggle(5, "left")
    editor.toggle(5, "right")
    v = editor.view()
    assert v.feet[5] == "both" and v.left[5] and v.right[5]
    editor.toggle(5, "left")
    assert editor.view().feet[5] == "right"
    editor.flag_range(40, 50, "left")
    editor.clear_range(45, 47)
    assert editor.store.ranges("walk", foot="left") == [(40, 45), (47, 50)]
    assert editor.store.mask("walk").sum() == 1 + 8
    with pytest.raises(AnnotationError):
        editor.flag_range(90, 120, "left")
    with pytest.raises(AnnotationError):
        editor.toggle(T, "left")


def test_unflagging_a_range_for_one_foot_keeps_the_other_foots_flags(editor: TrialEditor) -> None:
    """X with Foot "right" takes the right foot off the range: "both" becomes "left", right
    flags go, left flags and flags without a foot (accepted proposals) stay (X cleared every
    foot's flags while G flagged the chosen foot's); Foot "both" clears them all."""
    editor.flag_range(20, 41, "left")
    editor.flag_range(30, 51, "right")
    editor.accept(12)  # the proposal run 10-19 accepted: flags without a foot
    edits = editor.clear_range(15, 46, "right")
    assert len(edits) == 2
    v = editor.view()
    assert [v.feet[k] for k in (12, 15, 25, 35, 45, 47)] == ["", "", "left", "left", None, "right"]
    assert editor.store.ranges("walk", foot="left") == [(20, 41)] and editor.store.ranges("walk", foot="right") == [(46, 51)]
    assert editor.clear_range(60, 70, "left") == []  # nothing flagged there: no edit
    editor.clear_range(0, T, "both")
    assert not editor.store.mask("walk").any()
    with pytest.raises(AnnotationError, match="foot"):
        editor.clear_range(0, 5, "middle")


def test_flagging_a_range_for_one_foot_keeps_the_other_foots_flags(editor: TrialEditor) -> None:
    """G for the right foot over frames flagged for the left makes them "both" (it replaced
    the left flags before, and the reviewer's work was lost without notice); one undo
    restores the left flags exactly."""
    editor.flag_range(20, 41, "left")
    editor.flag_range(30, 51, "right")
    v = editor.view()
    assert [v.feet[k] for k in (25, 30, 40, 45)] == ["left", "both", "both", "right"]
    assert editor.store.ranges("walk", foot="left") == [(20, 41)] and editor.store.ranges("walk", foot="right") == [(30, 51)]
    from addb_viewer.app.flags import describe_flags

    # the parts add up to the whole (frames for both feet were counted under left and right)
    assert describe_flags(v).startswith("31 frames flagged (10 left, 10 right, 11 both feet)")
    editor.flag_range(35, 38, "left")  # a frame flagged for both stays both
    assert [editor.view().feet[k] for k in (34, 35, 37, 38)] == ["both"] * 4
    editor.store.undo()
    editor.store.undo()
    v = editor.view()
    assert editor.store.ranges("walk", foot="left") == [(20, 41)] and not v.right.any()


def test_accept_and_reject_proposals_are_durable_and_distinct(editor: TrialEditor, tmp_path: Path) -> None:
    assert editor.proposal_at(12) == (10, 20, "left foot off the plates")
    assert editor.accept(12) is not None
    edits = editor.reject(31)
    assert len(edits) == 1
    v = editor.view()
    assert v.accepted[10:20].all() and v.flagged[10:20].all() and not v.pending[10:20].any()
    assert v.rejected[30:35].all() and not v.flagged[30:35].any() and not v.pending.any()
    assert editor.accept() is None and editor.reject() == []  # nothing left
    # the record on disk says the same to another writer
    other = AnnotationStore.open(tmp_path, reviewer="bo")
    runs = other.flag_runs("walk")
    assert [(r.start, r.stop, r.provenance.source, r.provenance.reviewer) for r in runs] == [
        (10, 20, "proposal_accepted", "ana")
    ]
    notes = other.notes("walk")
    assert [(n.start, n.stop) for n in notes] == [(30, 35)] and notes[0].text.startswith(REJECTED_NOTE)
    other.close()
    # undo brings the rejected proposal back
    editor.store.undo()
    assert editor.view().pending[30:35].all()


def test_every_proposal_is_pending_agreed_or_rejected(editor: TrialEditor) -> None:
    """A proposal flagged by hand (not through Accept) is no longer pending and counts as
    agreed, as the status line calls it "accepted" and the timeline colours it (the
    verification run found 15 such frames of the walk in no category of the Flags summary)."""
    editor.flag_range(12, 16, "left")  # by hand, inside the proposal 10-20
    editor.reject(31)
    v = editor.view()
    assert v.agreed[12:16].all() and not v.accepted[12:16].any() and not v.pending[12:16].any()
    assert int(v.pending.sum()) + int(v.agreed.sum()) + int(v.rejected.sum()) == int(v.proposed.sum())
    assert "proposal (accepted)" in describe_frame(v, 13, ())


def test_accept_all_in_one_edit(editor: TrialEditor) -> None:
    before = editor.store.seq
    editor.accept()
    assert editor.store.seq == before + 1
    assert editor.store.ranges("walk") == [(10, 20), (30, 35)]


def _disk(paths) -> AnnotationStore:
    """A second store on the same file: what is on disk now."""
    return AnnotationStore.open(paths.annotations, reviewer="checker")


def test_page_controls_write_flags_to_the_store_on_disk(demo_paths, make_app) -> None:
    app = make_app(demo_paths)
    p = app.panel
    client = ProtocolClient(app.port)
    try:
        wait_for(lambda: app.server.get_clients(), what="the protocol client to register")
        client.set_value(p.frame, 40)
        wait_for(lambda: app.playback.frame == 40, what="seek to frame 40")
        client.set_value(p.toggle_flag, True)
        wait_for(lambda: "✓ saved" in p.saved.content, what="saved message")
        disk = _disk(demo_paths)
        flag = disk.flag("walk", 40)
        assert flag is not None and flag.foot == "both" and flag.provenance.reviewer == "tester"
        disk.close()

        # a range for the left foot: in point, out point, flag range
        client.set_value(p.foot, "left")
        wait_for(lambda: p.foot.value == "left")
        client.set_value(p.marks, "Set in")
        wait_for(lambda: app.playback.in_point == 40, what="in point")
        client.set_value(p.frame, 60)
        wait_for(lambda: app.playback.frame == 60)
        client.set_value(p.marks, "Set out")
        wait_for(lambda: app.playback.out_point == 60, what="out point")
        client.set_value(p.range_flags, "Flag range")
        wait_for(lambda: "flag frames 40–60" in p.saved.content and "✓" in p.saved.content, what="range saved")
        disk = _disk(demo_paths)
        assert disk.ranges("walk", foot="left") == [(40, 61)]
        disk.close()
        assert app.view.left[40:61].all()
        assert "UNMEASURED FORCE" in app.scene.banner.text

        # undo, and the reviewed mark
        client.set_value(p.history, "Undo")
        wait_for(lambda: "saved: undo" in p.saved.content, what="undo saved")
        client.set_value(p.reviewed, True)
        wait_for(lambda: "saved: trial reviewed" in p.saved.content, what="reviewed saved")
        disk = _disk(demo_paths)
        assert disk.ranges("walk") == [(40, 41)] and disk.flag("walk", 40).foot == "both"
        assert disk.is_reviewed("walk")
        disk.close()
    finally:
        client.close()


def test_other_writers_edits_appear_and_errors_do_not_say_saved(demo_paths, make_app) -> None:
    app = make_app(demo_paths)
    with AnnotationStore.open(demo_paths.annotations, reviewer="colleague") as other:
        other.set_unmeasured("walk", range(100, 110), foot="right")
    wait_for(lambda: app.view.right[100:110].all(), timeout=10, what="the other writer's flags")
    # an edit the store refuses is reported, not shown as saved
    app.edit("bad edit", lambda ed, _k, _f: ed.flag_range(200, 10_000, "left"))
    assert "not saved" in app.panel.saved.content


def test_a_rejected_proposal_flagged_by_hand_is_agreed_and_rejected_again_once_unflagged(editor: TrialEditor) -> None:
    """The fit leaves a flagged frame out whatever was said of its proposal before, so the
    timeline shows it green (agreed), not grey (rejected) as it did; unflagged, the
    rejection stands again."""
    editor.reject(12)
    assert editor.view().rejected[10:20].all()
    editor.flag_range(10, 12, "left")
    v = editor.view()
    assert v.agreed[10:12].all() and not v.rejected[10:12].any() and v.rejected[12:20].all()
    assert not v.pending[10:20].any()
    editor.clear_range(10, 12)
    assert editor.view().rejected[10:20].all()


def test_frames_left_out_without_a_proposal_are_counted_once_flags_replace_the_solvers_choice(editor: TrialEditor) -> None:
    """The solver leaves out frames it does not propose (two feet on one plate); once the
    reviewer's flags replace its choice they are fitted as measured unless flagged, and the
    Flags folder counts them (a reviewer saw 8 such frames fitted without any word)."""
    from addb_viewer.app.flags import FLAGGED_REASON, describe_flags, unproposed_replaced

    unobserved = editor.proposed.copy()
    unobserved[[50, 51]] = True  # left out, not proposed
    reasons = ["two feet on one plate"]
    assert unproposed_replaced(editor.view(), unobserved, editor.proposed, reasons) == 0  # the solver's choice stands
    editor.toggle(5, "left")
    v = editor.view()
    assert unproposed_replaced(v, unobserved, editor.proposed, reasons) == 2
    assert "2 more frames the solver left out without proposing them will be fitted as measured" in describe_flags(v, unproposed=2)
    editor.flag_range(50, 51, "both")
    assert unproposed_replaced(editor.view(), unobserved, editor.proposed, reasons) == 1
    assert unproposed_replaced(editor.view(), unobserved, editor.proposed, [FLAGGED_REASON]) == 0  # the fit took flags
