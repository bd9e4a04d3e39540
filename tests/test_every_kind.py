"""Every registered kind (:data:`clothlab.models.registry.MODEL_KINDS`, composites and physics options
included, read from the registry, never a hand list) through the same three checks (issue 25 item 2):

- the contract: the members of the interface table in :mod:`clothlab.models.base` exist on the class and the
  instance; ``components`` names exactly ``component_names``, each (N,) float64 and finite; the batched entry
  point gives the single one's rows; ``default_parameters`` never lists ``orientation`` and ``resolve`` lists it
  only when given; a texture model is a :class:`clothlab.models.base.Texture` with its model's declarations;
- orientation: turning the directions by an angle and setting ``orientation`` to it gives the unturned values
  (docs/design.md principle 1), an angle and that angle plus the kind's period give the same values, and an
  isotropic kind does not depend on it;
- the round trip: the model, its fit.json ``model`` entry (kind and ``settings()``, as
  :func:`clothlab.fit.store.fit_summary` writes it) and its ``weave.wv`` (``fitted_weave``), rebuilt by
  :func:`clothlab.config.build.model_from_fit`, give the same values at the same (JSON round-tripped) parameters.

And the rule of docs/design.md ("only the registry knows kinds"): no string literal naming a kind in clothlab/
outside models/, but for the allow-listed ones below (files other helpers own, file-format keys).
"""

from __future__ import annotations

import ast
import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from clothlab.errors import GeometryWarning
from clothlab.frames import rotate_about_normal, spherical_to_vector
from clothlab.models import base
from clothlab.models.base import ORIENTATION, Model, Texture
from clothlab.models.registry import MODEL_KINDS, build_model, model_class
from clothlab.weave.presets import get_preset

PACKAGE = Path(__file__).resolve().parents[1] / "clothlab"
WEAVE = get_preset("wool-gabardine")  # anisotropic (a twill), and it has a shipped network (kind neural)
QUADRATURE = ("gauss", 8)  # not the default (trapezoid 11): the round trip must carry it
ANGLE = 35.0
RNG = np.random.default_rng(25)


def _pairs(n):
    th = np.degrees(np.arccos(RNG.uniform(0.15, 1.0, (2, n))))
    return spherical_to_vector(th[0], RNG.uniform(0, 360, n)), spherical_to_vector(th[1], RNG.uniform(0, 360, n))


WI, WO = _pairs(24)


def _model(kind):
    return build_model(kind, WEAVE, QUADRATURE)  # a model that integrates nothing ignores it


def _components(model, wi, wo, params):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        return model.components(wi, wo, params)


def _interface_members() -> list[str]:
    """The names in the member table of the models/base.py docstring (its first column)."""
    lines = base.__doc__.splitlines()
    rules = [i for i, line in enumerate(lines) if line.startswith("=====")]
    return [line.split()[0].strip("`") for line in lines[rules[1] + 1:rules[2]] if line.startswith("``")]


def test_the_member_table_is_read():
    members = _interface_members()
    assert {"kind", "components", "components_many", "resolve", "texture", "orientation_period"} <= set(members)
    assert len(members) == len(set(members)) >= 30


@pytest.mark.parametrize("kind", MODEL_KINDS)
def test_every_kind_keeps_the_contract(kind):
    cls, model = model_class(kind), _model(kind)
    assert issubclass(cls, Model) and isinstance(model, cls) and model.kind == kind
    for name in _interface_members():
        assert hasattr(cls, name) or name in Model.__annotations__, (kind, name)
        assert hasattr(model, name), (kind, name)
    comps = _components(model, WI, WO, None)
    assert tuple(comps) == tuple(model.component_names), kind
    for name, value in comps.items():
        assert value.shape == (len(WI),) and value.dtype == np.float64 and np.all(np.isfinite(value)), (kind, name)
    defaults = model.default_parameters()
    assert ORIENTATION not in defaults and ORIENTATION in model.params
    assert set(defaults) <= set(model.params.names()), kind
    assert model.resolve(None) == defaults
    assert model.resolve({ORIENTATION: ANGLE}) == {**defaults, ORIENTATION: ANGLE}
    assert ORIENTATION in cls.declared_parameters()
    # the batched entry point: each row is the single evaluation at that set (two orientations in one batch)
    sets = [None, {ORIENTATION: ANGLE}]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        many = model.components_many(WI, WO, sets)
    for j, p in enumerate(sets):
        single = _components(model, WI, WO, p)
        for name in model.component_names:
            np.testing.assert_allclose(many[name][j], single[name], rtol=1e-12, atol=1e-15, err_msg=f"{kind} {name}")
    if model.has_texture:
        texture = model.texture()
        assert isinstance(texture, Texture), kind
        assert texture.params.names() == model.params.names(), kind
        assert set(model.component_names) <= set(texture.component_names), kind


@pytest.mark.parametrize("kind", MODEL_KINDS)
def test_every_kind_applies_its_orientation_and_has_its_period(kind):
    model = _model(kind)
    zero = _components(model, WI, WO, None)
    turned = _components(model, rotate_about_normal(WI, ANGLE), rotate_about_normal(WO, ANGLE), {ORIENTATION: ANGLE})
    for name in model.component_names:  # the weave turned with the directions: the same values
        np.testing.assert_allclose(turned[name], zero[name], rtol=1e-9, atol=1e-12, err_msg=f"{kind} {name}")
    period = model.orientation_period
    at = _components(model, WI, WO, {ORIENTATION: ANGLE})
    if not period:  # isotropic: nothing depends on it
        for name in model.component_names:
            np.testing.assert_allclose(at[name], zero[name], rtol=1e-12, atol=1e-15, err_msg=f"{kind} {name}")
        return
    later = _components(model, WI, WO, {ORIENTATION: ANGLE - period})
    for name in model.component_names:
        if model.footprint_queries:  # a network (kind neural) has the symmetry only to its training error (~2 %)
            assert np.max(np.abs(later[name] - at[name])) <= 0.05 * np.max(np.abs(at[name])), (kind, name)
        else:
            np.testing.assert_allclose(later[name], at[name], rtol=1e-9, atol=1e-12, err_msg=f"{kind} {name}")
    total = sum(at.values()) - sum(zero.values())  # and it does depend on it (an anisotropic twill)
    assert np.max(np.abs(total)) > 1e-3 * np.max(np.abs(sum(zero.values()))), kind


@pytest.mark.parametrize("kind", MODEL_KINDS)
def test_every_kind_round_trips_through_its_fit_directory_entries(kind, tmp_path):
    from clothlab.config.build import model_from_fit
    from clothlab.weave.wvformat import format_wv

    model = _model(kind)
    params = {**model.default_parameters(), ORIENTATION: ANGLE}
    # fit.json's recorded configuration holds the quadrature (a composite's model entry records it per part only)
    config = {"model": {"kind": kind, "quadrature": dict(zip(("rule", "nodes"), QUADRATURE, strict=True))}}
    fit = json.loads(json.dumps({"config": config, "model": {"kind": model.kind, **model.settings()},
                                 "parameters": {k: {"value": v} for k, v in params.items()}}))
    (tmp_path / "weave.wv").write_text(format_wv(model.fitted_weave(params)))
    rebuilt = model_from_fit(fit, tmp_path)
    assert type(rebuilt) is type(model) and rebuilt.settings() == model.settings(), kind
    again = {k: v["value"] for k, v in fit["parameters"].items()}
    assert rebuilt.resolve(again) == model.resolve(params), kind
    before, after = _components(model, WI, WO, params), _components(rebuilt, WI, WO, again)
    for name in model.component_names:
        np.testing.assert_array_equal(after[name], before[name], err_msg=f"{kind} {name}")


# ---------------------------------------------------------------------------------------------- kind names

#: (module under clothlab/, kind literal) pairs that may still name a kind outside models/, with the reason.
#: Only file-format keys and names remain (every kind choice asks the registry).
ALLOWED = {
    # file formats and layouts, not kind choices
    ("render/scene.py", "kang"): "the scene file's fabric.kang section (a file-format key)",
    ("studies/bench.py", "kang"): "a bench section's name (reports/bench/result.json)",
    ("studies/bench.py", "neural"): "a bench section's name (reports/bench/result.json)",
    ("studies/data.py", "kang"): "the kang.yaml variant of measurements/<fabric>/ (the data layout)",
}


def _kind_literals(tree: ast.AST, kinds) -> list[tuple[int, str]]:
    """(line, value) of every string constant that is exactly a kind name (docstrings never are)."""
    return [(node.lineno, node.value) for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in kinds]


def test_no_module_outside_models_names_a_kind():
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE)
        if rel.parts[0] == "models":
            continue
        for line, value in _kind_literals(ast.parse(path.read_text(encoding="utf-8")), MODEL_KINDS):
            if (rel.as_posix(), value) not in ALLOWED:
                found.append(f"{rel}:{line} {value!r}")
    assert not found, "kind names outside models/ (ask the registry: DEFAULT_KIND, PAPER_KIND, SHADERS, ...): " \
        + ", ".join(found)


def test_the_kind_scan_sees_a_kind_name():
    tree = ast.parse('"""irawan docs"""\nbuild_model("kang", w)\nx = f"{k} kang"\ny = "irawan+lambert"\n')
    assert sorted(_kind_literals(tree, MODEL_KINDS)) == [(2, "kang"), (4, "irawan+lambert")]
