"""A model evaluated at new directions (cold: the direction set's terms computed in the call) gives the values
of a warm evaluation (those terms kept from an earlier call), for the IM and the Kang model; the compiled
direction-set kernels agree with their literal numpy forms (issue 27)."""

from __future__ import annotations

import math
import zlib

import numpy as np
import pytest

from clothlab.frames import to_yarn_frame
from clothlab.models.irawan.integrals import yarn_integral_fabric
from clothlab.models.irawan.model import IrawanModel, Quadrature
from clothlab.models.kang.model import KangModel
from clothlab.weave.presets import PRESET_NAMES, get_preset


def _pairs(n, rng):
    """n direction pairs over the upper hemisphere, a few below the horizon and one retro pair wo = -wi."""
    def sphere(m):
        v = rng.standard_normal((m, 3))
        return v / np.linalg.norm(v, axis=1, keepdims=True)

    wi, wo = sphere(n), sphere(n)
    wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]), np.abs(wo[:, 2])
    wi[:3, 2] *= -1.0  # back-facing rows give 0
    wo[3] = -wi[3]
    return wi, wo


def _sets(model, rng, k):
    base = model.default_parameters()
    out = []
    for _ in range(k):
        p = dict(base)
        for kind in ("warp", "weft"):
            p[f"{kind}.umax"] = float(rng.uniform(5.0, 45.0))
            p[f"{kind}.kappa"] = float(rng.uniform(-0.3, 1.0))
        p["delta"] = float(rng.uniform(0.0, 0.5))
        out.append(p)
    return out


@pytest.mark.parametrize("rule", [("trapezoid", 11), ("gauss", 8), ("support", 4)])
@pytest.mark.parametrize("fabric", PRESET_NAMES)
def test_irawan_cold_equals_warm(fabric, rule):
    rng = np.random.default_rng(zlib.crc32(repr((fabric, rule)).encode()))  # str hash() is salted per process
    warm = IrawanModel(get_preset(fabric), Quadrature(*rule))
    sets = _sets(warm, rng, 3)
    d1, d2 = _pairs(200, rng), _pairs(150, rng)
    warm.components_many(*d1, sets[:1], normalised=False, warn=False)  # fills the direction terms of d1
    for directions in (d1, d2, d1):  # d1 again after another set: the terms are rebuilt and must agree
        warm_values = warm.components_many(*directions, sets, normalised=False, warn=False)
        cold = IrawanModel(get_preset(fabric), Quadrature(*rule))
        cold_values = cold.components_many(*directions, sets, normalised=False, warn=False)
        for name in ("specular_warp", "specular_weft"):
            np.testing.assert_array_equal(warm_values[name], cold_values[name])
            assert np.count_nonzero(cold_values[name]) > 20  # the comparison can fail
        for j, p in enumerate(sets):  # and the per-direction path (no direction terms) to rounding
            for kind in ("warp", "weft"):
                literal = yarn_integral_fabric(*directions, p, kind, warm.quadrature)
                got = cold_values[f"specular_{kind}"][j] / (p["alpha"] + _von_mises(directions, p["beta"]))
                # to rounding of the whole row: two summation orders, so an entry far below the row's largest
                # (cancellation) carries its absolute round-off; numba's target CPU changes the order too
                np.testing.assert_allclose(got, literal, rtol=1e-11, atol=1e-11 * float(np.max(np.abs(literal))))


def _von_mises(directions, beta):
    from clothlab.models.irawan.phase import von_mises

    wi, wo = directions
    return von_mises(-np.sum(wi * wo, axis=1), beta)


def test_staple_fit_computes_no_filament_moments():
    """The direction set's filament moments are made only when a parameter set takes the filament path."""
    model = IrawanModel(get_preset("cotton-denim"))  # psi = -30 deg: staple yarns
    wi, wo = _pairs(50, np.random.default_rng(1))
    p = model.default_parameters()
    model.components(wi, wo, p, normalised=False, warn=False)
    terms = model._at(wi, wo)["terms"]
    assert terms and all(not t._lazy for t in terms.values())
    model.components(wi, wo, {**p, "warp.psi": 0.0}, normalised=False, warn=False)
    assert "filament" in terms["warp"]._lazy and not terms["weft"]._lazy


def test_arctan_matches_the_library():
    from clothlab.models.irawan.kernels import arctan as compiled

    x = np.concatenate([np.linspace(-5, 5, 2001), np.geomspace(1e-300, 1e300, 601),
                        -np.geomspace(1e-300, 1e300, 601),
                        [0.0, -0.0, 1.0, -1.0, math.tan(math.pi / 8), np.nextafter(math.tan(math.pi / 8), 1),
                         np.nextafter(1.0, 0), np.nextafter(1.0, 2), np.inf, -np.inf]])
    got = np.array([compiled(v) for v in x])
    expected = np.arctan(x)
    assert np.all(np.abs(got - expected) <= 4e-16 * np.abs(expected))
    assert math.copysign(1.0, compiled(-0.0)) in (1.0, -1.0)  # finite, no NaN at the signed zero


def test_irawan_moments_match_the_literal_cosines():
    """cos u, sin u of eq. 4's u from the half vector (of the weft frame, which the kernel applies itself) equal
    the library's cos(atan(h_y / h_z))."""
    from clothlab.models.irawan import kernels
    from clothlab.models.irawan.quadrature import interval_rule

    wi, wo = _pairs(300, np.random.default_rng(2))
    lw, lo = np.ascontiguousarray(to_yarn_frame(wi, "weft")), np.ascontiguousarray(to_yarn_frame(wo, "weft"))
    nodes, weights = interval_rule("trapezoid", 11, -0.5 * np.pi, 0.5 * np.pi)
    ok, (u, inv, s0, s1, cu, su) = kernels.filament_moments(wi, wo, nodes[None], weights[None], False, True)
    with np.errstate(invalid="ignore"):  # the retro pair wo = -wi has no half vector
        h = (lw + lo) / np.linalg.norm(lw + lo, axis=1, keepdims=True)
        np.testing.assert_array_equal(ok, (lw[:, 2] > 0) & (lo[:, 2] > 0) & (np.hypot(h[:, 1], h[:, 2]) > 0))
    np.testing.assert_allclose(u[ok], np.arctan(h[ok, 1] / h[ok, 2]), rtol=1e-15, atol=1e-16)
    np.testing.assert_allclose(cu[ok], np.cos(u[ok]), rtol=2e-15)
    np.testing.assert_allclose(su[ok], np.sin(u[ok]), rtol=2e-15, atol=1e-16)
    assert np.all(u[~ok] == 0.0) and np.all(s0[~ok] == 0.0) and np.count_nonzero(s0) > 100


@pytest.mark.parametrize("rule", [("trapezoid", 11), ("support", 4)])
def test_moments_take_the_yarn_frame_themselves(rule):
    """The filament moments of fabric-frame directions with the weft flag equal those of the directions rotated
    into the weft frame by clothlab.frames.to_yarn_frame (bit for bit), and the warp's are the fabric frame's."""
    from clothlab.models.irawan import kernels
    from clothlab.models.irawan.integrals import filament_rule

    wi, wo = _pairs(400, np.random.default_rng(6))
    nodes = filament_rule(Quadrature(*rule))
    for kind in ("warp", "weft"):
        lw, lo = np.ascontiguousarray(to_yarn_frame(wi, kind)), np.ascontiguousarray(to_yarn_frame(wo, kind))
        ok, moments = kernels.filament_moments(wi, wo, *nodes, kind == "weft")
        ok_yarn, moments_yarn = kernels.filament_moments(lw, lo, *nodes, False)
        np.testing.assert_array_equal(ok, ok_yarn)
        np.testing.assert_array_equal(moments, moments_yarn)
        assert np.count_nonzero(moments[2]) > 200  # s0: the comparison can fail


def test_direction_set_kernels_match_numpy():
    """-wi . wo and the front mask of the compiled direction-set pass equal numpy's (einsum, the previous form);
    the compiled comparison of direction sets is numpy's array_equal (shape, values, NaN never equal)."""
    from clothlab.models.irawan import kernels
    from clothlab.models.irawan.integrals import filament_rule

    wi, wo = _pairs(500, np.random.default_rng(8))
    for kinds in ((False, False), (True, True)):
        cos_x, front, kept, _, _ = kernels.direction_set(wi, wo, *filament_rule(Quadrature()), *kinds)
        np.testing.assert_array_equal(kept[0], wi)
        np.testing.assert_array_equal(kept[1], wo)
        assert not np.shares_memory(kept, wi) and not np.shares_memory(kept, wo)
        np.testing.assert_array_equal(cos_x, -np.einsum("...k,...k->...", wi, wo))
        np.testing.assert_array_equal(front, (wi[:, 2] > 0) & (wo[:, 2] > 0))
        assert not front.all() and front.any()
    assert kernels.same_pairs(wi, wo, wi.copy(), wo.copy())
    changed = wo.copy()
    changed[-1, 2] = np.nextafter(changed[-1, 2], 2.0)
    assert not kernels.same_pairs(wi, wo, wi, changed)
    assert not kernels.same_pairs(wi, wo, wi[:-1].copy(), wo[:-1].copy())
    nan = wi.copy()
    nan[0, 0] = np.nan
    assert not kernels.same_pairs(nan, wo, nan, wo)


@pytest.mark.parametrize("rule", [("trapezoid", 11), ("gauss", 8), ("support", 4)])
def test_direction_set_moments_are_each_yarn_frames(rule):
    """The filament moments the direction-set pass makes for both yarn types from one read of the directions
    (the weft's from the warp's columns swapped, its x negated through sin v) equal, bit for bit, the moments
    of the directions rotated into each yarn frame by clothlab.frames.to_yarn_frame; a yarn type not asked
    for is not made (the model then computes it when first needed)."""
    from clothlab.models.irawan import kernels
    from clothlab.models.irawan.integrals import filament_rule

    wi, wo = _pairs(400, np.random.default_rng(12))
    wi[5, 0] = wo[5, 0] = 0.0  # x' = -0.0 in the weft frame: the sign of the product of a zero
    nodes = filament_rule(Quadrature(*rule))
    for asked in ((True, True), (True, False), (False, True)):
        _, _, _, ok, moments = kernels.direction_set(wi, wo, *nodes, *asked)
        for j, kind in enumerate(("warp", "weft")):
            if not asked[j]:
                continue
            lw, lo = np.ascontiguousarray(to_yarn_frame(wi, kind)), np.ascontiguousarray(to_yarn_frame(wo, kind))
            ok_yarn, moments_yarn = kernels.filament_moments(lw, lo, *nodes, False)
            np.testing.assert_array_equal(ok[j], ok_yarn)
            np.testing.assert_array_equal(moments[j], moments_yarn)
            assert np.count_nonzero(moments[j][2]) > 200  # s0: the comparison can fail


def test_filament_fit_makes_its_moments_with_the_directions():
    """A filament parameter set's new directions come with both yarn types' moments (one compiled call); a
    staple set's with none, and its moments are made when a later set takes the filament path."""
    wi, wo = _pairs(60, np.random.default_rng(13))
    model = IrawanModel(get_preset("silk-shantung"))
    p = model.default_parameters()
    model.components(wi, wo, p, normalised=False, warn=False)
    assert set(model._at(wi, wo)["filament"]) == {"warp", "weft"}
    only_warp = model.components(wi, wo, p, need=("specular_warp",), normalised=False, warn=False)
    model.forget_directions()
    model.components(wi, wo, p, need=("specular_warp",), normalised=False, warn=False)
    assert set(model._at(wi, wo)["filament"]) == {"warp"}
    weft = model.components(wi, wo, p, normalised=False, warn=False)["specular_weft"]  # weft's made lazily
    np.testing.assert_array_equal(weft, IrawanModel(get_preset("silk-shantung")).components(
        wi, wo, p, normalised=False, warn=False)["specular_weft"])
    assert np.count_nonzero(only_warp["specular_warp"]) > 10
    staple = IrawanModel(get_preset("silk-shantung"))
    staple.components(wi, wo, {**p, "warp.psi": 20.0, "weft.psi": 20.0}, normalised=False, warn=False)
    assert staple._at(wi, wo)["filament"] == {}


def test_irawan_directions_changed_in_place_are_seen():
    """A direction array changed in place after an evaluation gives the new directions' values, not the kept."""
    wi, wo = _pairs(80, np.random.default_rng(9))
    p = IrawanModel(get_preset("polyester-lining")).default_parameters()
    model = IrawanModel(get_preset("polyester-lining"))
    before = model.components(wi, wo, p, normalised=False, warn=False)
    wo[:, 0] *= -1.0
    after = model.components(wi, wo, p, normalised=False, warn=False)
    fresh = IrawanModel(get_preset("polyester-lining")).components(wi, wo, p, normalised=False, warn=False)
    for name in ("specular_warp", "specular_weft"):
        np.testing.assert_array_equal(after[name], fresh[name])
        assert not np.array_equal(after[name], before[name])  # the test can fail


@pytest.mark.parametrize("fabric", ["cotton-denim", "silk-charmeuse", "wool-gabardine"])
def test_kang_cold_equals_warm(fabric):
    rng = np.random.default_rng(7)
    warm = KangModel(get_preset(fabric))
    p = warm.default_parameters()
    d1, d2 = _pairs(300, rng), _pairs(120, rng)
    warm.components(*d1, p)
    for directions in (d1, d2, d1):
        warm_values = warm.components(*directions, {**p, "warp.ny": 40.0})
        cold = KangModel(get_preset(fabric))
        cold_values = cold.components(*directions, {**p, "warp.ny": 40.0})
        for name in ("specular_warp", "specular_weft"):
            np.testing.assert_array_equal(warm_values[name], cold_values[name])
            assert np.count_nonzero(cold_values[name]) > 50


def test_kang_direction_terms_match_numpy():
    """The compiled direction terms equal eq. 1's factors formed in numpy per yarn frame (the previous code)."""
    from clothlab.models.kang import kernels

    wi, wo = _pairs(400, np.random.default_rng(3))
    h, m5, inv_denom = kernels.direction_terms(wi, wo)
    for kind, got_h in (("warp", h), ("weft", h[:, [1, 0, 2]])):
        wi_l, wo_l = to_yarn_frame(wi, kind), to_yarn_frame(wo, kind)
        s = wi_l + wo_l
        norm = np.linalg.norm(s, axis=1, keepdims=True)
        h_l = np.divide(s, norm, out=np.zeros_like(s), where=norm > 0)
        cos_kh = np.sum(wi_l * h_l, axis=1)
        denom = 4.0 * cos_kh * np.maximum(wi_l[:, 2], wo_l[:, 2])
        lit = (wi_l[:, 2] > 0) & (wo_l[:, 2] > 0) & (cos_kh > 0) & (denom > 0)
        np.testing.assert_allclose(got_h, np.abs(h_l), rtol=1e-15, atol=1e-16)
        np.testing.assert_allclose(m5, (1.0 - np.clip(cos_kh, 0, 1)) ** 5, rtol=1e-14, atol=1e-300)
        np.testing.assert_allclose(inv_denom, np.divide(1.0, denom, out=np.zeros_like(denom), where=lit),
                                   rtol=1e-14)
        assert np.count_nonzero(inv_denom == 0.0) >= 4  # the back-facing and retro rows


def test_equal_row_groups_is_the_partition_of_equal_rows():
    from clothlab.models.kang import kernels

    rng = np.random.default_rng(4)
    keys = rng.integers(-3, 3, (2000, 3)).astype(np.int64) * 10**11  # many repeats, large values, negatives
    first, inverse = kernels.equal_row_groups(keys)
    unique, expected_inverse = np.unique(keys, axis=0, return_inverse=True)
    assert len(first) == len(unique)
    np.testing.assert_array_equal(keys[first][inverse], keys)  # every row maps to a group holding its value
    assert np.all(np.diff(first) > 0) and first[0] == 0  # groups in order of first appearance
    for g in range(len(first)):  # the group's first row is the earliest row with that value
        assert np.flatnonzero(inverse == g)[0] == first[g]
    assert len(np.unique(expected_inverse.ravel())) == len(first)


def test_yarn_integrals_keep_the_callers_geometry():
    """yarn_integrals converts psi, umax to radians on its own copy: a one-set geometry (whose transpose is a
    view) is not changed in place, so a repeated call gives the same values."""
    from clothlab.models.irawan.integrals import yarn_geometry_key, yarn_integrals, yarn_terms

    wi, wo = _pairs(100, np.random.default_rng(10))
    model = IrawanModel(get_preset("cotton-denim"))
    geometry = np.array([yarn_geometry_key(model.default_parameters(), "warp")])
    kept = geometry.copy()
    terms = yarn_terms(wi, wo, "warp", model.quadrature)
    first = yarn_integrals(terms, geometry, model.quadrature)
    np.testing.assert_array_equal(geometry, kept)
    np.testing.assert_array_equal(yarn_integrals(terms, geometry, model.quadrature), first)
    assert np.count_nonzero(first) > 10


def test_kang_half_vector_groups_match_the_numpy_form():
    """The compiled grouping of the warp's and the weft's half vectors (the weft's formed inside, x and y
    swapped) is numpy's: rint of the scaled blocks concatenated, then the partition of equal rows."""
    from clothlab.models.kang import kernels
    from clothlab.models.kang.model import GROUP_TOLERANCE

    wi, wo = _pairs(400, np.random.default_rng(11))
    wi[200:] = wi[:200]  # repeated pairs: groups with several members
    wo[200:] = wo[:200]
    h, _, _ = kernels.direction_terms(wi, wo)
    for weft in ([False], [True], [False, True]):
        blocks = np.concatenate([h[:, [1, 0, 2]] if w else h for w in weft])
        keys = np.rint(blocks * (1.0 / GROUP_TOLERANCE)).astype(np.int64)
        first, inverse = kernels.equal_row_groups(keys)
        reps, got_inverse = kernels.half_vector_groups(h, np.array(weft), 1.0 / GROUP_TOLERANCE)
        np.testing.assert_array_equal(reps, blocks[first])
        np.testing.assert_array_equal(got_inverse, inverse)
        assert len(reps) < len(blocks)  # the repeats were grouped


@pytest.mark.parametrize("lobe", [(18.689868705498743, 0.7060601781416875, 0.6089381031985782, 0.45360949857258265),
                                  (1.0, 30.0, 0.5, 0.3), (300.0, 2.0, 0.2, 0.6), (5.0, 5.0, 0.0, 0.4)])
def test_kang_tile_average_loop_over_all_along_nodes_is_the_scalar_rule(lobe):
    """The peak rule's compiled kernel, whose loop over a direction's along nodes runs vectorised (issue 27),
    equals the same rule evaluated node by node in plain Python floats (its py_func), bit for bit: at
    wool-gabardine's fitted lobe, the defaults, a sharp lobe and one without yarn curvature."""
    from clothlab.models.kang import kernels
    from clothlab.models.kang.model import PEAK_NODES, _gauss_legendre_table

    wi, wo = _pairs(40, np.random.default_rng(14))
    h, _, _ = kernels.direction_terms(wi, wo)
    x_gl, w_gl = _gauss_legendre_table(PEAK_NODES)
    args = (h, *lobe, x_gl, w_gl, PEAK_NODES)
    compiled = kernels.peak_tile_average(*args)
    with np.errstate(all="ignore"):  # the kernel's numpy error model: IEEE results where a lane is not used
        scalar = kernels.peak_tile_average.py_func(*args)
    np.testing.assert_array_equal(compiled, scalar)
    assert np.count_nonzero(compiled) > 30
