"""What README.md's "Reviewing a dataset (reviewer's guide)" promises a reviewer and no
other test checked, on a dataset of two shared subjects (``labA/walk``, ``labB/run``)
processed once by ``addb process`` and copied for each test:

* the keys the guide names: Ctrl+K lists each of them with its command; in the page, P
  jumps to the next pending proposal, I / L / O select frames, Y accepts and Z rejects the
  proposals inside, U undoes and Shift+U redoes, each written to the review record on disk;
  H jumps from range to range of frames over Hicks' limits; R opens the next trial that
  is not reviewed, in queue order;
* G flags for the foot chosen under Flags (after the Foot list, a click in the 3D view gives
  the keys back to the page), and the flag survives ``addb view`` killed (SIGKILL): the next
  ``addb view`` shows it in its timeline and Flags folder;
* Space plays and stops from the 3D view, and a focused checkbox takes it instead;
* Undo reaches only the edits made since the subject was opened (another subject starts a
  new history, also on coming back);
* the pages of one ``addb view`` share one view: a trial opened on one page is open on every
  page.

The browser tests drive Debian's Chromium with Playwright as tests/viewer/test_viewer_browser.py
does (they fail under ``CI=true`` when Chromium or Playwright is missing).
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from viewer_support import ViewProcess

from addb_viewer.app.flags import REJECTED_NOTE, true_runs
from addb_viewer.app.paths import ReviewPaths
from addb_viewer.app.queue import dataset_subjects
from addb_viewer.app.workbench import Workbench
from addb_viewer.cli import main as cli
from addb_viewer.locations import annotations_path
from annotations import AnnotationStore
from tests.conftest import SHARED_DATA, import_tool, needs_tool, tool_available, writable_copy

CHROMIUM = "/usr/bin/chromium"
PLAYWRIGHT_REASON = "the playwright package (test extra) is not installed"
ARGS = [
    "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]  # fmt: skip
SUBJECTS = {"labA/walk": "rajagopal2016_walk", "labB/run": "rajagopal2016_run"}
WALK_SHOWN = re.compile(r"labA/walk · walk · frame 0 / 237")  # the page's status line at the start
REPROCESS_TIMEOUT_S = 300

BROWSER_MARKS = [
    pytest.mark.browser,
    needs_tool("chromium", Path(CHROMIUM).exists(), f"{CHROMIUM} is not installed (Debian: apt-get install chromium)"),
    needs_tool("playwright", tool_available("playwright"), PLAYWRIGHT_REASON),
]


def _browser_test(fn):
    for mark in reversed(BROWSER_MARKS):
        fn = mark(fn)
    return fn


@pytest.fixture(scope="module")
def processed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The dataset (``labA/walk``, ``labB/run``) and its output tree ``addb_out``, processed once."""
    ds = tmp_path_factory.mktemp("guide") / "ds"
    for rel, name in SUBJECTS.items():
        writable_copy(SHARED_DATA / "subjects" / name, ds / rel)
    assert cli(["process", str(ds), "--out", str(ds / "addb_out"), "--workers", "1"]) == 0
    return ds


@pytest.fixture
def dataset(processed: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A private copy of the processed dataset (its review records go into it)."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    return Path(shutil.copytree(processed, tmp_path / "ds"))


def _subject(dataset: Path, rel: str):
    _, _, subjects = dataset_subjects(dataset)
    return next(s for s in subjects if s.rel == rel)


def _bench(dataset: Path, make_app) -> tuple[object, Workbench]:
    """The review app on labA/walk's walk with the dataset queue (no background processing)."""
    walk = _subject(dataset, "labA/walk")
    app = make_app(ReviewPaths.for_subject(walk.subject_dir, walk.out_dir), process_missing=False)
    app.load_trial("walk")
    bench = Workbench(app, dataset, workers=0)
    bench.current = ("labA/walk", "walk")
    return app, bench


def _press(command) -> None:
    """Trigger a command of the palette as viser does when its hotkey is pressed."""
    for cb in command._impl.trigger_cb:
        cb(type("Event", (), {"client_id": None, "client": None})())


def _record(dataset: Path, rel: str) -> AnnotationStore:
    """The subject's review record as on disk now (a second reader)."""
    s = _subject(dataset, rel)
    return AnnotationStore.open(annotations_path(s.subject_dir, s.out_dir), reviewer="checker")


# ---------------------------------------------------------------------------- no browser
def test_h_jumps_from_range_to_range_of_frames_over_hicks_limits(dataset: Path, make_app) -> None:
    """README: "**N**, **P** and **H** jump to the next flagged range, pending proposal and
    range over Hicks' limits" (the timeline's track of frames with measured force over
    Hicks' per-frame limits). The walk's own fit has none (H says so); reviewed with every
    proposal rejected and reprocessed, the walk's foot contacts off the plates are fitted
    as measured and H visits each range of that track in turn."""
    from addb_viewer.app.panel import HOTKEYS
    from addb_viewer.app.summary import hicks_exceeded
    from solver.results import load_processed

    assert HOTKEYS["Next frame over Hicks threshold"][0] == "H"
    walk = _subject(dataset, "labA/walk")
    app = make_app(ReviewPaths.for_subject(walk.subject_dir, walk.out_dir), process_missing=False)
    hotkey_h = app.panel.commands["Next frame over Hicks threshold"]
    assert not app.tracks.masks["over Hicks"].any()
    _press(hotkey_h)
    assert app.playback.frame == 0
    assert app.panel.saved.content == "No frame with measured force over Hicks' per-frame limits in this trial."

    app.edit("reject all", lambda ed, _k, _f: ed.reject())
    app.set_reviewed(True)
    assert app.store.is_reviewed("walk")
    app.jobs.reprocess()
    assert app.jobs.finished.wait(REPROCESS_TIMEOUT_S) and app.jobs.last_result.status == "done", app.panel.job_status.content
    over = hicks_exceeded(load_processed(app.paths.out_dir, "walk"))
    np.testing.assert_array_equal(app.tracks.masks["over Hicks"], over)
    starts = [s for s, _ in true_runs(over)]
    assert len(starts) >= 3 and starts[0] > 0, starts
    app.seek(0)
    visited = []
    for _ in starts:
        _press(hotkey_h)
        visited.append(app.playback.frame)
    assert visited == starts
    _press(hotkey_h)  # past the last range: round to the first
    assert app.playback.frame == starts[0]


def test_r_opens_the_next_trial_not_reviewed_in_queue_order(dataset: Path, make_app) -> None:
    """README: "**Next trial to review** (or **R**) opens the next unreviewed one", the queue
    "sorted so that what needs you comes first". With labA/walk's static marked reviewed by
    alice, R from the walk opens the run, the run's static, then the walk again: never the
    reviewed trial, each opened in the page (subject and trial)."""
    walk = _subject(dataset, "labA/walk")
    with AnnotationStore.open(annotations_path(walk.subject_dir, walk.out_dir), reviewer="alice") as store:
        store.set_reviewed("static")
    app, bench = _bench(dataset, make_app)
    assert bench.command.hotkey == "R" and bench.command.modifier is None
    assert [(r.subject.rel, r.trial) for r in bench.rows if r.needs_review] == [
        ("labA/walk", "walk"), ("labB/run", "run"), ("labB/run", "static")]  # fmt: skip
    opened = []
    for _ in range(3):
        _press(bench.command)
        opened.append((app.paths.subject_dir.name, app.trial.trial, bench.current))
    assert opened == [
        ("run", "run", ("labB/run", "run")),
        ("run", "static", ("labB/run", "static")),
        ("walk", "walk", ("labA/walk", "walk")),
    ]


def test_undo_does_not_reach_edits_made_before_the_subject_was_opened(dataset: Path, make_app) -> None:
    """README: "Undo reaches the edits made since the subject was opened (...; another
    subject starts a new history)". A flag on the walk, then the run opened: Undo takes back
    nothing, and neither does it once the walk is opened again; the flag stays on disk."""
    app, bench = _bench(dataset, make_app)
    app.select(100, 109)
    app.selection_edit("Flag")
    assert app.panel.saved.content.startswith("✓ saved: flag frames 100–109 (both feet) on walk")
    bench.open("labB/run")
    assert (app.paths.subject_dir.name, app.trial.trial) == ("run", "run")
    nothing = "Nothing to undo: the history holds the edits made since this subject was opened"
    app.history("Undo")
    assert app.panel.saved.content.startswith(nothing), app.panel.saved.content
    bench.open("labA/walk", "walk")
    app.history("Undo")
    assert app.panel.saved.content.startswith(nothing), app.panel.saved.content
    with _record(dataset, "labA/walk") as disk:
        assert disk.ranges("walk") == [(100, 110)]


# ---------------------------------------------------------------------------- in the browser
@pytest.fixture
def served(dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """``addb view DATASET_DIR`` in a subprocess (no background processing, no warm solver
    child, so that a SIGKILL leaves no process behind); stopped cleanly unless killed."""
    monkeypatch.setenv("ADDB_WARM_SOLVER", "0")
    views: list[ViewProcess] = []

    def start() -> ViewProcess:
        view = ViewProcess([str(dataset), "--port", "0", "--workers", "0", "--reviewer", "e2e"], tmp_path)
        views.append(view)
        return view

    yield start
    for view in views:
        if view.proc.poll() is None:
            view.stop()
        assert "Traceback" not in view.output, view.output


def _page(chromium, url: str, *, queue: bool = False):
    """A 1600 x 1000 page showing labA/walk's walk with the focus in the 3D view; ``queue``:
    with viser's WebGL notice closed, which covers the queue's controls in software WebGL."""
    from test_viewer_workbench_browser import _close_webgl_notice

    page = chromium.new_page(viewport={"width": 1600, "height": 1000})
    page.goto(url)
    page.get_by_text(WALK_SHOWN).first.wait_for(timeout=60_000)
    if queue:
        _close_webgl_notice(page)
    page.mouse.click(800, 900)  # the 3D view, below the queue's window: the keys act
    return page


def _saved(page, pattern: str) -> None:
    page.get_by_text(re.compile(pattern)).first.wait_for(timeout=20_000)


def _keyed_selection(page, start: int, stop: int) -> None:
    """Select frames ``start``-``stop`` of the walk (237 frames) with the keys alone, the
    playhead at ``start``: I, L pressed ``stop - start`` times, O; waits for the page to
    show the playhead at ``stop`` and the selection."""
    page.keyboard.press("i")
    for _ in range(stop - start):
        page.keyboard.press("l")
    page.get_by_text(f"labA/walk · walk · frame {stop} / 237").wait_for(timeout=20_000)
    page.keyboard.press("o")
    n = stop - start + 1
    page.get_by_text(re.compile(rf"^Selected: frames {start}–{stop} \({n} frames\)")).wait_for(timeout=20_000)


def _edit_next_proposal(page, key: str, start: int, stop: int, verb: str) -> None:
    """P to the next pending proposal (it must start at ``start``), frames ``start``-``stop``
    selected with the keys, then ``key`` (Y accepts, Z rejects); waits for the page's saved
    line naming ``verb`` ("accept" or "reject") and the frames."""
    page.keyboard.press("p")
    page.get_by_text(f"labA/walk · walk · frame {start} / 237").wait_for(timeout=20_000)
    _keyed_selection(page, start, stop)
    page.keyboard.press(key)
    _saved(page, rf"✓ saved: {verb} proposals in frames {start}–{stop} on walk — e2e")


@_browser_test
def test_ctrl_k_lists_every_key_of_the_guide_with_its_command(served) -> None:
    """README: "Every key is listed in the command palette (Ctrl+K)": I, O, G, X, Y, Z, N, P,
    H, U, Shift+U and R, each beside the command the guide gives it."""
    sync_api = import_tool("playwright.sync_api", reason=PLAYWRIGHT_REASON)
    view = served()
    expected = {
        "Set in point": "I", "Set out point": "O", "Flag selection": "G", "Unflag selection": "X",
        "Accept selection": "Y", "Reject selection": "Z", "Next flagged frame": "N", "Next proposal": "P",
        "Next frame over Hicks threshold": "H", "Undo": "U", "Redo": "Shift+U", "Next trial to review": "R",
    }  # fmt: skip
    with sync_api.sync_playwright() as p:
        chromium = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            page = _page(chromium, view.url)
            page.keyboard.press("Control+k")
            actions = page.locator(".mantine-Spotlight-action")
            actions.first.wait_for(timeout=20_000)
            listed = {}
            for text in actions.all_inner_texts():
                label, _, description = text.strip().partition("\n")
                m = re.search(r"\(([^()]+)\)$", description.strip())
                listed[label.strip()] = m.group(1) if m else None
            assert {label: listed.get(label) for label in expected} == expected, listed
        finally:
            chromium.close()


@_browser_test
def test_keys_jump_select_accept_reject_undo_and_redo_proposals_in_the_record(served, dataset: Path) -> None:
    """README: "press **I** and **O** (...) to choose frames, then (...) **Y** accepts and **Z**
    rejects the proposals inside; **N**, **P** (...) jump to the next (...) pending proposal;
    **U** undoes your last edit and **Shift+U** redoes it"; "Every edit is saved at once,
    with your name, in the subject's review record". All by keys in the page, the record read
    from disk after each."""
    sync_api = import_tool("playwright.sync_api", reason=PLAYWRIGHT_REASON)
    view = served()
    with _record(dataset, "labA/walk") as disk:
        assert disk.flag_runs("walk") == [] and disk.notes("walk") == []
    with sync_api.sync_playwright() as p:
        chromium = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            page = _page(chromium, view.url)
            # the walk's pending proposals are frames 0-44 and 199-237: P from frame 0 goes to 199
            _edit_next_proposal(page, "y", 199, 203, "accept")
            with _record(dataset, "labA/walk") as disk:
                runs = [(r.start, r.stop, r.provenance.source, r.provenance.reviewer) for r in disk.flag_runs("walk")]
                assert runs == [(199, 204, "proposal_accepted", "e2e")]
            # the next pending proposal now starts right after the accepted frames
            _edit_next_proposal(page, "z", 204, 206, "reject")
            with _record(dataset, "labA/walk") as disk:
                notes = disk.notes("walk")
                assert [(n.start, n.stop, n.provenance.reviewer) for n in notes] == [(204, 207, "e2e")]
                assert notes[0].text.startswith(REJECTED_NOTE)
            page.keyboard.press("u")
            _saved(page, r"✓ saved: undo \(reject proposals in frames 204–206\) on walk")
            with _record(dataset, "labA/walk") as disk:
                assert disk.notes("walk") == [] and len(disk.flag_runs("walk")) == 1
            page.keyboard.press("Shift+U")
            _saved(page, r"✓ saved: redo \(reject proposals in frames 204–206\) on walk")
            with _record(dataset, "labA/walk") as disk:
                assert [(n.start, n.stop) for n in disk.notes("walk")] == [(204, 207)]
                assert [(r.start, r.stop) for r in disk.flag_runs("walk")] == [(199, 204)]
        finally:
            chromium.close()


@_browser_test
def test_a_flag_keyed_for_the_chosen_foot_survives_addb_view_killed(served, dataset: Path) -> None:
    """README: "**G** flags them (for the foot chosen under Flags)"; "after clicking (...) a
    list (... Foot), click the 3D view before pressing them"; "Every edit is saved at once".
    Foot "left" picked in its list, frames 0-9 selected with I / L / O and flagged with G;
    ``addb view`` killed with SIGKILL (no clean exit); the next ``addb view`` shows the left
    foot's flag on its timeline and counts it in the Flags folder."""
    sync_api = import_tool("playwright.sync_api", reason=PLAYWRIGHT_REASON)
    first = served()
    with sync_api.sync_playwright() as p:
        chromium = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            page = _page(chromium, first.url)
            page.get_by_label("Foot", exact=True).click()
            page.get_by_role("option", name="left", exact=True).click()
            page.mouse.click(800, 900)  # the list had the focus: the 3D view gets it back
            _keyed_selection(page, 0, 9)
            page.keyboard.press("g")
            _saved(page, r"✓ saved: flag frames 0–9 \(left foot\) on walk — e2e")
            first.proc.kill()  # a crash: no store closed, nothing flushed at exit
            assert first.proc.wait(30) != 0

            second = served()
            page = _page(chromium, second.url)
            tips = page.locator("div.run[data-track='flag left']")
            assert tips.count() == 1 and tips.first.get_attribute("title") == "flag left, frames 0–9"
            assert page.locator("div.run[data-track='flag right']").count() == 0
            page.get_by_text("10 frames flagged (10 left, 0 right)").first.wait_for(timeout=20_000)
        finally:
            chromium.close()
    with _record(dataset, "labA/walk") as disk:
        assert disk.ranges("walk", foot="left") == [(0, 10)] and disk.ranges("walk", foot="right") == []
        assert disk.flag("walk", 5).provenance.reviewer == "e2e"


@_browser_test
def test_a_trial_opened_on_one_page_is_open_on_every_page(served) -> None:
    """README: "The pages of one ``addb view`` share one view (opening a trial on one page
    opens it on every page: a team reviewing together)". Page A opens labB/run's run from
    the queue; page B shows it. Page B picks the run's static in its Trial list; page A
    shows that."""
    sync_api = import_tool("playwright.sync_api", reason=PLAYWRIGHT_REASON)
    view = served()
    with sync_api.sync_playwright() as p:
        chromium = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            a = _page(chromium, view.url, queue=True)
            b = _page(chromium, view.url)
            a.get_by_label("Open", exact=True).click()
            a.get_by_role("option", name="labB/run / run", exact=True).click()
            run = re.compile(r"^labB/run · run · frame \d+ / \d+")
            a.get_by_text(run).first.wait_for(timeout=60_000)
            b.get_by_text(run).first.wait_for(timeout=20_000)
            assert b.get_by_text(WALK_SHOWN).count() == 0
            b.get_by_label("Trial", exact=True).click()
            b.get_by_role("option", name="static", exact=True).click()
            static = re.compile(r"^labB/run · static · frame \d+ / \d+")
            b.get_by_text(static).first.wait_for(timeout=60_000)
            a.get_by_text(static).first.wait_for(timeout=20_000)
        finally:
            chromium.close()


@_browser_test
def test_space_plays_from_the_3d_view_and_ticks_a_focused_checkbox_instead(served) -> None:
    """README: "The keys act when the page has the focus: after clicking a checkbox (...),
    click the 3D view before pressing them (a focused checkbox takes Space)". Space with the
    Follow pelvis checkbox focused toggles that checkbox and the playhead stays at frame 0;
    after a click in the 3D view Space starts the playback (the playhead moves) and stops it
    (the playhead stays where it stopped)."""
    sync_api = import_tool("playwright.sync_api", reason=PLAYWRIGHT_REASON)
    view = served()
    with sync_api.sync_playwright() as p:
        chromium = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            page = _page(chromium, view.url)
            follow = page.get_by_label("Follow pelvis", exact=True)
            follow.click()
            assert follow.is_checked()
            page.keyboard.press(" ")
            page.wait_for_function("""() => { const box = [...document.querySelectorAll('input[type=checkbox]')]
                .find(b => b.labels && [...b.labels].some(l => l.textContent.trim() === 'Follow pelvis'));
                return box !== undefined && !box.checked; }""", timeout=20_000)
            page.wait_for_timeout(1500)  # a playback started by the Space would have moved the playhead by now
            assert page.get_by_text(WALK_SHOWN).count() >= 1

            page.mouse.click(800, 900)  # the 3D view: the keys act
            page.keyboard.press(" ")
            moving = re.compile(r"labA/walk · walk · frame ([1-9]\d*) / 237")
            page.get_by_text(moving).first.wait_for(timeout=20_000)
            page.keyboard.press(" ")
            page.wait_for_timeout(1000)  # the stop reaches the server
            stopped = page.get_by_text(moving).first.inner_text()
            page.wait_for_timeout(1500)
            assert page.get_by_text(moving).first.inner_text() == stopped
            assert not follow.is_checked()
        finally:
            chromium.close()
