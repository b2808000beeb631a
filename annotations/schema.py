"""The on-disk schema (version 1): the subject file and the journal, encoded and validated.

This module is the single source of truth for the file formats; the store, the app and
any script that reads ``annotations.json`` go through it. Validation raises
:class:`~annotations.errors.AnnotationFileError` naming the file, the line (journal) and
the JSON path of the problem; nothing here uses ``assert``.

Subject file ``annotations.json`` (human-readable JSON, one run per line)::

    {
      "schema": "addb.annotations",
      "version": 1,
      "saved_at": "2026-11-21T16:00:00.000Z",
      "last_seq": 3,
      "journal": {"id": "5f0c...", "offset": 612, "lines": 4},
      "provenance": [
        ["ana", "2026-11-21T15:59:14.123Z", "imported"],
        ["ana", "2026-11-21T15:59:20.002Z", "manual"]
      ],
      "trials": {
        "walking1": {
          "reviewed": [true, 1],
          "n_frames": 136,
          "rate_hz": 100.0,
          "unmeasured_force": [
            [0, 24, null, 0],
            [60, 61, "left", 1]
          ],
          "excluded": [
            [100, 104, 1]
          ],
          "activities": [
            {"id": "a1", "start": 0, "stop": 136, "label": "overground_walking", "note": "",
             "prov": 1}
          ],
          "notes": [
            {"id": "n1", "text": "marker swap at heel strike", "start": 100, "stop": 104, "prov": 1}
          ]
        }
      },
      "conflicts": []
    }

``provenance`` is a table of ``[reviewer, UTC time, source]``; runs refer to it by index.
An ``unmeasured_force`` run is ``[start, stop, foot, provenance index]`` and an
``excluded`` run ``[start, stop, provenance index]``, frames half-open at the trial's
frame rate. ``reviewed`` is ``[value, provenance index or null]``. ``last_seq`` is the
last journal operation folded into the file and ``journal`` says where the journal
continues (byte ``offset``, line count), so that on start-up only newer lines are replayed.

Journal ``annotations.journal`` (append-only JSON lines). Every line is
``<crc32 of the JSON, 8 hex digits> <JSON>``; a line whose checksum does not match is a
torn write (the last line after a crash) and is ignored. The first line is a header::

    {"schema": "addb.annotations.journal", "version": 1, "id": "5f0c...", "base_seq": 0,
     "created": "..."}

and every other line one operation, e.g.::

    {"seq": 4, "id": "9b1e...", "session": "c2d4...", "reviewer": "ana",
     "time": "2026-11-21T15:59:20.002Z", "source": "manual", "op": "flags",
     "trial": "walking1", "kind": "unmeasured_force", "runs": [[60, 61, {"foot": "left"}]]}

Operations hold absolute values (the state of each frame after the edit), so applying
one twice gives the same state; ``seq`` orders them (1, 2, ... without gaps).
"""

from __future__ import annotations

import json
import math
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

from annotations.errors import AnnotationFileError
from annotations.model import (
    ACTIVITY_LABELS,
    EXCLUDED,
    FEET,
    FLAG_KINDS,
    SOURCES,
    ActivityRange,
    Conflict,
    Note,
    Provenance,
)

SCHEMA: Final = "addb.annotations"
JOURNAL_SCHEMA: Final = "addb.annotations.journal"
VERSION: Final = 1

OP_TYPES: Final = ("flags", "reviewed", "activity", "note", "trial_info", "clear_conflicts", "none")
CONFLICT_TARGETS: Final = (*FLAG_KINDS, "reviewed", "activity", "note", "trial_info")
CONFLICT_REASONS: Final = ("last_write_wins", "undo_skipped", "redo_skipped")

# Keys of the state (see annotations.state): each maps to one value.
#   ("flag", trial, kind, frame) -> None | (foot, Provenance)
#   ("reviewed", trial)          -> (bool, Provenance | None)
#   ("activity", trial, id)      -> ActivityRange | None
#   ("note", trial, id)          -> Note | None
#   ("info", trial)              -> (n_frames | None, rate_hz | None)
Key = tuple[Any, ...]

_MAX_NAME = 200


@dataclass(frozen=True, eq=False)
class Operation:
    """One journal operation, decoded.

    Attributes
    ----------
    seq
        Position in the journal (1, 2, ...).
    id
        Unique id (hex).
    session
        Id of the store session that wrote it (one per ``AnnotationStore.open``).
    op
        One of :data:`OP_TYPES`.
    trial
        Trial name (``None`` for ``clear_conflicts``).
    provenance
        Who, when, from where.
    puts
        ``{key: value}``: the state of each key after the operation (see ``Key``).
    conflicts
        Conflicts created by this operation.
    clear_ids
        Conflict ids removed (``clear_conflicts`` only).
    undo_of, redo_of
        For an undo, the id of the operation undone; for a redo, the id of the undo it
        reverts. ``None`` for ordinary edits.
    """

    seq: int
    id: str
    session: str
    op: str
    trial: str | None
    provenance: Provenance
    puts: dict[Key, Any]
    conflicts: tuple[Conflict, ...] = ()
    clear_ids: tuple[str, ...] = ()
    undo_of: str | None = None
    redo_of: str | None = None
    kind: str | None = field(default=None)


# --------------------------------------------------------------------------- checks
class _Ctx:
    """Where we are reading: the file, the line, for error messages."""

    __slots__ = ("line", "path")

    def __init__(self, path: str | Path, line: int | None = None) -> None:
        self.path = path
        self.line = line

    def fail(self, where: str, message: str) -> AnnotationFileError:
        return AnnotationFileError(message, path=self.path, line=self.line, where=where)


def _typename(value: Any) -> str:
    return "null" if value is None else type(value).__name__


def _int(ctx: _Ctx, value: Any, where: str, *, minimum: int = 0) -> int:
    if type(value) is not int or value < minimum:
        raise ctx.fail(
            where, f"expected an integer >= {minimum}, got {value!r} ({_typename(value)})"
        )
    return value


def _str(ctx: _Ctx, value: Any, where: str, *, choices: tuple[str, ...] | None = None) -> str:
    if type(value) is not str:
        raise ctx.fail(where, f"expected text, got {value!r} ({_typename(value)})")
    if choices is not None and value not in choices:
        raise ctx.fail(where, f"expected one of {', '.join(choices)}; got {value!r}")
    return value


def _name(ctx: _Ctx, value: Any, where: str) -> str:
    _str(ctx, value, where)
    if not value or len(value) > _MAX_NAME or any(ord(c) < 32 for c in value):
        raise ctx.fail(
            where, f"expected a non-empty name without control characters, got {value!r}"
        )
    return value


def _bool(ctx: _Ctx, value: Any, where: str) -> bool:
    if type(value) is not bool:
        raise ctx.fail(where, f"expected true or false, got {value!r} ({_typename(value)})")
    return value


def _dict(ctx: _Ctx, value: Any, where: str, required: tuple[str, ...] = ()) -> dict[str, Any]:
    if type(value) is not dict:
        raise ctx.fail(where, f"expected an object, got {_typename(value)}")
    missing = [k for k in required if k not in value]
    if missing:
        raise ctx.fail(where, f"missing field(s) {', '.join(missing)}")
    return value


def _list(ctx: _Ctx, value: Any, where: str, length: int | None = None) -> list[Any]:
    if type(value) is not list:
        raise ctx.fail(where, f"expected a list, got {_typename(value)}")
    if length is not None and len(value) != length:
        raise ctx.fail(where, f"expected a list of {length} items, got {len(value)}")
    return value


def _range(ctx: _Ctx, start: Any, stop: Any, where: str) -> tuple[int, int]:
    s = _int(ctx, start, where + ".start")
    e = _int(ctx, stop, where + ".stop")
    if e <= s:
        raise ctx.fail(where, f"empty or reversed frame range [{s}, {e})")
    return s, e


def _rate(ctx: _Ctx, value: Any, where: str) -> float | None:
    if value is None:
        return None
    if type(value) not in (int, float) or not math.isfinite(value) or value <= 0:
        raise ctx.fail(where, f"expected a frame rate > 0 in Hz or null, got {value!r}")
    return float(value)


def _prov(ctx: _Ctx, value: Any, where: str) -> Provenance:
    items = _list(ctx, value, where, 3)
    return Provenance(
        _name(ctx, items[0], where + "[0]"),
        _str(ctx, items[1], where + "[1]"),
        _str(ctx, items[2], where + "[2]", choices=SOURCES),
    )


def prov_to_json(prov: Provenance) -> list[str]:
    """``[reviewer, timestamp, source]``."""
    return [prov.reviewer, prov.timestamp, prov.source]


# --------------------------------------------------------------------------- conflicts
def conflict_to_json(c: Conflict) -> dict[str, Any]:
    """JSON object of a conflict (same form in the journal and in the subject file)."""
    return {
        "id": c.id,
        "trial": c.trial,
        "target": c.target,
        "item": c.item_id,
        "frames": [list(r) for r in c.frames],
        "kept_edit": c.kept_edit,
        "kept": None if c.kept is None else prov_to_json(c.kept),
        "overridden_edit": c.overridden_edit,
        "overridden": prov_to_json(c.overridden),
        "reason": c.reason,
    }


def _conflict(ctx: _Ctx, value: Any, where: str) -> Conflict:
    keys = ("id", "trial", "target", "item", "frames", "kept_edit", "kept", "overridden_edit")
    obj = _dict(ctx, value, where, (*keys, "overridden", "reason"))
    frames = []
    for i, r in enumerate(_list(ctx, obj["frames"], where + ".frames")):
        pair = _list(ctx, r, f"{where}.frames[{i}]", 2)
        frames.append(_range(ctx, pair[0], pair[1], f"{where}.frames[{i}]"))
    item = obj["item"]
    kept_edit = obj["kept_edit"]
    return Conflict(
        id=_str(ctx, obj["id"], where + ".id"),
        trial=_name(ctx, obj["trial"], where + ".trial"),
        target=_str(ctx, obj["target"], where + ".target", choices=CONFLICT_TARGETS),
        item_id=None if item is None else _str(ctx, item, where + ".item"),
        frames=tuple(frames),
        kept_edit=None if kept_edit is None else _str(ctx, kept_edit, where + ".kept_edit"),
        kept=None if obj["kept"] is None else _prov(ctx, obj["kept"], where + ".kept"),
        overridden_edit=_str(ctx, obj["overridden_edit"], where + ".overridden_edit"),
        overridden=_prov(ctx, obj["overridden"], where + ".overridden"),
        reason=_str(ctx, obj["reason"], where + ".reason", choices=CONFLICT_REASONS),
    )


# --------------------------------------------------------------------------- journal lines
def encode_line(obj: Mapping[str, Any]) -> bytes:
    """One journal line: ``<crc32 hex> <json>\\n`` (ASCII, no newline inside)."""
    body = json.dumps(obj, separators=(",", ":"), ensure_ascii=True).encode("ascii")
    return b"%08x %s\n" % (zlib.crc32(body), body)


class TornLine(Exception):
    """A journal line whose checksum or JSON is broken (an interrupted write)."""


def decode_line(raw: bytes) -> dict[str, Any]:
    """The JSON object of a journal line (without its newline).

    Raises
    ------
    TornLine
        If the checksum does not match or the text is not a JSON object.
    """
    if len(raw) < 10 or raw[8:9] != b" ":
        raise TornLine("line too short or without checksum")
    body = raw[9:]
    try:
        crc = int(raw[:8], 16)
    except ValueError:
        raise TornLine("checksum is not hexadecimal") from None
    if zlib.crc32(body) != crc:
        raise TornLine("checksum mismatch")
    try:
        obj = json.loads(body)
    except ValueError:
        raise TornLine("not JSON") from None
    if type(obj) is not dict:
        raise TornLine("not a JSON object")
    return obj


def journal_header(journal_id: str, base_seq: int, created: str) -> dict[str, Any]:
    """The first line of a journal."""
    return {
        "schema": JOURNAL_SCHEMA,
        "version": VERSION,
        "id": journal_id,
        "base_seq": base_seq,
        "created": created,
    }


def check_journal_header(obj: dict[str, Any], path: str | Path) -> tuple[str, int]:
    """Validate a journal header; returns ``(journal id, base_seq)``."""
    ctx = _Ctx(path, 1)
    _check_schema(ctx, obj, JOURNAL_SCHEMA)
    _dict(ctx, obj, "header", ("id", "base_seq"))
    return _str(ctx, obj["id"], "id"), _int(ctx, obj["base_seq"], "base_seq")


def _check_schema(ctx: _Ctx, obj: dict[str, Any], schema: str) -> None:
    if obj.get("schema") != schema:
        raise ctx.fail("schema", f'not an {schema} file: "schema" is {obj.get("schema")!r}')
    version = obj.get("version")
    if type(version) is not int:
        raise ctx.fail("version", f"version must be an integer, got {version!r}")
    if version != VERSION:
        newer = (
            " (written by a newer version of addb; upgrade to read it)" if version > VERSION else ""
        )
        raise ctx.fail(
            "version",
            f"unsupported schema version {version}; this program reads version {VERSION}{newer}",
        )


def operation_to_json(op: Operation) -> dict[str, Any]:
    """JSON object of an operation (one journal line)."""
    prov = op.provenance
    obj: dict[str, Any] = {
        "seq": op.seq,
        "id": op.id,
        "session": op.session,
        "reviewer": prov.reviewer,
        "time": prov.timestamp,
        "source": prov.source,
        "op": op.op,
        "trial": op.trial,
    }
    if op.op == "flags":
        obj["kind"] = op.kind
        obj["runs"] = _flag_runs_to_json(op.puts, prov)
    elif op.op == "reviewed":
        ((_key, (value, vprov)),) = op.puts.items()
        obj["value"] = value
        if vprov != prov:
            obj["prov"] = None if vprov is None else prov_to_json(vprov)
    elif op.op in ("activity", "note"):
        ((key, value),) = op.puts.items()
        obj["item"] = key[2]
        obj["value"] = None if value is None else _item_to_json(value, prov)
    elif op.op == "trial_info":
        ((_key, (n_frames, rate_hz)),) = op.puts.items()
        obj["n_frames"] = n_frames
        obj["rate_hz"] = rate_hz
    elif op.op == "clear_conflicts":
        obj["ids"] = list(op.clear_ids)
    if op.conflicts:
        obj["conflicts"] = [conflict_to_json(c) for c in op.conflicts]
    if op.undo_of is not None:
        obj["undo_of"] = op.undo_of
    if op.redo_of is not None:
        obj["redo_of"] = op.redo_of
    return obj


def _flag_runs_to_json(puts: dict[Key, Any], prov: Provenance) -> list[list[Any]]:
    runs: list[list[Any]] = []
    last_frame = -2
    last_value: Any = object()
    for key in sorted(puts, key=lambda k: k[3]):
        value = puts[key]
        frame = key[3]
        if frame == last_frame + 1 and value == last_value:
            runs[-1][1] = frame + 1
        else:
            if value is None:
                enc: Any = None
            else:
                enc = {"foot": value[0]}
                if value[1] != prov:
                    enc["prov"] = prov_to_json(value[1])
            runs.append([frame, frame + 1, enc])
        last_frame, last_value = frame, value
    return runs


def _item_to_json(item: ActivityRange | Note, prov: Provenance) -> dict[str, Any]:
    if isinstance(item, ActivityRange):
        obj: dict[str, Any] = {"start": item.start, "stop": item.stop, "label": item.label}
        obj["note"] = item.note
    else:
        obj = {"text": item.text, "start": item.start, "stop": item.stop}
    if item.provenance != prov:
        obj["prov"] = prov_to_json(item.provenance)
    return obj


def decode_operation(obj: dict[str, Any], path: str | Path, line: int) -> Operation:
    """Validate a journal line's object and build the :class:`Operation`.

    Raises
    ------
    AnnotationFileError
        Naming the journal and the line, if a field is missing or of the wrong type, or the
        operation type is unknown (e.g. written by a newer version).
    """
    ctx = _Ctx(path, line)
    base = ("seq", "id", "session", "reviewer", "time", "source", "op", "trial")
    _dict(ctx, obj, "operation", base)
    op = _str(ctx, obj["op"], "op")
    if op not in OP_TYPES:
        raise ctx.fail("op", f"unknown operation {op!r} (written by a newer version of addb?)")
    prov = Provenance(
        _name(ctx, obj["reviewer"], "reviewer"),
        _str(ctx, obj["time"], "time"),
        _str(ctx, obj["source"], "source", choices=SOURCES),
    )
    trial = None if op == "clear_conflicts" else _name(ctx, obj["trial"], "trial")
    puts, kind, clear_ids = _decode_payload(ctx, obj, op, trial, prov)
    conflicts = tuple(
        _conflict(ctx, c, f"conflicts[{i}]")
        for i, c in enumerate(_list(ctx, obj.get("conflicts", []), "conflicts"))
    )
    undo_of, redo_of = obj.get("undo_of"), obj.get("redo_of")
    return Operation(
        seq=_int(ctx, obj["seq"], "seq", minimum=1),
        id=_str(ctx, obj["id"], "id"),
        session=_str(ctx, obj["session"], "session"),
        op=op,
        trial=trial,
        provenance=prov,
        puts=puts,
        conflicts=conflicts,
        clear_ids=clear_ids,
        undo_of=None if undo_of is None else _str(ctx, undo_of, "undo_of"),
        redo_of=None if redo_of is None else _str(ctx, redo_of, "redo_of"),
        kind=kind,
    )


def _decode_payload(
    ctx: _Ctx, obj: dict[str, Any], op: str, trial: str | None, prov: Provenance
) -> tuple[dict[Key, Any], str | None, tuple[str, ...]]:
    puts: dict[Key, Any] = {}
    if op == "flags":
        _dict(ctx, obj, "operation", ("kind", "runs"))
        kind = _str(ctx, obj["kind"], "kind", choices=FLAG_KINDS)
        for i, run in enumerate(_list(ctx, obj["runs"], "runs")):
            where = f"runs[{i}]"
            item = _list(ctx, run, where, 3)
            s, e = _range(ctx, item[0], item[1], where)
            value = _flag_value(ctx, item[2], kind, prov, where + "[2]")
            puts.update(dict.fromkeys([("flag", trial, kind, f) for f in range(s, e)], value))
        return puts, kind, ()
    if op == "reviewed":
        value = _bool(ctx, obj.get("value"), "value")
        vprov = prov
        if "prov" in obj:
            vprov = None if obj["prov"] is None else _prov(ctx, obj["prov"], "prov")
        puts[("reviewed", trial)] = (value, vprov)
    elif op in ("activity", "note"):
        _dict(ctx, obj, "operation", ("item", "value"))
        item_id = _str(ctx, obj["item"], "item")
        raw = obj["value"]
        if raw is None:
            value = None
        elif op == "activity":
            value = _activity(ctx, raw, "value", item_id=item_id, table=None, default=prov)
        else:
            value = _note(ctx, raw, "value", item_id=item_id, table=None, default=prov)
        puts[(op, trial, item_id)] = value
    elif op == "trial_info":
        n = obj.get("n_frames")
        n_frames = None if n is None else _int(ctx, n, "n_frames", minimum=1)
        puts[("info", trial)] = (n_frames, _rate(ctx, obj.get("rate_hz"), "rate_hz"))
    elif op == "clear_conflicts":
        ids = _list(ctx, obj.get("ids"), "ids")
        return puts, None, tuple(_str(ctx, x, f"ids[{i}]") for i, x in enumerate(ids))
    return puts, None, ()  # "none": no values


def _flag_value(
    ctx: _Ctx, raw: Any, kind: str, prov: Provenance, where: str
) -> tuple[str | None, Provenance] | None:
    if raw is None:
        return None
    obj = _dict(ctx, raw, where, ("foot",))
    foot = obj["foot"]
    if foot is not None:
        _str(ctx, foot, where + ".foot", choices=FEET)
        if kind == EXCLUDED:
            raise ctx.fail(where + ".foot", "an excluded frame has no foot")
    vprov = _prov(ctx, obj["prov"], where + ".prov") if "prov" in obj else prov
    return (foot, vprov)


def _activity(
    ctx: _Ctx,
    raw: Any,
    where: str,
    *,
    item_id: str,
    table: list[Provenance] | None,
    default: Provenance | None,
) -> ActivityRange:
    obj = _dict(ctx, raw, where, ("start", "stop", "label", "note"))
    s, e = _range(ctx, obj["start"], obj["stop"], where)
    return ActivityRange(
        id=item_id,
        start=s,
        stop=e,
        label=_str(ctx, obj["label"], where + ".label", choices=ACTIVITY_LABELS),
        note=_str(ctx, obj["note"], where + ".note"),
        provenance=_item_prov(ctx, obj, where, table, default),
    )


def _note(
    ctx: _Ctx,
    raw: Any,
    where: str,
    *,
    item_id: str,
    table: list[Provenance] | None,
    default: Provenance | None,
) -> Note:
    obj = _dict(ctx, raw, where, ("text", "start", "stop"))
    if (obj["start"] is None) != (obj["stop"] is None):
        raise ctx.fail(where, "a note's start and stop are both frames or both null")
    s = e = None
    if obj["start"] is not None:
        s, e = _range(ctx, obj["start"], obj["stop"], where)
    return Note(
        id=item_id,
        text=_str(ctx, obj["text"], where + ".text"),
        start=s,
        stop=e,
        provenance=_item_prov(ctx, obj, where, table, default),
    )


def _item_prov(
    ctx: _Ctx,
    obj: dict[str, Any],
    where: str,
    table: list[Provenance] | None,
    default: Provenance | None,
) -> Provenance:
    if table is not None:
        return _prov_ref(ctx, obj.get("prov"), table, where + ".prov")
    if "prov" in obj:
        return _prov(ctx, obj["prov"], where + ".prov")
    if default is None:  # pragma: no cover - callers pass one of the two
        raise ctx.fail(where, "missing provenance")
    return default


def _prov_ref(ctx: _Ctx, value: Any, table: list[Provenance], where: str) -> Provenance:
    if type(value) is not int or not 0 <= value < len(table):
        raise ctx.fail(
            where,
            f"expected an index into the provenance table (0..{len(table) - 1}), got {value!r}",
        )
    return table[value]
