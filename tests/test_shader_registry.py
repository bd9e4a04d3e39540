"""Shaders are registered by kind (issue 25 item 2): the registry declares each shader's kind and shading
policy (:data:`clothlab.models.registry.SHADERS`), the renderer runs the policy (:data:`clothlab.render.shade.
POLICIES`) and ``clothlab render --help`` lists the registry's names; the scene as another kind goes through
:func:`clothlab.models.registry.from_irawan` (the IM-to-Kang mapping lives in models/kang/from_irawan.py)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from clothlab.errors import ConfigError
from clothlab.frames import spherical_to_vector
from clothlab.models import registry
from clothlab.models.components import combine
from clothlab.render import shade
from clothlab.weave.presets import get_preset


def test_every_shader_names_a_registered_kind_and_a_policy_the_renderer_runs():
    assert shade.SHADERS == tuple(registry.SHADERS)
    for name, (kind, policy) in registry.SHADERS.items():
        assert kind in registry.MODEL_KINDS and policy in shade.POLICIES, name
        # its antialiasing reference is a texture-level shader (compare_lod)
        assert registry.shader(shade.reference_shader(name))[1] in ("texture", "filtered-texture"), name
    for kind in registry.FROM_IRAWAN:
        assert kind in registry.MODEL_KINDS


def test_an_unknown_shader_is_a_config_error_at_shader():
    for bad in ("phong", None, ""):
        with pytest.raises(ConfigError) as err:
            registry.shader(bad)
        assert err.value.field == "shader"


def test_render_help_lists_the_registry_shaders():
    out = subprocess.run([sys.executable, "-m", "clothlab", "render", "--help"], capture_output=True, text=True,
                         check=True).stdout
    listed = " ".join(out.split())  # argparse wraps the help text
    for name in registry.SHADERS:
        assert name in listed, name


def test_the_im_to_kang_mapping_renders_the_im_diffuse_colour_on_both_yarns():
    """Kang's point ``diffuse`` is diffuse_warp + diffuse_weft (models/kang/model.py), so the IM coefficients
    mapped per yarn (kd_warp = kd_weft = kd) give the same image as kd on ``diffuse`` with the same ks."""
    weave = get_preset("cotton-denim")
    im = {"kd": np.array([0.2, 0.3, 0.4]), "ks_warp": np.array([0.5, 0.5, 0.5]), "ks_weft": np.array([0.1, 0.2, 0.3])}
    model, params, coefficients = registry.from_irawan("kang", weave, im, {"noise": 0.0})
    assert model.kind == "kang" and params == model.resolve({"noise": 0.0})
    rng = np.random.default_rng(3)
    n = 50
    wi = spherical_to_vector(rng.uniform(0, 80, n), rng.uniform(0, 360, n))
    wo = spherical_to_vector(rng.uniform(0, 80, n), rng.uniform(0, 360, n))
    comps = model.texture().components(rng.random(n), rng.random(n), wi, wo, params)
    per_yarn = combine({k: comps[k] for k in ("diffuse_warp", "diffuse_weft", "specular_warp", "specular_weft")},
                       coefficients)
    single = combine({k: comps[k] for k in ("diffuse", "specular_warp", "specular_weft")}, im)
    np.testing.assert_allclose(per_yarn, single, rtol=1e-12, atol=1e-15)


def test_a_kind_without_an_im_mapping_is_a_config_error():
    with pytest.raises(ConfigError) as err:
        registry.from_irawan("lambert", get_preset("cotton-denim"), {"kd": 0.5})
    assert err.value.field == "model.kind"
