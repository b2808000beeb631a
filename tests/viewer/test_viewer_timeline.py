"""The timeline: its tracks against the trial's own values, the strip's pixels, and the
selection edits (flag / unflag / accept / reject) written to the review record exactly."""

from __future__ import annotations

import html
import re

import numpy as np
import pytest

from addb_viewer.app.flags import build_view
from addb_viewer.app.paths import ReviewPaths
from addb_viewer.app.scene import plate_feet
from addb_viewer.app.timeline import TRACKS, TrackData, kinematic_contact, timeline_html, track_data
from addb_viewer.demo import DEMO_SUBJECT
from annotations import UNMEASURED_FORCE


@pytest.fixture(scope="module")
def demo_dynamics(tmp_path_factory: pytest.TempPathFactory):
    """The demo walk through the whole pipeline (proposals, plates assigned to the feet)."""
    from solver.pipeline import process_subject

    out = tmp_path_factory.mktemp("demo_dyn") / "out"
    process_subject(DEMO_SUBJECT, out)
    return out


@pytest.fixture
def dyn_paths(demo_dynamics, tmp_path, monkeypatch) -> ReviewPaths:
    import shutil

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    shutil.copytree(demo_dynamics, tmp_path / "out")
    return ReviewPaths.for_subject(DEMO_SUBJECT, tmp_path / "out")


def test_tracks_follow_the_trial(dyn_paths, make_app) -> None:
    app = make_app(dyn_paths)
    trial, view = app.trial, app.view
    data = track_data(trial, view, app.hicks)
    assert set(data.masks) == set(TRACKS)
    np.testing.assert_array_equal(data.masks["proposal"], view.proposed)
    np.testing.assert_array_equal(data.masks["over Hicks"], app.hicks)
    # measured force per foot: the vertical force of the plates assigned to that foot
    feet = plate_feet(trial)
    for foot in ("left", "right"):
        fy = sum(np.where(feet[i] == foot, np.nan_to_num(p.force[:, 1]), 0.0) for i, p in enumerate(trial.plates))
        expected = (fy > 20.0) & ~trial.unobserved
        np.testing.assert_array_equal(data.masks[f"force {foot}"], expected)
        assert expected.any()
    # kinematic contact covers most frames with measured force on that foot (stance)
    contact = kinematic_contact(trial, {f: data.masks[f"force {f}"] for f in ("left", "right")})
    for foot in ("left", "right"):
        loaded = data.masks[f"force {foot}"]
        assert contact[foot][loaded].mean() > 0.6, foot


def _blocks(html_text: str) -> list[dict]:
    """The positioned blocks of the strip: class, track, left/width (% of the trial), title."""
    out = []
    for m in re.finditer(r"<div class='(run|sel|playhead)'([^>]*)>", html_text):
        attrs = m.group(2)
        left = re.search(r"left:([\d.]+)%", attrs)
        width = re.search(r"width:(?:max\()?([\d.]+)%", attrs)
        track = re.search(r"data-track='([^']+)'", attrs)
        title = re.search(r"title='([^']*)'", attrs)
        out.append({"kind": m.group(1), "track": track.group(1) if track else None,
                    "left": float(left.group(1)), "width": float(width.group(1)) if width else 0.0,
                    "title": html.unescape(title.group(1)) if title else ""})  # fmt: skip
    return out


def test_strip_places_runs_playhead_and_selection_by_frame_with_tooltips() -> None:
    n = 2000
    state = np.zeros(n, np.int8)
    state[100:200] = 1
    state[300:310] = 2
    masks = {name: np.zeros(n, bool) for name in TRACKS}
    masks["flag left"][1000:1500] = True
    masks["flag right"][6] = True  # one frame: "frame 6", not "frames 6–6"
    masks["proposal"] = state > 0
    reasons = tuple("calcn_l in contact with no plate force" if 100 <= k < 200 else "" for k in range(n))
    text = timeline_html(TrackData(masks, state), reasons=reasons, frame=1999, selection=(40, 61))
    blocks = _blocks(text)
    flag = [b for b in blocks if b["track"] == "flag left"]
    assert len(flag) == 1 and flag[0]["left"] == pytest.approx(50.0) and flag[0]["width"] == pytest.approx(25.0)
    assert flag[0]["title"] == "flag left, frames 1000–1499"
    assert [b["title"] for b in blocks if b["track"] == "flag right"] == ["flag right, frame 6"]
    props = {b["title"] for b in blocks if b["track"] == "proposal"}
    assert props == {"proposal (pending), frames 100–199: calcn_l in contact with no plate force",
                     "proposal (accepted), frames 300–309: no reason given"}  # fmt: skip
    sel = next(b for b in blocks if b["kind"] == "sel")
    assert sel["left"] == pytest.approx(2.0) and sel["width"] == pytest.approx(21 / 20)
    head = next(b for b in blocks if b["kind"] == "playhead")
    assert head["left"] == pytest.approx(100 * 1999.5 / 2000) and head["title"] == "frame 1999"
    assert all(name in text for name in TRACKS)  # every track is labelled
    assert not [b for b in blocks if b["track"] not in (None, "flag left", "flag right", "proposal")]


def test_selection_edits_write_exactly_the_selected_frames(dyn_paths, make_app) -> None:
    app = make_app(dyn_paths)
    app.select(40, 20)  # either order
    assert app.playback.selection() == (20, 41)
    assert tuple(app.panel.selection.value) == (20, 40)
    app.panel.foot.value = "left"
    app.selection_edit("Flag")
    assert np.flatnonzero(app.store.mask("walk", app.trial.n_frames)).tolist() == list(range(20, 41))
    assert app.panel.saved.content.startswith("✓ saved: flag frames 20–40 (left foot) on walk")  # the foot named
    assert np.flatnonzero(app.tracks.masks["flag left"]).tolist() == list(range(20, 41))
    assert not app.tracks.masks["flag right"].any()
    app.playback.seek(200, now=0.0)
    app.mark("Set in")  # past the selected range's end: a new range at frame 200, not 20-200
    assert app.playback.selection() == (200, 201) and tuple(app.panel.selection.value) == (200, 200)
    app.mark("Clear marks")
    assert app.playback.selection() is None and tuple(app.panel.selection.value) == (0, 0)  # thumbs too
    app.select(30, 34)
    app.selection_edit("Unflag")
    assert np.flatnonzero(app.store.mask("walk", app.trial.n_frames)).tolist() == [*range(20, 30), *range(35, 41)]
    # proposals: accept one part of a pending run, reject another
    pending = np.flatnonzero(app.view.pending)
    assert pending.size > 10
    a, b = int(pending[0]), int(pending[0]) + 3
    app.select(a, b)
    app.selection_edit("Accept")
    view = build_view(app.store.review("walk"), app.trial.proposed)
    assert view.accepted[a : b + 1].all() and not view.pending[a : b + 1].any()
    app.select(b + 1, b + 2)
    app.selection_edit("Reject")
    view = build_view(app.store.review("walk"), app.trial.proposed)
    assert view.rejected[b + 1 : b + 3].all() and not view.rejected[: b + 1].any()
    assert app.tracks.proposal_state[a] == 2 and app.tracks.proposal_state[b + 1] == 3
    mask = app.store.mask("walk", app.trial.n_frames, kind=UNMEASURED_FORCE)
    assert mask[a : b + 1].all() and not mask[b + 1 : b + 3].any()


def test_selection_hotkeys_edit_the_selection(dyn_paths, make_app) -> None:
    """The G and X commands run the same edits as the buttons (their trigger handlers); U and
    Shift+U undo and redo, P jumps to the next pending proposal."""
    from addb_viewer.app.panel import HOTKEYS

    def press(label: str) -> None:
        for cb in app.panel.commands[label]._impl.trigger_cb:  # as viser calls them
            cb(type("Event", (), {"client_id": None, "client": None})())

    app = make_app(dyn_paths)
    assert HOTKEYS["Flag selection"][0] == "G" and HOTKEYS["Unflag selection"][0] == "X"
    assert HOTKEYS["Redo"][0] == "shift+U" and HOTKEYS["Next proposal"][0] == "P"
    redo = app.panel.commands["Redo"]
    assert (redo.hotkey, redo.modifier) == ("U", "shift")
    app.select(50, 59)
    press("Flag selection")
    assert np.flatnonzero(app.store.mask("walk", app.trial.n_frames)).tolist() == list(range(50, 60))
    press("Undo")
    assert not app.store.mask("walk", app.trial.n_frames).any()
    press("Redo")
    assert np.flatnonzero(app.store.mask("walk", app.trial.n_frames)).tolist() == list(range(50, 60))
    app.playback.seek(0, now=0.0)
    press("Next proposal")
    pending = app.view.pending
    run_starts = [i for i in range(1, pending.size) if pending[i] and not pending[i - 1]]
    assert run_starts and app.playback.frame == run_starts[0]  # the next pending run after frame 0


def test_one_press_is_one_undo_step_and_undo_names_it(dyn_paths, make_app) -> None:
    """Z over a selection with several pending runs saves one note per run; U brings back all
    of them (it brought back the last run only, as three presses of Z would), Shift+U rejects
    them again, and the saved line names what was undone."""
    app = make_app(dyn_paths)
    from addb_viewer.app.flags import true_runs

    pending = app.view.pending
    starts = [s for s, _ in true_runs(pending)]
    assert len(starts) >= 2, starts
    end = starts[1] + 1  # the selection reaches into the second run
    app.select(0, end)
    app.selection_edit("Reject")
    rejected = app.view.rejected.copy()
    assert rejected[starts[0]] and rejected[starts[1]] and int(rejected.sum()) > 1
    app.history("Undo")
    assert not app.view.rejected.any() and np.array_equal(app.view.pending, pending)
    assert f"undo (reject proposals in frames 0–{end})" in app.panel.saved.content, app.panel.saved.content
    app.history("Redo")
    assert np.array_equal(app.view.rejected, rejected)
    app.history("Redo")
    assert "Nothing to redo" in app.panel.saved.content and np.array_equal(app.view.rejected, rejected)
    app.history("Undo")
    app.history("Undo")
    assert not app.view.rejected.any()
    assert "Nothing to undo" in app.panel.saved.content


def test_a_refusal_is_taken_back_once_the_reviewer_acts_on_it(dyn_paths, make_app) -> None:
    """"Select frames first" went on standing beside a selection made since; a saved edit's
    line stays (it says what is in the record)."""
    from addb_viewer.app.panel import NO_EDITS

    app = make_app(dyn_paths)
    app.selection_edit("Flag")
    assert "Select frames on the timeline first" in app.panel.saved.content
    app.select(10, 12)
    assert app.panel.saved.content == NO_EDITS
    app.selection_edit("Flag")
    saved = app.panel.saved.content
    assert saved.startswith("✓ saved: flag frames 10–12")
    app.mark("Clear marks")
    app.load_trial("walk")
    assert app.panel.saved.content == saved


def test_a_trial_without_plates_is_said_to_be_kinematics_only(dyn_paths, make_app) -> None:
    """The static trial has no force plates: its status line said "no dynamics yet
    (residuals appear after a Reprocess…)", which no Reprocess would change."""
    app = make_app(dyn_paths)
    app.load_trial("static")
    assert "no force plates in this trial: kinematics only" in app.panel.status.content, app.panel.status.content
    titles = [c.handle.title for c in app.plots.charts]
    assert not any("no dynamics yet" in x for x in titles) and any("kinematics only" in x for x in titles), titles
    app.load_trial("walk")
    assert "residual" in app.panel.status.content and "no force plates" not in app.panel.status.content


def test_flags_edited_since_the_fit_are_said_to_differ_from_it(dyn_paths, make_app) -> None:
    """After a flag (or an Undo after a Reprocess) the results on screen were fitted with
    other flags: the Flags folder says so and how many frames differ, until the flags match
    the fit again (the explorer saw nothing say it after an Undo)."""
    app = make_app(dyn_paths)
    assert "fitted with other flags" not in app.panel.proposal_info.content  # the solver's own choice
    frame = int(np.flatnonzero(~app.view.proposed & ~app.trial.unobserved)[0])
    app.select(frame, frame + 4)
    app.selection_edit("Flag")
    info = app.panel.proposal_info.content
    # the flags now replace every proposal: 5 new frames, and the proposals no longer left out
    n = 5 + int(app.trial.unobserved.sum())
    assert f"fitted with other flags**</span> ({n} frames differ)" in info, info
    app.history("Undo")
    assert "fitted with other flags" not in app.panel.proposal_info.content
    # accepting every proposal leaves out what the fit left out: nothing differs
    app.edit("accept all", lambda ed, _k, _f: ed.accept())
    assert np.array_equal(app.view.flagged, app.trial.proposed)
    assert np.array_equal(app.trial.unobserved, app.trial.proposed)  # the demo's fit left out its proposals
    assert "fitted with other flags" not in app.panel.proposal_info.content


def test_a_jump_from_the_start_of_the_only_run_says_so(dyn_paths, make_app) -> None:
    """N with one flagged run, from its first frame: the search goes round to that run; it
    did nothing and said nothing (the last message stood)."""
    app = make_app(dyn_paths)
    app.select(30, 40)
    app.selection_edit("Flag")
    app.seek(30)
    app.jump("Flagged")
    assert app.playback.frame == 30
    assert app.panel.saved.content == "Frame 30 starts the only run of flagged frames in this trial."
    app.seek(50)
    app.jump("Flagged")  # from elsewhere: to the run, and the line above is taken back
    assert app.playback.frame == 30 and not app.panel.saved.content.startswith("Frame 30")


def test_the_selection_stays_when_the_trial_is_loaded_again(dyn_paths, make_app) -> None:
    """A Reprocess or the background run reloads the trial shown: the in and out points the
    reviewer set stay (they went, and the next G flagged one frame); another trial starts
    without them."""
    app = make_app(dyn_paths)
    app.select(40, 50)
    app.load_trial("walk", frame=45)
    assert app.playback.selection() == (40, 51) and tuple(app.panel.selection.value) == (40, 50)
    assert "frames 40–50" in app.panel.selection_info.content
    app.mark("Clear marks")
    app.mark("Set in")  # the in point alone (between I and O)
    app.load_trial("walk", frame=45)
    assert app.playback.selection() == (45, 46)
    app.load_trial("static")
    assert app.playback.selection() is None


def test_an_undo_that_another_writer_overlapped_says_what_it_left(dyn_paths, make_app) -> None:
    """Ana flags 180-190 (right foot) here, Cleo 185-195 (left foot) from another process on
    the same record; Ana's Undo cannot restore 185-190 without removing Cleo's flags: the
    store keeps them, and the saved line says which frames and whose (it said only
    "✓ saved: undo")."""
    from annotations import AnnotationStore

    app = make_app(dyn_paths)
    app.panel.foot.value = "right"
    app.select(180, 190)
    app.selection_edit("Flag")
    with AnnotationStore.open(app.paths.annotations, reviewer="cleo") as other:
        other.set_unmeasured("walk", range(185, 196), True, foot="left", keep_other_foot=True)
    assert app.store.refresh()
    app.history("Undo")
    saved = app.panel.saved.content
    assert "not all restored" in saved and "kept as cleo edited them since" in saved, saved
    assert "frames 185–190" in saved, saved
