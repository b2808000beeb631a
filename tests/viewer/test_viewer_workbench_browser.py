"""The review workbench in a real browser (headless Debian Chromium, Playwright): a dataset
tree of two shared subjects without a Geometry folder, processed by ``addb process``, then
``addb view DATASET_DIR`` in a subprocess at 1600x1000 (and a page at 1280x800, where the
docked panels leave the 3D view 40 % of the width, the queue's window fits it and the
walk's skeleton is drawn below it on its first and last frames). The queue lists both subjects and
their trials; opening the second works (its bones drawn, no axes fallback); the timeline's
plots lie inside the viewport and their frame cursors line up at the last frame; the Selection's thumb at the last frame lies clear of the panel's scrollbar; a selection dragged over frames 20-40 (each end within a
pixel's frames) and the flag hotkey write exactly the selected range to the record on disk; Reprocess ends with the before/after table: the
frames with measured force drop to the frames the reviewer did not flag (the flags replace
the solver's own choice, and the range adds frames that were in the fit) and the residuals
change. With ``ADDB_WRITE_SCREENSHOT=1`` it writes the README's screenshot of the
workbench (docs/images/workbench.png); otherwise the screenshot goes to a temporary folder.""" 

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import pytest
from viewer_support import ViewProcess

from addb_viewer.app.workbench import QUEUE_GAP_PX, QUEUE_HEIGHT_PX
from addb_viewer.cli import main as cli
from annotations import AnnotationStore
from solver.results import load_processed
from tests.conftest import SHARED_DATA, import_tool, needs_tool, tool_available, writable_copy

CHROMIUM = "/usr/bin/chromium"
PLAYWRIGHT_REASON = "the playwright package (test extra) is not installed"
REPO = Path(__file__).resolve().parents[2]
SCREENSHOT = REPO / "docs" / "images" / "workbench.png"
ARGS = [
    "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]  # fmt: skip
SUBJECTS = {"labA/walk": "rajagopal2016_walk", "labB/run": "rajagopal2016_run"}
REPROCESS_TIMEOUT_MS = 600_000

pytestmark = [
    pytest.mark.browser,
    pytest.mark.slow,
    needs_tool("chromium", Path(CHROMIUM).exists(), f"{CHROMIUM} is not installed (Debian: apt-get install chromium)"),
    needs_tool("playwright", tool_available("playwright"), PLAYWRIGHT_REASON),
]


@pytest.fixture
def workbench(tmp_path: Path):
    """The processed dataset and ``addb view`` serving it (no background processing)."""
    ds = tmp_path / "dataset"
    for rel, name in SUBJECTS.items():
        writable_copy(SHARED_DATA / "subjects" / name, ds / rel)
    out = ds / "addb_out"
    assert cli(["process", str(ds), "--out", str(out), "--workers", "2"]) == 0
    view = ViewProcess([str(ds), "--port", "0", "--workers", "0", "--reviewer", "e2e"], tmp_path)
    yield view.url, ds, out, view.lines
    view.stop()


def _selection(page) -> tuple[int, int] | None:
    text = page.get_by_text(re.compile(r"^(Selected: frames|Drag the ends)")).first.inner_text()
    m = re.search(r"Selected: frames (\d+)–(\d+)", text)
    return (int(m.group(1)), int(m.group(2))) if m else None


def _selection_slider(page):
    """The Selection slider's track (its bounding box) and its two thumbs (a locator)."""
    slider_id = page.get_by_text("Selection", exact=True).get_attribute("for")
    track = page.locator(f"[id='{slider_id}'] .multi-slider-track").bounding_box()
    return track, page.locator(f"[id='{slider_id}'] .multi-slider-thumb")


def _drag_thumb(page, thumb, x: float) -> float:
    """Press ``thumb`` at its centre and drag it along the track to page x ``x``; returns the
    page y of the drag."""
    box = thumb.bounding_box()
    y = box["y"] + box["height"] / 2
    page.mouse.move(box["x"] + box["width"] / 2, y)
    page.mouse.down()
    page.mouse.move(x, y, steps=6)
    page.mouse.up()
    return y


def _drag_selection(page, start: int, end: int, last_frame: int) -> tuple[int, int]:
    """Drag the Selection slider's two thumbs (the timeline's range) to frames ``start`` and
    ``end``: a drag from each thumb to the frame's place on the track, then, while the
    page reports another frame, a nudge by the difference. A pixel of the track can span
    several frames (a 900-frame run on a 300 px track), so the selection reached is returned:
    each end within one pixel's frames of the one asked for."""
    track, thumbs = _selection_slider(page)
    px = track["width"] / last_frame
    for index, frame in ((1, end), (0, start)):  # both start at frame 0: the top thumb first
        shift = 0.0
        for attempt in range(10):
            sel = _selection(page)
            now = sel[index] if sel is not None else None
            if now == frame:
                break
            if now is not None and attempt > 0:  # a nudge by what the last drag missed
                shift += 0.6 * (frame - now) * px
            _drag_thumb(page, thumbs.nth(index), track["x"] + frame * px + shift)
            page.wait_for_timeout(400)
    reached = _selection(page)
    per_pixel = int(np.ceil(1.0 / px))
    assert reached is not None and abs(reached[0] - start) <= per_pixel and abs(reached[1] - end) <= per_pixel, (reached, px)
    return reached


def _last_thumb_reachable(page, last_frame: int) -> None:
    """Drag the Selection's upper thumb past the end of its track: the selection ends at the
    last frame, and the thumb there lies clear of the docked panel's scrollbar (the element
    under its centre is the thumb, so a press there grabs it)."""
    track, thumbs = _selection_slider(page)
    thumb = thumbs.nth(1)
    y = _drag_thumb(page, thumb, track["x"] + track["width"] + 40)
    page.get_by_text(re.compile(rf"Selected: frames \d+–{last_frame} ")).wait_for(timeout=20_000)
    box = thumb.bounding_box()
    under = page.evaluate("([x, y]) => document.elementFromPoint(x, y).className", [box["x"] + box["width"] / 2, y])
    assert "multi-slider-thumb" in under, (under, box)


def _cursor_column(page, chart) -> int:
    """The page x of a chart's frame cursor: the pixel column with the most near-black
    pixels (the cursor is a dark vertical line through the plot area; grid lines are light)."""
    import imageio.v3 as iio

    box = chart.bounding_box()
    img = iio.imread(page.screenshot(clip=box)).astype(int)[..., :3]
    dark = (img.max(axis=2) < 90).sum(axis=0)
    assert dark.max() > 0.3 * img.shape[0], (box, int(dark.max()))  # a line over most of the height
    return round(box["x"]) + int(np.argmax(dark))


def _close_webgl_notice(page) -> None:
    """Headless Chromium renders WebGL in software, and viser says so in a notice over the
    top-left of the 3D view, where the queue's controls are: close it (a machine with a GPU
    shows none)."""
    from playwright.sync_api import TimeoutError as PlaywrightTimeout

    notice = page.get_by_role("alert").filter(has_text="WebGL")
    try:
        notice.first.wait_for(timeout=10_000)
    except PlaywrightTimeout:  # no notice: WebGL runs on a GPU
        return
    for one in notice.all():
        one.get_by_role("button").first.click()
        one.wait_for(state="detached", timeout=10_000)


def _skeleton_below_queue(page, when: str) -> None:
    """The queue's window lies inside the 3D canvas, and the skeleton's observed (blue) and
    model (orange) markers are drawn in the canvas below that window (its model markers
    mostly hide behind the observed ones: a few orange pixels are enough)."""
    from test_viewer_browser import _colored_pixels

    canvas = page.locator("canvas").first.bounding_box()
    counts = (0, 0)
    for _ in range(60):  # the camera is framed again once the page reports its canvas
        canvas = page.locator("canvas").first.bounding_box()
        window = page.get_by_role("button", name="Next trial to review").bounding_box()
        assert canvas["x"] <= window["x"] and window["x"] + window["width"] <= canvas["x"] + canvas["width"], (canvas, window)
        top = canvas["y"] + QUEUE_GAP_PX + QUEUE_HEIGHT_PX
        clip = {"x": canvas["x"], "y": top, "width": canvas["width"], "height": canvas["y"] + canvas["height"] - top}
        counts = _colored_pixels(page.screenshot(clip=clip))
        if counts[0] > 30 and counts[1] > 5:
            break
        page.wait_for_timeout(500)
    assert counts[0] > 30 and counts[1] > 5, f"{when}: blue/orange marker pixels below the queue {counts} in canvas {canvas}"


def test_workbench_in_the_browser(workbench, tmp_path: Path) -> None:
    sync_api = import_tool("playwright.sync_api", reason=PLAYWRIGHT_REASON)
    url, ds, out, log = workbench
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            page = browser.new_page(viewport={"width": 1600, "height": 1000})
            page.goto(url)
            page.get_by_text(re.compile(r"walk · frame \d+ / \d+")).wait_for(timeout=60_000)
            _close_webgl_notice(page)

            # on a 1280 x 800 laptop screen the docked panels leave the 3D view 40 % of the
            # width, the queue's window fits that canvas, and the walk's skeleton is drawn
            # below the window on its first and last frames
            small = browser.new_page(viewport={"width": 1280, "height": 800})
            small.goto(url)
            small.get_by_text(re.compile(r"walk · frame \d+ / \d+")).wait_for(timeout=60_000)
            view = small.locator("canvas").first.bounding_box()
            assert view["width"] >= 0.4 * 1280, view
            _skeleton_below_queue(small, "first frame")
            last_walk = int(re.search(r"frame \d+ / (\d+)", small.get_by_text(re.compile(r"walk · frame")).first.inner_text()).group(1))
            small.get_by_role("button", name="◀ Prev", exact=True).click()  # frame 0 -> the last (loop)
            small.get_by_text(f"frame {last_walk} / {last_walk}").first.wait_for(timeout=20_000)
            _skeleton_below_queue(small, "last frame")
            small.close()

            # the queue lists both subjects and their trials
            for label in ("labA/walk / walk", "labA/walk / static", "labB/run / run", "labB/run / static"):
                page.get_by_text(label, exact=False).first.wait_for(timeout=20_000)

            # open the second subject's dynamic trial from the queue
            open_box = page.get_by_label("Open")
            open_box.click()
            page.get_by_role("option", name="labB/run / run", exact=True).click()
            page.get_by_text(re.compile(r"run · run · frame \d+ / \d+")).wait_for(timeout=60_000)
            assert page.get_by_text("drawn as axes").count() == 0  # every bone found (bundled meshes)

            # the timeline and its plots lie inside the viewport
            page.wait_for_timeout(1500)
            charts = page.locator(".uplot")
            assert charts.count() >= 4
            for i in range(charts.count()):
                box = charts.nth(i).bounding_box()
                assert box and box["x"] >= 0 and box["y"] >= 0 and box["width"] > 300 and box["height"] > 60, box
                assert box["x"] + box["width"] <= 1600 and box["y"] + box["height"] <= 1000, (i, box)

            # the charts' frame cursors line up (one axis per chart, all on the left): at the
            # last frame (◀ Prev from frame 0), where a right axis would move one chart's
            last_run = int(re.search(r"frame \d+ / (\d+)", page.get_by_text(re.compile(r"run · run · frame")).inner_text()).group(1))
            page.get_by_role("button", name="◀ Prev", exact=True).click()
            page.get_by_text(f"frame {last_run} / {last_run}").first.wait_for(timeout=20_000)
            page.wait_for_timeout(1500)
            columns = [_cursor_column(page, charts.nth(i)) for i in range(charts.count())]
            box = charts.nth(0).bounding_box()
            assert max(columns) - min(columns) <= 2 and columns[0] > box["x"] + box["width"] / 2, (columns, box)
            page.get_by_role("button", name="Next ▶", exact=True).click()  # back to frame 0
            page.get_by_text(f"frame 0 / {last_run}").first.wait_for(timeout=20_000)
            # the Selection's thumb at the last frame can be grabbed (the panel's scrollbar
            # floated over it)
            _last_thumb_reachable(page, last_run)

            # the timeline's proposals carry their reason on hover (a title on each run)
            tip = page.locator("div.run[data-track='proposal']").first.get_attribute("title")
            assert re.match(r"proposal \(pending\), frames? \d+(–\d+)?: \S", tip), tip
            # ticking Trial reviewed with proposals pending only warns: the box stays unticked
            reviewed = page.get_by_label("Trial reviewed", exact=True)
            reviewed.click()
            page.get_by_text(re.compile(r"not marked reviewed: \d+ proposed frames of run are still pending")).first.wait_for(timeout=20_000)
            page.wait_for_timeout(500)
            assert not reviewed.is_checked()
            # accept the solver's proposals, select frames near 20-40 by dragging the timeline's
            # range, and flag them with the hotkey G
            page.get_by_role("button", name="Accept all", exact=True).click()
            page.get_by_text(re.compile(r"✓ saved: accept proposal")).first.wait_for(timeout=20_000)
            last = int(re.search(r"frame \d+ / (\d+)", page.get_by_text(re.compile(r"run · run · frame")).inner_text()).group(1))
            lo, hi = _drag_selection(page, 20, 40, last)
            page.get_by_text(f"Selected: frames {lo}–{hi} ({hi - lo + 1} frames)").wait_for(timeout=20_000)
            page.locator("body").click(position={"x": 800, "y": 900})  # focus the page, not an input
            page.keyboard.press("g")
            page.get_by_text(re.compile(rf"✓ saved: flag frames {lo}–{hi}")).first.wait_for(timeout=20_000)
            shot = SCREENSHOT if os.environ.get("ADDB_WRITE_SCREENSHOT") == "1" else tmp_path / "workbench.png"
            shot.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(shot))

            # exactly that range (besides the accepted proposals) is in the record on disk
            before = load_processed(out / "labB" / "run", "run")
            with AnnotationStore.open(ds / "labB" / "run", reviewer="checker") as disk:
                mask = disk.mask("run", before.n_frames)
                selected = np.isin(np.arange(before.n_frames), range(lo, hi + 1))
                assert np.array_equal(mask, selected | before.proposed)
                assert disk.flag("run", 30).provenance.reviewer == "e2e"
            # the reviewer's flags replace the solver's own choice: after the Reprocess the frames
            # left out are exactly the flags (the accepted proposals and the new range)
            newly = int((selected & ~before.proposed & ~before.unobserved).sum())
            assert newly > 0  # the range adds frames that were in the fit

            page.get_by_role("button", name="Reprocess", exact=True).click()
            page.get_by_text("Reprocess result").wait_for(timeout=REPROCESS_TIMEOUT_MS)
            row = page.get_by_role("row").filter(has_text="frames with measured force").inner_text()
            b, a = (int(x) for x in re.findall(r"\d+", row)[:2])
            assert b == int((~before.unobserved).sum()), row
            assert a == before.n_frames - int(mask.sum()) and a < b, row
            after = load_processed(out / "labB" / "run", "run")
            assert np.array_equal(after.unobserved, mask)
            res = page.get_by_role("row").filter(has_text="residual force RMS, measured frames (N)").inner_text()
            rb, ra = (float(x) for x in re.findall(r"\d+\.\d", res)[:2])
            assert rb != ra, res
        finally:
            browser.close()
    assert "Traceback" not in "".join(log), "".join(log)
