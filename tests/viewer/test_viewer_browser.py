"""End to end in a real browser: ``addb view`` on the demo in a subprocess, headless Debian
Chromium driven by Playwright. The 3D canvas renders, frames step (buttons and the J/L
hotkeys), a range is flagged and is then in the review record on disk, and Reprocess
ends with the before/after table.

Skipped when /usr/bin/chromium or playwright is missing (``.ci/run`` installs Chromium
with apt-get; playwright comes with the test extra; never ``playwright install``). No
frame rate or timing is asserted: software WebGL on a loaded 2-core machine is slow.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from viewer_support import ViewProcess

from addb_viewer.app.paths import ReviewPaths
from addb_viewer.demo import DEMO_SUBJECT
from annotations import AnnotationStore
from tests.conftest import import_tool, needs_tool, tool_available

CHROMIUM = "/usr/bin/chromium"
PLAYWRIGHT_REASON = "the playwright package (test extra) is not installed"
REPO = Path(__file__).resolve().parents[2]
REPROCESS_TIMEOUT_MS = 300_000  # the full solver on the demo; ~60 s here, more on a busy CI
ARGS = [
    "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]

pytestmark = [
    pytest.mark.browser,
    needs_tool("chromium", Path(CHROMIUM).exists(), f"{CHROMIUM} is not installed (Debian: apt-get install chromium)"),
    needs_tool("playwright", tool_available("playwright"), PLAYWRIGHT_REASON),
]


@pytest.fixture
def view_server(demo_out: Path, tmp_path: Path):
    """``addb view`` (as the console script runs it) serving the processed demo copy."""
    view = ViewProcess([str(DEMO_SUBJECT), "--out", str(demo_out), "--port", "0", "--reviewer", "e2e"], tmp_path)
    yield view.url, ReviewPaths.for_subject(DEMO_SUBJECT, demo_out), view.lines
    view.stop()


def _colored_pixels(png: bytes) -> tuple[int, int]:
    """(observed-marker blue, model-marker orange) pixel counts of a screenshot."""
    import imageio.v3 as iio

    img = iio.imread(png).astype(int)[..., :3]
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    blue = (b > 180) & (r < 110) & (g > 90)
    orange = (r > 200) & (g > 90) & (g < 190) & (b < 80)
    return int(blue.sum()), int(orange.sum())


def test_review_in_the_browser(view_server) -> None:
    sync_api = import_tool("playwright.sync_api", reason=PLAYWRIGHT_REASON)
    url, paths, log = view_server
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            page = browser.new_page(viewport={"width": 1000, "height": 720})
            page.goto(url)
            status = page.get_by_text(re.compile(r"frame \d+ / 237"))
            status.wait_for(timeout=60_000)

            # the 3D canvas renders the subject: marker colours appear in a screenshot
            canvas = page.locator("canvas").first
            counts = (0, 0)
            for _ in range(60):
                counts = _colored_pixels(canvas.screenshot())
                if min(counts) > 30:
                    break
                page.wait_for_timeout(500)
            assert min(counts) > 30, f"blue/orange marker pixels {counts}"

            # step frames: buttons, then the hotkeys L (next) and J (previous)
            nxt = page.get_by_role("button", name="Next ▶", exact=True)
            nxt.click()
            nxt.click()
            page.get_by_text("frame 2 / 237").wait_for(timeout=20_000)
            page.locator("body").click(position={"x": 300, "y": 300})  # focus the page, not an input
            page.keyboard.press("l")
            page.get_by_text("frame 3 / 237").wait_for(timeout=20_000)
            page.keyboard.press("j")
            page.get_by_text("frame 2 / 237").wait_for(timeout=20_000)

            # flag frames 2..12 for the left foot: in point, 10 steps, out point, flag range
            page.get_by_role("button", name="Set in", exact=True).click()
            page.get_by_text("Range: frames 2–2").wait_for(timeout=20_000)
            for _ in range(10):
                nxt.click()
            page.get_by_text("frame 12 / 237").wait_for(timeout=30_000)
            page.get_by_role("button", name="Set out", exact=True).click()
            page.get_by_text("Range: frames 2–12").wait_for(timeout=20_000)
            page.get_by_role("button", name="Flag range", exact=True).click()
            saved = page.get_by_text(re.compile(r"✓ saved: flag frames 2–12"))
            saved.first.wait_for(timeout=20_000)
            # said twice: in the Flags folder and under the timeline's buttons, where the keys
            # act; there in view without scrolling (the Flags folder's line is below the fold)
            assert saved.count() == 2
            boxes = [saved.nth(i).bounding_box() for i in range(2)]
            assert any(b is not None and 0 <= b["y"] and b["y"] + b["height"] <= 720 for b in boxes), boxes

            # the page said "saved": the range is in the review record on disk
            with AnnotationStore.open(paths.annotations, reviewer="checker") as disk:
                assert disk.ranges("walk") == [(2, 13)]
                flag = disk.flag("walk", 7)
                assert flag.foot == "both" and flag.provenance.reviewer == "e2e"

            # Reprocess with the flags, wait for the before/after table
            page.get_by_role("button", name="Reprocess", exact=True).click()
            page.get_by_text("Reprocess result").wait_for(timeout=REPROCESS_TIMEOUT_MS)
            page.get_by_text("frames left out of dynamics").wait_for(timeout=10_000)
            assert page.get_by_text("frame 12 / 237").count() >= 1  # reloaded at the same frame
            shot = page.screenshot()
            assert min(_colored_pixels(shot)) > 30
        finally:
            browser.close()
    text = "".join(log)
    assert "Traceback" not in text, text
