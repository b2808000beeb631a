"""The repository's scripts imported as modules, for the tests that call their functions.

Kept out of tests/conftest.py, which the benchmark scripts import: a change here changes no
figure (scripts/regenerate_figures.py, ``measured_paths``)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

REPO = Path(__file__).resolve().parents[1]


def load_script(rel: str) -> ModuleType:
    """The repository's script ``rel`` (e.g. ``scripts/regenerate_figures.py``) imported as a
    module named after its file, registered in ``sys.modules`` (dataclasses look their module
    up there); imported once per test process."""
    name = Path(rel).stem
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, REPO / rel)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]
