"""Findings 4 and 5 of docs/audits/2026-12-02-viewer.md, on the shared walk processed with
dynamics.

* A truncated annotations.json: the page names the record and its journal, says the journal
  still holds every edit and offers to rebuild the record from it; the rebuild keeps the
  damaged file and the journal, shows the earlier flags again and flagging works again.
* Reloading a page (a new client on loopback) keeps that page's own reviewer name, never the
  name typed on another page still open."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
from viewer_support import ProtocolClient, wait_for

from addb_viewer.app.paths import ReviewPaths
from annotations import AnnotationStore
from tests.conftest import SHARED_DATA, writable_copy

WALK = SHARED_DATA / "subjects" / "rajagopal2016_walk"


def _walk(walk_processed: Path, tmp_path: Path) -> ReviewPaths:
    subject = writable_copy(WALK, tmp_path / "walk")
    out = tmp_path / "out"
    shutil.copytree(walk_processed, out)
    return ReviewPaths.for_subject(subject, out)


def test_a_truncated_record_is_rebuilt_from_its_journal_from_the_page(walk_processed: Path, tmp_path: Path, make_app) -> None:
    paths = _walk(walk_processed, tmp_path)
    record = paths.annotations
    with AnnotationStore.open(record, reviewer="ana") as store:  # earlier sessions' flags
        store.set_unmeasured("walk", range(60, 71))
        store.set_unmeasured("walk", [180])
    journal = record.with_suffix(".journal")
    journal_before = journal.read_bytes()
    record.write_bytes(record.read_bytes()[:150])  # as `head -c 150` in the audit
    app = make_app(paths, reviewer="ana")
    p = app.panel
    assert app.store is None and app.trial.trial == "walk"
    shown = p.error.content
    # the message names the record, its journal, says the journal holds every edit and what to do
    assert p.error.visible and "flagging is disabled" in shown, shown
    assert str(record) in shown and str(journal) in shown, shown
    assert "still holds every edit" in shown and "Rebuild the review record from its journal" in shown, shown
    assert p.recover_record.visible
    assert "Every edit is saved at once" not in p.saved.content  # no promise while flagging is off
    app.recover_record()
    assert app.store is not None
    assert "rebuilt annotations.json from" in p.saved.content, p.saved.content
    assert not p.error.visible and not p.recover_record.visible
    # the earlier flags are shown again, the damaged file is kept, the journal is untouched
    assert np.flatnonzero(app.view.flagged).tolist() == [*range(60, 71), 180]
    assert [f.name[: len("annotations.json.damaged-")] for f in record.parent.glob("annotations.json.damaged-*")] == [
        "annotations.json.damaged-"
    ]
    assert journal.read_bytes().startswith(journal_before)
    # flagging works again, and is saved
    app.seek(100)
    app.edit("flag", lambda ed, k, foot: ed.toggle(k, foot))
    assert "✓ saved" in p.saved.content, p.saved.content
    with AnnotationStore.open(record, reviewer="checker") as disk:
        assert disk.ranges("walk") == [(60, 71), (100, 101), (180, 181)]


def test_a_record_the_journal_cannot_rebuild_says_to_restore_it(walk_processed: Path, tmp_path: Path, make_app) -> None:
    """Without its journal the page offers no rebuild and says what to do instead."""
    paths = _walk(walk_processed, tmp_path)
    record = paths.annotations
    with AnnotationStore.open(record, reviewer="ana") as store:
        store.set_unmeasured("walk", range(60, 71))
    record.write_bytes(record.read_bytes()[:150])
    record.with_suffix(".journal").unlink()
    app = make_app(paths, reviewer="ana")
    shown = app.panel.error.content
    assert app.store is None and not app.panel.recover_record.visible
    assert str(record) in shown and "does not hold every edit" in shown and "restore" in shown, shown


def test_a_reloaded_page_keeps_its_own_name_not_the_one_typed_on_another(walk_processed: Path, tmp_path: Path, make_app) -> None:
    app = make_app(_walk(walk_processed, tmp_path), reviewer="ana")  # loopback, no token
    a = ProtocolClient(app.port, "/")
    b = a2 = a3 = None
    try:
        (ida,) = wait_for(lambda: list(app.name_fields), what="page A's name field")
        b = ProtocolClient(app.port, "/")
        idb = wait_for(lambda: [c for c in app.name_fields if c != ida], what="page B's name field")[0]
        b.set_value(app.name_fields[idb], "bob")
        wait_for(lambda: app.client_names.get(idb) == "bob", what="B's name")
        # A reloads (its old connection first closed): it is still ana's page
        a.close()
        wait_for(lambda: ida not in app.name_fields, what="A gone")
        a2 = ProtocolClient(app.port, "/")
        (ida2,) = wait_for(lambda: [c for c in app.name_fields if c not in (ida, idb)], what="reloaded A")
        assert app.name_fields[ida2].value == "ana" and app.reviewer_name(ida2) == "ana"
        assert app.reviewer_name(idb) == "bob"
        # A types its own name, then reloads with the new page connected before the old one
        # closed: the name follows the page, and B's stays bob
        a2.set_value(app.name_fields[ida2], "carol")
        wait_for(lambda: app.client_names.get(ida2) == "carol", what="A's new name")
        a3 = ProtocolClient(app.port, "/")
        (ida3,) = wait_for(lambda: [c for c in app.name_fields if c not in (ida, ida2, idb)], what="A reloaded again")
        a2.close()
        wait_for(lambda: app.reviewer_name(ida3) == "carol", what="the reloaded page's own name")
        assert app.name_fields[ida3].value == "carol" and app.reviewer_name(idb) == "bob"
    finally:
        for c in (a, a2, a3, b):
            if c is not None:
                c.close()
