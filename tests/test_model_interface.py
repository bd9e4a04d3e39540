"""The model interface is declared, not probed (issue 25 item 1): every member the fitter, the config and the
studies ask of a model is declared on :class:`clothlab.models.base.Model` with a documented default, every
registered kind (composites included) answers it, and no module outside ``models/`` asks for one with
``getattr(obj, "name", default)`` or reads a model's private member."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from clothlab.models.base import Model
from clothlab.models.registry import MODEL_KINDS, model_class

PACKAGE = Path(__file__).resolve().parents[1] / "clothlab"
DECLARED = ("path_options", "check_option", "check_options", "options_class", "declared_free", "specular_class",
            "diffuse_class", "footprint_queries", "refine", "quadrature", "orientation_period", "forget_results",
            "forget_directions", "has_texture", "texture_filters", "quarter_turn_swaps", "default_free")


def test_every_member_asked_of_a_model_is_declared_on_model_and_documented():
    doc = Model.__module__ and __import__(Model.__module__, fromlist=["_"]).__doc__
    for name in DECLARED:
        assert hasattr(Model, name), name
        assert f"``{name}``" in doc, f"{name} is not in the interface table of models/base.py"


@pytest.mark.parametrize("kind", MODEL_KINDS)
def test_every_kind_answers_the_declared_interface(kind):
    cls = model_class(kind)
    assert isinstance(cls.path_options, tuple) and all(isinstance(n, str) for n in cls.path_options)
    takes = cls.options_class()
    assert issubclass(takes, Model)
    assert (takes is cls) == (cls.specular_class is None)
    assert (cls.specular_class is None) == (cls.diffuse_class is None)
    assert isinstance(cls.footprint_queries, bool) and isinstance(cls.refine, bool)
    assert takes.check_options({}) is None
    free = cls.declared_free(None) if not cls.path_options else cls.default_free
    declared = {p.name for p in cls.declared_parameters()}
    assert set(free) <= declared, (kind, set(free) - declared)


def _probes(tree: ast.AST):
    """(line, name) of every ``getattr(x, "name", ...)`` naming a declared model member, and every read of a
    private model member (``x._memo``)."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "getattr":
            if len(node.args) >= 2 and isinstance(node.args[1], ast.Constant) and node.args[1].value in DECLARED:
                yield node.lineno, node.args[1].value
        if isinstance(node, ast.Attribute) and node.attr == "_memo":
            yield node.lineno, node.attr


def test_no_module_outside_models_probes_the_interface_or_reads_a_private_member():
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.relative_to(PACKAGE).parts[0] == "models":
            continue
        found += [f"{path.relative_to(PACKAGE)}:{line} {name}"
                  for line, name in _probes(ast.parse(path.read_text(encoding="utf-8")))]
    assert not found, found


def test_the_probe_scan_sees_a_probe():
    """The scan itself finds what it looks for (so the test above can fail)."""
    tree = ast.parse('x = getattr(model, "path_options", ())\ny = model._memo\nz = getattr(model, "other")\n')
    assert sorted(_probes(tree)) == [(1, "path_options"), (2, "_memo")]
