"""``dataset_report.html`` drawn by a real browser (headless Debian Chromium): every label of
its bar charts lies inside its figure. The y-axis label (the tallest bar's count) of a
dataset with a thousand or more frames in a bin, such as ``4.62e+03``, was cut off at the
figure's left edge."""

from __future__ import annotations

from pathlib import Path

import pytest

from addb_viewer.cli import main as cli
from solver.dataset.report import render_report
from solver.dataset.summary import dataset_totals, subject_rows
from tests.conftest import import_tool, needs_tool, tool_available
from tests.dataset.dataset_tree import SUBJECTS

CHROMIUM = "/usr/bin/chromium"
PLAYWRIGHT_REASON = "the playwright package (test extra) is not installed"
ARGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-background-networking"]

pytestmark = [
    pytest.mark.browser,
    pytest.mark.slow,
    needs_tool("chromium", Path(CHROMIUM).exists(), f"{CHROMIUM} is not installed (Debian: apt-get install chromium)"),
    needs_tool("playwright", tool_available("playwright"), PLAYWRIGHT_REASON),
]

#: Every <text> of every chart: [label, left, right, top, bottom, figure width, figure height] in px.
MEASURE = """() => [...document.querySelectorAll('svg')].flatMap(s => [...s.querySelectorAll('text')].map(t => {
    const b = t.getBBox();
    return [t.textContent, b.x, b.x + b.width, b.y, b.y + b.height, s.width.baseVal.value, s.height.baseVal.value];
}))"""


def test_every_chart_label_of_the_report_lies_inside_its_figure(tmp_path: Path) -> None:
    sync_api = import_tool("playwright.sync_api", reason=PLAYWRIGHT_REASON)
    out = tmp_path / "walk"
    assert cli(["process", str(SUBJECTS / "rajagopal2016_walk"), "--out", str(out)]) == 0
    rows = subject_rows(out)
    # thirty subjects walking as this one does: thousands of measured frames per bin
    subjects = [{"rel": f"lab/s{k:02d}", "status": "ok", "trials": rows} for k in range(30)]
    totals = dataset_totals(subjects)
    assert max(totals["residual_force_hist_BW"]) >= 1000  # a label of 5 characters or more
    page_html = render_report({"dataset": "/d", "out": "/o", "addb_version": "x", "finished": "now", "seconds": 1.0,
                               "totals": totals, "subjects": subjects})  # fmt: skip
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.set_content(page_html)
            labels = page.evaluate(MEASURE)
        finally:
            browser.close()
    assert len(labels) >= 12 and any("e+03" in t[0] for t in labels), labels  # 4 charts, y label and 3 ticks each
    outside = [t for t in labels if t[1] < 0 or t[2] > t[5] or t[3] < 0 or t[4] > t[6]]
    assert not outside, outside
