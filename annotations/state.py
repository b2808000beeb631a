"""The store's in-memory state and the pure logic of edits: apply, invert, detect conflicts.

The state is a mapping from keys to values (see ``annotations.schema.Key``): one key per
flagged frame and kind, per trial's "reviewed" mark, per activity range, note and
trial info. An operation is a set of ``{key: new value}``; applying it is a dict update,
so applying the same operation twice gives the same state. Undo puts back the values
an edit replaced; redo puts back the values the edit wrote.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from annotations.masks import frames_to_ranges
from annotations.model import (
    EXCLUDED,
    FLAG_KINDS,
    UNMEASURED_FORCE,
    ActivityRange,
    Conflict,
    FlagRun,
    Note,
    Provenance,
    TrialReview,
)
from annotations.schema import Key, Operation

FlagEntry = tuple[str | None, Provenance]
"""Value of a flagged frame: ``(foot, provenance)``; an unflagged frame has no entry."""


class TrialState:
    """Mutable record of one trial (internal; the public snapshot is ``TrialReview``)."""

    __slots__ = ("activities", "flags", "info", "notes", "reviewed")

    def __init__(self) -> None:
        self.flags: dict[str, dict[int, FlagEntry]] = {k: {} for k in FLAG_KINDS}
        self.reviewed: tuple[bool, Provenance | None] = (False, None)
        self.activities: dict[str, ActivityRange] = {}
        self.notes: dict[str, Note] = {}
        self.info: tuple[int | None, float | None] = (None, None)

    def is_empty(self) -> bool:
        """True if nothing at all is recorded (such trials are not listed or saved)."""
        return (
            not any(self.flags.values())
            and self.reviewed == (False, None)
            and not self.activities
            and not self.notes
            and self.info == (None, None)
        )


class SubjectState:
    """All trials of a subject plus the list of conflicts."""

    __slots__ = ("conflicts", "trials")

    def __init__(self) -> None:
        self.trials: dict[str, TrialState] = {}
        self.conflicts: dict[str, Conflict] = {}

    # -- key access -------------------------------------------------------------------
    def trial(self, name: str) -> TrialState:
        """The trial's record, created empty if absent."""
        t = self.trials.get(name)
        if t is None:
            t = self.trials[name] = TrialState()
        return t

    def get(self, key: Key) -> Any:
        """Current value of a key (``None`` / defaults for absent entries)."""
        t = self.trials.get(key[1])
        kind = key[0]
        if kind == "flag":
            return None if t is None else t.flags[key[2]].get(key[3])
        if kind == "reviewed":
            return (False, None) if t is None else t.reviewed
        if kind == "activity":
            return None if t is None else t.activities.get(key[2])
        if kind == "note":
            return None if t is None else t.notes.get(key[2])
        if kind == "info":
            return (None, None) if t is None else t.info
        raise KeyError(key)

    def put_all(self, puts: dict[Key, Any]) -> None:
        """Set every key to its value (absolute: idempotent)."""
        for key, value in puts.items():
            t = self.trial(key[1])
            kind = key[0]
            if kind == "flag":
                flags = t.flags[key[2]]
                if value is None:
                    flags.pop(key[3], None)
                else:
                    flags[key[3]] = value
            elif kind == "reviewed":
                t.reviewed = value
            elif kind in ("activity", "note"):
                items = t.activities if kind == "activity" else t.notes
                if value is None:
                    items.pop(key[2], None)
                else:
                    items[key[2]] = value
            else:
                t.info = value

    def apply(self, op: Operation) -> None:
        """Apply a decoded operation (its values, the conflicts it lists, cleared conflicts)."""
        self.put_all(op.puts)
        for c in op.conflicts:
            self.conflicts[c.id] = c
        for cid in op.clear_ids:
            self.conflicts.pop(cid, None)

    # -- snapshots ----------------------------------------------------------------------
    def trial_names(self) -> list[str]:
        """Names of trials with anything recorded, sorted."""
        return sorted(n for n, t in self.trials.items() if not t.is_empty())

    def review(self, name: str, *, flags: bool = True) -> TrialReview:
        """Immutable snapshot of one trial (empty if unknown); without flag runs if not
        ``flags`` (cheaper when only activities and notes are needed)."""
        t = self.trials.get(name) or TrialState()
        return TrialReview(
            trial=name,
            reviewed=t.reviewed[0],
            reviewed_provenance=t.reviewed[1],
            unmeasured_force=tuple(flag_runs(t.flags[UNMEASURED_FORCE], UNMEASURED_FORCE))
            if flags
            else (),
            excluded=tuple(flag_runs(t.flags[EXCLUDED], EXCLUDED)) if flags else (),
            activities=tuple(sorted(t.activities.values(), key=lambda a: (a.start, a.stop, a.id))),
            notes=tuple(sorted(t.notes.values(), key=_note_order)),
            n_frames=t.info[0],
            rate_hz=t.info[1],
        )


def _note_order(n: Note) -> tuple[int, str]:
    return (-1 if n.start is None else n.start, n.id)


def flag_runs(flags: dict[int, FlagEntry], kind: str) -> list[FlagRun]:
    """Group flagged frames into runs of consecutive frames with equal foot and provenance."""
    runs: list[FlagRun] = []
    if not flags:
        return runs
    frames = sorted(flags)
    start = prev = frames[0]
    entry = flags[start]
    for f in frames[1:]:
        e = flags[f]
        if f != prev + 1 or e != entry:
            runs.append(FlagRun(start, prev + 1, kind, entry[0], entry[1]))
            start, entry = f, e
        prev = f
    runs.append(FlagRun(start, prev + 1, kind, entry[0], entry[1]))
    return runs


def flag_mask(flags: dict[int, FlagEntry], n_frames: int, foot: str | None = None) -> np.ndarray:
    """``(n_frames,)`` bool mask of the flagged frames (optionally of one foot, "both" counts
    for each foot). Frames at or past ``n_frames`` must not be flagged (checked by caller)."""
    if foot is None:
        frames = np.fromiter(flags.keys(), dtype=np.int64, count=len(flags))
    else:
        frames = np.fromiter(
            (f for f, (ft, _p) in flags.items() if ft in (foot, "both")), dtype=np.int64
        )
    out = np.zeros(n_frames, dtype=bool)
    out[frames] = True
    return out


# --------------------------------------------------------------------------- conflicts
def _content(key: Key, value: Any) -> Any:
    """The part of a value that matters for a conflict (provenance ignored)."""
    kind = key[0]
    if value is None:
        return None
    if kind == "flag":
        return ("set", value[0])
    if kind == "reviewed":
        return value[0]
    if kind == "activity":
        return (value.start, value.stop, value.label, value.note)
    if kind == "note":
        return (value.text, value.start, value.stop)
    return value


def _target(key: Key) -> tuple[str, str | None]:
    kind = key[0]
    if kind == "flag":
        return key[2], None
    if kind in ("activity", "note"):
        return kind, key[2]
    return ("reviewed" if kind == "reviewed" else "trial_info"), None


def _value_prov(key: Key, value: Any) -> Provenance | None:
    if value is None or key[0] == "info":
        return None
    if key[0] in ("flag", "reviewed"):
        return value[1]
    return value.provenance


def detect_overrides(
    puts: dict[Key, Any],
    window: Iterable[Operation],
    *,
    session: str,
    edit_id: str,
    provenance: Provenance,
) -> list[Conflict]:
    """Conflicts created by writing ``puts`` after the other writers' ``window`` operations.

    ``window`` holds the operations by other sessions that this writer had not seen when
    its user made the edit (read from the journal just before appending). A conflict is a
    key whose latest value in the window differs, ignoring provenance, from the new one.
    """
    latest: dict[Key, Operation] = {}
    for op in window:
        if op.session == session:
            continue
        small, large = (op.puts, puts) if len(op.puts) < len(puts) else (puts, op.puts)
        for key in small:
            if key in large:
                latest[key] = op
    groups: dict[tuple[str, str, str, str | None], list[Key]] = {}
    for key, op in latest.items():
        if _content(key, op.puts[key]) != _content(key, puts[key]):
            target, item = _target(key)
            groups.setdefault((op.id, key[1], target, item), []).append(key)
    conflicts = []
    ordered = sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1], kv[0][2], kv[0][3] or ""))
    for n, ((other_id, trial, target, item), keys) in enumerate(ordered):
        other = latest[keys[0]]
        frames = frames_to_ranges(k[3] for k in keys) if keys[0][0] == "flag" else []
        conflicts.append(
            Conflict(
                id=f"{edit_id}/{n}",
                trial=trial,
                target=target,
                item_id=item,
                frames=tuple(frames),
                kept_edit=edit_id,
                kept=provenance,
                overridden_edit=other_id,
                overridden=other.provenance,
                reason="last_write_wins",
            )
        )
    return conflicts


def undo_puts(
    state: SubjectState, forward: dict[Key, Any], prior: dict[Key, Any]
) -> tuple[dict[Key, Any], dict[Key, Any]]:
    """Values that undo an edit: ``prior`` for every key still as the edit left it.

    Returns
    -------
    restore
        ``{key: prior value}`` for keys whose current value equals what the edit wrote.
    skipped
        ``{key: current value}`` for keys another writer changed since (left as they are).
    """
    restore: dict[Key, Any] = {}
    skipped: dict[Key, Any] = {}
    for key, value in forward.items():
        current = state.get(key)
        if current == value:
            restore[key] = prior[key]
        else:
            skipped[key] = current
    return restore, skipped


def skipped_conflicts(
    skipped: dict[Key, Any], *, edit_id: str, provenance: Provenance, reason: str
) -> list[Conflict]:
    """Conflicts recording the keys an undo or redo left alone (``reason``
    ``"undo_skipped"`` or ``"redo_skipped"``)."""
    groups: dict[tuple[str, str, str | None, Provenance | None], list[Key]] = {}
    for key, value in skipped.items():
        target, item = _target(key)
        groups.setdefault((key[1], target, item, _value_prov(key, value)), []).append(key)
    out = []
    ordered = sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1], kv[0][2] or ""))
    for n, ((trial, target, item, kept), keys) in enumerate(ordered):
        frames = frames_to_ranges(k[3] for k in keys) if keys[0][0] == "flag" else []
        out.append(
            Conflict(
                id=f"{edit_id}/s{n}",
                trial=trial,
                target=target,
                item_id=item,
                frames=tuple(frames),
                kept_edit=None,
                kept=kept,
                overridden_edit=edit_id,
                overridden=provenance,
                reason=reason,
            )
        )
    return out
