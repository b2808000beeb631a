"""``addb view FILE.b3d`` in a real browser (headless Debian Chromium): the published subject
is converted, processed, and its trials are listed in the page."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest
from viewer_support import ViewProcess

from tests.conftest import SHARED_DATA, import_tool, needs_tool, tool_available

CHROMIUM = "/usr/bin/chromium"
PLAYWRIGHT_REASON = "the playwright package (test extra) is not installed"
ARGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-background-networking"]
B3D = SHARED_DATA / "b3d" / "results.b3d"

pytestmark = [
    pytest.mark.browser,
    pytest.mark.slow,
    needs_tool("chromium", Path(CHROMIUM).exists(), f"{CHROMIUM} is not installed (Debian: apt-get install chromium)"),
    needs_tool("playwright", tool_available("playwright"), PLAYWRIGHT_REASON),
]


def test_b3d_file_opens_in_the_review_app_with_its_trials(tmp_path: Path) -> None:
    sync_api = import_tool("playwright.sync_api", reason=PLAYWRIGHT_REASON)
    b3d = shutil.copyfile(B3D, tmp_path / "published.b3d")
    view = ViewProcess([str(b3d), "--port", "0", "--reviewer", "e2e"], tmp_path)
    try:
        assert "converting" in view.output
        with sync_api.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
            try:
                page = browser.new_page(viewport={"width": 1600, "height": 1000})
                page.goto(view.url)
                # named by its file, not its cache folder (published-<digest>)
                page.get_by_text(re.compile(r"published\.b3d · walking\d_segment_0 · frame \d+ / \d+")).wait_for(timeout=120_000)
                assert page.get_by_text("addb · published.b3d", exact=True).count() == 1
                page.get_by_label("Trial", exact=True).click()
                names = {page.get_by_role("option").nth(i).inner_text() for i in range(page.get_by_role("option").count())}
                assert {"walking1_segment_0", "walking2_segment_0"} <= names, names
            finally:
                browser.close()
    finally:
        view.stop()
    assert "Traceback" not in view.output, view.output
