"""Two writers on one subject: last write wins, and the overridden edits are listed."""

from __future__ import annotations

import threading
from pathlib import Path

from annotations import AnnotationStore


def _two(subject: Path, clock) -> tuple[AnnotationStore, AnnotationStore]:
    a = AnnotationStore.open(subject, reviewer="ana", clock=clock)
    b = AnnotationStore.open(subject, reviewer="bob", clock=clock)
    return a, b


def test_stale_writer_overrides_and_the_conflict_is_listed_everywhere(subject: Path, clock) -> None:
    a, b = _two(subject, clock)
    first = a.set_unmeasured("walk", range(5, 9), foot="left")
    second = b.set_unmeasured("walk", range(7, 12), foot="right")  # b had not seen a's edit
    (conflict,) = second.conflicts
    assert conflict.frames == ((7, 9),) and conflict.target == "unmeasured_force"
    assert (conflict.kept_edit, conflict.overridden_edit) == (second.id, first.id)
    assert conflict.overridden.reviewer == "ana" and conflict.kept.reviewer == "bob"
    assert conflict.reason == "last_write_wins"
    assert a.refresh()
    assert a.conflicts() == b.conflicts() == [conflict]
    assert a.flag("walk", 8).foot == "right" and a.flag("walk", 6).foot == "left"  # last write
    a.close()
    b.close()
    reopened = AnnotationStore.open(subject, reviewer="carl")
    assert reopened.conflicts() == [conflict]  # saved in the subject file
    reopened.clear_conflicts()
    assert reopened.conflicts() == []
    reopened.close()


def test_no_conflict_when_the_writer_had_seen_the_edit_or_agrees(subject: Path, clock) -> None:
    a, b = _two(subject, clock)
    a.set_unmeasured("walk", 5, foot="left")
    b.refresh()  # b's user saw frame 5 flagged left
    assert b.set_unmeasured("walk", 5, foot="right").conflicts == ()
    a.set_excluded("walk", 6)
    assert b.set_excluded("walk", 6).conflicts == ()  # same value, no conflict
    assert b.set_unmeasured("walk", 30).conflicts == ()  # other frames
    assert a.set_unmeasured("walk", 31).conflicts == ()
    assert a.conflicts() == b.conflicts() == []
    a.close()
    b.close()


def test_activity_and_reviewed_conflicts(subject: Path, clock) -> None:
    a, b = _two(subject, clock)
    act = a.add_activity("dj", 0, 50, "drop_jump")
    b.refresh()
    a.update_activity("dj", act.item_id, label="jump")
    edit = b.update_activity("dj", act.item_id, note="landing on plate 2")
    (c,) = edit.conflicts
    assert (c.target, c.item_id, c.frames) == ("activity", act.item_id, ())
    a.set_reviewed("dj", True)
    (r,) = b.set_reviewed("dj", False).conflicts
    assert r.target == "reviewed" and r.overridden.reviewer == "ana"
    a.refresh()
    assert a.activities("dj")[0].label == "drop_jump"  # b's whole value won
    assert not a.is_reviewed("dj")
    a.close()
    b.close()


def test_undo_leaves_frames_changed_by_another_writer(subject: Path, clock) -> None:
    a, b = _two(subject, clock)
    a.set_unmeasured("walk", range(4), foot="left")
    b.refresh()
    b.set_unmeasured("walk", 2, foot="right")
    undo = a.undo()
    assert [a.flag("walk", f) for f in (0, 1, 3)] == [None, None, None]
    assert a.flag("walk", 2).foot == "right"  # b's later edit is kept
    (c,) = undo.conflicts
    assert (c.reason, c.frames, c.kept.reviewer) == ("undo_skipped", ((2, 3),), "bob")
    redo = a.redo()
    assert redo.conflicts == () and a.ranges("walk", foot="left") == [(0, 2), (3, 4)]
    a.close()
    b.close()


def test_threads_sharing_a_store_and_a_second_store_lose_nothing(subject: Path) -> None:
    shared = AnnotationStore.open(subject, reviewer="tabs", compact_every=40)
    other = AnnotationStore.open(subject, reviewer="script", compact_every=40)
    errors: list[BaseException] = []

    def work(store: AnnotationStore, base: int) -> None:
        try:
            for i in range(60):
                store.set_unmeasured("t", base + i, foot="left" if base % 2 else "right")
        except BaseException as exc:  # noqa: BLE001  # pragma: no cover - a thread's error, reported below
            errors.append(exc)

    threads = [threading.Thread(target=work, args=(shared, 1000 * k)) for k in range(3)]
    threads.append(threading.Thread(target=work, args=(other, 3001)))
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    shared.close()
    other.close()
    check = AnnotationStore.open(subject, reviewer="check")
    assert check.seq == 240
    assert check.ranges("t") == [(0, 60), (1000, 1060), (2000, 2060), (3001, 3061)]
    assert check.conflicts() == []
    check.close()
