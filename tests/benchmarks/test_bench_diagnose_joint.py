"""tests/benchmarks/bench_diagnose_joint.py's ``--compare``: the table's draws beside themselves
change nothing, the second column carries the joint fit's prior or the label given, and
``--compare`` without ``--with`` is an error rather than an empty table."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
SCRIPT = REPO / "tests" / "benchmarks" / "bench_diagnose_joint.py"
TABLE = [REPO / "docs" / "diagnose" / f"results_draws_{part}.json" for part in ("0_9", "10_19")]


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(SCRIPT), *args], cwd=REPO, capture_output=True, text=True, check=False)


def test_compare_without_with_is_an_error_naming_it() -> None:
    out = _run("--compare", *map(str, TABLE))
    assert out.returncode == 2
    assert "--compare needs --with" in out.stderr
    assert out.stdout == ""


def test_compare_names_the_prior_or_the_label_and_lists_no_change_for_the_same_draws() -> None:
    by_prior = _run("--sigma", "0.1", "--compare", *map(str, TABLE), "--with", *map(str, TABLE))
    assert by_prior.returncode == 0, by_prior.stderr
    assert "| within tolerance, alternation (judged fit) | within tolerance, joint fit, mass_sigma 0.1 |" in by_prior.stdout
    assert "Draws whose verdict changed (0 of 180;" in by_prior.stdout
    sys.path.insert(0, str(SCRIPT.parent))
    try:
        import bench_diagnose_joint
    finally:
        sys.path.remove(str(SCRIPT.parent))
    labelled = bench_diagnose_joint.compare(TABLE, TABLE, sigma=0.1, label="another rule")
    assert "| within tolerance, another rule |" in labelled and "(another rule)." in labelled
    assert "mass_sigma" not in labelled and "joint fit" not in labelled
