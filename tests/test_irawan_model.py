"""The Irawan-Marschner reflectance model against the independent scalar reference (tests/im_reference.py),
scipy quad, and the paper's identities."""

from __future__ import annotations

import math
import warnings

import im_reference as ref
import numpy as np
import pytest

from clothlab.errors import GeometryWarning, ParameterError
from clothlab.frames import spherical_to_vector, to_yarn_frame
from clothlab.models.irawan.model import (
    PSI_FILAMENT_THRESHOLD,
    IrawanModel,
    Quadrature,
    geometry_warnings,
    specular_albedo,
    yarn_specular,
)
from clothlab.models.irawan.phase import von_mises
from clothlab.models.irawan.spine import axis_ratio, spine_radius
from clothlab.weave.presets import PRESET_NAMES, get_preset

RNG = np.random.default_rng(12345)


def random_pairs(n, max_theta=80.0, rng=RNG):
    wi = spherical_to_vector(rng.uniform(0, max_theta, n), rng.uniform(0, 360, n))
    wo = spherical_to_vector(rng.uniform(0, max_theta, n), rng.uniform(0, 360, n))
    return wi, wo


def preset_params(name):
    model = IrawanModel(get_preset(name))
    return model, model.default_parameters()


# ---------------------------------------------------------------- spine radius (sec. 5.4)

@pytest.mark.parametrize("kappa", [-0.9, -0.7, -0.3, 0.0, 0.5, 2.0])
@pytest.mark.parametrize("umax_deg", [5.0, 22.0, 40.0, 70.0])
def test_spine_radius_matches_branchwise_reference(kappa, umax_deg):
    umax = math.radians(umax_deg)
    r_hat = axis_ratio(kappa, umax)
    if r_hat < 0 and abs(r_hat * math.tan(umax)) >= 1:
        pytest.skip("outside the hyperbola's domain")
    for u in np.linspace(-umax, umax, 9):
        expected = ref.spine_radius(u, umax, kappa, 1.0, 3.0)
        assert spine_radius(u, umax, kappa, 1.0, 3.0) == pytest.approx(expected, rel=1e-9)


def test_spine_radius_continuous_across_parabola():
    umax = math.radians(30)
    kappa0 = -1.0 / (1.0 + 1.0 / math.tan(umax))  # r_hat = 0
    u = np.linspace(-umax, umax, 7)
    below = spine_radius(u, umax, kappa0 - 1e-9, 1.0, 3.0)
    at = spine_radius(u, umax, kappa0, 1.0, 3.0)
    above = spine_radius(u, umax, kappa0 + 1e-9, 1.0, 3.0)
    np.testing.assert_allclose(below, at, rtol=1e-7)
    np.testing.assert_allclose(above, at, rtol=1e-7)
    parabola = (1.5 - 0.5 * math.sin(umax)) / math.tan(umax) / np.cos(u) ** 3
    np.testing.assert_allclose(at, parabola, rtol=1e-12)


# ---------------------------------------------------------------- phase function (eq. 7)

def test_von_mises_normalised_and_overflow_free():
    from scipy.integrate import quad

    for beta in [0.5, 4.0, 50.0, 800.0]:
        total, _ = quad(lambda x, b=beta: von_mises(math.cos(x), b), -math.pi, math.pi, points=[0.0], limit=200)
        assert total == pytest.approx(1.0, rel=1e-8)
    values = von_mises(np.linspace(-1, 1, 11), 1e4)
    assert np.all(np.isfinite(values)) and np.all(values >= 0)


# ---------------------------------------------------------------- the yarn integral vs the reference

def _reference_values(wi, wo, p, kind):
    lw, lo = to_yarn_frame(wi, kind), to_yarn_frame(wo, kind)
    out = []
    for a, b in zip(lw, lo, strict=True):
        value, _ = ref.specular_reference(
            a, b, psi=math.radians(p[f"{kind}.psi"]), umax=math.radians(p[f"{kind}.umax"]),
            kappa=p[f"{kind}.kappa"], w=p[f"{kind}.w"], l=p[f"{kind}.l"], alpha=p["alpha"], beta=p["beta"],
            delta=p["delta"], psi_threshold=PSI_FILAMENT_THRESHOLD)
        out.append(value)
    return np.array(out)


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_quadrature_rules_against_scipy_quad(name, record_property):
    """Every preset, both yarn types: the adaptive rule matches quad; the paper's trapezoid-11 and the other
    rules are reported as median / 80th percentile relative errors over random directions."""
    model, p = preset_params(name)
    wi, wo = random_pairs(60, rng=np.random.default_rng(7))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        for kind in ("warp", "weft"):
            if any(m.startswith(kind) for m in geometry_warnings(p)):
                continue  # the reference does not define segments violating sec. 5.3 (cotton-twill weft)
            expected = _reference_values(wi, wo, p, kind)
            scale = expected.max()
            significant = expected > 1e-3 * scale
            assert significant.sum() >= 5
            errors = {}
            for rule, nodes in [("adaptive", 8), ("support", 16), ("trapezoid", 11), ("gauss", 11)]:
                got = yarn_specular(wi, wo, p, kind, Quadrature(rule, nodes))
                rel = np.abs(got - expected)[significant] / expected[significant]
                errors[f"{rule}-{nodes}"] = (float(np.median(rel)), float(np.percentile(rel, 80)))
                assert np.all(np.abs(got - expected) <= 0.6 * scale + 1e-300)
            record_property(f"{name}-{kind}", errors)
            assert errors["adaptive-8"][1] < 2e-4, errors
            assert errors["support-16"][0] < 2e-3, errors
            # The paper's claim (sec. 7.3) that trapezoid-11 is "sufficient": within a few percent at the median.
            assert errors["trapezoid-11"][0] < 0.08, errors


def test_reciprocity_and_non_negativity_all_presets():
    wi, wo = random_pairs(400)
    for name in PRESET_NAMES:
        model = IrawanModel(get_preset(name), Quadrature("support", 8))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", GeometryWarning)
            forward = model.components(wi, wo, normalised=False)
            backward = model.components(wo, wi, normalised=False)
        for key in forward:
            f, b = forward[key], backward[key]
            assert np.all(np.isfinite(f)) and np.all(f >= 0)
            np.testing.assert_allclose(f, b, rtol=1e-9, atol=1e-12 * max(f.max(), 1e-300))


def test_staple_to_filament_switch_is_continuous():
    """As psi -> 0 the staple integral (eqs. 1, 5) tends to the filament one (eqs. 2, 6)."""
    wi, wo = random_pairs(300, max_theta=70)
    base = {"alpha": 0.02, "beta": 4.0, "delta": 0.0, "warp.umax": 30.0, "warp.kappa": 0.0, "warp.w": 1.0,
            "warp.l": 3.0}
    q = Quadrature("adaptive", 8)
    filament = yarn_specular(wi, wo, {**base, "warp.psi": 0.0}, "warp", q)
    scale = filament.max()
    for sign in (-1, 1):
        psi_deg = sign * math.degrees(PSI_FILAMENT_THRESHOLD) * 1.0001
        staple = yarn_specular(wi, wo, {**base, "warp.psi": psi_deg}, "warp", q)
        assert np.max(np.abs(staple - filament)) < 5e-3 * scale


# ---------------------------------------------------------------- normalisation, warnings, ranges

def test_specular_albedo_is_one_after_normalisation():
    """The normalised specular component has unit mean albedo, checked with an independent product rule."""
    model, p = preset_params("wool-gabardine")
    # Independent estimate: Gauss-Legendre in mu^2 and the trapezoid rule in phi for both directions.
    n_mu, n_phi = 12, 24
    x, wx = np.polynomial.legendre.leggauss(n_mu)
    s, ws = 0.5 * (x + 1), 0.5 * wx
    phi = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    mu = np.sqrt(1 - s)
    dirs = np.array([[math.sqrt(1 - m * m) * math.cos(f), math.sqrt(1 - m * m) * math.sin(f), m]
                     for m in mu for f in phi])
    weights = np.repeat(ws, n_phi) / n_phi  # sums to 1 for the cosine-weighted average
    i, o = np.meshgrid(np.arange(len(dirs)), np.arange(len(dirs)), indexing="ij")
    comps = model.components(dirs[i.ravel()], dirs[o.ravel()], p)
    w2 = (weights[:, None] * weights[None, :]).ravel()
    for kind in ("warp", "weft"):
        albedo = math.pi * np.sum(w2 * comps[f"specular_{kind}"])
        assert albedo == pytest.approx(1.0, rel=0.03)
    assert math.pi * np.sum(w2 * comps["diffuse"]) == pytest.approx(1.0, rel=1e-12)


def test_albedo_is_deterministic():
    """The fixed Sobol point set makes a_j reproducible bit for bit: recomputed after emptying every cache
    (albedo and direction sets) it is the same number, while another point count gives another estimate."""
    import clothlab.models.irawan.model as im

    model, p = preset_params("polyester-lining")
    a = specular_albedo(p, "warp", model.quadrature)
    im._specular_albedo_cached.cache_clear()
    im._albedo_directions.cache_clear()
    assert specular_albedo(dict(p), "warp", model.quadrature) == a
    other = specular_albedo(p, "warp", model.quadrature, samples=2**12)
    assert other != a and other == pytest.approx(a, rel=0.05)


def test_twill_weft_constraint_warns_and_stays_non_negative():
    model, p = preset_params("cotton-twill")
    messages = geometry_warnings(p, "cotton-twill")
    assert len(messages) == 1 and "weft" in messages[0] and "sec. 5.3" in messages[0]
    wi, wo = random_pairs(200)
    with pytest.warns(GeometryWarning, match="weft"):
        comps = model.components(wi, wo, p, normalised=False)
    weft = comps["specular_weft"]
    assert np.all(np.isfinite(weft)) and np.all(weft >= 0) and weft.max() > 0


def test_out_of_range_parameters_are_named():
    model = IrawanModel(get_preset("polyester-lining"))
    with pytest.raises(ParameterError, match="warp.kappa"):
        model.components(*random_pairs(3), {"warp.kappa": -1.0})
    with pytest.raises(ParameterError, match="weft.umax"):
        model.components(*random_pairs(3), {"weft.umax": 95.0})
    with pytest.raises(ParameterError, match="unknown parameter"):
        model.components(*random_pairs(3), {"warp.radius": 1.0})
    with pytest.raises(ParameterError, match="quadrature"):
        Quadrature("simpson", 11)


def test_zero_albedo_yarn_warns_instead_of_a_silent_zero():
    """A filament with umax -> 0 reflects along a line only: its albedo is 0 and its normalised specular
    cannot be formed; the model returns 0 for it and says so, naming the yarn."""
    model = IrawanModel(get_preset("polyester-lining"))
    wi = spherical_to_vector(np.array([30.0]), np.array([0.0]))
    wo = spherical_to_vector(np.array([30.0]), np.array([180.0]))
    with pytest.warns(GeometryWarning, match="polyester-lining warp: the specular albedo is 0"):
        comps = model.components(wi, wo, {"warp.umax": 1e-9})
    assert np.all(comps["specular_warp"] == 0.0) and np.all(comps["specular_weft"] > 0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model.components(wi, wo, {"warp.umax": 1e-9}, warn=False)


# ---------------------------------------------------------------- the yarn-integral memo

def test_directions_changed_in_place_give_fresh_values():
    """The memo of I_j is keyed on the directions' contents: overwriting wi in place (as in a notebook)
    and evaluating again equals a fresh model at the new directions, not the remembered integral."""
    model, p = preset_params("cotton-denim")
    wi = spherical_to_vector(np.array([30.0, 40.0]), np.array([0.0, 20.0]))
    wo = spherical_to_vector(np.array([30.0, 35.0]), np.array([180.0, 200.0]))
    before = model.components(wi, wo, p, warn=False)["specular_warp"].copy()
    wi[:] = spherical_to_vector(np.array([50.0, 10.0]), np.array([90.0, 300.0]))
    after = model.components(wi, wo, p, warn=False)["specular_warp"]
    fresh = IrawanModel(get_preset("cotton-denim")).components(wi.copy(), wo.copy(), p, warn=False)
    np.testing.assert_array_equal(after, fresh["specular_warp"])
    assert not np.allclose(before, after)  # the directions changed the value (the test can fail)


def test_memo_reuses_the_integral_when_only_the_phase_changes(monkeypatch):
    """A fit that varies only alpha / beta (f_c factors out of eq. 10) computes I_j once per segment type,
    even for equal directions in new arrays; a warp geometry change recomputes the warp integral only."""
    import clothlab.models.irawan.model as im

    calls = []
    original = im.yarn_integrals

    def counting(*args, **kwargs):
        calls.append(args[0].kind)
        return original(*args, **kwargs)

    monkeypatch.setattr(im, "yarn_integrals", counting)
    model, p = preset_params("cotton-denim")
    wi, wo = random_pairs(50, rng=np.random.default_rng(7))
    first = model.components(wi, wo, p, normalised=False, warn=False)
    for alpha, beta in ((0.1, 2.0), (0.3, 8.0)):
        out = model.components(wi.copy(), wo.copy(), {**p, "alpha": alpha, "beta": beta}, normalised=False,
                               warn=False)
        lit = first["specular_warp"] > 0.0
        assert lit.any() and not np.allclose(out["specular_warp"][lit], first["specular_warp"][lit])
    assert sorted(calls) == ["warp", "weft"]
    model.components(wi, wo, {**p, "warp.umax": p["warp.umax"] + 5.0}, normalised=False, warn=False)
    assert sorted(calls) == ["warp", "warp", "weft"]


def test_umax_at_its_limit_is_finite_and_below_it_refused():
    """umax -> 0 (staple): the components reach their limit (1e-6 and 1e-9 deg agree to float precision, no
    warning); below the declared lowest value (1e-9 deg; 1e-200 made the yarn integrals 0 / 0) the value is
    refused naming the parameter, never evaluated to inf / NaN."""
    from clothlab.weave.parameters import UMAX_LOWEST_DEG

    model = IrawanModel(get_preset("cotton-denim"))
    wi = spherical_to_vector(np.array([30.0]), np.array([0.0]))
    wo = spherical_to_vector(np.array([30.0]), np.array([180.0]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        near = model.components(wi, wo, {"warp.umax": 1e-6})["specular_warp"]
        lowest = model.components(wi, wo, {"warp.umax": UMAX_LOWEST_DEG})["specular_warp"]
    assert np.all(np.isfinite(lowest)) and np.all(lowest > 0.0)
    np.testing.assert_allclose(lowest, near, rtol=1e-9)
    for bad in (1e-200, 0.5 * UMAX_LOWEST_DEG, 0.0):
        with pytest.raises(ParameterError, match="warp.umax"):
            model.components(wi, wo, {"warp.umax": bad})
