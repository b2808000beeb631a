"""The import structure the README's architecture section promises: no import circles
between the project's modules (imports inside functions and under TYPE_CHECKING count:
they are circles a reader has to untangle all the same), and imports that run one way
(``addb_viewer`` -> ``solver``, ``annotations``; ``solver`` and ``annotations`` import
neither each other nor the app); and the README's map of the layout, which names every
module under its own folder."""

from __future__ import annotations

import ast
import fnmatch
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("solver", "annotations", "addb_viewer")


def _modules() -> dict[str, Path]:
    mods = {}
    for pkg in PACKAGES:
        for f in (REPO / pkg).rglob("*.py"):
            parts = f.relative_to(REPO).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            mods[name] = f
    return mods


def import_graph() -> dict[str, set[str]]:
    """Module -> the project modules it imports (anywhere in the file)."""
    mods = _modules()

    def resolve(name: str) -> str | None:
        while name and name not in mods:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, set[str]] = {m: set() for m in mods}
    for m, f in mods.items():
        pkg = m if f.name == "__init__.py" else m.rpartition(".")[0]
        for node in ast.walk(ast.parse(f.read_text(), filename=str(f))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = pkg
                    for _ in range(node.level - 1):
                        up = up.rpartition(".")[0]
                    base = f"{up}.{node.module}" if node.module else up
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in mods else base for a in node.names]
            for t in targets:
                r = resolve(t)
                if r and r != m:
                    graph[m].add(r)
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected groups of more than one module (Tarjan's algorithm, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = 0
    for root, targets in graph.items():
        if root in index:
            continue
        work = [(root, iter(sorted(targets)))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                group = []
                while True:
                    x = stack.pop()
                    on.discard(x)
                    group.append(x)
                    if x == v:
                        break
                if len(group) > 1:
                    out.append(sorted(group))
    return out


def test_the_circle_finder_finds_a_circle() -> None:
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_circles() -> None:
    graph = import_graph()
    assert len(graph) > 100
    assert circles(graph) == []


def test_imports_run_one_way() -> None:
    wrong = [
        (m, t)
        for m, targets in import_graph().items()
        for t in targets
        if (m.startswith("solver") and t.split(".")[0] in ("addb_viewer", "annotations"))
        or (m.startswith("annotations") and t.split(".")[0] in ("addb_viewer", "solver"))
    ]
    assert wrong == []


#: Column where the architecture map's descriptions start; a line whose text starts left of it
#: opens an entry (a folder ``name/`` or a file ``name.py``), one that starts there continues one.
_DESCRIPTION_COLUMN = 22


def layout_map(readme: str) -> dict[str, set[str]]:
    """The README's architecture map (the first fenced block after ``## Architecture``) as
    folder -> the file names and patterns (``b3d*.py``) written for it.

    An entry's folder is read from its indentation (two spaces a level under the folder entry
    above it); the ``.py`` names in an entry and its continuation lines belong to the folder the
    entry is (a folder entry: ``dataset/  discover.py (...), manifest.py``) or is in (a file
    entry: ``stage.py ... result.py its frozen results``). A folder with an entry of its own
    maps to a set, empty when none of its files is named."""
    block = readme.split("\n## Architecture", 1)[1].split("```", 2)[1]
    out: dict[str, set[str]] = {}
    stack: list[tuple[int, str]] = []  # (indent, folder path) of the open folder entries
    folder = ""  # the folder the current entry's names belong to
    for line in block.splitlines():
        text = line.lstrip(" ")
        indent = len(line) - len(text)
        if not text:
            continue
        if indent < _DESCRIPTION_COLUMN:
            name = text.split()[0]
            while stack and stack[-1][0] >= indent:
                stack.pop()
            parent = stack[-1][1] if stack else ""
            if name.endswith("/"):
                folder = f"{parent}{name}"
                stack.append((indent, folder))
                out.setdefault(folder, set())
            else:
                folder = parent
        out.setdefault(folder, set()).update(re.findall(r"(?<![\w*/])[\w*]+\.py", text))  # not a path elsewhere
    return out


def test_the_layout_map_reader_follows_indentation() -> None:
    readme = (
        "x\n## Architecture\n\n```\n"
        "pkg/                  the package (cli.py)\n"
        "  sub/                parts: a.py, b*.py\n"
        "    deep.py           deep, with c.py\n"
        "  top.py              top\n"
        "                      continued with d.py (made by scripts/e.py)\n"
        "```\n"
    )
    assert layout_map(readme) == {"pkg/": {"cli.py", "top.py", "d.py"}, "pkg/sub/": {"a.py", "b*.py", "deep.py", "c.py"}}


def test_the_readme_architecture_names_every_module() -> None:
    """Every module of the packages is named in the README's architecture map under its own
    folder (by its file name or a pattern), and every folder holding modules has an entry: the
    map tells the layout as it really is (a newcomer finds where a thing happens from it)."""
    names = layout_map((REPO / "README.md").read_text())
    missing = []
    for pkg in PACKAGES:
        for f in sorted((REPO / pkg).rglob("*.py")):
            folder = f.parent.relative_to(REPO).as_posix() + "/"
            if folder not in names:
                missing.append(folder)
            elif f.name != "__init__.py" and not any(fnmatch.fnmatch(f.name, n) for n in names[folder]):
                missing.append(f.relative_to(REPO).as_posix())
    assert sorted(set(missing)) == []


def test_every_module_the_readme_architecture_names_exists() -> None:
    """The other way: every file name (or pattern) the map writes for a folder of the packages
    is a module of that folder, so a module renamed or removed leaves no stale line in the map."""
    names = layout_map((REPO / "README.md").read_text())
    stale = [
        f"{folder}{n}"
        for folder, written in names.items()
        if folder.split("/")[0] in PACKAGES
        for n in sorted(written)
        if not any(fnmatch.fnmatch(f.name, n) for f in (REPO / folder).glob("*.py"))
    ]
    assert stale == []
