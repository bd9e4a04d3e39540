"""The IM model for many parameter sets at once (what the posterior evaluates per ensemble half) against the
literal scalar integrands of tests/im_reference.py and the one-set kernels, per set and per direction."""

from __future__ import annotations

import math

import im_reference as ref
import numpy as np
import pytest

from clothlab.frames import spherical_to_vector, to_yarn_frame
from clothlab.models.irawan.model import IrawanModel, Quadrature, yarn_specular
from clothlab.weave.presets import get_preset


def _pairs(n, rng):
    wi = spherical_to_vector(rng.uniform(0, 85, n), rng.uniform(0, 360, n))
    wo = spherical_to_vector(rng.uniform(0, 85, n), rng.uniform(0, 360, n))
    wi[0, 2] = -wi[0, 2]  # one back-facing pair: 0
    return wi, wo


def _sets(model, rng, m, free):
    """m parameter dicts around the preset's values (umax, kappa, psi, delta, w, l varied where free)."""
    base = model.default_parameters()
    out = []
    for _ in range(m):
        p = dict(base)
        for kind in ("warp", "weft"):
            p[f"{kind}.umax"] = float(np.clip(base[f"{kind}.umax"] + rng.normal(0, 8), 2, 80))
            p[f"{kind}.kappa"] = float(rng.uniform(-0.8, 1.5))
            if "psi" in free:
                p[f"{kind}.psi"] = float(base[f"{kind}.psi"] + rng.normal(0, 5))
            if "w" in free:
                p[f"{kind}.w"], p[f"{kind}.l"] = float(rng.uniform(0.5, 2)), float(rng.uniform(1, 3))
        p["alpha"], p["beta"] = float(rng.uniform(0, 0.3)), float(rng.uniform(0.5, 30))
        if "delta" in free:
            p["delta"] = float(rng.choice([0.0, 0.2, 0.7]))
        out.append(p)
    return out


@pytest.mark.parametrize("fabric, free", [("polyester-lining", ("delta", "w")), ("silk-shantung", ("delta",)),
                                          ("cotton-denim", ("psi", "w")), ("wool-gabardine", ("psi",))])
@pytest.mark.parametrize("rule", [("trapezoid", 11), ("gauss", 9), ("support", 6), ("adaptive", 4)])
def test_many_sets_equal_one_set_at_a_time(fabric, free, rule):
    """components_many (J, N) row j equals the one-set kernels (yarn_specular, the per-set quadrature loop)
    at set j to 1e-12 relative, and components() of set j; the staple path under a fixed rule bit for bit."""
    rng = np.random.default_rng(len(fabric) + rule[1])
    model = IrawanModel(get_preset(fabric), Quadrature(*rule))
    wi, wo = _pairs(120, rng)
    sets = _sets(model, rng, 5, free)
    many = model.components_many(wi, wo, sets, normalised=False, warn=False)
    assert many["specular_warp"].shape == (5, 120)
    for j, p in enumerate(sets):
        one = IrawanModel(get_preset(fabric), Quadrature(*rule)).components(wi, wo, p, normalised=False, warn=False)
        for kind in ("warp", "weft"):
            expected = yarn_specular(wi, wo, p, kind, model.quadrature)
            got = many[f"specular_{kind}"][j]
            assert np.all(np.abs(got - expected) <= 1e-12 * np.abs(expected) + 1e-300), (kind, p)
            np.testing.assert_array_equal(got, one[f"specular_{kind}"])
            if "psi" in free and rule[0] in ("trapezoid", "gauss"):
                np.testing.assert_array_equal(got, expected)
        assert got[0] == 0.0 and np.count_nonzero(got) > 10  # back-facing 0; the test can fail


def test_filament_moments_against_the_literal_integrand():
    """The filament sum from the per-direction moments (eq. 2 with eqs. 4, 6, 8, 9) equals the literal
    trapezoid sum of tests/im_reference.py, including the |u| >= umax cut and the smoothstep fade."""
    rng = np.random.default_rng(3)
    model = IrawanModel(get_preset("polyester-lining"))
    wi, wo = _pairs(60, rng)
    sets = _sets(model, rng, 4, ("delta", "w"))
    many = model.components_many(wi, wo, sets, normalised=False, warn=False)
    lw, lo = to_yarn_frame(wi, "warp"), to_yarn_frame(wo, "warp")
    cos_x = -np.sum(wi * wo, axis=1)
    for j, p in enumerate(sets):
        integral = np.array([ref.discrete_sum(a, b, staple=False, rule="trapezoid", n=11, psi=0.0,
                                              umax=math.radians(p["warp.umax"]), kappa=p["warp.kappa"],
                                              w=p["warp.w"], l=p["warp.l"], delta=p["delta"])
                             for a, b in zip(lw, lo, strict=True)])
        phase = p["alpha"] + np.exp(p["beta"] * (np.clip(cos_x, -1, 1) - 1)) / (2 * np.pi * np.i0(p["beta"])
                                                                                 * np.exp(-p["beta"]))
        np.testing.assert_allclose(many["specular_warp"][j], phase * integral, rtol=1e-10, atol=1e-300)
        assert np.count_nonzero(integral) > 5


def test_normalised_and_need_follow_components():
    rng = np.random.default_rng(4)
    model = IrawanModel(get_preset("cotton-twill"))
    wi, wo = _pairs(40, rng)
    sets = _sets(model, rng, 3, ("psi",))
    many = model.components_many(wi, wo, sets, need=("diffuse", "specular_weft"), warn=False)
    assert set(many) == {"diffuse", "specular_weft"}
    for j, p in enumerate(sets):
        one = model.components(wi, wo, p, need=("diffuse", "specular_weft"), warn=False)
        np.testing.assert_array_equal(many["specular_weft"][j], one["specular_weft"])
        np.testing.assert_array_equal(many["diffuse"][j], one["diffuse"])


def test_bad_parameter_in_a_batch_is_named():
    from clothlab.errors import ParameterError

    model = IrawanModel(get_preset("polyester-lining"))
    wi, wo = _pairs(5, np.random.default_rng(5))
    sets = [model.default_parameters(), {**model.default_parameters(), "warp.kappa": -1.5}]
    with pytest.raises(ParameterError, match="warp.kappa"):
        model.components_many(wi, wo, sets)
