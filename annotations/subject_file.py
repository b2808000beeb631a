"""Read and write the subject file ``annotations.json`` (schema in :mod:`annotations.schema`)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from annotations.errors import AnnotationFileError
from annotations.model import EXCLUDED, FEET, UNMEASURED_FORCE, Provenance
from annotations.schema import (
    SCHEMA,
    VERSION,
    _activity,
    _check_schema,
    _conflict,
    _Ctx,
    _dict,
    _int,
    _list,
    _name,
    _note,
    _prov,
    _prov_ref,
    _range,
    _rate,
    _str,
    conflict_to_json,
    prov_to_json,
)
from annotations.state import SubjectState, TrialState, flag_runs


@dataclass(frozen=True, slots=True)
class SubjectFile:
    """Decoded subject file.

    Attributes
    ----------
    state
        Everything recorded, as of journal operation ``last_seq``.
    last_seq
        Last journal operation folded into the file (0: none).
    journal_id
        Id of the journal that continues this file.
    journal_offset
        Byte offset in that journal just after operation ``last_seq``.
    journal_lines
        Number of journal lines before ``journal_offset`` (header included).
    """

    state: SubjectState
    last_seq: int
    journal_id: str
    journal_offset: int
    journal_lines: int


_FOOT_JSON = {None: "null", **{f: f'"{f}"' for f in FEET}}
_TRIAL_FIELDS = (
    "reviewed",
    "n_frames",
    "rate_hz",
    UNMEASURED_FORCE,
    EXCLUDED,
    "activities",
    "notes",
)


def encode_subject_file(
    state: SubjectState,
    *,
    last_seq: int,
    journal_id: str,
    journal_offset: int,
    journal_lines: int,
    saved_at: str,
) -> bytes:
    """The subject file's bytes: indented JSON with one run, range or note per line."""
    table: dict[Provenance, int] = {}

    def ref(p: Provenance | None) -> int | None:
        if p is None:
            return None
        i = table.get(p)
        if i is None:
            i = table[p] = len(table)
        return i

    def dumps(obj: Any) -> str:
        return json.dumps(obj, ensure_ascii=False)

    trial_chunks = []
    for name in state.trial_names():
        t = state.trials[name]
        runs_uf = [
            f"[{r.start}, {r.stop}, {_FOOT_JSON[r.foot]}, {ref(r.provenance)}]"
            for r in flag_runs(t.flags[UNMEASURED_FORCE], UNMEASURED_FORCE)
        ]
        runs_ex = [
            f"[{r.start}, {r.stop}, {ref(r.provenance)}]"
            for r in flag_runs(t.flags[EXCLUDED], EXCLUDED)
        ]
        review = state.review(name, flags=False)
        acts = [
            dumps(
                {
                    "id": a.id,
                    "start": a.start,
                    "stop": a.stop,
                    "label": a.label,
                    "note": a.note,
                    "prov": ref(a.provenance),
                }
            )
            for a in review.activities
        ]
        notes = [
            dumps(
                {
                    "id": n.id,
                    "text": n.text,
                    "start": n.start,
                    "stop": n.stop,
                    "prov": ref(n.provenance),
                }
            )
            for n in review.notes
        ]
        fields = [
            f'"reviewed": {dumps([t.reviewed[0], ref(t.reviewed[1])])}',
            f'"n_frames": {dumps(t.info[0])}',
            f'"rate_hz": {dumps(t.info[1])}',
            f'"{UNMEASURED_FORCE}": {_block(runs_uf, 8)}',
            f'"{EXCLUDED}": {_block(runs_ex, 8)}',
            f'"activities": {_block(acts, 8)}',
            f'"notes": {_block(notes, 8)}',
        ]
        trial_chunks.append(f"    {dumps(name)}: {{\n      " + ",\n      ".join(fields) + "\n    }")
    conflicts = [dumps(conflict_to_json(c)) for c in state.conflicts.values()]
    prov_lines = [dumps(prov_to_json(p)) for p in table]
    trials = "{\n" + ",\n".join(trial_chunks) + "\n  }" if trial_chunks else "{}"
    head = [
        f'"schema": "{SCHEMA}"',
        f'"version": {VERSION}',
        f'"saved_at": {dumps(saved_at)}',
        f'"last_seq": {last_seq}',
        f'"journal": {dumps({"id": journal_id, "offset": journal_offset, "lines": journal_lines})}',
        f'"provenance": {_block(prov_lines, 4)}',
        f'"trials": {trials}',
        f'"conflicts": {_block(conflicts, 4)}',
    ]
    return ("{\n  " + ",\n  ".join(head) + "\n}\n").encode("utf-8")


def _block(lines: list[str], indent: int) -> str:
    if not lines:
        return "[]"
    pad = " " * indent
    return "[\n" + ",\n".join(pad + x for x in lines) + "\n" + " " * (indent - 2) + "]"


def decode_subject_file(data: bytes, path: str | Path) -> SubjectFile:
    """Parse and validate a subject file.

    Parameters
    ----------
    data
        The file's bytes.
    path
        Its path, for error messages.

    Raises
    ------
    AnnotationFileError
        Naming the file and the problem: not UTF-8 JSON (truncated), another schema, an
        unsupported version, a missing field or a field of the wrong type or range.
    """
    ctx = _Ctx(path)
    try:
        obj = json.loads(data)
    except UnicodeDecodeError as exc:
        raise AnnotationFileError(f"not UTF-8 text ({exc.reason})", path=path) from None
    except json.JSONDecodeError as exc:
        stripped = data.rstrip()
        hint = "; the file looks truncated" if stripped and not stripped.endswith(b"}") else ""
        raise AnnotationFileError(
            f"not valid JSON: {exc.msg} (line {exc.lineno}, column {exc.colno}){hint}", path=path
        ) from None
    _dict(ctx, obj, "file")
    _check_schema(ctx, obj, SCHEMA)
    _dict(ctx, obj, "file", ("last_seq", "journal", "provenance", "trials", "conflicts"))
    journal = _dict(ctx, obj["journal"], "journal", ("id", "offset", "lines"))
    table = [
        _prov(ctx, p, f"provenance[{i}]")
        for i, p in enumerate(_list(ctx, obj["provenance"], "provenance"))
    ]
    state = SubjectState()
    for name, raw in _dict(ctx, obj["trials"], "trials").items():
        _name(ctx, name, "trials")
        state.trials[name] = _decode_trial(ctx, raw, f"trials.{name}", table)
    for i, c in enumerate(_list(ctx, obj["conflicts"], "conflicts")):
        conflict = _conflict(ctx, c, f"conflicts[{i}]")
        state.conflicts[conflict.id] = conflict
    return SubjectFile(
        state=state,
        last_seq=_int(ctx, obj["last_seq"], "last_seq"),
        journal_id=_str(ctx, journal["id"], "journal.id"),
        journal_offset=_int(ctx, journal["offset"], "journal.offset"),
        journal_lines=_int(ctx, journal["lines"], "journal.lines", minimum=1),
    )


def _decode_trial(ctx: _Ctx, raw: Any, where: str, table: list[Provenance]) -> TrialState:
    obj = _dict(ctx, raw, where, _TRIAL_FIELDS)
    t = TrialState()
    reviewed = _list(ctx, obj["reviewed"], where + ".reviewed", 2)
    if type(reviewed[0]) is not bool:
        raise ctx.fail(where + ".reviewed[0]", f"expected true or false, got {reviewed[0]!r}")
    rprov = (
        None if reviewed[1] is None else _prov_ref(ctx, reviewed[1], table, where + ".reviewed[1]")
    )
    t.reviewed = (reviewed[0], rprov)
    n = obj["n_frames"]
    t.info = (
        None if n is None else _int(ctx, n, where + ".n_frames", minimum=1),
        _rate(ctx, obj["rate_hz"], where + ".rate_hz"),
    )
    uf = t.flags[UNMEASURED_FORCE]
    for i, run in enumerate(_list(ctx, obj[UNMEASURED_FORCE], where + "." + UNMEASURED_FORCE)):
        w = f"{where}.{UNMEASURED_FORCE}[{i}]"
        item = _list(ctx, run, w, 4)
        s, e = _range(ctx, item[0], item[1], w)
        foot = item[2]
        if foot is not None:
            _str(ctx, foot, w + "[2]", choices=FEET)
        uf.update(dict.fromkeys(range(s, e), (foot, _prov_ref(ctx, item[3], table, w + "[3]"))))
    ex = t.flags[EXCLUDED]
    for i, run in enumerate(_list(ctx, obj[EXCLUDED], where + "." + EXCLUDED)):
        w = f"{where}.{EXCLUDED}[{i}]"
        item = _list(ctx, run, w, 3)
        s, e = _range(ctx, item[0], item[1], w)
        ex.update(dict.fromkeys(range(s, e), (None, _prov_ref(ctx, item[2], table, w + "[2]"))))
    for i, raw_a in enumerate(_list(ctx, obj["activities"], where + ".activities")):
        w = f"{where}.activities[{i}]"
        a_id = _str(ctx, _dict(ctx, raw_a, w, ("id",))["id"], w + ".id")
        t.activities[a_id] = _activity(ctx, raw_a, w, item_id=a_id, table=table, default=None)
    for i, raw_n in enumerate(_list(ctx, obj["notes"], where + ".notes")):
        w = f"{where}.notes[{i}]"
        n_id = _str(ctx, _dict(ctx, raw_n, w, ("id",))["id"], w + ".id")
        t.notes[n_id] = _note(ctx, raw_n, w, item_id=n_id, table=table, default=None)
    return t
