"""The baseline models beside IM: Lambert and Oren-Nayar (Oren & Nayar 1994, "Generalization of Lambert's
reflectance model", SIGGRAPH, the qualitative model eq. 30), each one package plus one registry line."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate

from clothlab.errors import ConfigError, ParameterError
from clothlab.frames import spherical_to_vector
from clothlab.models.baselines.lambert import LambertModel
from clothlab.models.baselines.oren_nayar import OrenNayarModel
from clothlab.models.registry import build_model, model_class
from clothlab.weave.presets import get_preset

WEAVE = get_preset("polyester-lining")
RNG = np.random.default_rng(1994)


def random_pairs(n, max_theta=89.0, rng=RNG):
    wi = spherical_to_vector(rng.uniform(0, max_theta, n), rng.uniform(0, 360, n))
    wo = spherical_to_vector(rng.uniform(0, max_theta, n), rng.uniform(0, 360, n))
    return wi, wo


def oren_nayar_reference(theta_i, phi_i, theta_o, phi_o, sigma_deg):
    """Eq. 30 of the paper, scalar and in angles (radians; sigma in degrees), divided by E0 cos(theta_i)."""
    s = math.radians(sigma_deg)
    a = 1.0 - 0.5 * s * s / (s * s + 0.33)
    b = 0.45 * s * s / (s * s + 0.09)
    alpha, beta = max(theta_i, theta_o), min(theta_i, theta_o)
    return (a + b * max(0.0, math.cos(phi_o - phi_i)) * math.sin(alpha) * math.tan(beta)) / math.pi


def test_registry_builds_both_kinds():
    assert model_class("lambert") is LambertModel and model_class("oren-nayar") is OrenNayarModel
    assert isinstance(build_model("oren-nayar", WEAVE, ("trapezoid", 11)), OrenNayarModel)
    with pytest.raises(ConfigError, match="takes no option 'sigma'"):
        build_model("oren-nayar", WEAVE, None, sigma=3.0)
    with pytest.raises(ConfigError, match="takes no option"):
        build_model("lambert", WEAVE, None, tile_nodes=3)


def test_lambert_is_one_over_pi_in_front_and_zero_behind():
    wi, wo = random_pairs(200)
    wo[::3, 2] *= -1.0  # every third exitant direction below the surface
    d = LambertModel(WEAVE).components(wi, wo)["diffuse"]
    front = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    assert front.any() and not front.all()
    np.testing.assert_array_equal(d[front], 1.0 / np.pi)
    np.testing.assert_array_equal(d[~front], 0.0)
    with pytest.raises(ParameterError, match="unknown parameter"):
        LambertModel(WEAVE).components(wi, wo, {"sigma": 1.0})


def test_oren_nayar_at_sigma_zero_is_lambert():
    wi, wo = random_pairs(500)
    on = OrenNayarModel(WEAVE).components(wi, wo, {"sigma": 0.0})["diffuse"]
    np.testing.assert_array_equal(on, LambertModel(WEAVE).components(wi, wo)["diffuse"])
    rough = OrenNayarModel(WEAVE).components(wi, wo, {"sigma": 30.0})["diffuse"]
    assert not np.allclose(rough, on)


@pytest.mark.parametrize("sigma", [5.0, 20.0, 45.0, 89.0])
def test_oren_nayar_matches_the_scalar_formula_of_eq_30(sigma):
    rng = np.random.default_rng(int(sigma))
    ti, to = rng.uniform(0, 89, 300), rng.uniform(0, 89, 300)
    pi_, po = rng.uniform(0, 360, 300), rng.uniform(0, 360, 300)
    got = OrenNayarModel(WEAVE).components(spherical_to_vector(ti, pi_), spherical_to_vector(to, po),
                                           {"sigma": sigma})["diffuse"]
    expected = [oren_nayar_reference(*np.deg2rad([a, b, c, d]), sigma) for a, b, c, d in zip(ti, pi_, to, po,
                                                                                             strict=True)]
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-15)
    # the retro-reflective rise the model exists for: backscatter at 70 deg exceeds the value at the normal
    model = OrenNayarModel(WEAVE)
    back = model.components(spherical_to_vector([70.0], [0.0]), spherical_to_vector([70.0], [0.0]),
                            {"sigma": sigma})["diffuse"][0]
    normal = model.components(np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, 1.0]]), {"sigma": sigma})
    assert back > normal["diffuse"][0] > 0.0


@pytest.mark.parametrize("model,params", [(LambertModel(WEAVE), {}), (OrenNayarModel(WEAVE), {"sigma": 35.0})])
def test_reciprocity_and_non_negativity(model, params):
    wi, wo = random_pairs(1000, max_theta=90.0)
    wi[::7] *= -1.0  # some back-facing pairs too
    a = model.components(wi, wo, params)["diffuse"]
    b = model.components(wo, wi, params)["diffuse"]
    np.testing.assert_array_equal(a, b)
    assert np.all(np.isfinite(a)) and np.all(a >= 0.0)
    assert np.all(a[(wi[:, 2] <= 0) | (wo[:, 2] <= 0)] == 0.0)


def directional_albedo(model, params, theta_i_deg):
    """int f_r cos(theta_o) dw_o over the hemisphere by scipy dblquad (phi_i = 0)."""
    wi = spherical_to_vector(np.array([theta_i_deg]), np.array([0.0]))

    def integrand(phi, theta):
        wo = spherical_to_vector(np.array([np.degrees(theta)]), np.array([np.degrees(phi)]))
        return model.components(wi, wo, params)["diffuse"][0] * math.cos(theta) * math.sin(theta)

    value, _ = integrate.dblquad(integrand, 0.0, math.pi / 2, 0.0, 2 * math.pi, epsabs=1e-9, epsrel=1e-9)
    return value


@pytest.mark.parametrize("sigma", [0.0, 30.0, 89.9])
@pytest.mark.parametrize("theta_i", [0.0, 45.0, 85.0])
def test_directional_albedo_at_most_one(sigma, theta_i):
    albedo = directional_albedo(OrenNayarModel(WEAVE), {"sigma": sigma}, theta_i)
    assert 0.0 < albedo <= 1.0
    if sigma == 0.0:
        assert albedo == pytest.approx(1.0, abs=1e-7)  # Lambert: exactly 1 (the quadrature has teeth)
    else:
        assert albedo < 1.0  # rough: the facets' masking and shadowing lose energy (no interreflection)
    if theta_i == 0.0:  # at normal incidence beta = 0, so the albedo is A exactly
        s2 = math.radians(sigma) ** 2
        assert albedo == pytest.approx(1.0 - 0.5 * s2 / (s2 + 0.33), abs=1e-7)


def test_lambert_albedo_is_one():
    assert directional_albedo(LambertModel(WEAVE), {}, 60.0) == pytest.approx(1.0, abs=1e-7)


def test_declared_sigma_range():
    model = OrenNayarModel(WEAVE)
    for bad in (-1.0, 90.0, float("nan")):
        with pytest.raises(ParameterError, match="sigma"):
            model.components(*random_pairs(2), {"sigma": bad})
    assert model.params["sigma"].unit == "deg" and model.default_free == ("sigma",)


# ---------------------------------------------------------------------------------------------- fits

def simulated_config(tmp_path, kind, free, truth, kd=(0.3, 0.2, 0.1), noise=0.01):
    """Oren-Nayar / Lambert data on the paper's sampling, written as a table, and a fit configuration."""
    from clothlab.config import config_from_dict
    from clothlab.io.table import write_table
    from clothlab.simulate.gonio import NoiseModel, simulate

    generator = OrenNayarModel(WEAVE)
    m = simulate(generator, truth, {"kd": np.asarray(kd)}, noise=NoiseModel(noise, 0.0, 3))
    path = write_table(m, tmp_path / "data.csv")
    return config_from_dict({
        "name": f"baseline-{kind}", "measurement": {"path": str(path)},
        "model": {"kind": kind, "weave": "preset:polyester-lining"},
        "fit": {"free": list(free), "optimizer": {"global": "GN_CRS2_LM", "local": "LN_BOBYQA", "max_evals": 300,
                                                  "starts": 1, "seed": 1}},
        "output": {"fits": str(tmp_path / "fits"), "reports": str(tmp_path / "reports")}}, base_dir=tmp_path)


def test_oren_nayar_recovers_sigma_from_its_own_simulated_data(tmp_path):
    from clothlab.fit.runner import build_problem, run_fit

    config = simulated_config(tmp_path, "oren-nayar", ["sigma"], {"sigma": 30.0})
    problem = build_problem(config)
    assert problem.free == ("sigma",) and problem.component_names == ("diffuse",)
    result = run_fit(config)
    assert result.params["sigma"] == pytest.approx(30.0, abs=1.0)
    np.testing.assert_allclose(result.coefficients["kd"], [0.3, 0.2, 0.1], rtol=0.02)
    # the objective at the truth is below the one at sigma = 0 (the data do determine sigma)
    assert problem.solve({"sigma": 30.0}).objective < problem.solve({"sigma": 0.0}).objective


def test_lambert_fit_solves_kd_alone(tmp_path):
    from clothlab.fit.runner import run_fit

    result = run_fit(simulated_config(tmp_path, "lambert", [], {"sigma": 0.0}))
    np.testing.assert_allclose(result.coefficients["kd"], [0.3, 0.2, 0.1], rtol=0.02)


# ------------------------------------------------------------- the interface every registered model implements

def _rst_rows(doc: str, header_first: str) -> list[list[str]]:
    """Data rows (cells split on 2+ spaces) of the simple RST table whose header starts with ``header_first``."""
    import re

    lines = doc.splitlines()
    start = next(i for i, line in enumerate(lines) if line.split() and line.split()[0] == header_first
                 and i > 0 and lines[i - 1].startswith("=="))
    rows = []
    for line in lines[start + 2:]:
        if line.startswith("=="):
            break
        if line[:1].strip():  # a line starting with spaces continues the row above
            rows.append(re.split(r"\s{2,}", line.strip()))
    return rows


def _declared_range(spec) -> str:
    lo, hi = spec.valid
    return f"{'(' if spec.open_lower else '['}{lo:g}, {hi:g}{')' if spec.open_upper else ']'}"


@pytest.mark.parametrize("kind", ["irawan", "kang", "lambert", "oren-nayar"])
def test_each_model_file_opens_with_a_true_parameter_table(kind):
    """The docstring table of a model's module lists exactly its declared parameters with their declared
    unit, physical range and default (the declarations are the truth; the table must follow them)."""
    import sys

    cls = model_class(kind)
    assert kind in __import__("clothlab.models.registry", fromlist=["MODEL_KINDS"]).MODEL_KINDS
    from clothlab.models.base import ORIENTATION

    rows = _rst_rows(sys.modules[cls.__module__].__doc__, "parameter")
    specs = [s for s in cls.params if s.name != ORIENTATION]  # every model's, documented once in models.base
    if not specs:
        assert rows == [["(none)"]]
        return
    assert [r[0] for r in rows] == [s.name for s in specs]
    for row, spec in zip(rows, specs, strict=True):
        assert row[1:4] == [spec.unit, _declared_range(spec), f"{spec.default:g}"], spec.name


def test_the_base_table_names_real_members():
    from clothlab.models.base import Model

    names = [row[0].strip("`") for row in _rst_rows(sys_doc("clothlab.models.base"), "member")]
    assert len(names) >= 10 and len(set(names)) == len(names)
    for name in names:
        assert hasattr(Model, name) or name in Model.__annotations__, name
    public = {n for n in vars(Model) if not n.startswith("_")} | set(Model.__annotations__)
    assert public <= set(names)  # and every public member is in the table


def sys_doc(module: str) -> str:
    import importlib

    return importlib.import_module(module).__doc__


@pytest.mark.parametrize("kind", ["irawan", "kang", "lambert", "oren-nayar"])
def test_registered_models_answer_the_interface(kind):
    """What the fitter, report, texture fit and renderer ask of every model, asked of each kind."""
    from clothlab.models.base import Model

    cls = model_class(kind)
    model = build_model(kind, WEAVE, ("trapezoid", 11))
    assert issubclass(cls, Model) and model.kind == kind
    p = model.default_parameters()
    assert set(p) | {"orientation"} == set(model.params.names())  # orientation: only when given (models.base)
    assert set(model.default_free) <= set(p)
    wi, wo = random_pairs(20, max_theta=80.0)
    comps = model.components(wi, wo, p)
    assert tuple(comps) == tuple(model.component_names) and all(c.shape == (20,) for c in comps.values())
    assert set(model.components(wi, wo, p, need=("diffuse",))) == {"diffuse"}
    assert isinstance(cls.describe_settings({"kind": kind, **model.settings()}), str)
    assert model.with_quadrature("gauss", 5).components(wi, wo, p).keys() == comps.keys()
    assert isinstance(model.geometry_warnings(p), list)
    assert model.fitted_weave(p).tile_width == WEAVE.tile_width
    if model.has_texture:
        texture = model.texture()
        out = texture.components(np.full(20, 0.3), np.full(20, 0.6), wi, wo, p)
        assert set(model.component_names) <= set(out) <= set(texture.component_names)
    else:
        with pytest.raises(ConfigError, match="no texture model"):
            model.texture()


def test_baselines_without_texture_are_refused_by_texture_consumers(tmp_path):
    """BTF simulation / texture fit and the renderer ask has_texture and say what is missing."""
    from pathlib import Path

    from clothlab.errors import InputError
    from clothlab.simulate.btf import load_source

    fit_dir = Path(__file__).resolve().parents[1] / "fits" / "polyester-lining-oren-nayar"
    with pytest.raises(InputError, match="'oren-nayar' has no texture model"):
        load_source(fit_dir)
    kang_fit = fit_dir.parent / "polyester-lining-kang"
    with pytest.raises(InputError, match="declares no warp.w"):
        load_source(kang_fit)
