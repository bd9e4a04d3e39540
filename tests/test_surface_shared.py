"""The surface model's compiled paths (issue 23 item 3): the texture kernel and the tile average against a
literal numpy evaluation of eqs. 1-2 and decision 2 (Chen, Wang & Wang 2024, sec. 3.1), the vectorisable
1 - exp(-x) against math.expm1, and the projected areas shared by the points of a footprint (runs of equal
directions, the last set kept) against the same points evaluated one by one."""

from __future__ import annotations

import math

import numpy as np
import pytest

from clothlab.frames import to_yarn_frame
from clothlab.models.surface import kernels
from clothlab.models.surface.geometry import cylinder_angles, projected_area
from clothlab.models.surface.model import SurfaceModel
from clothlab.models.surface.parameters import draw_table2
from clothlab.surrogate.labels import TextureProbe
from clothlab.weave.lookup import locate_segments
from clothlab.weave.patterns import get_pattern


def hemisphere(rng, n, min_z=0.0):
    z = rng.uniform(min_z, 1.0, n)
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def literal_frame(u, v, psi, beta):
    """n_p, t_p (N, 3) by the geometry module docstring's formulas, in numpy (cross product, Gram-Schmidt)."""
    n = np.stack([np.sin(v), np.sin(u) * np.cos(v), np.cos(u) * np.cos(v)], axis=-1)
    spine = np.stack([0 * u, np.cos(u), -np.sin(u)], axis=-1)
    t = np.cos(psi) * spine + np.sin(psi) * np.cross(n, spine)
    n_p = n * [beta, beta, 1.0]
    n_p /= np.linalg.norm(n_p, axis=-1, keepdims=True)
    t_p = t * [1.0, 1.0, beta]
    t_p -= np.sum(t_p * n_p, axis=-1, keepdims=True) * n_p
    return n_p, t_p / np.linalg.norm(t_p, axis=-1, keepdims=True)


def literal_point(n, t, wi, wo, area_i, area_o, alpha, blend):
    """(specular, diffuse) (N,) of eqs. 1-2 with S = I - (1 - alpha^2) t t^T, times decision 2's factor
    <wi.n> <wo.n> / (<n_s.n> A~_i A~_o), written out from the model docstring (yarn-frame vectors)."""
    ci, co = np.sum(wi * n, axis=1), np.sum(wo * n, axis=1)
    h = wi + wo
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    eye = np.eye(3)
    spec = np.zeros(len(n))
    lit = (ci > 0) & (co > 0)
    for k in np.flatnonzero(lit):
        s = eye - (1.0 - alpha * alpha) * np.outer(t[k], t[k])
        sigma_i, sigma_o = np.sqrt(wi[k] @ s @ wi[k]), np.sqrt(wo[k] @ s @ wo[k])
        q = h[k] @ np.linalg.inv(s) @ h[k]
        d = 1.0 / (np.pi * alpha * q * q)
        lam = sigma_i / ci[k] + sigma_o / co[k]
        g = -np.expm1(-2.0 * lam) / lam
        spec[k] = d * g / (4.0 * ci[k] * co[k])
    weight = ci * co / (n[:, 2] * area_i * area_o)
    return np.where(lit, spec * weight, 0.0), (1.0 - blend) / np.pi + np.where(lit, blend * weight / np.pi, 0.0)


@pytest.fixture(scope="module")
def material():
    model = SurfaceModel(get_pattern("twill-3x3"))
    params = draw_table2(np.random.default_rng(31), 1, {"blend": 0.3})[0]
    return model, params


def test_one_minus_exp_neg_is_expm1_to_a_few_ulp():
    xs = np.concatenate([np.geomspace(1e-300, 1.0, 3001), np.linspace(0.0, 80.0, 4001), [0.3465, 0.3466, 745.0]])
    for x in xs:
        ref = -math.expm1(-x)
        assert abs(kernels.one_minus_exp_neg(x) - ref) <= 4.0 * np.spacing(ref), x
    assert kernels.one_minus_exp_neg(math.inf) == 1.0 and kernels.one_minus_exp_neg(0.0) == 0.0


def test_texture_points_are_the_literal_point_formula(material):
    model, params = material
    p = model.resolve(params)
    rng = np.random.default_rng(32)
    n = 400
    u, v = rng.uniform(-1.5, 2.5, n), rng.uniform(-1.5, 2.5, n)
    wi, wo = hemisphere(rng, n, 0.02), hemisphere(rng, n, 0.02)
    got = model.texture().components(u, v, wi, wo, params)
    area_i, area_o = projected_area(wi, model.shares, p), projected_area(wo, model.shares, p)
    seg, x, y = locate_segments(model.weave, u, v)
    weft = np.array([s.kind == "weft" for s in model.weave.segments])[seg]
    covered = np.zeros(n, dtype=bool)
    for kind, rows in (("warp", ~weft), ("weft", weft)):
        g = model.weave.geometry(kind)
        rows = np.flatnonzero(rows & (np.abs(x) < 0.5 * (1.0 - p["gap"]) * g.w))
        cu, cv = cylinder_angles(x[rows], y[rows], g.w, g.l, np.deg2rad(p[f"{kind}.umax"]))
        nn, tt = literal_frame(cu, cv, np.deg2rad(p[f"{kind}.psi"]), p[f"{kind}.beta"])
        spec, diff = literal_point(nn, tt, to_yarn_frame(wi[rows], kind), to_yarn_frame(wo[rows], kind),
                                   area_i[rows], area_o[rows], p[f"{kind}.alpha"], p["blend"])
        np.testing.assert_allclose(got[f"specular_{kind}"][rows], spec, rtol=1e-11, atol=0.0)
        np.testing.assert_allclose(got[f"diffuse_{kind}"][rows], diff, rtol=1e-12, atol=0.0)
        other = "weft" if kind == "warp" else "warp"
        assert np.all(got[f"specular_{other}"][rows] == 0.0) and np.all(got[f"diffuse_{other}"][rows] == 0.0)
        covered[rows] = True
    assert 0.5 * n < covered.sum() < n  # points on both yarn types and in the gap, which gives 0
    assert all(np.all(c[~covered] == 0.0) for c in got.values())


def test_tile_average_is_the_literal_mean_over_its_nodes(material):
    """R (compiled, vectorised over the ply nodes) = the literal point formula averaged over the same nodes."""
    model, params = material
    small = SurfaceModel(model.weave, tile_nodes=[8, 4])
    p = small.resolve(params)
    rng = np.random.default_rng(33)
    wi, wo = hemisphere(rng, 12, 0.02), hemisphere(rng, 12, 0.02)
    got = small.components(wi, wo, params)
    area_i, area_o = projected_area(wi, small.shares, p), projected_area(wo, small.shares, p)
    half = 0.5 * np.pi * (1.0 - p["gap"])
    for kind in ("warp", "weft"):
        vv = half * (2.0 * (np.arange(8) + 0.5) / 8 - 1.0)
        uu = np.deg2rad(p[f"{kind}.umax"]) * (2.0 * (np.arange(4) + 0.5) / 4 - 1.0)
        cu, cv = (a.ravel() for a in np.meshgrid(uu, vv, indexing="ij"))
        nn, tt = literal_frame(cu, cv, np.deg2rad(p[f"{kind}.psi"]), p[f"{kind}.beta"])
        scale = small.shares[kind] * (1.0 - p["gap"])
        for k in range(len(wi)):
            rep = np.repeat
            spec, diff = literal_point(nn, tt, rep(to_yarn_frame(wi[k:k + 1], kind), 32, 0),
                                       rep(to_yarn_frame(wo[k:k + 1], kind), 32, 0), rep(area_i[k], 32),
                                       rep(area_o[k], 32), p[f"{kind}.alpha"], p["blend"])
            assert got[f"specular_{kind}"][k] == pytest.approx(scale * spec.mean(), rel=1e-11)
            assert got[f"diffuse_{kind}"][k] == pytest.approx(scale * diff.mean(), rel=1e-12)


def test_probe_with_shared_directions_equals_points_one_by_one(material):
    """A 3 x 3 probe passes each query's directions repeated for its 9 points (one run, areas once per query,
    then kept for the next call); the same points evaluated one call each (areas per point) agree."""
    model, params = material
    texture = model.texture()
    rng = np.random.default_rng(34)
    n = 40
    wi, wo = hemisphere(rng, n, 0.01), hemisphere(rng, n, 0.01)
    centre, size = rng.uniform(-1, 2, (n, 2)), rng.uniform(0.03, 5.0, n)
    model.forget_directions()
    model.components(wi, wo, params)  # R first, as a residual query does: its areas are kept
    shared = TextureProbe(texture, params, 3)(wi, wo, centre, size)
    points = centre[:, None, :] + size[:, None, None] * TextureProbe(texture, params, 3).offsets()[None]
    for i in range(n):
        for j in range(9):
            model.forget_directions()
            one = texture.components(points[i, j, :1], points[i, j, 1:], wi[i], wo[i], params)
            values = [one[name][0] for name in texture.component_names]
            np.testing.assert_allclose(shared[i, 4 * j:4 * j + 4], values, rtol=1e-12, atol=0.0)


def test_kept_areas_follow_the_directions_and_the_parameters(material):
    model, params = material
    p = model.resolve(params)
    rng = np.random.default_rng(35)
    wi, wo = hemisphere(rng, 30, 0.05), hemisphere(rng, 30, 0.05)
    model.forget_directions()
    first = model.projected_areas(wi, wo, p)
    np.testing.assert_array_equal(first[0], projected_area(wi, model.shares, p))
    wi[3] = hemisphere(rng, 1, 0.05)[0]  # the caller's array changed in place: no stale area
    again = model.projected_areas(wi, wo, p)
    np.testing.assert_array_equal(again[0], projected_area(wi, model.shares, p))
    np.testing.assert_array_equal(again[1], first[1])
    other = {**p, "warp.beta": p["warp.beta"] + 0.3}
    np.testing.assert_array_equal(model.projected_areas(wi, wo, other)[1], projected_area(wo, model.shares, other))
    repeated = model.projected_areas(np.repeat(wi, 4, 0), np.repeat(wo, 4, 0), p)
    np.testing.assert_array_equal(repeated[0], np.repeat(projected_area(wi, model.shares, p), 4))
    model.forget_directions()
    assert model._area_memo == {}
