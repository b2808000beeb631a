"""The registry of diagnosis causes: every cause holds all of its parts, a cause that lacks
one is refused loudly, an unknown cause name is an error (not an effect of size zero), and
no code outside a cause's own module dispatches on its name."""

from __future__ import annotations

import ast
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from solver.corrections import CORRECTIONS, read_extensions
from solver.diagnose.causes import registry
from solver.diagnose.causes.base import Cause, check
from solver.diagnose.selection import ChoiceRule, Evaluation, channels, effect_size, t_value
from solver.errors import SubjectFolderError

REPO = Path(__file__).resolve().parents[2]
DIAGNOSE = REPO / "solver" / "diagnose"


def _string_constants(path: Path) -> list[tuple[int, str, list[str]]]:
    """(line, value, enclosing function/class names) of every string constant of a module."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    out: list[tuple[int, str, list[str]]] = []

    def visit(node: ast.AST, scope: list[str]) -> None:
        for child in ast.iter_child_nodes(node):
            inner = scope + [child.name] if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)) else scope
            if isinstance(child, ast.Constant) and isinstance(child.value, str):
                out.append((child.lineno, child.value, scope))
            visit(child, inner)

    visit(tree, [])
    return out


def test_a_cause_name_appears_only_in_its_own_module() -> None:
    """No string constant equal to a registered cause's name anywhere in solver/diagnose but
    in that cause's own module (``causes/<name>.py``); in solver/corrections.py only as a key
    of its table :data:`solver.corrections.CORRECTIONS` (and in ``extension_masks``, the
    unmeasured-force mask's own code). Adding a cause is one module and one registry line."""
    names = set(registry.NAMES)
    wrong = []
    for path in sorted(DIAGNOSE.rglob("*.py")):
        own = path.stem if path.parent.name == "causes" else None
        for line, value, _ in _string_constants(path):
            if value in names and value != own:
                wrong.append(f"{path.relative_to(REPO)}:{line}: {value!r}")
    corrections = REPO / "solver" / "corrections.py"
    tree = ast.parse(corrections.read_text(encoding="utf-8"))
    table_keys = {
        id(k)
        for node in ast.walk(tree)
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and node.target.id == "CORRECTIONS"
        for k in node.value.keys  # type: ignore[union-attr]
    }
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef) and node.name == "extension_masks":
            table_keys |= {id(c) for c in ast.walk(node)}
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and node.value in names and id(node) not in table_keys:
            wrong.append(f"solver/corrections.py:{node.lineno}: {node.value!r}")
    assert wrong == []


def test_every_registered_cause_has_every_part() -> None:
    """Each cause sets its attributes, has a correction, and its name is its module's."""
    assert registry.NAMES[:8] == (
        "unmeasured_force",
        "body_mass",
        "force_time_offset",
        "plate_force_offset",
        "plate_force_gain",
        "plate_position_offset",
        "segment_mass_distribution",
        "marker_offset",
    )
    check(registry.CAUSES)
    for c in registry.CAUSES:
        assert type(c).__module__ == f"solver.diagnose.causes.{c.name}"
        assert c.name in CORRECTIONS
        assert registry.cause(c.name) is c
        assert channels(c.name) == c.channel
    rule = ChoiceRule()
    assert set(rule.min_effect) == set(registry.NAMES)
    assert rule.max_effect == {c.name: c.max_effect for c in registry.CAUSES if math.isfinite(c.max_effect)}


def _cause_class(*without: str) -> type[Cause]:
    """A :class:`Cause` subclass with every part but ``without`` (for the tests that take
    one away)."""
    parts: dict[str, Any] = {
        "name": "test_cause",
        "label": "test cause",
        "channel": "residuals",
        "main_parameter": "x",
        "min_effect": 1.0,
        "alternatives": lambda self, ctx, full: [],
        "effect_size": lambda self, parameters: abs(parameters["x"]),
        "extension": lambda self, parameters, inputs: {"cause": self.name},
        "refit": lambda self, setup, parameters, inputs: setup,
        "describe": lambda self, parameters, uncertainty: "",
    }
    return type("TestCause", (Cause,), {k: v for k, v in parts.items() if k not in without})


@pytest.mark.parametrize("method", sorted(Cause.__abstractmethods__))
def test_a_cause_missing_a_method_cannot_be_made(method: str) -> None:
    assert set(Cause.__abstractmethods__) == {"alternatives", "effect_size", "extension", "refit", "describe"}
    _cause_class()()  # every part: fine
    with pytest.raises(TypeError, match=method):
        _cause_class(method)()


@pytest.mark.parametrize("attribute", ["name", "label", "channel", "main_parameter", "min_effect"])
def test_a_cause_missing_an_attribute_is_refused(attribute: str) -> None:
    with pytest.raises(ValueError, match=f"lacks its {attribute!r}"):
        check([_cause_class(attribute)()])


def test_a_cause_without_a_correction_or_with_a_wrong_part_is_refused() -> None:
    # every part there, but no correction says how its extension is applied
    with pytest.raises(ValueError, match="'test_cause' has no correction in solver.corrections.CORRECTIONS"):
        check([_cause_class()()])
    bad = _cause_class()()
    bad.channel = "nowhere"  # type: ignore[misc]
    with pytest.raises(ValueError, match="channel 'nowhere'"):
        check([bad])
    with pytest.raises(ValueError, match="registered twice"):
        check([registry.CAUSES[0], registry.CAUSES[0]])
    with pytest.raises(TypeError, match="not a solver.diagnose.causes.base.Cause"):
        check([object()])  # type: ignore[list-item]


def test_an_unknown_cause_name_is_an_error() -> None:
    """Before the registry, ``effect_size`` gave 0.0 for a cause it did not know: a cause
    left out of one of its places was silently never named."""
    with pytest.raises(KeyError, match="unknown diagnosis cause 'nope'.*plate_registration"):
        registry.cause("nope")
    ev = Evaluation("nope", None, {"value": 1.0, "x": 1.0}, 0.1, 1, 1.0, 1.0, np.ones(5), 1.0)
    with pytest.raises(KeyError, match="nope"):
        effect_size(ev)
    with pytest.raises(KeyError, match="nope"):
        t_value(ev)
    assert not registry.registered("nope") and registry.registered("body_mass")


def test_an_extension_of_an_unknown_cause_is_refused(tmp_path: Path) -> None:
    (tmp_path / "addb_extensions.json").write_text(
        '{"schema": "addb.extensions", "version": 1, "extensions": [{"cause": "body_mass", "trial": null, "mass_change_kg": 1.0},'
        ' {"cause": "plate_tilt", "trial": "walk"}]}'
    )
    with pytest.raises(SubjectFolderError, match="addb_extensions.json.*extension 2 has cause 'plate_tilt'"):
        read_extensions(tmp_path)


def test_the_command_help_names_every_cause() -> None:
    """``addb diagnose --help`` lists the causes it tests (each cause's ``label``)."""
    import argparse

    from addb_viewer.commands import diagnose

    parser = argparse.ArgumentParser()
    diagnose.register(parser.add_subparsers())
    text = " ".join(parser._subparsers._group_actions[0].choices["diagnose"].description.split())  # type: ignore[union-attr]
    for c in registry.CAUSES:
        assert c.label in text, c.label
