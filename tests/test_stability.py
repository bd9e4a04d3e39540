"""Stability of the IM reflectance model on the numerics.md cases: finite, non-negative, reciprocal."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from clothlab.errors import GeometryWarning
from clothlab.frames import spherical_to_vector
from clothlab.models.irawan.model import PSI_FILAMENT_THRESHOLD, Quadrature, yarn_specular

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


@pytest.mark.parametrize("rule", [Quadrature("trapezoid", 11), Quadrature("support", 8), Quadrature("adaptive", 4)],
                         ids=lambda q: q.rule)
@pytest.mark.parametrize("case", CASES)
def test_extreme_cases_finite_non_negative_reciprocal(case, rule):
    params = {**BASE, **CASES[case]}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        forward = yarn_specular(WI, WO, params, "warp", rule)
        backward = yarn_specular(WO, WI, params, "warp", rule)
    assert np.all(np.isfinite(forward)), case
    assert np.all(forward >= 0.0), case
    back = (WI[:, 2] <= 0) | (WO[:, 2] <= 0)
    assert np.all(forward[back] == 0.0)
    scale = max(np.max(np.abs(forward)), 1e-300)
    np.testing.assert_allclose(forward, backward, rtol=1e-9, atol=1e-12 * scale)


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
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        value = yarn_specular(WI[:60], WO[:60], params, "warp", Quadrature("trapezoid", 11))
        mirrored = yarn_specular(WO[:60], WI[:60], params, "warp", Quadrature("trapezoid", 11))
    assert np.all(np.isfinite(value)) and np.all(value >= 0.0)
    np.testing.assert_allclose(value, mirrored, rtol=1e-9, atol=1e-12 * max(value.max(), 1e-300))
