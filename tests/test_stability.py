"""Stability of the IM reflectance model on its numerical traps (kappa -> -1, r_hat = 0, umax and psi at their
limits, sharp lobes, segments that do not fit their rectangle, grazing directions): finite, non-negative,
reciprocal, *and* a signal where the specular condition holds (Irawan & Marschner 2012, eq. 3: at a mirror
pair, h = z, the top of the yarn at u = v = 0 reflects wi into wo), *and* for the paper's trapezoid-11 (and
Gauss-11) the same discrete sum as the literal integrands of tests/im_reference.py."""

from __future__ import annotations

import math
import warnings

import im_reference as ref
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from clothlab.errors import GeometryWarning
from clothlab.frames import spherical_to_vector
from clothlab.models.irawan.model import PSI_FILAMENT_THRESHOLD, Quadrature, yarn_specular
from clothlab.models.irawan.yarn import staple_path

BASE = {"alpha": 0.02, "beta": 4.0, "delta": 0.3, "warp.psi": -30.0, "warp.umax": 30.0, "warp.kappa": 0.0,
        "warp.w": 1.0, "warp.l": 3.0}
KAPPA_PARABOLA_30 = -1.0 / (1.0 + 1.0 / math.tan(math.radians(30.0)))  # r_hat = 0 at umax = 30 deg
PSI_EDGE = math.degrees(PSI_FILAMENT_THRESHOLD)

CASES = {
    "kappa -> -1": {"warp.kappa": -1.0 + 1e-9},
    "kappa -> -1 filament": {"warp.kappa": -1.0 + 1e-9, "warp.psi": 0.0},
    "r_hat = 0-": {"warp.kappa": KAPPA_PARABOLA_30 - 1e-12},
    "r_hat = 0": {"warp.kappa": KAPPA_PARABOLA_30},
    "r_hat = 0+": {"warp.kappa": KAPPA_PARABOLA_30 + 1e-12},
    "kappa large": {"warp.kappa": 500.0},
    "beta 1e4": {"beta": 1e4},
    "beta 1e4 filament": {"beta": 1e4, "warp.psi": 0.0},
    "beta tiny": {"beta": 1e-6},
    "umax -> 0": {"warp.umax": 1e-6},
    "umax -> 0 filament": {"warp.umax": 1e-6, "warp.psi": 0.0},
    "umax -> 90": {"warp.umax": 90.0 - 1e-6},
    "umax -> 90 filament": {"warp.umax": 90.0 - 1e-6, "warp.psi": 0.0},
    "psi -> 0+": {"warp.psi": 1e-9},
    "psi -> 0-": {"warp.psi": -1e-9},
    "psi at threshold+": {"warp.psi": PSI_EDGE * (1 + 1e-9)},
    "psi at threshold-": {"warp.psi": -PSI_EDGE * (1 + 1e-9)},
    "psi -> 90": {"warp.psi": 90.0 - 1e-6},
    "segment violates sec. 5.3": {"warp.w": 4.0, "warp.l": 1.0},
    "segment violates sec. 5.3 filament": {"warp.w": 4.0, "warp.l": 1.0, "warp.psi": 0.0},
    "no smoothing": {"delta": 0.0, "warp.psi": 0.0},
    "full smoothing": {"delta": 1.0 - 1e-9, "warp.psi": 0.0},
}


def _directions():
    rng = np.random.default_rng(99)
    n = 400
    wi = spherical_to_vector(rng.uniform(0, 89.9, n), rng.uniform(0, 360, n))
    wo = spherical_to_vector(rng.uniform(0, 89.9, n), rng.uniform(0, 360, n))
    # special pairs: wi = wo, mirror pairs, grazing to 89.9 deg, normal incidence, back-facing
    special_i = spherical_to_vector([0, 30, 89.9, 89.9, 45, 60, 89.9, 120, 10],
                                    [0, 40, 0, 90, 10, 200, 180, 0, 0])
    special_o = spherical_to_vector([0, 30, 89.9, 89.9, 45, 60, 89.9, 10, 100],
                                    [0, 40, 180, 270, 190, 20, 0, 0, 0])
    return np.vstack([wi, special_i]), np.vstack([wo, special_o])


WI, WO = _directions()


def _mirror_pairs(theta):
    """wi on a (theta, phi) grid and wo its mirror image about the normal, so h = (0, 0, 1): the specular
    condition h . t = 0 of eq. 3 (staple) and eq. 4 (filament) holds at u = v = 0 for every psi."""
    t, p = np.meshgrid(theta, [0.0, 37.0, 90.0, 151.0, 200.0, 290.0, 333.0])
    wi = spherical_to_vector(t.ravel(), p.ravel())
    return wi, wi * np.array([-1.0, -1.0, 1.0])


# Up to 65 deg the lit window (both cosines of eq. 8 > 0) is wide enough for every rule; grazing pairs: below.
MIRROR_WI, MIRROR_WO = _mirror_pairs([5.0, 20.0, 35.0, 50.0, 65.0])
RULES = [Quadrature("trapezoid", 11), Quadrature("support", 8), Quadrature("adaptive", 4)]


def _quiet_specular(wi, wo, params, rule):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        return yarn_specular(wi, wo, params, "warp", rule)


def _reference_sum(wi, wo, params, rule="trapezoid", n=11):
    """f_c times the n-node trapezoid or Gauss-Legendre sum of the reference's literal integrand (eq. 1 or 2)
    per pair; ValueError where the reference does not define the geometry."""
    psi, umax = math.radians(params["warp.psi"]), math.radians(params["warp.umax"])
    staple = staple_path(psi, umax, rule, n, PSI_FILAMENT_THRESHOLD)
    geometry = dict(psi=psi, umax=umax, kappa=params["warp.kappa"], w=params["warp.w"], l=params["warp.l"],
                    delta=params["delta"])
    return np.array([ref.discrete_sum(a, b, staple=staple, rule=rule, n=n, **geometry)
                     * (ref.phase(a, b, params["alpha"], params["beta"]) if a[2] > 0 and b[2] > 0 else 0.0)
                     for a, b in zip(wi, wo, strict=True)])


@pytest.mark.parametrize("rule", RULES, ids=lambda q: q.rule)
@pytest.mark.parametrize("case", CASES)
def test_extreme_cases_finite_non_negative_reciprocal(case, rule):
    params = {**BASE, **CASES[case]}
    forward = _quiet_specular(WI, WO, params, rule)
    backward = _quiet_specular(WO, WI, params, rule)
    mirror = _quiet_specular(MIRROR_WI, MIRROR_WO, params, rule)
    assert np.all(mirror > 0.0), (case, mirror)  # a signal where the specular condition holds
    assert np.all(np.isfinite(mirror)), case
    assert np.all(np.isfinite(forward)), case
    assert np.all(forward >= 0.0), case
    back = (WI[:, 2] <= 0) | (WO[:, 2] <= 0)
    assert np.all(forward[back] == 0.0)
    scale = max(np.max(np.abs(forward)), 1e-300)
    np.testing.assert_allclose(forward, backward, rtol=1e-9, atol=1e-12 * scale)


@pytest.mark.parametrize("case", CASES)
def test_extreme_cases_trapezoid_is_the_reference_sum(case):
    """The paper's trapezoid-11 (sec. 7.3) at the random pairs = the same sum over the reference's literal
    integrands (eqs. 3-9 written out, one pair at a time), within the conditioning of the spine near
    kappa = -1 and r_hat = 0."""
    params = {**BASE, **CASES[case]}
    try:
        expected = _reference_sum(WI[:80], WO[:80], params)
    except ValueError as error:
        assert "does not fit its rectangle" in str(error)
        pytest.skip("the reference does not define segments violating sec. 5.3 (the model uses R = 0)")
    got = _quiet_specular(WI[:80], WO[:80], params, Quadrature("trapezoid", 11))
    scale = max(expected.max(), 1e-300)
    np.testing.assert_allclose(got, expected, rtol=1e-6, atol=1e-12 * scale)
    # Gauss-Legendre (no end nodes, which the mirror pairs put on the visibility cut |v| = pi/2 when
    # psi = -umax) at the random and the mirror pairs, where the signal is guaranteed
    wi, wo = np.vstack([WI[:80], MIRROR_WI]), np.vstack([WO[:80], MIRROR_WO])
    expected = _reference_sum(wi, wo, params, "gauss", 11)
    got = _quiet_specular(wi, wo, params, Quadrature("gauss", 11))
    assert np.count_nonzero(expected) >= len(MIRROR_WI), case
    np.testing.assert_allclose(got, expected, rtol=1e-6, atol=1e-12 * expected.max())


def test_support_rule_sees_the_narrow_lit_window_at_grazing():
    """At grazing mirror pairs the lit window (both cosines of eq. 8 > 0) is a few degrees of u wide (+-0.5 deg at
    89 deg); the support rule splits at the zeros of c_i and c_r (roots of a quartic in tan u), so it agrees with
    the independent quad reference there (which locates those zeros by scanning; 0.0712 at 80 deg, phi 290 deg)."""
    wi, wo = _mirror_pairs([80.0, 89.0])
    expected = np.array([ref.specular_reference(
        a, b, psi=math.radians(BASE["warp.psi"]), umax=math.radians(BASE["warp.umax"]), kappa=BASE["warp.kappa"],
        w=BASE["warp.w"], l=BASE["warp.l"], alpha=BASE["alpha"], beta=BASE["beta"], delta=BASE["delta"],
        psi_threshold=PSI_FILAMENT_THRESHOLD)[0] for a, b in zip(wi, wo, strict=True)])
    assert np.all(expected > 0.0)
    assert expected[10] == pytest.approx(0.0712, abs=5e-5)  # 80 deg, phi 290 deg: the value in issue 12
    for n in (8, 16):
        got = _quiet_specular(wi, wo, BASE, Quadrature("support", n))
        np.testing.assert_allclose(got, expected, rtol=1e-4 if n == 8 else 1e-7)


def test_support_breakpoints_contain_the_zeros_of_both_cosines():
    """The compiled breakpoints (:func:`clothlab.models.irawan.yarn.staple_breaks`) include every zero of c_i
    and c_r on the specular curve that the literal reference finds by scanning (tests/im_reference.py)."""
    from clothlab.models.irawan.yarn import staple_breaks

    psi, umax = math.radians(BASE["warp.psi"]), math.radians(BASE["warp.umax"])
    front = (WI[:, 2] > 0) & (WO[:, 2] > 0)
    wi, wo = WI[front][:150], WO[front][:150]
    table, _ = staple_breaks(wi, wo, psi, umax)
    found = 0
    for n in range(len(wi)):
        for point in ref._staple_breakpoints(tuple(wi[n]), tuple(wo[n]), psi, umax):
            assert np.min(np.abs(table[n] - point)) < 1e-7, (n, point, table[n])
            found += 1
    assert found > 100


def test_continuity_across_r_hat_zero_and_kappa():
    """R(u) is continuous in kappa, so the specular is too: no jump across the parabola."""
    q = Quadrature("support", 16)
    values = [yarn_specular(WI, WO, {**BASE, "warp.kappa": KAPPA_PARABOLA_30 + d}, "warp", q)
              for d in (-1e-7, 0.0, 1e-7)]
    scale = values[1].max()
    assert np.max(np.abs(values[0] - values[1])) < 1e-5 * scale
    assert np.max(np.abs(values[2] - values[1])) < 1e-5 * scale


@settings(max_examples=60, deadline=None)
@given(psi=st.floats(-89.0, 89.0), umax=st.floats(0.01, 89.9), kappa=st.floats(-0.999, 20.0),
       beta=st.floats(1e-3, 1e4), w=st.floats(0.05, 10.0), l=st.floats(0.05, 10.0), delta=st.floats(0.0, 0.999))
def test_random_parameters_finite_non_negative(psi, umax, kappa, beta, w, l, delta):
    params = {"alpha": 0.01, "beta": beta, "delta": delta, "warp.psi": psi, "warp.umax": umax, "warp.kappa": kappa,
              "warp.w": w, "warp.l": l}
    rule = Quadrature("trapezoid", 11)
    value = _quiet_specular(WI[:60], WO[:60], params, rule)
    mirrored = _quiet_specular(WO[:60], WI[:60], params, rule)
    assert np.all(np.isfinite(value)) and np.all(value >= 0.0)
    np.testing.assert_allclose(value, mirrored, rtol=1e-9, atol=1e-12 * max(value.max(), 1e-300))
    # a signal where the specular condition holds: the node u = 0 (staple) or v = 0 (filament) is lit
    assert np.all(_quiet_specular(MIRROR_WI[:10], MIRROR_WO[:10], params, rule) > 0.0)
    if w * math.sin(math.radians(umax)) < l:  # the reference defines only segments that fit (sec. 5.3)
        expected = _reference_sum(WI[:30], WO[:30], params)
        np.testing.assert_allclose(value[:30], expected, rtol=1e-6, atol=1e-12 * max(expected.max(), 1e-300))


@pytest.mark.parametrize("preset", ["silk-shantung", "polyester-lining"])
def test_denormal_smoothing_is_the_unsmoothed_limit(preset):
    """delta so small that delta * umax underflows (a denormal, found by hypothesis): eq. 9's fade takes its
    delta -> 0 limit (no fade) instead of dividing by zero; reflectance and texture equal the delta = 0 values."""
    from clothlab.models.irawan.model import IrawanModel
    from clothlab.weave.presets import get_preset

    model = IrawanModel(get_preset(preset))
    rng = np.random.default_rng(3)
    wi, wo = (np.abs(rng.normal(size=(40, 3))) for _ in range(2))
    wi, wo = wi / np.linalg.norm(wi, axis=1)[:, None], wo / np.linalg.norm(wo, axis=1)[:, None]
    limit = model.components(wi, wo, {"delta": 0.0})
    texture = model.texture()
    u, v = rng.random(40), rng.random(40)
    for tiny in (5e-324, 1e-310):
        got = model.components(wi, wo, {"delta": tiny})
        for name in limit:
            np.testing.assert_allclose(got[name], limit[name], rtol=1e-12, atol=0.0)
        t0 = texture.components(u, v, wi, wo, {"delta": 0.0}, noise=False)
        t1 = texture.components(u, v, wi, wo, {"delta": tiny}, noise=False)
        for name in t0:
            np.testing.assert_allclose(t1[name], t0[name], rtol=1e-12, atol=0.0)
