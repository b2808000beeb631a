"""scripts/probe_judged_fit.py: its patches apply once to this tree and refuse a tree where
their text is gone, and its reading of pytest's JUnit XML tells every outcome apart."""

from __future__ import annotations

import importlib.util
import shutil
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def probe():
    spec = importlib.util.spec_from_file_location("probe_judged_fit", REPO / "scripts" / "probe_judged_fit.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["probe_judged_fit"] = module
    spec.loader.exec_module(module)
    return module


def test_the_patches_apply_to_this_tree_and_change_what_they_name(probe, tmp_path) -> None:
    for rel, _, _ in probe.PATCHES:
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(REPO / rel, tmp_path / rel)
    probe.patch(tmp_path)
    judged = (tmp_path / "solver/diagnose/judged_fit.py").read_text()
    assert "    return recorded  # probe_judged_fit.py" in judged
    assert "return FitSettings(derivative=recorded.derivative)" not in judged
    harness = (tmp_path / "tests/diagnose/harness.py").read_text()
    assert '"--fit", "band"' not in harness
    # every other line is as in the repository
    for rel, old, new in probe.PATCHES:
        assert (tmp_path / rel).read_text() == (REPO / rel).read_text().replace(old, new)
    # patched once, the text is gone: a second patch stops with status 2, naming the file
    with pytest.raises(SystemExit, match=r"solver/diagnose/judged_fit.py: the text this probe replaces is not there once"):
        probe.patch(tmp_path)


JUNIT = """<?xml version="1.0" encoding="utf-8"?>
<testsuites><testsuite name="pytest">
<testcase classname="tests.diagnose.test_a" name="test_ok" time="1"/>
<testcase classname="tests.diagnose.test_a" name="test_wrong[x-1]" time="1">
  <failure message="AssertionError: plate_registration stands out: it removes 12%&#10;assert 'a' == 'b'">trace</failure></testcase>
<testcase classname="tests.diagnose.test_a" name="test_bare" time="1">
  <failure message="AssertionError">    def f():
&gt;       assert after["marker_rms_m"] &lt; before["marker_rms_m"]
E       AssertionError</failure></testcase>
<testcase classname="tests.diagnose.test_b" name="test_known_miss" time="1">
  <skipped type="pytest.xfail" message="walk: a known miss"/></testcase>
<testcase classname="tests.diagnose.test_b" name="test_named_now" time="1">
  <failure message="[XPASS(strict)] run: a known miss">trace</failure></testcase>
<testcase classname="tests.diagnose.test_b" name="test_broken" time="1">
  <error message="failed on setup with &quot;OSError&quot;">trace</error></testcase>
</testsuite></testsuites>
"""


def test_outcomes_tell_passed_failed_expected_failures_and_strict_passes_apart(probe, tmp_path) -> None:
    (tmp_path / "junit.xml").write_text(JUNIT)
    assert probe.outcomes(tmp_path / "junit.xml") == [
        ("test_a::test_ok", "passed", ""),
        ("test_a::test_wrong[x-1]", "failed", "plate_registration stands out: it removes 12%"),
        ("test_a::test_bare", "failed", 'assert after["marker_rms_m"] < before["marker_rms_m"]'),
        ("test_b::test_known_miss", "xfailed", "walk: a known miss"),
        ("test_b::test_named_now", "xpassed (strict)", "[XPASS(strict)] run: a known miss"),
        ("test_b::test_broken", "error", 'failed on setup with "OSError"'),
    ]
