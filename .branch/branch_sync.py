"""Bring the branch pending-host's README and derived test files in line with main after a rebase.

This folder (.branch/) lives on the branch only: delete it when the branch is merged into main.
A rebase: ``git rebase -X ours main`` (main's side wins the README's and the derived tests'
conflicting hunks), then ``python3 .branch/branch_sync.py ../main`` and commit.

README: each known-fault text of main (branch_pairs.json: [main text, branch text]) is replaced
by the branch's text. Tests: each test file of main with an expected failure whose reason names
pending-host is, on the branch, main's file without those markers (the branch mends what they
record).
"""

import json
import re
import subprocess
import sys
from pathlib import Path

MAIN = Path(sys.argv[1])
PAIRS = json.loads(Path(__file__).with_name("branch_pairs.json").read_text())
MARKER = re.compile(r"^@pytest\.mark\.xfail\(strict=True, reason=\(\n(?:.*\n)*?.*\)\)  # fmt: skip\n", re.MULTILINE)
SHARED = re.compile(r"^PENDING = pytest\.mark\.xfail\(strict=True, reason=\(\n(?:.*\n)*?.*\)\)  # fmt: skip\n", re.MULTILINE)

readme = Path("README.md").read_text()
for old, new in PAIRS:
    if old in readme:
        readme = readme.replace(old, new)
    elif new not in readme:
        sys.exit(f"neither side of a README pair is in README.md: {old[:90]!r}")
Path("README.md").write_text(readme)

changed = []
for f in sorted(MAIN.glob("tests/**/*.py")):
    text = f.read_text()
    if "pending-host" not in text:
        continue
    text = MARKER.sub(lambda m: "" if "pending-host" in m.group(0) else m.group(0), text)
    text = SHARED.sub(lambda m: "" if "pending-host" in m.group(0) else m.group(0), text)
    text = re.sub(r"^@PENDING\n", "", text, flags=re.MULTILINE)
    rel = f.relative_to(MAIN)
    Path(rel).write_text(text)
    changed.append(str(rel))
if changed:
    subprocess.run([str(MAIN / ".venv/bin/ruff"), "check", "--fix", "--select", "F401", "-q", *changed], check=False)
    for rel in changed:  # an import removed leaves two blank lines inside the import block
        p = Path(rel)
        p.write_text(re.sub(r"^((?:import|from) [^\n]+\n)\n\n(?=(?:import|from) )", r"\1\n", p.read_text(), flags=re.MULTILINE))
print("README pairs:", len(PAIRS), "| test files derived:", ", ".join(changed))
