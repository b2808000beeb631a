"""The digest that the kinematics cache and the dataset manifest key on covers the solver
modules processing runs, and only those (dataset audit 2026-12-02, finding 8: an edit to
solver/io/b3d_convert.py made every finished subject of a dataset stale)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

from solver.provenance import code_digest, processing_modules
from tests.conftest import SHARED_DATA

SOLVER = Path(__file__).resolve().parents[1] / "solver"


def test_the_modules_a_run_loads_are_those_the_digest_covers(tmp_path: Path) -> None:
    """Every solver module an ``addb process`` of the walk has loaded when it ends is one of
    :func:`processing_modules` (read from the source, not run), and the .b3d export, the
    diagnosis, the benchmark and the dataset runner are not."""
    code = ("import json, sys\nfrom solver.pipeline import process_subject\nprocess_subject(sys.argv[1], sys.argv[2])\n"
            "print(json.dumps(sorted(m.__file__ for n, m in sys.modules.items() if n.split('.')[0] == 'solver' and getattr(m, '__file__', None))))")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code, str(SHARED_DATA / "subjects" / "rajagopal2016_walk"), str(tmp_path / "out")],
                         capture_output=True, text=True, check=True, cwd=SOLVER.parent)  # fmt: skip
    loaded = {Path(f).resolve() for f in json.loads(out.stdout.strip().splitlines()[-1])}
    covered = set(processing_modules())
    assert loaded <= covered, sorted(str(f) for f in loaded - covered)
    names = {f.relative_to(SOLVER).as_posix() for f in covered}
    assert not {"io/b3d_convert.py", "io/b3d_writer.py", "dataset/runner.py", "diagnose/core.py", "benchmark/run.py"} & names
    assert {"pipeline.py", "dynamics/fit.py", "kinematics/ik.py", "io/trc.py", "model/skeleton.py"} <= names


def test_an_edit_outside_processing_keeps_the_digest(tmp_path: Path) -> None:
    """In a copy of the solver package: an edit to the .b3d conversion or the dataset runner
    leaves the digest as it was; an edit to the dynamics fit, or to a module it imports
    inside a function only, changes it."""
    copy = tmp_path / "solver"
    shutil.copytree(SOLVER, copy, ignore=shutil.ignore_patterns("__pycache__"))

    def digest() -> str:
        return code_digest(copy)

    before = digest()
    assert before == code_digest()  # the copy is the package
    for outside in ("io/b3d_convert.py", "dataset/runner.py"):
        (copy / outside).write_text((copy / outside).read_text() + "\n# an edit\n")
        assert digest() == before, outside
    (copy / "dynamics" / "fit.py").write_text((copy / "dynamics" / "fit.py").read_text() + "\n# an edit\n")
    after_fit = digest()
    assert after_fit != before
    lazy = "dynamics/stage.py"  # imported by pipeline inside functions only (the dynamics stage loads when it runs)
    assert "from solver.dynamics.stage import" in (copy / "pipeline.py").read_text()
    (copy / lazy).write_text((copy / lazy).read_text() + "\n# an edit\n")
    assert digest() != after_fit
