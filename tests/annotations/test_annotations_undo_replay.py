"""Property tests: undo/redo returns to the same state; journal replay is idempotent."""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

from annotation_support import StepClock
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, invariant, precondition, rule

from annotations import ACTIVITY_LABELS, AnnotationStore
from annotations.journal import read_header, scan
from annotations.state import SubjectState

TRIALS = st.sampled_from(["walk", "run"])
FEET = st.sampled_from(["left", "right", "both", None])
FRAMES = st.one_of(
    st.integers(0, 40),
    st.tuples(st.integers(0, 40), st.integers(1, 15)).map(lambda t: range(t[0], t[0] + t[1])),
    st.lists(st.integers(0, 40), min_size=1, max_size=6),
)


class UndoRedo(RuleBasedStateMachine):
    """Random edits, undos, redos and reopenings of one store, against a stack of snapshots."""

    def __init__(self) -> None:
        super().__init__()
        self.folder = Path(tempfile.mkdtemp(prefix="addb-undo-"))
        self.clock = StepClock()
        self.store = self._open()
        self.past: list[dict] = []  # snapshot before each undoable edit
        self.future: list[dict] = []  # snapshot before each undo, for redo

    def _open(self) -> AnnotationStore:
        return AnnotationStore.open(self.folder, reviewer="prop", clock=self.clock, compact_every=7)

    def _edited(self, before: dict, edit) -> None:
        if edit.changed:
            self.past.append(before)
            self.future.clear()
        else:
            assert self.store.snapshot() == before

    @rule(trial=TRIALS, frames=FRAMES, value=st.booleans(), foot=FEET)
    def unmeasured(self, trial, frames, value, foot) -> None:
        before = self.store.snapshot()
        self._edited(
            before, self.store.set_unmeasured(trial, frames, value, foot=foot if value else None)
        )

    @rule(trial=TRIALS, frames=FRAMES, value=st.booleans())
    def excluded(self, trial, frames, value) -> None:
        before = self.store.snapshot()
        self._edited(before, self.store.set_excluded(trial, frames, value))

    @rule(
        trial=TRIALS,
        start=st.integers(0, 30),
        length=st.integers(1, 20),
        label=st.sampled_from(ACTIVITY_LABELS),
        note=st.text(max_size=8),
    )
    def activity(self, trial, start, length, label, note) -> None:
        before = self.store.snapshot()
        self._edited(
            before, self.store.add_activity(trial, start, start + length, label, note=note)
        )

    @rule(trial=TRIALS, data=st.data())
    def change_or_remove_activity(self, trial, data) -> None:
        acts = self.store.activities(trial)
        if not acts:
            return
        target = data.draw(st.sampled_from(acts))
        before = self.store.snapshot()
        if data.draw(st.booleans()):
            edit = self.store.update_activity(
                trial, target.id, label=data.draw(st.sampled_from(ACTIVITY_LABELS))
            )
        else:
            edit = self.store.remove_activity(trial, target.id)
        self._edited(before, edit)

    @rule(trial=TRIALS, reviewed=st.booleans())
    def reviewed(self, trial, reviewed) -> None:
        before = self.store.snapshot()
        self._edited(before, self.store.set_reviewed(trial, reviewed))

    @rule(trial=TRIALS, text=st.text(max_size=10))
    def note(self, trial, text) -> None:
        before = self.store.snapshot()
        self._edited(before, self.store.add_note(trial, text))

    @rule()
    def undo(self) -> None:
        before = self.store.snapshot()
        edit = self.store.undo()
        if not self.past:
            assert edit is None
            return
        assert edit is not None and not edit.conflicts
        assert self.store.snapshot() == self.past.pop()
        self.future.append(before)

    @rule()
    def redo(self) -> None:
        before = self.store.snapshot()
        edit = self.store.redo()
        if not self.future:
            assert edit is None
            return
        assert edit is not None and not edit.conflicts
        assert self.store.snapshot() == self.future.pop()
        self.past.append(before)

    @precondition(lambda self: True)
    @rule()
    def reopen(self) -> None:
        before = self.store.snapshot()
        self.store.close()
        self.store = self._open()
        assert self.store.snapshot() == before
        assert not self.store.can_undo and not self.store.can_redo
        self.past.clear()
        self.future.clear()

    @invariant()
    def a_second_reader_sees_the_same_state(self) -> None:
        if len(self.past) % 5 == 0:  # not every step: it costs an open
            other = AnnotationStore.open(self.folder, reviewer="reader")
            assert other.snapshot() == self.store.snapshot()
            other.close()

    def teardown(self) -> None:
        self.store.close()
        shutil.rmtree(self.folder, ignore_errors=True)


UndoRedo.TestCase.settings = settings(
    max_examples=25,
    stateful_step_count=30,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
TestUndoRedo = UndoRedo.TestCase


def _journal_ops(folder: Path):
    import os

    path = folder / "annotations.journal"
    fd = os.open(path, os.O_RDONLY)
    try:
        _jid, base, header = read_header(fd, path)
        data = os.pread(fd, os.fstat(fd).st_size - header, header)
    finally:
        os.close(fd)
    return scan(data, path=path, first_line=2, next_seq=base + 1).ops


@given(
    st.lists(st.tuples(TRIALS, FRAMES, st.booleans(), FEET), min_size=1, max_size=25),
    st.integers(0, 3),
)
@settings(max_examples=30, deadline=None)
def test_replay_is_idempotent(edits, n_undo: int) -> None:
    folder = Path(tempfile.mkdtemp(prefix="addb-replay-"))
    try:
        store = AnnotationStore.open(
            folder, reviewer="prop", clock=StepClock(), compact_every=10**6
        )
        for trial, frames, value, foot in edits:
            store.set_unmeasured(trial, frames, value, foot=foot if value else None)
        for _ in range(n_undo):
            store.undo()
        ops = _journal_ops(folder)
        assert [op.seq for op in ops] == list(range(1, len(ops) + 1))

        def replay(sequence) -> dict:
            state = SubjectState()
            for op in sequence:
                state.apply(op)
            return {t: state.review(t) for t in state.trial_names()}

        once = replay(ops)
        assert once == store.snapshot()
        assert replay([op for op in ops for _ in range(2)]) == once  # each op applied twice
        assert replay(ops + ops) == once  # the whole journal replayed again
        store.close()
        reopened = AnnotationStore.open(folder, reviewer="prop")
        assert reopened.snapshot() == once
        reopened.close()
    finally:
        shutil.rmtree(folder, ignore_errors=True)
