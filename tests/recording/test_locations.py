"""Default output folder and review record of a subject (addb_viewer.locations)."""

from __future__ import annotations

from pathlib import Path

import pytest

from addb_viewer.demo import DEMO_SUBJECT
from addb_viewer.locations import annotations_path, default_output_dir


def test_writable_subject_keeps_outputs_inside(tmp_path: Path) -> None:
    subject = tmp_path / "s01"
    subject.mkdir()
    out = default_output_dir(subject)
    assert out == subject.resolve() / "addb_out"
    assert annotations_path(subject, out) == subject.resolve() / "annotations.json"


def test_demo_goes_to_user_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    out = default_output_dir(DEMO_SUBJECT)
    assert out.parent == tmp_path / "cache" / "addb"
    assert (
        out.name.startswith("rajagopal2016_walk-")
        and len(out.name) == len("rajagopal2016_walk-") + 8
    )
    ann = annotations_path(DEMO_SUBJECT, out)
    # beside the output folder, never inside it (the pipeline replaces that folder)
    assert ann.parent == out.parent and not ann.is_relative_to(out)


def test_custom_out_for_demo_puts_record_beside_it(tmp_path: Path) -> None:
    out = tmp_path / "o"
    assert annotations_path(DEMO_SUBJECT, out) == tmp_path / "o.annotations.json"
