"""Orientation, declarations and component names over every registered kind (composites included), with
``kind: neural`` among them (issue 23, build item 6): the model's components and, where a kind answers
footprint queries (``footprint_queries``: kind neural), those queries apply ``orientation`` (0 and 40 deg
differ on an anisotropic weave; turning the directions and the orientation together changes nothing); every
texture model declares what its model declares, names the same components and refuses an orientation other
than 0 as a ConfigError at ``orientation`` (it evaluates the weave in its tile frame)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from clothlab.errors import ConfigError, GeometryWarning
from clothlab.frames import rotate_about_normal, spherical_to_vector
from clothlab.models.base import ORIENTATION
from clothlab.models.registry import MODEL_KINDS, build_model
from clothlab.weave.presets import get_preset

TWILL = get_preset("wool-gabardine")  # anisotropic; it has a shipped network
ANGLE = 40.0
RNG = np.random.default_rng(23)


def _pairs(n):
    th = np.degrees(np.arccos(RNG.uniform(0.2, 1.0, (2, n))))
    return spherical_to_vector(th[0], RNG.uniform(0, 360, n)), spherical_to_vector(th[1], RNG.uniform(0, 360, n))


WI, WO = _pairs(40)
CENTRE = RNG.random((40, 2))
SIZE = RNG.uniform(0.05, 2.0, 40)


def _model(kind):
    return build_model(kind, TWILL, ("trapezoid", 11)) if kind != "neural" else build_model(kind, TWILL)


def _evaluations(model):
    """(name, f(wi, wo, params)) of every direction-taking entry point of ``model``."""
    out = [("components", lambda wi, wo, p: model.components(wi, wo, p))]
    if getattr(model, "footprint_queries", False):
        out.append(("query", lambda wi, wo, p: model.query(CENTRE, SIZE, wi, wo, p)))
    return out


def _total(values: dict) -> np.ndarray:
    return np.sum([np.asarray(v, dtype=np.float64) for v in values.values()], axis=0)


@pytest.mark.parametrize("kind", sorted(MODEL_KINDS))
def test_orientation_is_applied_by_every_kind_and_every_entry_point(kind):
    model = _model(kind)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        for name, f in _evaluations(model):
            zero, turned = _total(f(WI, WO, {ORIENTATION: 0.0})), _total(f(WI, WO, {ORIENTATION: ANGLE}))
            if model.orientation_period:  # anisotropic: the orientation changes the values
                assert np.max(np.abs(turned - zero)) > 1e-3 * np.max(np.abs(zero)), (kind, name)
            else:
                np.testing.assert_allclose(turned, zero, rtol=1e-12, atol=1e-15, err_msg=f"{kind} {name}")
            # directions turned with the weave: the weave-frame directions are those at orientation 0
            together = _total(f(rotate_about_normal(WI, ANGLE), rotate_about_normal(WO, ANGLE), {ORIENTATION: ANGLE}))
            np.testing.assert_allclose(together, zero, rtol=1e-9, atol=1e-12, err_msg=f"{kind} {name}")


TEXTURED = [k for k in sorted(MODEL_KINDS) if _model(k).has_texture]


@pytest.mark.parametrize("kind", TEXTURED)
def test_texture_models_declare_as_their_model_and_refuse_an_orientation(kind):
    model = _model(kind)
    texture = model.texture()
    if model.texture_filters:  # it stands alone (kang: its point shader adds per-yarn diffuse parts, sec. 4.2.1)
        assert set(model.component_names) <= set(texture.component_names)
    else:  # a renderer blends it with the model's components: the same names
        assert tuple(texture.component_names) == tuple(model.component_names)
    assert texture.params.names() == model.params.names()
    for name in model.params.names():
        assert texture.params[name].bounds == model.params[name].bounds, name
    assert texture.resolve(None) == model.resolve(None)
    u, v = np.full(3, 0.2), np.full(3, 0.4)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        texture.components(u, v, WI[:3], WO[:3], {ORIENTATION: 0.0})
        with pytest.raises(ConfigError) as err:
            texture.components(u, v, WI[:3], WO[:3], {ORIENTATION: ANGLE})
    assert err.value.field == ORIENTATION


def test_neural_texture_is_a_model_texture_and_its_footprint_query_is_the_models():
    from clothlab.models.base import ModelTexture

    model = _model("neural")
    texture = model.texture()
    assert isinstance(texture, ModelTexture)
    direct = model.query(CENTRE, SIZE, WI, WO)
    via = texture.components(CENTRE[:, 0], CENTRE[:, 1], WI, WO, footprint=SIZE)
    for name in model.component_names:
        np.testing.assert_allclose(via[name], direct[name], rtol=1e-6, atol=1e-12)
