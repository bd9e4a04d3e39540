"""The fabric surface model (Chen, Wang & Wang 2024, sec. 3.1, eqs. 1-2): eq. 2 against literal matrix
formulas and scipy quadrature, the ply geometry, the tile average = texture average identity, reciprocity,
non-negativity and the white furnace over 10,000 Table 2 samples, grazing and alpha-bound stability, the
generated weave patterns and the model's reach (config, fit)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate

from clothlab.errors import ConfigError
from clothlab.frames import to_yarn_frame
from clothlab.models.registry import build_model
from clothlab.models.surface import kernels
from clothlab.models.surface.geometry import cylinder_angles, ply_frame, projected_area, yarn_area
from clothlab.models.surface.model import SurfaceModel, ply_nodes
from clothlab.weave.lookup import locate_segments
from clothlab.weave.patterns import PATTERN_NAMES, get_pattern
from clothlab.weave.presets import resolve_weave


def unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def hemisphere(rng, n, min_z=0.0):
    z = rng.uniform(min_z, 1.0, n)
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def literal_s(t, alpha):
    """S = R^T diag(1, 1, alpha^2) R with R's rows an orthonormal basis whose third row is t (eq. 2)."""
    a = unit(np.cross(t, [0.3, -0.5, 0.8]))
    b = np.cross(t, a)
    rot = np.stack([a, b, t])
    return rot.T @ np.diag([1.0, 1.0, alpha * alpha]) @ rot


# ------------------------------------------------------------------------------------------ eq. 2


def test_sigma_and_d_equal_the_literal_matrix_forms():
    rng = np.random.default_rng(1)
    for _ in range(200):
        t, w, h = unit(rng.normal(size=3)), unit(rng.normal(size=3)), unit(rng.normal(size=3))
        alpha = rng.uniform(0.05, 1.0)
        s = literal_s(t, alpha)
        sigma = np.sqrt(w @ s @ w)
        d = 1.0 / (np.pi * alpha * (h @ np.linalg.inv(s) @ h) ** 2)
        assert kernels.projected_sigma(w @ t, alpha) == pytest.approx(sigma, rel=1e-12)
        assert kernels.microflake_d(h @ t, alpha) == pytest.approx(d, rel=1e-10)


def frame_about(w):
    """Rows: an orthonormal basis whose third row is w."""
    a = unit(np.cross(w, [0.3, -0.5, 0.8]))
    return np.stack([a, np.cross(w, a), w])


@pytest.mark.parametrize("alpha", [0.1, 0.35, 1.0])
def test_d_is_normalised_by_its_projected_area(alpha):
    """int <w . m> D(m) dm over the sphere = sigma(w) (SGGX normalisation), and the specular phase function
    D(h) / (4 sigma(wi)) integrates to 1 over all wo (scipy quadrature in spherical coordinates about w,
    where the integrands are smooth; t a fixed fibre direction)."""
    t = unit([0.2, -0.4, 0.9])
    opts = {"limit": 200, "epsrel": 1e-7}
    for w in (unit([0.3, 0.1, 0.9]), unit([1.0, 0.2, 0.1])):
        basis = frame_about(w)

        def direction(theta, phi, basis=basis):
            return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]) @ basis

        def projected(theta, phi, direction=direction):  # the hemisphere about w: <w . m> = cos theta
            return np.cos(theta) * kernels.microflake_d(direction(theta, phi) @ t, alpha) * np.sin(theta)

        value, _ = integrate.nquad(projected, [[0.0, np.pi / 2], [0.0, 2.0 * np.pi]], opts=[opts, opts])
        assert value == pytest.approx(kernels.projected_sigma(w @ t, alpha), rel=1e-5)

        def phase(theta, phi, wi=w, direction=direction):
            h = unit(wi + direction(theta, phi))
            return kernels.microflake_d(h @ t, alpha) / (4.0 * kernels.projected_sigma(wi @ t, alpha)) * np.sin(theta)

        value, _ = integrate.nquad(phase, [[0.0, np.pi], [0.0, 2.0 * np.pi]], opts=[opts, opts])
        assert value == pytest.approx(1.0, rel=1e-4)


def test_attenuation_matches_eq2_and_has_finite_grazing_limit():
    rng = np.random.default_rng(2)
    for _ in range(100):
        ci, co, si, so = rng.uniform(0.05, 1.0, 4)
        lam = si / ci + so / co
        g = (1.0 - np.exp(-2.0 * lam)) / lam  # eq. 2, T rho = 2
        assert kernels.attenuation_over_cosines(ci, co, si, so) == pytest.approx(g / (ci * co), rel=1e-12)
    # cos_i -> 0: G / (ci co) -> 1 / (sigma_i co); an underflowing product gives that limit exactly
    assert kernels.attenuation_over_cosines(1e-12, 0.5, 0.7, 0.9) == pytest.approx(1.0 / (0.7 * 0.5), rel=1e-9)
    assert kernels.attenuation_over_cosines(1e-200, 1e-200, 0.7, 0.9) == pytest.approx(1.0 / (1.6e-200), rel=1e-12)


# ------------------------------------------------------------------------------------------ geometry


def test_ply_frame_is_orthonormal_and_reduces_to_the_cylinder():
    rng = np.random.default_rng(3)
    u, v = rng.uniform(-0.8, 0.8, 500), rng.uniform(-1.2, 1.2, 500)
    psi, beta = rng.uniform(-0.6, 0.6, 500), rng.uniform(0.0, 2.0, 500)
    n, t = ply_frame(u, v, psi, beta)
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0) and np.allclose(np.linalg.norm(t, axis=1), 1.0)
    assert np.allclose(np.sum(n * t, axis=1), 0.0, atol=1e-12)
    # beta = 1, psi = 0: IM's cylinder normal (sin v, sin u cos v, cos u cos v) and the spine (0, cos u, -sin u)
    n1, t1 = ply_frame(u, v, 0.0, 1.0)
    assert np.allclose(n1, np.stack([np.sin(v), np.sin(u) * np.cos(v), np.cos(u) * np.cos(v)], 1))
    assert np.allclose(t1, np.stack([0 * u, np.cos(u), -np.sin(u)], 1))
    # beta = 0 flattens: n = z, t = the in-plane direction of the twisted fibre
    n0, t0 = ply_frame(u, v, psi, 0.0)
    assert np.allclose(n0, [0.0, 0.0, 1.0]) and np.allclose(t0[:, 2], 0.0)
    assert np.allclose(t0, unit(np.stack([-np.sin(psi) * np.cos(v),
                                          np.cos(psi) * np.cos(u) + np.sin(psi) * np.sin(v) * np.sin(u), 0 * u], 1)))
    # the twist turns t about n by psi (beta = 1)
    n2, t2 = ply_frame(u, v, psi, 1.0)
    assert np.allclose(np.sum(t2 * t1, axis=1), np.cos(psi))


def test_projected_area_matches_a_brute_force_mean_and_bounds_w_z():
    rng = np.random.default_rng(4)
    w = hemisphere(rng, 40, min_z=0.02)
    umax, beta, gap = np.deg2rad(35.0), 1.3, 0.2
    half = 0.5 * np.pi * (1 - gap)
    m = 600
    v = half * (2 * (np.arange(m) + 0.5) / m - 1)
    u = umax * (2 * (np.arange(m // 2) + 0.5) / (m // 2) - 1)
    uu, vv = np.meshgrid(u, v)
    n, _ = ply_frame(uu.ravel(), vv.ravel(), 0.0, beta)
    brute = np.mean(np.maximum(w @ n.T, 0.0) / n[:, 2], axis=1)
    assert np.allclose(yarn_area(w, umax, beta, gap), brute, rtol=3e-3)
    assert np.all(yarn_area(w, umax, beta, gap) >= w[:, 2] - 1e-12)
    assert np.allclose(yarn_area(w, umax, 0.0, gap), w[:, 2])
    shares = {"warp": 0.5, "weft": 0.5}
    params = {"gap": gap, "warp.umax": 35.0, "weft.umax": 20.0, "warp.beta": 0.0, "weft.beta": 0.0}
    assert np.allclose(projected_area(w, shares, params), w[:, 2])


# ------------------------------------------------------------------------------------------ identities


@pytest.mark.parametrize("weave", ["pattern:twill-3x3", "preset:polyester-lining", "pattern:satin-5x10"])
def test_tile_average_equals_texture_average(weave):
    """components() = the texture's mean over a dense grid of the tile (to the quadrature's accuracy)."""
    model = SurfaceModel(resolve_weave(weave, "."), tile_nodes=[160, 80])
    params = {"warp.psi": 30.0, "weft.psi": -30.0, "warp.umax": 40.0, "weft.umax": 20.0,
              "warp.alpha": 0.3, "weft.alpha": 0.6, "warp.beta": 1.5, "weft.beta": 0.7}
    rng = np.random.default_rng(5)
    wi, wo = hemisphere(rng, 4, 0.2), hemisphere(rng, 4, 0.2)
    tile = model.components(wi, wo, params)
    height, width = model.weave.pattern.shape
    nu, nv = 120 * width, 120 * height
    uu, vv = np.meshgrid((np.arange(nu) + 0.5) / nu, (np.arange(nv) + 0.5) / nv)
    texture = model.texture()
    for k in range(len(wi)):
        point = texture.components(uu, vv, wi[k], wo[k], params)
        for name in model.component_names:
            assert point[name].mean() == pytest.approx(tile[name][k], rel=5e-3, abs=1e-6), name


def test_tile_average_is_the_texture_mean_at_the_quadrature_nodes():
    """Exactly (1e-9): the texture at the tile quadrature's ply nodes, placed on one segment per yarn type
    and found by the segment lookup, averages (times share and ply fraction) to components()."""
    weave = get_pattern("twill-5x5")
    model = SurfaceModel(weave, tile_nodes=[12, 6])
    params = model.resolve({"warp.psi": -30.0, "warp.beta": 1.8, "weft.alpha": 0.15, "gap": 0.3})
    wi, wo = unit([[0.3, -0.2, 0.8]]), unit([[-0.5, 0.1, 0.4]])
    tile = model.components(wi, wo, params)
    texture = model.texture()
    width, height = weave.tile_width, weave.tile_height
    for kind in ("warp", "weft"):
        seg = next(s for s in weave.segments if s.kind == kind)
        g = weave.geometry(kind)
        half = 0.5 * np.pi * (1 - params["gap"])
        v = half * (2 * (np.arange(12) + 0.5) / 12 - 1)
        u = np.deg2rad(params[f"{kind}.umax"]) * (2 * (np.arange(6) + 0.5) / 6 - 1)
        uu, vv = np.meshgrid(u, v, indexing="ij")
        x = g.w * vv.ravel() / np.pi  # eq. 11 inverted
        y = g.l * uu.ravel() / (2 * np.deg2rad(params[f"{kind}.umax"]))
        du, dv = (x, y) if kind == "warp" else (y, -x)  # local -> fabric axes (weave.lookup)
        tu = (seg.center_u * width + du) / width
        tv = (seg.center_v * height + dv) / height
        index, lx, ly = locate_segments(weave, tu, tv)
        assert np.all(index == weave.segments.index(seg)) and np.allclose(lx, x) and np.allclose(ly, y)
        point = texture.components(tu, tv, wi[0], wo[0], params)
        factor = weave.cell_share(kind) * (1 - params["gap"])
        for comp in (f"diffuse_{kind}", f"specular_{kind}"):
            assert factor * point[comp].mean() == pytest.approx(tile[comp][0], rel=1e-9)


# ------------------------------------------------------------------------------------------ Table 2 samples


def table2_samples(rng, n):
    """n materials of Table 2 (pattern, psi in {-30, 0, 30}, umax U(15, 45), alpha U(0.1, 1), beta U(0, 2),
    drawn per yarn type), with gap 0.2 and blend U(0, 1)."""
    out = {"pattern": rng.integers(0, len(PATTERN_NAMES), n), "blend": rng.uniform(0, 1, n)}
    for kind in ("warp", "weft"):
        out[f"{kind}.psi"] = rng.choice([-30.0, 0.0, 30.0], n)
        out[f"{kind}.umax"] = rng.uniform(15.0, 45.0, n)
        out[f"{kind}.alpha"] = rng.uniform(0.1, 1.0, n)
        out[f"{kind}.beta"] = rng.uniform(0.0, 2.0, n)
    return out


def batch_areas(w, s, shares):
    """A~ of each row's material (rows of w with their sample arrays s)."""
    return projected_area(w, shares, {"gap": 0.2, **{k: s[k] for k in s if k.endswith(("umax", "beta"))}})


def batch_shares(pattern):
    shares = np.array([[get_pattern(p).cell_share(k) for k in ("warp", "weft")] for p in PATTERN_NAMES])
    return {"warp": shares[pattern, 0], "weft": shares[pattern, 1]}


def batch_points(s, kind, cu, cv, wi, wo, ai, ao):
    n, t = ply_frame(cu, cv, np.deg2rad(s[f"{kind}.psi"]), s[f"{kind}.beta"])
    return kernels.point_values(np.ascontiguousarray(np.concatenate([n, t], 1)),
                                np.ascontiguousarray(to_yarn_frame(wi, kind)),
                                np.ascontiguousarray(to_yarn_frame(wo, kind)),
                                np.ascontiguousarray(ai), np.ascontiguousarray(ao),
                                np.ascontiguousarray(s[f"{kind}.alpha"]), 0.5)


def test_reciprocity_and_non_negativity_over_10000_table2_samples():
    rng = np.random.default_rng(6)
    n = 10_000
    s = table2_samples(rng, n)
    shares = batch_shares(s["pattern"])
    wi, wo = hemisphere(rng, n, 1e-4), hemisphere(rng, n, 1e-4)
    ai, ao = batch_areas(wi, s, shares), batch_areas(wo, s, shares)
    for kind in ("warp", "weft"):
        cu = np.deg2rad(s[f"{kind}.umax"]) * rng.uniform(-1, 1, n)
        cv = 0.5 * np.pi * 0.8 * rng.uniform(-1, 1, n)
        forward = batch_points(s, kind, cu, cv, wi, wo, ai, ao)
        backward = batch_points(s, kind, cu, cv, wo, wi, ao, ai)
        for a, b in zip(forward, backward, strict=True):
            assert np.all(np.isfinite(a)) and np.all(a >= 0.0)
            assert np.allclose(a, b, rtol=1e-12, atol=0.0)
    # and the tile average of a few materials
    for j in range(7):
        model = SurfaceModel(get_pattern(PATTERN_NAMES[j]), tile_nodes=[16, 8])
        params = {k: float(s[k][j]) for k in s if "." in k}
        a, b = model.components(wi[:200], wo[:200], params), model.components(wo[:200], wi[:200], params)
        for name in model.component_names:
            assert np.allclose(a[name], b[name], rtol=1e-12, atol=0.0) and np.all(a[name] >= 0.0)


def test_white_furnace_albedo_at_most_one_over_10000_table2_samples():
    """Albedo int f cos_o dwo <= 1 for each unit component (so for kd + ks <= 1 the fabric conserves
    energy), per Table 2 material at a random wi (grazing included): the tile average over 2 x 2 ply nodes
    per yarn type, wo by Gauss-Legendre in cos theta (6) x 12 azimuths, vectorised over materials (coarse
    rules: the fine-rule test below checks the model's own tile average)."""
    rng = np.random.default_rng(7)
    n = 10_000
    s = table2_samples(rng, n)
    mu, wmu = np.polynomial.legendre.leggauss(6)
    mu, wmu = 0.5 * (mu + 1), 0.5 * wmu
    phi = 2 * np.pi * (np.arange(12) + 0.5) / 12
    r = np.sqrt(1 - mu**2)
    wo_nodes = np.stack([np.outer(r, np.cos(phi)).ravel(), np.outer(r, np.sin(phi)).ravel(),
                         np.repeat(mu, 12)], 1)
    weights = np.repeat(wmu, 12) * (2 * np.pi / 12) * wo_nodes[:, 2]  # dw cos_o
    wi = hemisphere(rng, n, 1e-3)
    albedo = {}
    for start in range(0, n, 1000):
        part = slice(start, start + 1000)
        sp = {k: v[part] for k, v in s.items()}
        m = len(sp["pattern"])
        shares = batch_shares(sp["pattern"])
        ai = batch_areas(wi[part], sp, shares)
        rep = {k: np.repeat(v, len(wo_nodes)) for k, v in sp.items()}
        wo = np.tile(wo_nodes, (m, 1))
        ao = batch_areas(wo, rep, {k: np.repeat(v, len(wo_nodes)) for k, v in shares.items()})
        wi_rep = np.repeat(wi[part], len(wo_nodes), axis=0)
        ai_rep = np.repeat(ai, len(wo_nodes))
        for kind in ("warp", "weft"):
            total = {"specular": 0.0, "diffuse": 0.0}
            for cu_frac in (-0.5, 0.5):
                for cv_frac in (-0.5, 0.5):
                    cu = np.deg2rad(rep[f"{kind}.umax"]) * cu_frac
                    cv = np.full(len(wo), 0.5 * np.pi * 0.8 * cv_frac)
                    spec, diff = batch_points(rep, kind, cu, cv, wi_rep, wo, ai_rep, ao)
                    total["specular"] = total["specular"] + spec / 4
                    total["diffuse"] = total["diffuse"] + diff / 4
            for comp, value in total.items():
                a = shares[kind] * 0.8 * (value * np.tile(weights, m)).reshape(m, -1).sum(axis=1)
                albedo.setdefault(f"{comp}_{kind}", []).append(a)
    for name, parts in albedo.items():
        a = np.concatenate(parts)
        assert np.all(np.isfinite(a)) and np.all(a >= 0.0), name
        assert a.max() <= 1.0, (name, a.max())
    both = {c: np.concatenate(albedo[f"{c}_warp"]) + np.concatenate(albedo[f"{c}_weft"])
            for c in ("specular", "diffuse")}
    assert both["diffuse"].max() <= 1.0 and both["specular"].max() <= 1.0


def test_white_furnace_with_fine_quadrature_for_a_few_materials():
    """The same bound with the model's own tile average and a fine wo rule (64 x 96), incl. grazing wi."""
    mu, wmu = np.polynomial.legendre.leggauss(64)
    mu, wmu = 0.5 * (mu + 1), 0.5 * wmu
    phi = 2 * np.pi * (np.arange(96) + 0.5) / 96
    r = np.sqrt(1 - mu**2)
    wo = np.stack([np.outer(r, np.cos(phi)).ravel(), np.outer(r, np.sin(phi)).ravel(), np.repeat(mu, 96)], 1)
    weights = np.repeat(wmu, 96) * (2 * np.pi / 96) * wo[:, 2]
    for pattern, params in (("plain", {"warp.beta": 2.0, "weft.beta": 2.0, "warp.alpha": 1.0, "weft.alpha": 1.0}),
                            ("twill-3x3", {"warp.beta": 0.0, "weft.beta": 0.0}),
                            ("satin-8x8", {"warp.beta": 1.0, "warp.alpha": 0.1, "warp.psi": 30.0})):
        model = SurfaceModel(get_pattern(pattern), tile_nodes=[16, 8])
        for wi in (unit([0.0, 0.0, 1.0]), unit([1.0, 0.3, 0.02]), unit([0.2, 1.0, 0.001])):
            comps = model.components(np.broadcast_to(wi, wo.shape), wo, params)
            diffuse = sum(comps[f"diffuse_{k}"] for k in ("warp", "weft")) @ weights
            specular = sum(comps[f"specular_{k}"] for k in ("warp", "weft")) @ weights
            assert 0.0 < diffuse <= 1.0 and 0.0 < specular <= 1.0
            if params["warp.beta"] == 0.0:  # flat plies: Lambert on the 80 % the gap leaves
                assert diffuse == pytest.approx(0.8, rel=1e-6)


@pytest.mark.parametrize("alpha", [1e-3, 1.0])
@pytest.mark.parametrize("beta", [0.0, 4.0])
def test_finite_at_grazing_and_at_alpha_bounds(alpha, beta):
    model = build_model("surface", get_pattern("twill-3x3"))
    params = {"warp.alpha": alpha, "weft.alpha": alpha, "warp.beta": beta, "weft.beta": beta}
    grazing = [1e-300, 1e-12, 1e-6, 1e-2]
    wi = np.array([[np.sqrt(1 - z * z), 0.0, z] for z in grazing] + [[0.0, 0.0, 1.0]] * 4)
    wo = np.array([[0.0, 0.0, 1.0]] * 4 + [[-np.sqrt(1 - z * z), 0.1 * z, z] for z in grazing])
    wo = unit(wo)
    for a, b in ((wi, wo), (wi, wi), (wi, -wi * [1, 1, -1])):  # incl. mirror pairs and back-facing
        comps = model.components(a, b, params)
        for value in comps.values():
            assert np.all(np.isfinite(value)) and np.all(value >= 0.0)
        tex = model.texture().components(np.full(len(a), 0.3), np.full(len(a), 0.6), a, b, params)
        for value in tex.values():
            assert np.all(np.isfinite(value)) and np.all(value >= 0.0)
    back = model.components(wi, -wo, params)
    assert all(np.all(v == 0.0) for v in back.values())


# ------------------------------------------------------------------------------------------ patterns, reach


@pytest.mark.parametrize("name", PATTERN_NAMES)
def test_patterns_have_rectangular_floats(name):
    """Every cell of the pattern lies inside its segment's w x l rectangle and the rectangles tile."""
    weave = get_pattern(name)
    h, w = weave.pattern.shape
    assert (w, h) == {"plain": (2, 2), "twill-3x3": (3, 3), "twill-5x5": (5, 5), "twill-8x8": (8, 8),
                      "satin-5x5": (5, 5), "satin-8x8": (8, 8), "satin-5x10": (5, 10)}[name]
    k = 16
    uu, vv = np.meshgrid((np.arange(k * w) + 0.5) / (k * w), (np.arange(k * h) + 0.5) / (k * h))
    seg, x, y = locate_segments(weave, uu, vv)
    kinds = np.array([s.kind for s in weave.segments])[seg]
    length = np.where(kinds == "weft", weave.weft.l, weave.warp.l)
    assert np.all(np.abs(x) < 0.5) and np.all(np.abs(y) < 0.5 * length)
    for kind in ("warp", "weft"):  # each segment covers exactly w x l cells
        ids = [i for i, s in enumerate(weave.segments) if s.kind == kind]
        for i in ids:
            assert np.sum(seg == i) / k**2 == pytest.approx(weave.geometry(kind).l)


def test_pattern_names_resolve_and_unknown_ones_fail_clearly(tmp_path):
    assert resolve_weave("pattern:Twill-3x3", tmp_path).name == "twill-3x3"
    with pytest.raises(ConfigError, match="known patterns"):
        resolve_weave("pattern:twill-4x4", tmp_path)
    from clothlab.config import load_config

    (tmp_path / "d.csv").write_text("theta_i,phi_i,theta_o,phi_o,value\n10,0,20,180,0.3\n")
    cfg = tmp_path / "fabric.yaml"
    cfg.write_text("name: t\nmeasurement: {path: d.csv}\nmodel: {kind: surface, weave: 'pattern:satin-5x10'}\n"
                   "fit: {free: [warp.alpha]}\n")
    assert load_config(cfg).model.weave == "pattern:satin-5x10"
    cfg.write_text(cfg.read_text().replace("satin-5x10", "satin-9x9"))
    with pytest.raises(ConfigError, match="satin-9x9"):
        load_config(cfg)


def test_ply_nodes_and_options():
    model = build_model("surface", get_pattern("plain"), tile_nodes=[8, 4])
    assert model.tile_nodes == (8, 4) and ply_nodes(model.default_parameters(), "warp", (8, 4)).shape == (32, 6)
    with pytest.raises(ConfigError, match="tile_nodes"):
        build_model("surface", get_pattern("plain"), tile_nodes=0)
    u, v = cylinder_angles(0.25, -0.5, 1.0, 2.0, 0.4)
    assert (u, v) == pytest.approx((-0.2, 0.25 * np.pi))


# ------------------------------------------------------------------------------------------ recovery

SURFACE_TWILL = __import__("pathlib").Path(__file__).resolve().parents[1] / "measurements" / "surface-twill"


def test_shipped_set_is_reproduced_at_its_generating_parameters():
    """The shipped clean set (generated by kind surface) is a zero of the fit objective at its recorded
    parameters, with the recorded coefficients recovered by NNLS (to 1e-6 relative)."""
    from clothlab.config import load_config
    from clothlab.fit.problem import build_problem

    problem = build_problem(load_config(SURFACE_TWILL / "surface-clean.yaml"))
    truth = problem.measurement.provenance["parameters"]
    solution = problem.solve({k: truth[k] for k in problem.start})
    assert solution.objective < 1e-20
    colours = problem.measurement.provenance["coefficients"]
    for i, name in enumerate(problem.component_names):
        coef = {"diffuse_warp": "kd_warp", "diffuse_weft": "kd_weft"}.get(name, name.replace("specular", "ks"))
        np.testing.assert_allclose(solution.coefficients[i], colours[coef], rtol=1e-6)


def test_fit_recovers_the_shipped_sets_parameters():
    """Local polish (BOBYQA) from a start 20-40 % off, on 400 of the clean set's rows: alpha and beta of
    both yarn types within 1 % and umax within 0.5 deg of the generator (tolerances of a noise-free fit)."""
    from clothlab.config import load_config
    from clothlab.fit.optimize import minimize
    from clothlab.fit.problem import FitProblem, build_problem

    full = build_problem(load_config(SURFACE_TWILL / "surface-clean.yaml"))
    truth = full.measurement.provenance["parameters"]
    rows = np.random.default_rng(8).choice(full.measurement.n, 400, replace=False)
    measurement = full.measurement.subset(rows)
    free = ("warp.umax", "weft.umax", "warp.alpha", "weft.alpha", "warp.beta", "weft.beta")
    start = {k: truth[k] for k in full.start} | {"warp.umax": 28.0, "weft.umax": 32.0, "warp.alpha": 0.4,
                                                 "weft.alpha": 0.35, "warp.beta": 0.9, "weft.beta": 1.1}
    problem = FitProblem(full.model, measurement, free, start, metric="relative")
    result = minimize(problem, problem.to_unit(start), np.zeros(len(free)), np.ones(len(free)),
                      global_algorithm=None, max_evals=600, seed=1)
    fitted = problem.from_unit(result.x)
    for name in free:
        if name.endswith("umax"):
            assert abs(fitted[name] - truth[name]) < 0.5, (name, fitted[name])
        else:
            assert fitted[name] == pytest.approx(truth[name], rel=1e-2), (name, fitted[name])


# ------------------------------------------------------------------------------------------ reach


def surface_scene(height):
    from clothlab.render import scene_from_dict

    return scene_from_dict({
        "patch": {"size_mm": [20000, 20000], "tile_mm": 1.0},
        "camera": {"position": [0, 0, height], "look_at": [0, 0, 0], "up": [0, 1, 0], "fov_deg": 20.0,
                   "resolution": [8, 6]},
        "light": {"type": "directional", "direction": [0.3, -0.2, 1.0], "intensity": 2.0},
        "fabric": {"weave": "pattern:twill-3x3", "coefficients": {"kd": 0.2, "ks_warp": 0.3, "ks_weft": 0.1}},
    })


def test_surface_shaders_render_and_the_far_view_is_the_tile_average():
    """surface-texture up close and surface-lod far away: finite, non-negative; far away every pixel takes the
    tile average (components) at its pixel-centre directions, which a head-on view shares almost exactly."""
    from clothlab.render import render

    near = render(surface_scene(3.0), shader="surface-texture", spp=1)
    assert np.all(np.isfinite(near.image)) and np.all(near.image >= 0.0) and near.image.max() > 0.0
    assert near.stats["texture_pixel_fraction"] == 1.0
    far = render(surface_scene(20000.0), shader="surface-lod", spp=1)
    assert far.stats["texture_pixel_fraction"] == 0.0
    model = build_model("surface", get_pattern("twill-3x3"))
    wi, wo = unit([[0.3, -0.2, 1.0]]), np.array([[0.0, 0.0, 1.0]])
    f = model.evaluate(wi, wo, {"kd_warp": 0.2, "kd_weft": 0.2, "ks_warp": 0.3, "ks_weft": 0.1})[0, 0]
    irradiance = 2.0 * wi[0, 2]  # directional light of intensity 2, cosine at the patch
    image = far.image[..., 0]  # pixels look 0-10 deg off the normal: the head-on value lies within their range
    assert image.min() < f * irradiance < image.max() and np.allclose(image, f * irradiance, rtol=0.05)


def test_eval_cli_with_texture_points(tmp_path, capsys):
    from clothlab.cli.main import main

    directions = tmp_path / "d.csv"
    directions.write_text("theta_i,phi_i,theta_o,phi_o,u,v\n30,0,30,180,0.1,0.2\n40,90,10,250,0.55,0.45\n")
    assert main(["eval", str(SURFACE_TWILL / "simulate.yaml"), str(directions)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    header = lines[0].split(",")
    model = build_model("surface", get_pattern("twill-3x3"))
    from clothlab.config import load_config

    params = dict(load_config(SURFACE_TWILL / "simulate.yaml").model.params)
    row = dict(zip(header, map(float, lines[1].split(",")), strict=True))
    wi = np.array([[np.sin(np.deg2rad(30)), 0, np.cos(np.deg2rad(30))]])
    wo = np.array([[-np.sin(np.deg2rad(30)), 0, np.cos(np.deg2rad(30))]])
    comps = model.texture().components(0.1, 0.2, wi, wo, params)
    for name in model.component_names:
        assert row[name] == pytest.approx(float(comps[name]), rel=1e-9, abs=1e-15)


def test_btf_stack_of_a_surface_config(tmp_path):
    from clothlab.simulate.btf import simulate_btf_command

    out = tmp_path / "btf"
    simulate_btf_command(SURFACE_TWILL / "simulate.yaml", out, n_directions=4, size=8, kd="0.3", ks_warp="0.2",
                         ks_weft="0.1")
    import yaml

    manifest = yaml.safe_load((out / "manifest.yaml").read_text())
    text = str(manifest)
    assert "kd_warp" in text and "kd_weft" in text and "surface" in text


def test_warp_and_weft_swap_under_a_quarter_turn():
    """Plain weave, identical yarn types: turning both directions by +90 deg about z turns every warp component
    into the weft one (the weft's yarn frame is the warp's turned by 90 deg, and a segment is symmetric under
    the remaining half turn, (u, v) -> (-u, -v))."""
    model = build_model("surface", get_pattern("plain"))
    params = {"warp.psi": 30.0, "weft.psi": 30.0, "warp.umax": 33.0, "weft.umax": 33.0, "warp.alpha": 0.2,
              "weft.alpha": 0.2, "warp.beta": 1.4, "weft.beta": 1.4}
    rng = np.random.default_rng(9)
    wi, wo = hemisphere(rng, 300, 0.05), hemisphere(rng, 300, 0.05)
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # +90 deg about z
    a = model.components(wi, wo, params)
    b = model.components(wi @ turn.T, wo @ turn.T, params)
    for comp in ("diffuse", "specular"):
        np.testing.assert_allclose(b[f"{comp}_weft"], a[f"{comp}_warp"], rtol=1e-10, atol=1e-14)


def test_fit_cli_runs_kind_surface(tmp_path):
    from clothlab.cli.main import main

    assert main(["-q", "fit", str(SURFACE_TWILL / "surface-clean.yaml"), "-o", str(tmp_path), "--max-evals", "4"]) == 0
    import json

    fit = json.loads((tmp_path / "surface-twill-clean" / "fit.json").read_text())
    assert fit["model"]["kind"] == "surface" and set(fit["coefficients"]) == {"kd_warp", "kd_weft", "ks_warp",
                                                                              "ks_weft"}


def test_shared_directions_equal_per_point_directions():
    """(1, 3) directions shared by all points give the same values as the same directions repeated per point."""
    model = build_model("surface", get_pattern("satin-5x5"))
    texture = model.texture()
    assert texture.shared_directions and not hasattr(texture, "micro_normals")
    rng = np.random.default_rng(10)
    u, v = rng.uniform(-2, 3, 500), rng.uniform(-2, 3, 500)
    wi, wo = unit([[0.4, -0.3, 0.7]]), unit([[-0.1, 0.5, 0.6]])
    shared = texture.components(u, v, wi, wo, {"warp.beta": 1.7})
    repeated = texture.components(u, v, np.repeat(wi, 500, 0), np.repeat(wo, 500, 0), {"warp.beta": 1.7})
    for name in model.component_names:
        np.testing.assert_array_equal(shared[name], repeated[name])


def test_whole_tile_footprint_is_the_tile_average():
    """Through the footprint aggregation (eqs. 3-5, when present): a box footprint of whole tiles, by
    summed-area tables and by stratified MC, equals components() - the texture needs no micro-normal weights."""
    footprint = pytest.importorskip("clothlab.footprint")
    model = SurfaceModel(get_pattern("twill-3x3"), tile_nodes=[128, 64])
    params = {"warp.psi": 30.0, "warp.alpha": 0.4, "weft.alpha": 0.7, "warp.beta": 1.2, "weft.beta": 0.6}
    rng = np.random.default_rng(11)
    wi, wo = hemisphere(rng, 6, 0.3), hemisphere(rng, 6, 0.3)
    centre, size = rng.uniform(0, 1, (6, 2)), np.array([1.0, 2.0, 3.0, 1.0, 2.0, 1.0])
    tile = model.components(wi, wo, params)
    sat = footprint.footprint_components(model.texture(), params, wi, wo, centre, size, method="sat",
                                         resolution=384)
    mc = footprint.footprint_components(model.texture(), params, wi, wo, centre, size, method="mc", samples=4096)
    for name in model.component_names:
        # 128 texels per cell: the gap edge (x = 0.4 cell) and the steep ply edges cost the tables ~0.7 %
        np.testing.assert_allclose(sat[name], tile[name], rtol=1.5e-2, atol=1e-6)
        np.testing.assert_allclose(mc[name], tile[name], rtol=0.05, atol=1e-4)
