"""The diagnosis judging the default fit's motion as processed: the hidden-cause tests on a patched copy.

    .venv/bin/python scripts/probe_judged_fit.py [TEST_FILE ...]

``addb diagnose`` judges every trial on the band dynamics fit its rules were calibrated on
(``solver/diagnose/judged_fit.py``): an output of the pipeline's default fit (the converged
fit) is processed again with the band fit for it. Issue 29 asks for those rules re-derived on
the converged fit. This probe shows where they stand there: it copies the working tree (the
files git tracks or would track) into a temporary folder with ``../shared`` linked beside it,
patches the copy so that

* ``judged_fit`` returns the fit the output was made with (the motion is judged as processed),
* the neutral bases of ``tests/diagnose/harness.py`` are processed with the default fit,

runs pytest there on TEST_FILEs (default: the hidden-cause tests of the walk and the run, and
the consistent trials; two workers, one file each), and prints the counts and every test
that failed or whose strict expected failure passed, with the first line of its message (the
diagnosis' verdict, for a wrong choice). The repository is not changed. Takes about 4 min.

Exit status 0 when the probe ran (whatever the tests' outcome), 2 when a patch no longer
applies (the text it replaces is gone: the probe must follow the code).
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

DEFAULT_TESTS = (
    "tests/diagnose/test_diagnose_hidden_walk.py",
    "tests/diagnose/test_diagnose_hidden_run.py",
    "tests/diagnose/test_diagnose_consistent.py",
)

#: (file, text, replacement): the copy's changes.
PATCHES = (
    ("solver/diagnose/judged_fit.py",
     "    return FitSettings(derivative=recorded.derivative)\n",
     "    return recorded  # probe_judged_fit.py: the motion is judged as processed\n"),
    ("tests/diagnose/harness.py",
     '"--out", str(subject / "addb_out"), "--fit", "band"])',
     '"--out", str(subject / "addb_out")])'),
)  # fmt: skip


def copy_tree(dst: Path) -> Path:
    """Copy the working tree's files (tracked, or untracked and not ignored) to ``dst/addb``
    and link ``dst/shared`` to the repository's ``../shared``; returns ``dst/addb``."""
    listed = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
                            cwd=REPO, check=True, capture_output=True, text=True).stdout  # fmt: skip
    tree = dst / "addb"
    for rel in filter(None, listed.split("\0")):
        src = REPO / rel
        if src.is_file():
            (tree / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, tree / rel)
    (dst / "shared").symlink_to(REPO.parent / "shared")
    return tree


def patch(tree: Path) -> None:
    """Apply :data:`PATCHES` to the copy; exit with status 2 naming the file whose text is gone."""
    for rel, old, new in PATCHES:
        path = tree / rel
        text = path.read_text()
        if text.count(old) != 1:
            sys.exit(f"error: {rel}: the text this probe replaces is not there once ({old.strip()!r}); update PATCHES")
        path.write_text(text.replace(old, new))


def outcomes(junit: Path) -> list[tuple[str, str, str]]:
    """``(test id, outcome, first line of the message)`` of every test in pytest's JUnit XML;
    outcome is ``passed``, ``failed``, ``error``, ``xfailed``, ``skipped`` or ``xpassed (strict)``."""
    rows = []
    for case in ET.parse(junit).getroot().iter("testcase"):
        test = f"{case.get('classname', '').rsplit('.', 1)[-1]}::{case.get('name')}"
        outcome, message = "passed", ""
        for child in case:
            if child.tag in ("failure", "error", "skipped"):
                lines = (child.get("message") or "").strip().splitlines()
                message = lines[0] if lines else ""
                if message in ("", "AssertionError"):  # a bare assert: the failing statement instead
                    stated = [ln[1:].strip() for ln in (child.text or "").splitlines() if ln.startswith(">")]
                    message = stated[-1] if stated else message
                if child.tag == "skipped":
                    outcome = "xfailed" if child.get("type") == "pytest.xfail" else "skipped"
                elif message.startswith("[XPASS(strict)]"):
                    outcome = "xpassed (strict)"
                else:
                    outcome = "failed" if child.tag == "failure" else "error"
        rows.append((test, outcome, message.removeprefix("AssertionError: ")))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("tests", nargs="*", default=list(DEFAULT_TESTS), help="test files (paths from the repository root)")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="addb_probe_judged_") as tmp:
        tree = copy_tree(Path(tmp))
        patch(tree)
        junit = Path(tmp) / "junit.xml"
        env = dict(os.environ, PYTHONPATH=str(tree))
        cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", f"--junitxml={junit}", *args.tests]
        if args.workers > 0:
            cmd += ["-n", str(args.workers), "--dist", "loadfile"]
        subprocess.run(cmd, cwd=tree, env=env, check=False, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        if not junit.exists():
            sys.exit("error: pytest wrote no report (see its output: run the same command in the copy)")
        rows = outcomes(junit)
    counts = {o: sum(r[1] == o for r in rows) for o in ("passed", "failed", "error", "xfailed", "xpassed (strict)", "skipped")}
    print("the diagnosis judging the motion of the default (converged) fit as processed; neutral bases processed with it too")
    print(f"{len(rows)} tests of {', '.join(args.tests)}: " + ", ".join(f"{n} {o}" for o, n in counts.items() if n) + "\n")
    print("| test | outcome | message (the diagnosis' verdict for a wrong choice) |")
    print("| --- | --- | --- |")
    for test, outcome, message in rows:
        if outcome not in ("passed", "xfailed"):
            print(f"| `{test}` | {outcome} | {message.replace('|', '/')} |")


if __name__ == "__main__":
    main()
