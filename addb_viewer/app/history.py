"""The review app's undo history by reviewer action (no viser).

The review record (:class:`annotations.AnnotationStore`) undoes and redoes one edit at a
time, with one history for the whole server: every page, every reviewer of a team server
and every trial of the subject. A reviewer's one press may save several edits (Z over three
runs of proposals saves three notes, X for one foot over a range of "both" flags two), and
the last edit may be another reviewer's or on a trial that page does not show. This module
keeps, beside the store's history, who made each action, on which trial and with how many
edits, so that Undo takes back exactly the reviewer's last press or refuses, naming whose
it is (:meth:`ReviewApp.history <addb_viewer.app.server.ReviewApp.history>`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from annotations import Edit

#: Actions remembered: the store's own undo depth (its default ``max_undo``).
KEPT = 10_000


@dataclass(frozen=True)
class Action:
    """One reviewer action in the history: who made it (``reviewer``), on which ``trial``,
    how many of the store's ``edits`` it saved (undone and redone together) and ``what``
    it was (as the page said it: "flag frames 20–40")."""

    reviewer: str
    trial: str
    edits: int
    what: str


class ActionHistory:
    """The actions the store can undo (oldest first) and those it can redo."""

    def __init__(self) -> None:
        self.undo: list[Action] = []
        self.redo: list[Action] = []

    def clear(self) -> None:
        """Forget every action (a new store: a new history)."""
        self.undo, self.redo = [], []

    def record(self, edits: list[Edit], what: str) -> None:
        """Note one action that saved ``edits`` (in the store's order): the edits that changed
        a trial (not trial information, not no-ops) make one undo step; a new action
        empties the redo list, as the store's does."""
        kept = [e for e in edits if e.trial is not None and e.changed and e.op not in ("none", "trial_info")]
        if kept:
            self.undo.append(Action(kept[-1].provenance.reviewer, kept[-1].trial, len(kept), what))
            self.redo.clear()
        del self.undo[:-KEPT]

    def last(self, undo: bool) -> Action | None:
        """The action Undo (``undo``) or Redo would take back next; None when unknown (the
        store may still hold edits from before this history, taken one at a time)."""
        stack = self.undo if undo else self.redo
        return stack[-1] if stack else None

    def step(self, store_step: Callable[[], Edit | None], undo: bool) -> list[Edit]:
        """Undo (``undo``) or redo the next action: ``store_step`` (the store's ``undo`` or
        ``redo``) as many times as the action saved edits (once when it is unknown); the
        action moves to the other list when anything was undone. Returns the store's
        edits (empty: nothing to undo or redo)."""
        stack, other = (self.undo, self.redo) if undo else (self.redo, self.undo)
        action = stack[-1] if stack else None
        done = []
        for _ in range(action.edits if action is not None else 1):
            e = store_step()
            if e is None:
                break
            done.append(e)
        if done and stack:
            other.append(stack.pop())
        return done
