"""scripts/regenerate_figures.py: every figure of the registry has exactly one block in its
document (and no block lacks a figure); a run replaces only its block, with the stamp and
the command's output, and a failed command leaves the document as it was."""

from __future__ import annotations

import subprocess
import sys
from functools import partial
from pathlib import Path

import pytest

from tests.conftest import SHARED_DATA, writable_copy
from tests.scripts import load_script

REPO = Path(__file__).resolve().parents[2]


def git_in(repo: Path, *args: str) -> str:
    """``git ARGS`` in the test's own repository ``repo`` (a fixed author; no user config)."""
    env = {"GIT_AUTHOR_NAME": "t", "GIT_AUTHOR_EMAIL": "t@t", "GIT_COMMITTER_NAME": "t", "GIT_COMMITTER_EMAIL": "t@t", "PATH": "/usr/bin:/bin"}
    return subprocess.run(["git", *args], cwd=repo, check=True, capture_output=True, text=True, env=env).stdout.strip()


def repository_of(root: Path, files: dict[str, str]) -> str:
    """A new git repository in ``root`` holding ``files`` (path -> text) in one commit;
    returns that commit's short hash."""
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    git_in(root, "init", "-q")
    git_in(root, "add", "-A")
    git_in(root, "commit", "-q", "-m", "one")
    return git_in(root, "rev-parse", "--short", "HEAD")


def stamped_repository(root: Path, scripts: dict[str, str]) -> str:
    """A new git repository in ``root`` holding ``scripts/NAME.py`` for each ``NAME -> code`` of
    ``scripts`` and ``doc.md`` with one block per name, stamped at the commit of the scripts
    (returned), "old" inside; both committed."""
    made = repository_of(root, {f"scripts/{name}.py": code for name, code in scripts.items()})
    (root / "doc.md").write_text("".join(
        f"<!-- begin: {n} -->\nMade by `cmd` on 2026-01-01, commit {made} (1 s).\n\nold\n<!-- end: {n} -->\n" for n in scripts))
    git_in(root, "add", "-A")
    git_in(root, "commit", "-q", "-m", "blocks")
    return made


@pytest.fixture(scope="module")
def rf():
    return load_script("scripts/regenerate_figures.py")


def test_every_figure_has_exactly_one_block(rf) -> None:
    assert rf.check() == []
    names = [f.name for f in rf.FIGURES]
    assert len(names) == len(set(names))


def test_check_names_a_missing_a_repeated_and_an_unmade_block(rf, tmp_path, monkeypatch) -> None:
    """What the test above relies on: in a repository of its own, ``check()`` passes
    documents in order, and names a figure whose block is missing or repeated and a block
    no figure makes (in a figure's document or in RESULTS.md), each with its document."""
    (tmp_path / "tests" / "benchmarks").mkdir(parents=True)
    doc, results = tmp_path / "doc.md", tmp_path / "tests" / "benchmarks" / "RESULTS.md"

    def block(name: str) -> str:
        return f"<!-- begin: {name} -->\nfigure\n<!-- end: {name} -->\n"

    monkeypatch.setattr(rf, "REPO", tmp_path)
    monkeypatch.setattr(rf, "FIGURES", (rf.Figure("a", "doc.md", "true", "accuracy", 0.0),
                                        rf.Figure("w", "", "true", "accuracy", 0.0)))
    doc.write_text("Prose.\n\n" + block("a"))
    results.write_text("Prose.\n")
    assert rf.check() == []
    doc.write_text("Prose.\n")
    assert rf.check() == ["doc.md: block 'a' missing or repeated"]
    doc.write_text(block("a") + "\n" + block("a"))
    assert rf.check() == ["doc.md: block 'a' missing or repeated"]
    doc.write_text(block("a") + block("b"))
    results.write_text(block("c"))
    assert rf.check() == ["doc.md: block 'b' made by no figure", "tests/benchmarks/RESULTS.md: block 'c' made by no figure"]


def test_a_run_replaces_its_block_and_keeps_the_prose(rf, tmp_path, monkeypatch) -> None:
    doc = tmp_path / "doc.md"
    prose_before, prose_after = "# Title\n\nProse 1.5 cm before.\n\n", "\n\nProse after.\n"
    other = "<!-- begin: other -->\nkept as it is\n<!-- end: other -->"
    doc.write_text(prose_before + "<!-- begin: fig -->\nold figure\n<!-- end: fig -->" + prose_after + other + "\n")
    monkeypatch.setattr(rf, "REPO", tmp_path)
    monkeypatch.setattr(rf, "stamp", lambda fig, seconds: f"Made by `{fig.command}` on DATE, commit HASH.")
    fig = rf.Figure("fig", "doc.md", "printf 'a | 1\\nb | 2\\n'", "accuracy", 0.0)
    assert rf.run(fig)
    expected = (
        prose_before
        + "<!-- begin: fig -->\nMade by `printf 'a | 1\\nb | 2\\n'` on DATE, commit HASH.\n\n```\na | 1\nb | 2\n```\n<!-- end: fig -->"
        + prose_after + other + "\n"
    )
    assert doc.read_text() == expected
    assert rf.run(fig)  # a second run gives the same document
    assert doc.read_text() == expected
    assert not rf.run(rf.Figure("fig", "doc.md", "echo partial; exit 3", "accuracy", 0.0))
    assert doc.read_text() == expected


def test_a_missing_block_is_an_error_naming_the_document(rf, tmp_path) -> None:
    doc = tmp_path / "doc.md"
    doc.write_text("no block here\n")
    fig = rf.Figure("fig", "doc.md", "true", "accuracy", 0.0)
    with pytest.raises(ValueError, match="doc.md: no block"):
        rf.replace_block(doc, fig, rf.block_text(fig, "stamp", ""))
    rf.replace_block(doc, fig, rf.block_text(fig, "stamp", ""), append=True)
    assert doc.read_text() == "no block here\n\n<!-- begin: fig -->\nstamp\n<!-- end: fig -->\n"



def test_stale_names_blocks_made_before_a_change_to_their_code(rf, tmp_path, monkeypatch) -> None:
    """In a repository of its own: a block stamped at HEAD is current; one stamped at a commit
    after which the measured code changed is listed with the changed paths (a change outside
    it is not); an uncommitted stamp is listed as such, and an empty block as never made; an
    unstamped figure is left out."""
    git = partial(git_in, tmp_path)

    git("init", "-q")
    (tmp_path / "solver").mkdir()
    (tmp_path / "solver" / "fit.py").write_text("x = 1\n")
    (tmp_path / "scripts").mkdir()
    (tmp_path / "scripts" / "bench.py").write_text("from solver.fit import x\n")
    (tmp_path / "notes.md").write_text("a\n")
    git("add", "-A")
    git("commit", "-q", "-m", "one")
    old = git("rev-parse", "--short", "HEAD")
    (tmp_path / "solver" / "fit.py").write_text("x = 2\n")
    git("commit", "-q", "-am", "the measured code changes")
    mid = git("rev-parse", "--short", "HEAD")
    (tmp_path / "notes.md").write_text("b\n")
    git("commit", "-q", "-am", "a change outside it")
    head = git("rev-parse", "--short", "HEAD")
    monkeypatch.setattr(rf, "REPO", tmp_path)

    def block(name: str, commit: str, note: str = "") -> str:
        return f"<!-- begin: {name} -->\nMade by `cmd` on 2026-01-01, commit {commit}{note} (1 s).\n\nfigure\n<!-- end: {name} -->\n"

    (tmp_path / "doc.md").write_text(block("now", head) + block("mid", mid) + block("old", old)
                                      + block("dirty", head, " plus uncommitted changes to the measured code"))
    figs = [rf.Figure(n, "doc.md", "python scripts/bench.py", "accuracy", 0.0) for n in ("now", "mid", "old", "dirty", "unstamped")]
    found = {fig.name: (commit, paths) for fig, commit, paths in rf.stale(figs)}
    assert found == {"old": (old, ["solver/fit.py"]), "dirty": (head, ["uncommitted changes"])}
    # an empty block (registered, never made) is listed as such, not an error
    (tmp_path / "doc.md").write_text("<!-- begin: new -->\n<!-- end: new -->\n" + block("now", head))
    assert [(f.name, c, p) for f, c, p in rf.stale([rf.Figure(n, "doc.md", "cmd", "accuracy", 0.0) for n in ("new", "now")])] == [
        ("new", "", ["its block is empty"])
    ]
    # a block whose stamp cannot be read is an error, not a figure silently left out
    (tmp_path / "doc.md").write_text("<!-- begin: bad -->\nno stamp\n<!-- end: bad -->\n")
    with pytest.raises(ValueError, match="doc.md: block 'bad' has no stamp"):
        rf.stale([rf.Figure("bad", "doc.md", "cmd", "accuracy", 0.0)])
    # what stamp() writes is what stamp_of() reads (here HEAD of this repository, clean)
    fig = rf.Figure("fresh", "doc.md", "python scripts/bench.py", "accuracy", 0.0)
    (tmp_path / "doc.md").write_text(rf.block_text(fig, rf.stamp(fig, 75.0), "figure") + "\n")
    assert rf.stamp_of(fig) == (head, False)
    # the stamp's "uncommitted" reads the same measured paths as stale(): a change to a
    # script the command does not run leaves it clean, one to the module it imports marks it
    (tmp_path / "scripts" / "tool.py").write_text("y = 1\n")
    git("add", "-A")
    git("commit", "-q", "-m", "a script")
    head = git("rev-parse", "--short", "HEAD")
    (tmp_path / "scripts" / "tool.py").write_text("y = 2\n")
    (tmp_path / "notes.md").write_text("c\n")
    assert rf.stamp(fig, 1.0).endswith(f"commit {head} (1 s).")
    runs_tool = rf.Figure("tool", "doc.md", "python scripts/tool.py", "accuracy", 0.0)
    assert rf.stamp(runs_tool, 1.0).endswith(f"commit {head} plus uncommitted changes to the measured code (1 s).")
    (tmp_path / "solver" / "fit.py").write_text("x = 3\n")
    assert rf.stamp(fig, 1.0).endswith(f"commit {head} plus uncommitted changes to the measured code (1 s).")
    # so does a measured file not yet committed (a new benchmark run before its commit)
    git("checkout", "-q", "--", ".")
    assert rf.stamp(runs_tool, 1.0).endswith(f"commit {head} (1 s).")
    (tmp_path / "scripts" / "new.py").write_text("w = 1\n")
    runs_new = rf.Figure("new", "doc.md", "python scripts/new.py", "accuracy", 0.0)
    assert rf.stamp(runs_new, 1.0).endswith(f"commit {head} plus uncommitted changes to the measured code (1 s).")
    assert rf.stamp(runs_tool, 1.0).endswith(f"commit {head} (1 s).")
    # an edit of a docstring or a comment while a figure runs is no change of its code (as for stale())
    (tmp_path / "scripts" / "new.py").unlink()
    (tmp_path / "solver" / "fit.py").write_text('"""What x is."""\n\nx = 2  # the measured value\n')
    assert rf.stamp(fig, 1.0).endswith(f"commit {head} (1 s).")
    (tmp_path / "solver" / "fit.py").write_text('"""What x is."""\n\nx = 4\n')
    assert rf.stamp(fig, 1.0).endswith(f"commit {head} plus uncommitted changes to the measured code (1 s).")
    # a script named in the command counts as measured code
    assert "scripts/b3d_compare.py" in rf.measured_paths(rf.Figure("x", "", ".venv/bin/python scripts/b3d_compare.py --md a.md", "accuracy", 0.0))


def test_a_docstring_alone_is_no_change_of_code_in_an_empty_module_or_function(rf, tmp_path, monkeypatch) -> None:
    """A package's empty ``__init__.py`` given a docstring, and a function whose ``pass`` became
    a docstring, run the same code (as any docstring edit); a statement added beside is a change."""
    repository_of(tmp_path, {"solver/__init__.py": "", "solver/fit.py": "def f():\n    pass\n"})
    monkeypatch.setattr(rf, "REPO", tmp_path)
    (tmp_path / "solver" / "__init__.py").write_text('"""The package."""\n')
    (tmp_path / "solver" / "fit.py").write_text('def f():\n    """Nothing."""\n')
    assert rf._same_code("HEAD", "solver/__init__.py", None)
    assert rf._same_code("HEAD", "solver/fit.py", None)
    (tmp_path / "solver" / "__init__.py").write_text('"""The package."""\n\nx = 1\n')
    assert not rf._same_code("HEAD", "solver/__init__.py", None)


def test_a_data_writer_is_stale_with_the_block_that_pools_its_output(rf, tmp_path, monkeypatch) -> None:
    """A figure that writes only a data file (the diagnosis' draws) has no stamp of its own:
    it is read against the stamp of the block whose command reads that file, with its own
    measured code, so a change to that code after the block was made lists the writer too
    (and a change to the pooling script alone does not); a writer no block reads is left out;
    while the pooling block is empty (registered, not made), the writer is listed with it."""
    git = partial(git_in, tmp_path)
    repository_of(tmp_path, {"solver/fit.py": "x = 1\n", "scripts/draws.py": "from solver.fit import x\n", "scripts/pool.py": "y = 1\n"})
    made = git("rev-parse", "--short", "HEAD")
    monkeypatch.setattr(rf, "REPO", tmp_path)
    (tmp_path / "doc.md").write_text(f"<!-- begin: pool -->\nMade by `cmd` on 2026-01-01, commit {made} (1 s).\n\nt\n<!-- end: pool -->\n")
    draws = rf.Figure("draws", "", "python scripts/draws.py --json out/d.json", "accuracy", 0.0)
    pool = rf.Figure("pool", "doc.md", "python scripts/pool.py --from-json out/d.json", "accuracy", 0.0)
    lone = rf.Figure("lone", "", "python scripts/draws.py --json out/other.json", "accuracy", 0.0)
    figs = [draws, pool, lone]
    assert rf.stale(figs, readers=figs) == []
    (tmp_path / "scripts" / "pool.py").write_text("y = 2\n")
    git("commit", "-q", "-am", "the pooling script changes")
    assert [(f.name, p) for f, _, p in rf.stale(figs, readers=figs)] == [("pool", ["scripts/pool.py"])]
    (tmp_path / "solver" / "fit.py").write_text("x = 2\n")
    git("commit", "-q", "-am", "the code the draws measure changes")
    assert [(f.name, c, p) for f, c, p in rf.stale(figs, readers=figs)] == [
        ("draws", made, ["solver/fit.py"]),
        ("pool", made, ["scripts/pool.py"]),
    ]
    (tmp_path / "doc.md").write_text("<!-- begin: pool -->\n<!-- end: pool -->\n")
    assert [(f.name, c, p) for f, c, p in rf.stale(figs, readers=figs)] == [
        ("draws", "", ["block 'pool', which reads its data, is empty"]),
        ("pool", "", ["its block is empty"]),
    ]


def test_a_figure_measures_the_scripts_its_command_reaches_and_no_others(rf, tmp_path, monkeypatch) -> None:
    """measured_paths follows the command's script through its imports (a sibling by bare
    name, a module of tests/ and each package's __init__.py, an import inside a function)
    and the scripts it runs by file name, into the packages' modules; another benchmark's
    script is not measured, so a change to it leaves the figure current while a change to
    a helper it imports stales it."""
    git = partial(git_in, tmp_path)

    files = {
        "tests/benchmarks/bench_a.py": "import json\nfrom helper import f\n\ndef g():\n    from tests.lab.tools import h\n"
                                       "    run([sys.executable, str(REPO / 'scripts' / 'make.py')])\n",
        "tests/benchmarks/helper.py": "from solver.fit import x\n",
        "tests/benchmarks/bench_other.py": "y = 1\n",
        "tests/lab/__init__.py": "",
        "tests/lab/tools.py": "h = 1\n",
        "scripts/make.py": "z = 1\n",
        "solver/fit.py": "x = 1\n",
        "notes.md": "a\n",
    }
    old = repository_of(tmp_path, files)
    monkeypatch.setattr(rf, "REPO", tmp_path)
    fig = rf.Figure("a", "doc.md", ".venv/bin/python tests/benchmarks/bench_a.py --fast", "accuracy", 0.0)
    assert rf.measured_paths(fig) == ("scripts/make.py", "solver/fit.py", "tests/benchmarks/bench_a.py", "tests/benchmarks/helper.py",
                                      "tests/lab/__init__.py", "tests/lab/tools.py")
    (tmp_path / "doc.md").write_text(f"<!-- begin: a -->\nMade by `cmd` on 2026-01-01, commit {old} (1 s).\n\nfigure\n<!-- end: a -->\n")
    (tmp_path / "tests/benchmarks/bench_other.py").write_text("y = 2\n")
    git("commit", "-q", "-am", "another benchmark changes")
    assert rf.stale([fig]) == []
    (tmp_path / "tests/lab/tools.py").write_text("h = 2\n")
    git("commit", "-q", "-am", "a helper it imports changes")
    assert [(f.name, paths) for f, _, paths in rf.stale([fig])] == [("a", ["tests/lab/tools.py"])]


def test_a_figure_measures_the_package_modules_its_subcommand_reaches(rf, tmp_path, monkeypatch) -> None:
    """Through ``addb``: a benchmark that runs ``addb process`` measures the command line, the
    process subcommand's module and what it imports (lazily too), and the data files beside
    a module reached; of the diagnose subcommand, only its module, which the command line
    imports to register it, not what its handler imports; so a change to the
    diagnosis, or to a docstring, comment or help text of the pipeline, leaves its figure current,
    while a change to the pipeline's code stales it. A figure that runs ``addb diagnose``
    measures the diagnosis."""
    git = partial(git_in, tmp_path)

    files = {
        "addb_viewer/__init__.py": "",
        "addb_viewer/cli.py": "import importlib\nCOMMANDS = ('addb_viewer.commands.process', 'addb_viewer.commands.diagnose')\n",
        "addb_viewer/commands/__init__.py": "",
        "addb_viewer/commands/process.py": "def register(sub):\n    sub.add_argument('--fit', help='the fit')\n\n\n"
                                           "def run(args):\n    from solver.pipeline import process\n",
        "addb_viewer/commands/diagnose.py": "def run(args):\n    from solver.diagnose.core import diagnose\n",
        "addb_viewer/geometry_data/femur.vtp": "mesh\n",
        "solver/__init__.py": "",
        "solver/pipeline.py": '"""The pipeline."""\n\ndef process():\n    return 1  # one\n',
        "solver/diagnose/__init__.py": "",
        "solver/diagnose/core.py": "def diagnose():\n    return 2\n",
        "tests/benchmarks/bench_process.py": "import subprocess, sys\nfrom pathlib import Path\n\n"
                                             "subprocess.run([str(Path(sys.executable).parent / 'addb'), 'process', 'x'])\n",
    }
    old = repository_of(tmp_path, files)
    monkeypatch.setattr(rf, "REPO", tmp_path)
    fig = rf.Figure("p", "doc.md", ".venv/bin/python tests/benchmarks/bench_process.py", "timing", 0.0)
    assert rf.measured_paths(fig) == (
        "addb_viewer/__init__.py", "addb_viewer/cli.py", "addb_viewer/commands/__init__.py", "addb_viewer/commands/diagnose.py",
        "addb_viewer/commands/process.py", "addb_viewer/geometry_data/femur.vtp", "solver/__init__.py", "solver/pipeline.py", "tests/benchmarks/bench_process.py",
    )  # fmt: skip
    on_shell = rf.Figure("d", "doc.md", "cd /tmp && .venv/bin/addb diagnose x", "accuracy", 0.0)
    assert "solver/diagnose/core.py" in rf.measured_paths(on_shell) and "solver/pipeline.py" not in rf.measured_paths(on_shell)
    (tmp_path / "doc.md").write_text(f"<!-- begin: p -->\nMade by `cmd` on 2026-01-01, commit {old} (1 s).\n\nfigure\n<!-- end: p -->\n")
    (tmp_path / "solver/diagnose/core.py").write_text("def diagnose():\n    return 3\n")
    (tmp_path / "solver/pipeline.py").write_text('"""The pipeline, reworded."""\n\n\ndef process():\n    return 1  # the one\n')
    (tmp_path / "addb_viewer/commands/process.py").write_text(
        "def register(sub):\n    sub.add_argument('--fit', help='the dynamics fit, ' f'{1}')\n\n\n"
        "def run(args):\n    from solver.pipeline import process\n"
    )
    git("commit", "-q", "-am", "the diagnosis and the words of the pipeline and of its help change")
    assert rf.stale([fig]) == []
    (tmp_path / "solver/pipeline.py").write_text('"""The pipeline, reworded."""\n\n\ndef process():\n    return 2\n')
    git("commit", "-q", "-am", "the pipeline's code changes")
    assert [(f.name, paths) for f, _, paths in rf.stale([fig])] == [("p", ["solver/pipeline.py"])]


@pytest.mark.parametrize(
    ("figure", "command"),
    [
        ("kinematics", ["kinematics", "{subject}", "--out", "{out}"]),
        ("process", ["process", "{subject}", "--out", "{out}"]),
        ("b3d", ["convert", str(SHARED_DATA / "b3d" / "results.b3d"), "--out", "{out}"]),
        ("diagnose-draws-0-9", ["diagnose", "{subject}", "--trial", "walk", "--out", "{out}", "--json"]),
    ],
    ids=["addb kinematics", "addb process", "addb convert", "addb diagnose"],
)  # fmt: skip
def test_every_module_a_command_loads_is_measured_by_its_figure(rf, figure: str, command: list[str], tmp_path) -> None:
    """The static closure against a real run: every module of the packages that ``addb
    kinematics``, ``addb process``, ``addb convert`` (of results.b3d) or ``addb diagnose``
    (after ``addb process``) has loaded when it exits (``sys.modules``, the subcommand's
    module imported by name included) is among the files the figure that times (or
    measures) that command counts as measured."""
    subject = writable_copy(SHARED_DATA / "subjects" / "rajagopal2016_walk", tmp_path / "walk")
    out, listed = tmp_path / "out", tmp_path / "modules.txt"
    if command[0] == "diagnose":
        subprocess.run([str(Path(sys.executable).parent / "addb"), "process", str(subject), "--out", str(out)], check=True, capture_output=True)
    args = [a.format(subject=subject, out=out) for a in command]
    run_cli = (  # the console script's own start, with the loaded modules written at exit
        "import atexit, sys; from pathlib import Path; "
        f"atexit.register(lambda: Path({str(listed)!r}).write_text(chr(10).join(sorted(sys.modules)))); "
        f"from addb_viewer.cli import main; sys.exit(main({args!r}))"
    )
    subprocess.run([sys.executable, "-c", run_cli], check=True, capture_output=True, cwd=tmp_path)
    ours = [m for m in listed.read_text().split() if m.split(".")[0] in rf.PACKAGES]
    assert f"addb_viewer.commands.{command[0]}" in ours  # imported by name (importlib), not by a statement
    measured = set(rf.measured_paths(next(f for f in rf.FIGURES if f.name == figure)))
    files = {m: [p.relative_to(REPO).as_posix() for p in rf._module_files(m, REPO)][-1:] for m in ours}
    missing = sorted(m for m, f in files.items() if not f or f[0] not in measured)
    assert missing == []


def test_a_pooling_block_waits_for_its_draws_and_readers_of_one_file_do_not_wait(rf) -> None:
    """:func:`prerequisites`: a figure waits for the earlier ones that write a file it names
    (``--json`` draws pooled by a later block) or that name a file it writes, and for those
    sharing a scratch folder; two readers of one file, and unrelated figures, do not wait."""
    fig = partial(rf.Figure, doc="doc.md", kind="accuracy", minutes=0.0)
    chosen = [
        fig("draws-a", command="python draws.py --json out/a.json"),
        fig("draws-b", command="python draws.py --first 10 --json out/b.json"),
        fig("pool", command="python pool.py --from-json out/a.json out/b.json"),
        fig("compare", command="python compare.py --compare out/a.json --with out/c.json"),
        fig("redraw-a", command="python draws.py --json out/a.json"),
        fig("bench", command="python bench.py --work /tmp/addb_work --fresh"),
        fig("variants", command="python variants.py --work /tmp/addb_work --fresh"),
        fig("alone", command="python other.py"),
    ]
    assert rf.prerequisites(chosen) == {
        "draws-a": set(), "draws-b": set(), "pool": {"draws-a", "draws-b"}, "compare": {"draws-a"},
        "redraw-a": {"draws-a", "pool", "compare"}, "bench": set(), "variants": {"bench"}, "alone": set(),
    }
    # the registry: the diagnosis' table pools exactly its two halves of draws
    assert rf.prerequisites(list(rf.FIGURES))["diagnose-results"] == {"diagnose-draws-0-9", "diagnose-draws-10-19"}


def test_run_all_runs_accuracy_figures_side_by_side_timing_ones_alone_and_skips_what_a_failure_feeds(rf, tmp_path, monkeypatch) -> None:
    """:func:`run_all` with two jobs: two accuracy figures run at the same time (each waits
    for the other to have started, so run one after the other the first would fail), a
    timing figure runs with nothing else running, a pooling block starts after its draws
    end, and a figure whose draws failed is not run (its block left as it was)."""
    names = ["a", "t", "b", "pool", "bad", "after-bad"]
    doc = tmp_path / "doc.md"
    doc.write_text("".join(f"<!-- begin: {n} -->\nold\n<!-- end: {n} -->\n" for n in names))
    for d in ("started", "running", "ended"):
        (tmp_path / d).mkdir()
    monkeypatch.setattr(rf, "REPO", tmp_path)
    monkeypatch.setattr(rf, "stamp", lambda fig, seconds: "stamp")

    def side_by_side(me: str, other: str) -> str:  # an accuracy figure that needs ``other`` running with it
        return (f": --json out/{me}.json; touch started/{me} running/{me}; "
                f"for i in $(seq 200); do [ -e started/{other} ] && break; sleep 0.05; done; "
                f"test -e started/{other} && echo {me} saw {other}; rm running/{me}; touch ended/{me}")

    fig = partial(rf.Figure, doc="doc.md", minutes=0.0)
    chosen = [
        fig("a", command=side_by_side("a", "b"), kind="accuracy"),
        fig("t", command="touch running/t; echo others running: $(ls running | grep -vx t | wc -l); sleep 0.3; rm running/t", kind="timing"),
        fig("b", command=side_by_side("b", "a"), kind="accuracy"),
        fig("pool", command=": --from-json out/a.json; test -e ended/a && echo after a", kind="accuracy"),
        fig("bad", command=": --json out/bad.json; exit 3", kind="accuracy"),
        fig("after-bad", command=": --from-json out/bad.json; touch ran", kind="accuracy"),
    ]
    assert rf.run_all(chosen, jobs=2, poll=0.02) == ["bad", "after-bad"]
    blocks = {n: rf._pattern(n).findall(doc.read_text())[0].split("\n")[2:-1] for n in names}
    assert blocks["a"] == ["", "```", "a saw b", "```"]
    assert blocks["b"] == ["", "```", "b saw a", "```"]
    assert blocks["t"] == ["", "```", "others running: 0", "```"]
    assert blocks["pool"] == ["", "```", "after a", "```"]
    assert blocks["bad"] == blocks["after-bad"] == []  # "old" is line 1: left as it was
    assert "old" in rf._pattern("bad").findall(doc.read_text())[0]
    assert not (tmp_path / "ran").exists()


def test_run_stale_remakes_only_the_stale_blocks(rf, tmp_path, monkeypatch) -> None:
    """``--run-stale``: in a repository of its own where one figure's measured code changed
    after both blocks were made, only that figure runs; its block is re-stamped at HEAD, so
    ``--stale`` then lists nothing and a second ``--run-stale`` runs nothing."""
    git = partial(git_in, tmp_path)
    stamped_repository(tmp_path, {"one": "print(1)\n", "two": "print(2)\n"})
    (tmp_path / "scripts" / "two.py").write_text("print(22)\n")
    git("commit", "-q", "-am", "the second figure's code changes")
    monkeypatch.setattr(rf, "REPO", tmp_path)
    monkeypatch.setattr(rf, "FIGURES", tuple(rf.Figure(n, "doc.md", f"python3 scripts/{n}.py", "accuracy", 0.0) for n in ("one", "two")))
    assert [f.name for f, _, _ in rf.stale()] == ["two"]
    assert rf.main(["--run-stale", "--jobs", "2"]) == 0
    text = (tmp_path / "doc.md").read_text()
    assert "old" in rf._pattern("one").findall(text)[0]
    assert rf._pattern("two").findall(text)[0].split("\n")[3:-1] == ["```", "22", "```"]
    assert rf.stale() == []
    assert rf.main(["--run-stale"]) == 0
    assert (tmp_path / "doc.md").read_text() == text


def test_a_retired_figure_is_never_stale_and_runs_only_when_named(rf, tmp_path, monkeypatch) -> None:
    """A retired figure whose measured code changed after its block was made is not listed by
    ``stale()`` (nor used as the pooling block of a live writer), is left out of a plain run
    and of ``--run-stale``, and is re-made when named with ``--only``."""
    git = partial(git_in, tmp_path)
    made = stamped_repository(tmp_path, {"live": "print(1)\n", "probe": "print(2)\n"})
    for name in ("live", "probe"):
        (tmp_path / "scripts" / f"{name}.py").write_text(f"print('{name} now')\n")
    git("commit", "-q", "-am", "both figures' code changes")
    monkeypatch.setattr(rf, "REPO", tmp_path)
    live = rf.Figure("live", "doc.md", "python3 scripts/live.py", "accuracy", 0.0)
    probe = rf.Figure("probe", "doc.md", "python3 scripts/probe.py", "accuracy", 0.0, retired="2026-01-02: a lead not taken")
    monkeypatch.setattr(rf, "FIGURES", (live, probe))
    assert [f.name for f, _, _ in rf.stale()] == ["live"]
    assert rf.main([]) == 0
    text = (tmp_path / "doc.md").read_text()
    assert "live now" in rf._pattern("live").findall(text)[0]
    assert "old" in rf._pattern("probe").findall(text)[0]
    assert rf.main(["--run-stale"]) == 0 and (tmp_path / "doc.md").read_text() == text
    assert rf.main(["--only", "probe"]) == 0
    assert "probe now" in rf._pattern("probe").findall((tmp_path / "doc.md").read_text())[0]
    # a live writer is judged by a live pooling block, not by a retired one that reads its data
    # (here stamped before the writer's code changed: read as a judge, it would list the writer)
    (tmp_path / "doc.md").write_text(f"<!-- begin: probe -->\nMade by `cmd` on 2026-01-01, commit {made} (1 s).\n\nold\n<!-- end: probe -->\n")
    writer = rf.Figure("draws", "", "python3 scripts/live.py --json out/d.json", "accuracy", 0.0)
    pooled = rf.Figure("probe", "doc.md", "python3 scripts/probe.py --with out/d.json", "accuracy", 0.0, retired="2026-01-02")
    assert rf.stale([writer, pooled], readers=[writer, pooled]) == []


def test_no_live_figure_reads_what_a_retired_one_writes(rf) -> None:
    """A retired figure's data files are a record of old code: a live figure that read them
    would pool them with data made by the current code (:func:`_files`)."""
    retired_writes = {path: f.name for f in rf.FIGURES if f.retired for path in rf._files(f)[1]}
    assert retired_writes  # the registry has retired writers (their draws)
    for fig in rf.FIGURES:
        if not fig.retired:
            named = rf._files(fig)[0]
            assert not named & set(retired_writes), (fig.name, sorted(named & set(retired_writes)))


def test_every_timing_block_made_with_a_host_reference_records_it(rf) -> None:
    """Each live timing figure whose command asks for the host reference has its best time
    in its block (what :func:`host_check` compares the host with), in the range OpenSim's IK
    tool on the walk has taken on the development machine (4.5-10 s on a quiet host, 12-17 s
    on the host slowed about 2.5x of 2026-12-01, where blocks were made with ``--any-host``);
    no other block has one."""
    recorded = rf.recorded_host_references()
    asked = {f.name for f in rf.FIGURES if f.kind == "timing" and not f.retired and "--host-reference" in f.command}
    assert set(recorded) == asked
    assert all(3.0 < seconds < 20.0 for seconds in recorded.values()), recorded


def test_timing_figures_are_not_made_on_a_slowed_host(rf, tmp_path, monkeypatch) -> None:
    """``main``: with a timing figure chosen, a host reference above HOST_SLACK times the
    blocks' median stops the run (exit 2, nothing run, the reason on standard error naming
    both times); at the median it runs; ``--any-host`` runs without timing the host; with only
    accuracy figures chosen the host is not timed."""
    doc = tmp_path / "doc.md"
    line = "host reference, OpenSim 4.6 IK tool on the walk (whole process, as block `kinematics`): best {} s (runs ...)"
    doc.write_text("".join(f"<!-- begin: {n} -->\nMade by `x` on 2026-01-01, commit abcdef0 (1 s).\n\n{line.format(s)}\n<!-- end: {n} -->\n"
                           for n, s in (("t1", "4.00"), ("t2", "5.00"), ("t3", "9.00"))) + "<!-- begin: a -->\n<!-- end: a -->\n")
    figures = (*(rf.Figure(n, "doc.md", "true", "timing", 0.0) for n in ("t1", "t2", "t3")), rf.Figure("a", "doc.md", "true", "accuracy", 0.0))
    monkeypatch.setattr(rf, "REPO", tmp_path)
    monkeypatch.setattr(rf, "FIGURES", figures)
    assert rf.recorded_host_references() == {"t1": 4.0, "t2": 5.0, "t3": 9.0}
    ran: list[list[str]] = []
    monkeypatch.setattr(rf, "run_all", lambda chosen, jobs, gate=None: ran.append([f.name for f in chosen]) or [])
    timed: list[float] = []

    def host(seconds: float):
        def measure() -> float:
            timed.append(seconds)
            return seconds
        return measure

    monkeypatch.setattr(rf, "measure_host_reference", host(rf.HOST_SLACK * 5.0 + 0.01))
    assert rf.main(["--only", "t1", "a"]) == 2 and ran == [] and len(timed) == 1
    assert rf.main(["--only", "a"]) == 0 and ran == [["a"]] and len(timed) == 1
    assert rf.main(["--only", "t1", "--any-host"]) == 0 and ran[-1] == ["t1"] and len(timed) == 1
    monkeypatch.setattr(rf, "measure_host_reference", host(5.0))
    assert rf.main(["--only", "t1", "t2"]) == 0 and ran[-1] == ["t1", "t2"] and timed[-1] == 5.0
    reason = rf.host_check(list(figures), measure=host(6.0))
    assert reason is not None and "6.00 s now, median 5.00 s" in reason and "--any-host" in reason


def test_the_host_gate_times_the_host_again_waits_for_it_and_refuses_a_figure_it_does_not_come_back_for(rf, capsys) -> None:
    """:class:`HostGate` with a fake clock: found quick less than ``recheck`` before, a figure
    starts untimed; later the host is timed again, and while slower than HOST_SLACK times the
    median it pauses and times it again, starting the figure once it is quick; a host that
    stays slow past ``wait`` refuses the figure, naming the time and the ratio; a failed
    measurement refuses it too."""
    clock = [0.0]
    readings: list[float] = []
    timed: list[float] = []
    slept: list[float] = []

    def measure() -> float:
        timed.append(clock[0])
        clock[0] += 20.0  # a measurement takes time
        return readings.pop(0)

    def sleep(seconds: float) -> None:
        slept.append(seconds)
        clock[0] += seconds

    fig = rf.Figure("t", "doc.md", "true", "timing", 0.0)
    gate = rf.HostGate(5.0, measure, wait=600.0, pause=120.0, recheck=300.0, last_quick=0.0, clock=lambda: clock[0], sleep=sleep)
    clock[0] = 299.0
    assert gate(fig) and timed == []  # found quick 299 s before
    clock[0] = 301.0
    readings[:] = [rf.HOST_SLACK * 5.0 + 0.01, 7.0, 5.5]
    assert gate(fig) and slept == [120.0, 120.0] and len(timed) == 3 and readings == []
    assert gate.last_quick == clock[0]
    clock[0] += 301.0
    readings[:] = [8.0] * 10
    assert not gate(fig)
    assert len(slept) == 2 + 4  # pauses that end before the deadline (600 s after the first timing began)
    assert "8.00 s, 1.60x the 5.00 s" in capsys.readouterr().err

    def failing() -> float:
        raise RuntimeError("could not time the host reference (cmd): no opensim")

    assert not rf.HostGate(5.0, failing, wait=600.0)(fig)
    assert "t not run: could not time the host reference (cmd): no opensim" in capsys.readouterr().err


def test_run_all_leaves_out_a_timing_figure_the_gate_refuses_and_what_reads_its_data(rf, tmp_path, monkeypatch) -> None:
    """:func:`run_all` asks the gate before each timing figure only; a refused one keeps its
    block, counts as failed, and a figure that reads its data is not run; the others run."""
    names = ["a", "t1", "reads-t1", "t2"]
    doc = tmp_path / "doc.md"
    doc.write_text("".join(f"<!-- begin: {n} -->\nold\n<!-- end: {n} -->\n" for n in names))
    monkeypatch.setattr(rf, "REPO", tmp_path)
    monkeypatch.setattr(rf, "stamp", lambda fig, seconds: "stamp")
    fig = partial(rf.Figure, doc="doc.md", minutes=0.0)
    chosen = [
        fig("a", command="echo a", kind="accuracy"),
        fig("t1", command=": --json out/t1.json; echo t1", kind="timing"),
        fig("reads-t1", command=": --from-json out/t1.json; echo r", kind="accuracy"),
        fig("t2", command="echo t2", kind="timing"),
    ]
    asked: list[str] = []

    def gate(f) -> bool:
        asked.append(f.name)
        return f.name != "t1"

    assert rf.run_all(chosen, jobs=2, poll=0.02, gate=gate) == ["t1", "reads-t1"]
    assert asked == ["t1", "t2"]
    text = doc.read_text()
    assert "old" in rf._pattern("t1").findall(text)[0] and "old" in rf._pattern("reads-t1").findall(text)[0]
    assert "t2" in rf._pattern("t2").findall(text)[0].split("\n")[2:-1][-2]
    assert "old" not in rf._pattern("a").findall(text)[0]


def test_a_host_reference_that_cannot_be_timed_stops_the_timing_figures(rf) -> None:
    """Without OpenSim (the measurement fails), timing figures are not made: the reason names
    the failure and the way past it."""
    def failing() -> float:
        raise RuntimeError("could not time the host reference (cmd): ModuleNotFoundError: No module named 'opensim'")

    timing = next(f for f in rf.FIGURES if f.name == "process")
    reason = rf.host_check([timing], measure=failing)
    assert reason is not None and "No module named 'opensim'" in reason
