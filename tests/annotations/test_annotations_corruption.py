"""Damaged, truncated, wrong-version and wrong-type files: a clear error, nothing overwritten,
and recovery from the journal."""

from __future__ import annotations

import json
import warnings
from collections.abc import Callable
from pathlib import Path

import pytest

from annotations import AnnotationFileError, AnnotationStore
from annotations.schema import encode_line


def _make_subject(folder: Path, clock) -> dict:
    store = AnnotationStore.open(folder, reviewer="ana", clock=clock)
    store.set_unmeasured("walk", range(24))
    store.set_unmeasured("walk", 60, foot="left")
    store.set_excluded("walk", range(100, 104))
    store.add_activity("walk", 0, 136, "overground_walking", note="ok")
    store.add_note("walk", "RASI swap", start=100, stop=104)
    store.set_reviewed("walk")
    store.set_trial_info("walk", n_frames=136, rate_hz=100.0)
    store.close()
    return store.snapshot()


def _files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.name != "annotations.lock"}


def _mutate(path: Path, change: Callable[[dict], None]) -> None:
    data = json.loads(path.read_bytes())
    change(data)
    path.write_text(json.dumps(data, indent=2))


def _set(*keys_and_value):
    *keys, value = keys_and_value

    def change(d: dict) -> None:
        for k in keys[:-1]:
            d = d[k]
        d[keys[-1]] = value

    return change


CORRUPTIONS = {
    "truncated": (lambda p: p.write_bytes(p.read_bytes()[: len(p.read_bytes()) // 2]), "truncated"),
    "empty": (lambda p: p.write_bytes(b""), "not valid JSON"),
    "binary garbage": (lambda p: p.write_bytes(b"\x00\xff\xfe garbage"), "not UTF-8 text"),
    "not an object": (lambda p: p.write_text("[1, 2, 3]"), "expected an object"),
    "other schema": (
        lambda p: _mutate(p, _set("schema", "something.else")),
        "not an addb.annotations",
    ),
    "newer version": (lambda p: _mutate(p, _set("version", 2)), "unsupported schema version 2"),
    "version as text": (lambda p: _mutate(p, _set("version", "1")), "version must be an integer"),
    "missing field": (lambda p: _mutate(p, lambda d: d.pop("trials")), "missing field(s) trials"),
    "trials is a list": (lambda p: _mutate(p, _set("trials", [])), "expected an object"),
    "n_frames as text": (
        lambda p: _mutate(p, _set("trials", "walk", "n_frames", "136")),
        "expected an integer",
    ),
    "reversed run": (
        lambda p: _mutate(p, _set("trials", "walk", "excluded", [[104, 100, 0]])),
        "reversed",
    ),
    "float frame": (
        lambda p: _mutate(p, _set("trials", "walk", "excluded", [[100.0, 104, 0]])),
        "integer",
    ),
    "unknown foot": (
        lambda p: _mutate(p, _set("trials", "walk", "unmeasured_force", [[0, 3, "middle", 0]])),
        "expected one of left, right, both",
    ),
    "bad provenance index": (
        lambda p: _mutate(p, _set("trials", "walk", "excluded", [[100, 104, 99]])),
        "index into the provenance table",
    ),
    "reviewed as int": (
        lambda p: _mutate(p, _set("trials", "walk", "reviewed", [1, 0])),
        "true or false",
    ),
    "unknown label": (
        lambda p: _mutate(p, lambda d: d["trials"]["walk"]["activities"][0].update(label="skip")),
        "expected one of overground_walking",
    ),
}


@pytest.mark.parametrize("case", sorted(CORRUPTIONS))
def test_damaged_subject_file_gives_a_clear_error_and_is_not_overwritten(
    subject: Path, clock, case: str
) -> None:
    _make_subject(subject, clock)
    damage, message = CORRUPTIONS[case]
    main = subject / "annotations.json"
    damage(main)
    before = _files(subject)
    with pytest.raises(AnnotationFileError) as info:
        AnnotationStore.open(subject, reviewer="bob")
    err = info.value
    assert str(main) in str(err) and err.path == str(main)
    assert message in str(err)
    assert _files(subject) == before  # neither the file nor the journal was touched


@pytest.mark.parametrize(
    "case",
    [
        "truncated",
        "empty",
        "binary garbage",
        "not an object",
        "reversed run",
        "bad provenance index",
        "n_frames as text",
    ],
)
def test_recover_rebuilds_from_the_journal_and_keeps_the_damaged_file(
    subject: Path, clock, case: str
) -> None:
    expected = _make_subject(subject, clock)
    main = subject / "annotations.json"
    CORRUPTIONS[case][0](main)
    damaged = main.read_bytes()
    report = AnnotationStore.recover(subject)
    assert report.action == "rebuilt_from_journal" and report.operations == 7
    (kept,) = report.moved_aside
    assert kept.name.startswith("annotations.json.damaged-") and kept.read_bytes() == damaged
    store = AnnotationStore.open(subject, reviewer="bob")
    assert store.snapshot() == expected
    store.close()
    assert AnnotationStore.recover(subject).action == "nothing_to_do"


def test_newer_version_is_not_recovered_over(subject: Path, clock) -> None:
    _make_subject(subject, clock)
    CORRUPTIONS["newer version"][0](subject / "annotations.json")
    before = _files(subject)
    with pytest.raises(AnnotationFileError, match="newer version"):
        AnnotationStore.recover(subject)
    assert _files(subject) == before


def test_file_damaged_while_open_is_not_overwritten_and_edits_stay_safe(
    subject: Path, clock
) -> None:
    _make_subject(subject, clock)
    store = AnnotationStore.open(subject, reviewer="ana", clock=clock, compact_every=3)
    main = subject / "annotations.json"
    main.write_bytes(b'{"schema": "addb.annot')  # another program broke it
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for f in range(200, 206):  # passes the compaction threshold twice
            store.set_unmeasured("walk2", f)
    assert any("not overwritten" in str(w.message) for w in caught)
    assert store.problems() and "recover" in store.problems()[0]
    assert main.read_bytes() == b'{"schema": "addb.annot'
    with pytest.raises(AnnotationFileError, match="not overwritten"):
        store.close()
    assert main.read_bytes() == b'{"schema": "addb.annot'
    AnnotationStore.recover(subject)
    again = AnnotationStore.open(subject, reviewer="bob")
    assert again.ranges("walk2") == [(200, 206)] and again.ranges("walk") == [(0, 24), (60, 61)]
    again.close()


def test_torn_last_journal_line_is_ignored_then_cut(subject: Path, clock) -> None:
    expected = _make_subject(subject, clock)
    journal = subject / "annotations.journal"
    good = journal.read_bytes()
    line = encode_line({"seq": 8, "op": "flags"})
    with journal.open("ab") as f:
        f.write(line[: len(line) // 2])  # a write interrupted by a crash
    store = AnnotationStore.open(subject, reviewer="bob")
    assert store.snapshot() == expected
    store.set_excluded("walk", 120)  # the next writer cuts the torn line before appending
    assert journal.read_bytes().startswith(good)
    assert store.seq == 8
    store.close()
    again = AnnotationStore.open(subject, reviewer="carl")
    assert again.ranges("walk", "excluded") == [(100, 104), (120, 121)]
    again.close()


def test_damaged_line_followed_by_valid_lines_is_an_error_naming_the_line(
    subject: Path, clock
) -> None:
    store = AnnotationStore.open(subject, reviewer="ana", clock=clock, compact_every=10**6)
    for f in range(5):
        store.set_unmeasured("walk", f)
    store._release_fds()  # simulate a crash: no compaction
    journal = subject / "annotations.journal"
    lines = journal.read_bytes().split(b"\n")
    lines[3] = lines[3].replace(b'"walk"', b'"wa1k"')  # bit rot in an acknowledged edit (seq 3)
    journal.write_bytes(b"\n".join(lines))
    before = _files(subject)
    with pytest.raises(AnnotationFileError) as info:
        AnnotationStore.open(subject, reviewer="bob")
    assert info.value.path == str(journal) and info.value.line == 4
    assert "damaged" in str(info.value) and "skip_damaged_lines" in str(info.value)
    assert _files(subject) == before
    with pytest.raises(AnnotationFileError):
        AnnotationStore.recover(subject)
    report = AnnotationStore.recover(subject, skip_damaged_lines=True)
    assert report.damaged_lines == (4,) and report.operations == 4
    again = AnnotationStore.open(subject, reviewer="bob")
    assert again.ranges("walk") == [(0, 2), (3, 5)]  # only the damaged edit (frame 2) is lost
    again.close()


def test_unknown_operation_in_the_journal_is_refused(subject: Path, clock) -> None:
    _make_subject(subject, clock)
    journal = subject / "annotations.journal"
    n_lines = journal.read_bytes().count(b"\n")
    future = {
        "seq": 8,
        "id": "x",
        "session": "s",
        "reviewer": "zoe",
        "time": "t",
        "source": "manual",
        "op": "paint_frames",
        "trial": "walk",
    }
    with journal.open("ab") as f:
        f.write(encode_line(future))
    before = _files(subject)
    with pytest.raises(AnnotationFileError, match="unknown operation 'paint_frames'") as info:
        AnnotationStore.open(subject, reviewer="bob")
    assert info.value.line == n_lines + 1 and info.value.path == str(journal)
    assert _files(subject) == before


def test_damaged_journal_header_is_recovered_by_a_new_journal(subject: Path, clock) -> None:
    expected = _make_subject(subject, clock)
    journal = subject / "annotations.journal"
    journal.write_bytes(b"garbage\n" + journal.read_bytes())
    with pytest.raises(AnnotationFileError, match="journal header is damaged"):
        AnnotationStore.open(subject, reviewer="bob")
    report = AnnotationStore.recover(subject)
    assert report.action == "new_journal" and report.moved_aside[0].read_bytes().startswith(
        b"garbage"
    )
    store = AnnotationStore.open(subject, reviewer="bob")
    assert store.snapshot() == expected
    store.set_reviewed("walk", False)
    store.close()


def test_subject_file_of_another_journal_is_refused(subject: Path, tmp_path: Path, clock) -> None:
    expected = _make_subject(subject, clock)
    other = tmp_path / "other"
    other.mkdir()
    AnnotationStore.open(other, reviewer="x").close()
    (subject / "annotations.json").write_bytes((other / "annotations.json").read_bytes())
    with pytest.raises(AnnotationFileError, match="belongs to journal"):
        AnnotationStore.open(subject, reviewer="bob")
    assert AnnotationStore.recover(subject).action == "rebuilt_from_journal"
    store = AnnotationStore.open(subject, reviewer="bob")
    assert store.snapshot() == expected
    store.close()


def test_missing_journal_restarts_one_after_the_file(subject: Path, clock) -> None:
    expected = _make_subject(subject, clock)
    (subject / "annotations.journal").unlink()
    with pytest.warns(UserWarning, match="missing"):
        store = AnnotationStore.open(subject, reviewer="bob")
    assert store.snapshot() == expected
    store.set_excluded("walk", 130)
    store.close()
    again = AnnotationStore.open(subject, reviewer="bob")
    assert again.ranges("walk", "excluded") == [(100, 104), (130, 131)]
    again.close()


def test_subject_file_pointing_into_the_middle_of_a_journal_line_is_refused(
    subject: Path, clock
) -> None:
    expected = _make_subject(subject, clock)
    main = subject / "annotations.json"
    _mutate(main, lambda d: d["journal"].update(offset=d["journal"]["offset"] - 7))
    before = _files(subject)
    with pytest.raises(AnnotationFileError, match="not the start of a line"):
        AnnotationStore.open(subject, reviewer="bob")
    assert _files(subject) == before
    assert AnnotationStore.recover(subject).action == "rebuilt_from_journal"
    store = AnnotationStore.open(subject, reviewer="bob")
    assert store.snapshot() == expected
    store.close()
