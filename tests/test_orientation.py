"""The weave orientation, a parameter of every model (clothlab.models.base): default 0 changes nothing, rotating
data and orientation together changes nothing, the symmetries the periods claim hold, reciprocity survives."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from clothlab.errors import ConfigError, GeometryWarning
from clothlab.frames import rotate_about_normal, spherical_to_vector, to_weave_frame
from clothlab.io.measurement import Measurement
from clothlab.models.base import ORIENTATION, common_period
from clothlab.models.registry import MODEL_KINDS, build_model, model_class
from clothlab.weave.presets import get_preset

RNG = np.random.default_rng(14)
KINDS = ("irawan", "kang", "surface", "lambert", "oren-nayar", "irawan+oren-nayar")
TWILL = get_preset("wool-gabardine")


def pairs(n, rng=RNG, max_theta=85.0):
    lo = np.cos(np.deg2rad(max_theta))
    th = np.degrees(np.arccos(rng.uniform(lo, 1.0, (2, n))))
    return spherical_to_vector(th[0], rng.uniform(0, 360, n)), spherical_to_vector(th[1], rng.uniform(0, 360, n))


WI, WO = pairs(60)


def comps(model, params, wi=WI, wo=WO):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        return model.components(wi, wo, params)


def test_rotation_helper_is_a_rotation_about_the_normal():
    """R(a) keeps z and lengths, turns the azimuth by +a (counter-clockwise), and R(a) R(-a) = identity."""
    theta, phi = RNG.uniform(0, 89, 50), RNG.uniform(0, 360, 50)
    w = spherical_to_vector(theta, phi)
    turned = rotate_about_normal(w, 37.0)
    np.testing.assert_allclose(turned, spherical_to_vector(theta, phi + 37.0), atol=1e-15)
    np.testing.assert_allclose(to_weave_frame(turned, 37.0), w, atol=1e-15)
    assert np.array_equal(rotate_about_normal(w, 0.0), w)


@pytest.mark.parametrize("kind", KINDS)
def test_orientation_zero_is_bitwise_todays_model(kind):
    model = build_model(kind, TWILL, ("trapezoid", 11))
    plain, zero = comps(model, {}), comps(model, {ORIENTATION: 0.0})
    assert plain.keys() == zero.keys()
    for name in plain:
        assert np.array_equal(plain[name], zero[name]), name
    assert ORIENTATION in model.params and ORIENTATION not in model.default_parameters()
    assert model.resolve({ORIENTATION: 12.5})[ORIENTATION] == 12.5


@pytest.mark.parametrize("kind", KINDS)
def test_the_half_turn_symmetry_and_the_declared_period(kind):
    """f(orientation + 180) = f(orientation) for every model (the weave's half-turn symmetry, models.base); an
    isotropic model does not depend on the orientation at all."""
    model = build_model(kind, TWILL, ("trapezoid", 11))
    a, b = comps(model, {ORIENTATION: 25.0}), comps(model, {ORIENTATION: 205.0})
    for name in a:
        np.testing.assert_allclose(b[name], a[name], rtol=1e-10, atol=1e-14 * np.max(np.abs(a[name])))
    other = comps(model, {ORIENTATION: 70.0})
    moved = max(np.max(np.abs(other[n] - a[n])) / np.max(np.abs(a[n])) for n in a)
    cls = model_class(kind)
    if cls.orientation_period == 0.0:
        assert moved < 1e-12
    else:
        assert cls.orientation_period == 180.0 and moved > 1e-3
        assert cls.params[ORIENTATION].bounds == (-90.0, 90.0)


@pytest.mark.parametrize("kind", ["irawan", "kang"])
def test_a_quarter_turn_swaps_warp_and_weft_when_they_are_alike(kind):
    """With warp and weft parameters equal, a quarter turn maps specular_warp onto a multiple of specular_weft
    (cell shares aside), so the fit period is 90 deg; with different ones it stays 180."""
    model = build_model(kind, TWILL, ("trapezoid", 11))
    p = model.resolve({})
    alike = {k.replace("warp.", "weft."): v for k, v in p.items() if k.startswith("warp.")
             and k.replace("warp.", "weft.") in p}
    a, b = comps(model, alike), comps(model, {**alike, ORIENTATION: 90.0})
    for mine, theirs in (("specular_warp", "specular_weft"), ("specular_weft", "specular_warp")):
        x, y = a[mine], b[theirs]
        scale = (x @ y) / (y @ y)
        assert np.max(np.abs(x - scale * y)) < 1e-9 * np.max(np.abs(x))
    assert model.fit_period(alike) == 90.0
    if kind == "irawan":
        assert model.fit_period({}) == 180.0  # the gabardine preset's warp and weft segments differ (w, l)


def test_surface_model_does_not_claim_the_quarter_turn():
    model = build_model("surface", TWILL)
    p = model.resolve({})
    alike = {k.replace("warp.", "weft."): v for k, v in p.items() if k.startswith("warp.")}
    assert model.fit_period(alike) == 180.0


@pytest.mark.parametrize("kind", ["irawan", "kang", "oren-nayar", "irawan+oren-nayar"])
def test_reciprocity_holds_with_an_orientation(kind):
    model = build_model(kind, TWILL, ("trapezoid", 11))
    ab, ba = comps(model, {ORIENTATION: 37.0}), comps(model, {ORIENTATION: 37.0}, WO, WI)
    for name in ab:
        np.testing.assert_allclose(ba[name], ab[name], rtol=1e-9, atol=1e-14)


def test_a_batch_of_orientations_equals_one_by_one():
    model = build_model("irawan", TWILL, ("trapezoid", 11))
    sets = [{ORIENTATION: 10.0, "alpha": 0.1}, {"alpha": 0.2}, {ORIENTATION: 10.0, "beta": 2.0},
            {ORIENTATION: -40.0}]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        many = model.components_many(WI, WO, sets)
        for j, p in enumerate(sets):
            one = model.components(WI, WO, p)
            for name in one:
                np.testing.assert_allclose(many[name][j], one[name], rtol=1e-13, atol=0.0)


def test_rotating_the_data_and_the_orientation_together_leaves_the_fit_invariant():
    """A table whose azimuths are all turned by 50 deg, fitted with the orientation box turned by 50 deg, gives
    the same objective at every unit-box point (to rounding) and the same fit, orientation shifted by 50."""
    from clothlab.fit.optimize import minimize
    from clothlab.fit.problem import FitProblem

    model = build_model("irawan", TWILL, ("trapezoid", 11))
    wi, wo = pairs(80, np.random.default_rng(3))
    truth = {ORIENTATION: 20.0, "warp.umax": 25.0}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        values = model.evaluate(wi, wo, {"kd": [0.1], "ks_warp": [0.1], "ks_weft": [0.05]}, truth)

    def table(turn):
        ti, pi_ = (np.degrees(np.arccos(wi[:, 2])), np.degrees(np.arctan2(wi[:, 1], wi[:, 0])) + turn)
        to, po = (np.degrees(np.arccos(wo[:, 2])), np.degrees(np.arctan2(wo[:, 1], wo[:, 0])) + turn)
        return Measurement(ti, np.mod(pi_, 360), to, np.mod(po, 360), values, ("grey",))

    free = (ORIENTATION, "warp.umax", "alpha")
    a = FitProblem(model, table(0.0), free, {ORIENTATION: 0.0}, {ORIENTATION: (-90.0, 90.0)})
    b = FitProblem(model, table(50.0), free, {ORIENTATION: 50.0}, {ORIENTATION: (-40.0, 140.0)})
    for x in np.random.default_rng(5).random((5, 3)):
        assert b(x) == pytest.approx(a(x), rel=1e-9)
    ra = minimize(a, a.to_unit(a.start), np.zeros(3), np.ones(3), global_algorithm=None, max_evals=120)
    rb = minimize(b, b.to_unit(b.start), np.zeros(3), np.ones(3), global_algorithm=None, max_evals=120)
    # the same path up to rounding: both reach the (noise-free) truth, b's orientation turned by 50 deg
    assert ra.fun < 1e-3 * a(a.to_unit(a.start)) and rb.fun < 1e-3 * b(b.to_unit(b.start))
    assert a.from_unit(ra.x)[ORIENTATION] == pytest.approx(20.0, abs=0.2)
    assert b.from_unit(rb.x)[ORIENTATION] == pytest.approx(70.0, abs=0.2)


def test_a_fit_ending_at_the_period_edge_is_not_flagged(tmp_path):
    """Bounds spanning one period are one point: a truth of 90 deg (= -90) at the box edge gives no bound note."""
    from clothlab.config import config_from_dict
    from clothlab.fit.runner import run_fit
    from clothlab.io.table import write_table
    from clothlab.simulate.gonio import simulate
    from clothlab.simulate.sampling import random_sampling

    model = build_model("irawan", TWILL, ("trapezoid", 11))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        m = simulate(model, {ORIENTATION: 90.0}, {"kd": [0.1], "ks_warp": [0.08], "ks_weft": [0.05]},
                     channels=("grey",), sampling=random_sampling(120, seed=2))
    write_table(m, tmp_path / "t.csv")
    cfg = config_from_dict({"name": "edge", "measurement": {"path": "t.csv"},
                            "model": {"weave": "preset:wool-gabardine", "params": {ORIENTATION: 85.0}},
                            "fit": {"free": [ORIENTATION], "optimizer": {"max_evals": 80, "global": None,
                                                                         "polish": 40}}}, base_dir=tmp_path)
    result = run_fit(cfg)
    assert abs(abs(result.params[ORIENTATION]) - 90.0) < 0.5
    assert not any("ended at its" in w for w in result.warnings), result.warnings


def test_config_frees_orientation_with_a_start_and_one_period_of_bounds(tmp_path):
    from clothlab.config import config_from_dict
    from clothlab.fit.problem import build_problem
    from clothlab.io.table import write_table
    from clothlab.simulate.gonio import simulate
    from clothlab.simulate.sampling import random_sampling

    m = simulate(build_model("lambert", TWILL), {}, {"kd": [0.1]}, channels=("grey",),
                 sampling=random_sampling(10, seed=1))
    write_table(m, tmp_path / "t.csv")
    for kind, bounds in (("irawan", [-90.0, 90.0]), ("lambert", [-180.0, 180.0])):
        cfg = config_from_dict({"name": "o", "measurement": {"path": "t.csv"},
                                "model": {"kind": kind, "weave": "preset:wool-gabardine"},
                                "fit": {"free": [ORIENTATION]}}, base_dir=tmp_path)
        assert cfg.model.params[ORIENTATION] == 0.0
        problem = build_problem(cfg)
        assert [problem.lower[0], problem.upper[0]] == bounds
    with pytest.raises(ConfigError, match="orientation"):
        config_from_dict({"name": "o", "measurement": {"path": "t.csv"},
                          "model": {"weave": "preset:wool-gabardine", "params": {ORIENTATION: 400}}},
                         base_dir=tmp_path)


def test_texture_models_refuse_an_orientation():
    for kind in [k for k in sorted(MODEL_KINDS) if model_class(k).has_texture]:  # every texture, one base
        texture = build_model(kind, TWILL).texture()
        wi, wo = WI[:3], WO[:3]
        texture.components(np.full(3, 0.2), np.full(3, 0.4), wi, wo, {ORIENTATION: 0.0})
        with pytest.raises(ConfigError, match="takes no orientation"):
            texture.components(np.full(3, 0.2), np.full(3, 0.4), wi, wo, {ORIENTATION: 10.0})


def test_common_period():
    assert common_period([180.0, 0.0]) == 180.0
    assert common_period([0.0, 0.0]) == 0.0
    assert common_period([90.0, 180.0]) == 180.0
    assert common_period([120.0, 180.0]) == 360.0


def test_orientation_bounds_wider_than_one_period_are_refused():
    from clothlab.errors import ConfigError
    from clothlab.fit.problem import FitProblem
    from clothlab.io.measurement import Measurement
    from clothlab.models.registry import build_model
    from clothlab.weave.presets import get_preset

    model = build_model("irawan", get_preset("cotton-denim"))
    m = Measurement(np.full(4, 30.0), np.zeros(4), np.full(4, 40.0), np.arange(4) * 90.0, np.ones((4, 1)), ("grey",))
    period = model.params["orientation"].period
    FitProblem(model, m, ("orientation",), {"orientation": 0.0}, {"orientation": (-period / 2, period / 2)})
    with pytest.raises(ConfigError, match="period") as info:
        FitProblem(model, m, ("orientation",), {"orientation": 0.0}, {"orientation": (-period / 2, period / 2 + 1)})
    assert info.value.field == "fit.bounds.orientation"


def test_a_subclass_writes_the_hooks_and_cannot_bypass_the_orientation():
    """The public methods apply the orientation (template methods of models/base.py); a class that defines one
    itself, as NeuralTexture once did, is refused when it is created, for models and for textures."""
    from clothlab.models.base import TEMPLATE_METHODS, TEXTURE_TEMPLATE_METHODS, Model, ModelTexture
    from clothlab.params import ParamTable

    for name in TEMPLATE_METHODS:
        with pytest.raises(TypeError, match=f"_{name}"):
            type("Bypass", (Model,), {name: lambda self, *a, **k: None})
    for name in TEXTURE_TEMPLATE_METHODS:
        with pytest.raises(TypeError, match=f"_{name}"):
            type("BypassTexture", (ModelTexture,), {name: lambda self, *a, **k: None})

    class Plain(Model):  # hooks only: the base applies the orientation
        kind = "plain-test"
        component_names = ("diffuse",)
        params = ParamTable([])

        def _default_parameters(self):
            return {}

        def _components(self, wi, wo, params=None, *, need=None, normalised=True, warn=True):
            return {"diffuse": np.asarray(wi, dtype=np.float64)[:, 0]}  # the weave-frame x of wi

    model = Plain(TWILL)
    assert ORIENTATION in Plain.params and model.default_parameters() == {}
    got = model.components(WI[:4], WO[:4], {ORIENTATION: 90.0})["diffuse"]
    np.testing.assert_allclose(got, to_weave_frame(WI[:4], 90.0)[:, 0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(got, WI[:4, 1], rtol=0, atol=1e-15)  # a quarter turn: the table's y is the weave's x
