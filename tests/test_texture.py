"""The Irawan-Marschner texture model (sec. 7.2, eqs. 11-13, Algorithms 3-4) and its noise (sec. 7.2.1).

Independent checks: the reflectance model with the adaptive rule (identity of docs/presets.md), the
scalar reference integrands of tests/im_reference.py (band position and brightness), known splitmix64
outputs, closed-form moments of the capped exponential, and a separate Python process (reproducibility).
"""

from __future__ import annotations

import ast
import math
import subprocess
import sys
import warnings

import im_reference as ref
import numpy as np
import pytest

from clothlab.errors import GeometryWarning
from clothlab.frames import spherical_to_vector, to_yarn_frame
from clothlab.models.irawan.model import IrawanModel, Quadrature, specular_albedo
from clothlab.models.irawan.texture import IrawanTexture
from clothlab.models.irawan.texture_noise import INTENSITY_CAP, exponential_noise, hash_bits, hash_uniform, perlin_1d
from clothlab.weave.presets import PRESET_NAMES, get_preset

ALBEDO_RULE = Quadrature("support", 4)  # a_j only scales both sides alike
REFERENCE_RULE = Quadrature("adaptive", 8)
# (theta_i, phi_i), (theta_o, phi_o) in degrees: an in-plane mirror pair along the weft, one along the
# warp, and two generic off-plane pairs.
PAIRS = [((30, 0), (30, 180)), ((45, 90), (45, 270)), ((60, 30), (20, 200)), ((70, 300), (40, 100))]


def directions(pairs):
    wi = spherical_to_vector([p[0][0] for p in pairs], [p[0][1] for p in pairs])
    wo = spherical_to_vector([p[1][0] for p in pairs], [p[1][1] for p in pairs])
    return wi, wo


def tile_grid(weave, per_cell):
    """Cell-centred grid over one tile, ``per_cell`` samples per cell and axis (u, v in tile units)."""
    nu, nv = per_cell * weave.tile_width, per_cell * weave.tile_height
    return np.meshgrid((np.arange(nu) + 0.5) / nu, (np.arange(nv) + 0.5) / nv)


def quiet_texture(name, **kw):
    return IrawanTexture(get_preset(name), ALBEDO_RULE, **kw)


def reference_texture(weave, params, kind, x, y, wi, wo):
    """Algorithms 3-4 for one point from the scalar reference integrands (raw T / cell share)."""
    yi, yo = to_yarn_frame(np.asarray(wi), kind), to_yarn_frame(np.asarray(wo), kind)
    psi, umax = math.radians(params[f"{kind}.psi"]), math.radians(params[f"{kind}.umax"])
    kappa, w, l, hw = params[f"{kind}.kappa"], params[f"{kind}.w"], params[f"{kind}.l"], params["hwidth"]
    s = yi + yo
    h = tuple(s / np.linalg.norm(s))
    fc = ref.phase(wi, wo, params["alpha"], params["beta"])
    if abs(psi) >= 1e-3:
        u = 2.0 * umax * y / l
        v = ref._staple_v(u, h, psi)
        if abs(u) > umax or v is None or abs(v) >= 0.5 * math.pi:
            return 0.0
        centre = float(np.clip(w * v / math.pi, -0.5 * (w - hw * w), 0.5 * (w - hw * w)))
        lit = abs(x - centre) < 0.5 * hw * w
        value = 2.0 * umax * ref.staple_integrand(u, yi, yo, psi, umax, kappa, w, l) / hw
    else:
        v = math.pi * x / w
        u = ref._filament_u(h)
        if abs(v) > 0.5 * math.pi or u is None:
            return 0.0
        centre = float(np.clip(l * u / (2.0 * umax), -0.5 * (l - hw * l), 0.5 * (l - hw * l)))
        lit = abs(y - centre) < 0.5 * hw * l
        value = math.pi * ref.filament_integrand(v, yi, yo, umax, kappa, w, l, params["delta"]) / hw
    return fc * value / weave.cell_share(kind) if lit else 0.0


# ------------------------------------------------------------------ identity (docs/presets.md)

SMOOTHED_FILAMENTS = [n for n in PRESET_NAMES if get_preset(n).delta > 0 and get_preset(n).warp.psi == 0.0]


@pytest.mark.parametrize(("name", "arc"), [(n, "full") for n in PRESET_NAMES] +
                         [(n, "shortened") for n in SMOOTHED_FILAMENTS])
def test_tile_average_equals_reflectance_model(name, arc):
    """Tile average over a 96-per-cell grid (no noise) = reflectance component (normalised), 0.5 %, under
    both ``filament_arc`` options (the shortened one only changes the smoothed filament presets).

    The tile average of a band of fixed width is a Riemann sum: per grid row the lit count is off by at
    most one sample, h / Dx = (1/96) / 0.5 = 2.1 % for a band that sits at the same x in every row (the
    mirror pair along the weft on denim's weft); measured 0.15 % there and <= 0.05 % elsewhere."""
    weave = get_preset(name)
    texture = IrawanTexture(weave, ALBEDO_RULE, filament_arc=arc)
    params = texture.default_parameters()
    wi, wo = directions(PAIRS)
    raw = IrawanModel(weave, REFERENCE_RULE, filament_arc=arc).components(wi, wo, warn=False, normalised=False)
    u, v = tile_grid(weave, 96)
    checked = 0
    for k in range(len(PAIRS)):
        comps = texture.components(u, v, wi[k], wo[k], noise=False, warn=False)
        assert comps["diffuse"].mean() == pytest.approx(1.0 / np.pi, rel=1e-12)
        for kind in ("warp", "weft"):
            expected = raw[f"specular_{kind}"][k] / specular_albedo(params, kind, ALBEDO_RULE, filament_arc=arc)
            got = comps[f"specular_{kind}"].mean()
            if expected < 1e-3 * max(raw["specular_warp"][k], raw["specular_weft"][k]):
                assert got <= 0.005 * expected + 1e-12
                continue
            assert got == pytest.approx(expected, rel=5e-3), (name, PAIRS[k], kind)
            checked += 1
    assert checked >= 6


def test_raw_components_tile_average_to_raw_model():
    weave = get_preset("wool-gabardine")
    wi, wo = directions(PAIRS[2:3])
    raw = IrawanModel(weave, REFERENCE_RULE).components(wi, wo, normalised=False)
    u, v = tile_grid(weave, 64)
    comps = IrawanTexture(weave).components(u, v, wi, wo, normalised=False, noise=False)
    for kind in ("warp", "weft"):
        assert comps[f"specular_{kind}"].mean() == pytest.approx(raw[f"specular_{kind}"][0], rel=5e-3)


def test_presets_declared_areas_equal_pattern_shares():
    """The texture divides by the cell share; for the presets it equals the declared warpArea/weftArea."""
    for name in PRESET_NAMES:
        weave = get_preset(name)
        for kind in ("warp", "weft"):
            assert weave.cell_share(kind) == pytest.approx(weave.area_share(kind), abs=1e-12)


# ------------------------------------------------------------------ pointwise: band and brightness

@pytest.mark.parametrize("name", ["cotton-denim", "silk-charmeuse", "silk-shantung", "polyester-lining"])
def test_points_match_scalar_reference(name):
    """Texture at random points (also far outside [0, 1]) = Algorithms 3-4 from the reference integrands."""
    weave = get_preset(name)
    texture = IrawanTexture(weave)
    params = texture.default_parameters()
    rng = np.random.default_rng(7)
    n = 400
    u = rng.uniform(-40.0, 40.0, n)
    v = rng.uniform(-40.0, 40.0, n)
    wi = spherical_to_vector(rng.uniform(0, 75, n), rng.uniform(0, 360, n))
    wo = -wi * np.array([1.0, 1.0, -1.0]) + rng.normal(0.0, 0.3, (n, 3)) * np.array([1.0, 1.0, 0.0])
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    comps = texture.components(u, v, wi, wo, noise=False, normalised=False)
    points = texture.locate(u, v)
    lit = 0
    for i in range(n):
        kind = "weft" if points.is_weft[i] else "warp"
        other = "warp" if kind == "weft" else "weft"
        expected = reference_texture(weave, params, kind, points.x[i], points.y[i], wi[i], wo[i])
        assert comps[f"specular_{kind}"][i] == pytest.approx(expected, rel=1e-9, abs=1e-12)
        assert comps[f"specular_{other}"][i] == 0.0
        lit += expected > 0
    assert lit > 20


@pytest.mark.parametrize("hwidth", [0.2, 0.5, 0.9])
def test_band_covers_hwidth_of_the_segment(hwidth):
    """Staple (denim, band across x) and filament (charmeuse, band along y): lit fraction = hWidth."""
    wi, wo = directions([((40, 20), (35, 215))])
    for name, kind, across in (("cotton-denim", "warp", True), ("silk-charmeuse", "warp", False)):
        weave = get_preset(name)
        texture = IrawanTexture(weave)
        seg = next(i for i, s in enumerate(weave.segments) if s.kind == kind)
        centre_u = weave.segments[seg].center_u * weave.tile_width
        centre_v = weave.segments[seg].center_v * weave.tile_height
        g = weave.geometry(kind)
        n = 2000
        t = (np.arange(n) + 0.5) / n - 0.5  # fractions across the segment, centred
        lit_lines = 0
        for line in np.linspace(-0.45, 0.45, 19):
            if across:  # warp: x = dU across, y = dV along
                uu, vv = centre_u + t * g.w, np.full(n, centre_v + line * g.l)
            else:
                uu, vv = np.full(n, centre_u + line * g.w), centre_v + t * g.l
            comps = texture.components(uu / weave.tile_width, vv / weave.tile_height, wi, wo,
                                       {"hwidth": hwidth}, noise=False)
            values = comps[f"specular_{kind}"]
            if values.max() == 0.0:
                continue  # no visible specular point on this line
            lit_lines += 1
            assert np.mean(values > 0.0) == pytest.approx(hwidth, abs=2.0 / n)
            lit = np.flatnonzero(values > 0)
            assert np.all(np.diff(lit) == 1)  # one contiguous band
        assert lit_lines >= 5, name


def test_periodic_without_noise_and_segments_across_tile_edges():
    """Shifting by whole tiles (negative too) changes nothing; segments whose centres lie outside [0, 1]
    (shantung weft u = -1/6, charmeuse warp v = -0.35, 1.05, 1.25) are lit continuously across the edge."""
    wi, wo = directions([((35, 100), (40, 285))])
    for name in ("silk-shantung", "silk-charmeuse", "cotton-denim"):
        weave = get_preset(name)
        texture = IrawanTexture(weave)
        u, v = tile_grid(weave, 16)
        base = texture.components(u, v, wi, wo, noise=False)
        for du, dv in ((-3, 0), (0, -7), (12, -5), (-1000, 2000)):
            moved = texture.components(u + du, v + dv, wi, wo, noise=False)
            for key in base:
                np.testing.assert_allclose(moved[key], base[key], rtol=1e-9, atol=1e-12)
    # charmeuse warp id 5 (centre v = -0.35, V from -8 to +1 cells, column 2) is id 4 (v = 0.65) of the
    # tile below: one physical segment crossing the edge v = 0, y measured from V = -3.5 on both sides
    weave = get_preset("silk-charmeuse")
    texture = IrawanTexture(weave)
    params = texture.default_parameters()
    v = np.linspace(-0.79, 0.09, 177)  # crosses v = 0 inside the segment
    u = np.full_like(v, 0.5 + 0.03)
    comps = texture.components(u, v, wi, wo, noise=False, normalised=False)
    points = texture.locate(u, v)
    assert set(points.segment.tolist()) == {3, 4}
    np.testing.assert_allclose(points.y, v * weave.tile_height + 3.5, atol=1e-9)
    for i in range(len(v)):
        expected = reference_texture(weave, params, "warp", points.x[i], points.y[i], wi[0], wo[0])
        assert comps["specular_warp"][i] == pytest.approx(expected, rel=1e-9, abs=1e-12)


def test_reciprocity():
    """T depends on wi, wo through h, |wi + wo|, ci cr / (ci + cr) and wi.wo: swapping them is exact,
    for both paths and with noise on (the noise does not depend on directions)."""
    rng = np.random.default_rng(3)
    n = 3000
    wi = spherical_to_vector(rng.uniform(0, 85, n), rng.uniform(0, 360, n))
    wo = spherical_to_vector(rng.uniform(0, 85, n), rng.uniform(0, 360, n))
    for name in ("cotton-twill", "silk-shantung"):
        texture = quiet_texture(name)
        u, v = rng.uniform(-5, 5, n), rng.uniform(-5, 5, n)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", GeometryWarning)
            a = texture.components(u, v, wi, wo)
            b = texture.components(u, v, wo, wi)
        for key in a:
            np.testing.assert_allclose(a[key], b[key], rtol=1e-12, atol=0.0)
        assert np.count_nonzero(a["specular_warp"]) > 10


def test_twill_weft_warns_like_the_reflectance_model():
    texture = IrawanTexture(get_preset("cotton-twill"))
    with pytest.warns(GeometryWarning, match="weft"):
        texture.components([0.1], [0.2], [0, 0, 1.0], [0, 0, 1.0])


def test_extreme_inputs_finite_and_non_negative():
    rng = np.random.default_rng(11)
    n = 2000
    u = np.concatenate([rng.uniform(-1e7, 1e7, n // 2), rng.uniform(-1e-300, 1e-300, n // 2)])
    v = np.concatenate([rng.uniform(-1e7, 1e7, n // 2), -np.abs(u[n // 2:])])
    theta_i = rng.choice([0.0, 1e-9, 45.0, 89.0, 89.9999, 90.0, 95.0], n)
    theta_o = rng.choice([0.0, 1e-9, 60.0, 89.9999, 90.0, 120.0], n)
    phi = rng.uniform(0, 360, n)
    wi = spherical_to_vector(theta_i, phi)
    wo = spherical_to_vector(theta_o, np.where(rng.random(n) < 0.5, phi + 180.0, phi))
    wo[:10] = -wi[:10]  # degenerate half vector
    wo[10:20] = wi[10:20]
    for name in PRESET_NAMES:
        texture = quiet_texture(name)
        for params in ({}, {"hwidth": 1.0}, {"hwidth": 1e-3}, {"warp.psi": 0.06, "weft.psi": -0.06},
                       {"warp.umax": 89.0, "weft.kappa": -0.95, "delta": 0.95}):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", GeometryWarning)
                comps = texture.components(u, v, wi, wo, params, normalised=False)
            for key, value in comps.items():
                assert np.all(np.isfinite(value)) and np.all(value >= 0.0), (name, params, key)
            back = (wi[:, 2] <= 0) | (wo[:, 2] <= 0)
            assert np.all(comps["specular_warp"][back] == 0) and np.all(comps["diffuse"][back] == 0)


def test_texture_evaluates_a_512_grid_at_once():
    """A 512 x 512 grid of tile positions in one call keeps the grid's shape (its time is measured by the bench
    section ``texture``, not here)."""
    weave = get_preset("silk-shantung")  # Perlin noise on
    texture = IrawanTexture(weave)
    u, v = np.meshgrid((np.arange(512) + 0.5) / 512, (np.arange(512) + 0.5) / 512)
    wi, wo = directions(PAIRS[:1])
    comps = texture.components(u, v, wi, wo)
    assert comps["specular_weft"].shape == (512, 512)
    assert np.all(np.isfinite(comps["specular_weft"])) and comps["specular_weft"].max() > 0


# ------------------------------------------------------------------ noise (sec. 7.2.1)

def test_hash_is_splitmix64():
    """Known outputs of splitmix64 from state 0 (published test vector): the mixer is the standard one."""
    from clothlab.models.irawan.texture_noise import _mix

    z = _mix(np.zeros(1, dtype=np.uint64))
    assert int(z[0]) == 0xE220A8397B1DCDAF
    z2 = _mix(np.array([0x9E3779B97F4A7C15], dtype=np.uint64))
    assert int(z2[0]) == 0x6E789E6AA1B965F4


def test_hash_rejects_floats_and_handles_negative_keys():
    with pytest.raises(TypeError, match="integers"):
        hash_bits(np.array([0.5]))
    a = hash_uniform(np.array([-1, -2, 3]), 7)
    assert np.all((a > 0) & (a < 1)) and len(set(a.tolist())) == 3
    assert hash_uniform(-1, 7) == pytest.approx(a[0], abs=0)


def test_texture_same_in_float32_and_float64_and_across_runs():
    for name in ("cotton-denim", "silk-shantung"):  # intensity noise / Perlin noise
        texture = quiet_texture(name, seed=5)
        rng = np.random.default_rng(1)
        u32 = rng.uniform(-30, 30, 5000).astype(np.float32)
        v32 = rng.uniform(-30, 30, 5000).astype(np.float32)
        wi, wo = directions(PAIRS[2:3])
        a = texture.components(u32, v32, wi, wo, normalised=False)
        b = texture.components(u32.astype(np.float64), v32.astype(np.float64), wi, wo, normalised=False)
        for key in a:
            assert np.array_equal(a[key], b[key])
        assert np.unique(texture.intensity_noise(texture.locate(u32, v32), texture.default_parameters())
                         if get_preset(name).fineness else texture.umax_offsets(texture.locate(u32, v32))).size > 50
    code = (
        "import numpy as np\n"
        "from clothlab.models.irawan.texture import IrawanTexture\n"
        "from clothlab.weave.presets import get_preset\n"
        "from clothlab.frames import spherical_to_vector\n"
        "t = IrawanTexture(get_preset('cotton-denim'), seed=5)\n"
        "u = np.linspace(-7.3, 9.1, 64); v = np.linspace(3.7, -12.2, 64)\n"
        "c = t.components(u, v, spherical_to_vector(60, 30), spherical_to_vector(20, 200), normalised=False)\n"
        "print(repr(c['specular_warp'].tolist()), repr(c['specular_weft'].tolist()))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    texture = IrawanTexture(get_preset("cotton-denim"), seed=5)
    u = np.linspace(-7.3, 9.1, 64)
    v = np.linspace(3.7, -12.2, 64)
    here = texture.components(u, v, spherical_to_vector(60, 30), spherical_to_vector(20, 200), normalised=False)
    # another process, the same machine: the seeded noise repeats; compared within a few ulps, not bit for bit
    # (docs/testing.md: only one process compares bit for bit)
    warp_text, weft_text = out.strip().split("] [")
    there_warp = np.array(ast.literal_eval(warp_text + "]"))
    there_weft = np.array(ast.literal_eval("[" + weft_text))
    np.testing.assert_allclose(there_warp, here["specular_warp"], rtol=64 * np.finfo(np.float64).eps, atol=0)
    np.testing.assert_allclose(there_weft, here["specular_weft"], rtol=64 * np.finfo(np.float64).eps, atol=0)
    other = IrawanTexture(get_preset("cotton-denim"), seed=6).components(
        u, v, spherical_to_vector(60, 30), spherical_to_vector(20, 200), normalised=False)
    assert not np.array_equal(other["specular_warp"], here["specular_warp"])


def test_exponential_noise_mean_one_and_distribution():
    """Mean 1 within 5 standard errors; the standard deviation from the closed-form capped moments."""
    from scipy import integrate

    n = 400_000
    x = exponential_noise(np.arange(n), 12, seed=9)
    cap = INTENSITY_CAP
    mean_capped = integrate.quad(lambda t: min(t, cap) * math.exp(-t), 0, 60, points=[cap])[0]
    second = integrate.quad(lambda t: min(t, cap) ** 2 * math.exp(-t), 0, 60, points=[cap])[0]
    sigma = math.sqrt(second / mean_capped**2 - 1.0)
    assert abs(x.mean() - 1.0) < 5.0 * sigma / math.sqrt(n)
    assert x.std() == pytest.approx(sigma, rel=0.02)
    assert x.min() > 0.0 and x.max() <= cap / mean_capped + 1e-12
    # P(X > 1) = exp(-mean_capped) for the rescaled variable (binomial 5-sigma tolerance)
    p = math.exp(-mean_capped)
    assert abs(np.mean(x > 1.0) - p) < 5.0 * math.sqrt(p * (1 - p) / n)


def test_texture_intensity_noise_per_cell_and_mean_one():
    """k x k constant cells per segment instance (denim: fineness 3), mean 1 over many tiles."""
    weave = get_preset("cotton-denim")
    texture = IrawanTexture(weave, seed=2)
    params = texture.default_parameters()
    k = int(weave.fineness)
    # warp segment 1 at (0.1667, 0.75): w = 1, l = 5 cells; sample a fine grid inside one instance
    cu, cv = 0.5, 4.5
    du, dv = np.meshgrid(np.linspace(-0.49, 0.49, 60), np.linspace(-2.49, 2.49, 150))
    pts = texture.locate((cu + du + 3 * 7) / 3, (cv + dv - 6 * 4) / 6)
    noise = texture.intensity_noise(pts, params)
    i = np.floor((du + 0.5) * k).astype(int)
    j = np.floor((dv / 5 + 0.5) * k).astype(int)
    assert np.unique(noise).size == k * k
    for a in range(k):
        for b in range(k):
            assert np.unique(noise[(i == a) & (j == b)]).size == 1
    # the physical segment of ids 1 (centre V = 4.5 cells) and 2 (V = -1.5, the same one a tile lower)
    # spans V = 2..7 across the tile edge V = 6; its top noise cell (V 5.33..7) is one draw on both sides
    pts = texture.locate(np.full(40, 0.5 / 3), (np.linspace(5.4, 6.9, 40) - 18.0) / 6)
    assert set(pts.segment.tolist()) == {0, 1}
    assert np.unique(texture.intensity_noise(pts, params)).size == 1
    # mean over the cell centres of 2,000 tiles
    tiles = np.arange(2000)
    cells = []
    for seg in weave.segments:
        g = weave.geometry(seg.kind)
        for a in range(k):
            for b in range(k):
                off_across, off_along = (a + 0.5) / k - 0.5, (b + 0.5) / k - 0.5
                if seg.kind == "warp":
                    uu, vv = off_across * g.w, off_along * g.l
                else:
                    uu, vv = off_along * g.l, -off_across * g.w
                cells.append(((seg.center_u * 3 + uu) / 3 + tiles, (seg.center_v * 6 + vv) / 6 - 3 * tiles))
    u = np.concatenate([c[0] for c in cells])
    v = np.concatenate([c[1] for c in cells])
    noise = texture.intensity_noise(texture.locate(u, v), params)
    capped = np.count_nonzero(noise == noise.max())  # the cap (P = e^-10) repeats its value
    assert np.unique(noise).size == noise.size - capped + 1  # every cell its own draw
    assert abs(noise.mean() - 1.0) < 5.0 / math.sqrt(noise.size)


def test_noise_off_when_fineness_zero_and_noise_false():
    texture = IrawanTexture(get_preset("wool-gabardine"))
    pts = texture.locate([0.1, 0.7], [0.3, 0.9])
    assert texture.intensity_noise(pts, texture.default_parameters()) is None
    assert texture.umax_offsets(pts) is None
    denim = IrawanTexture(get_preset("cotton-denim"))
    u, v = tile_grid(get_preset("cotton-denim"), 8)
    wi, wo = directions(PAIRS[:1])
    a = denim.components(u, v, wi, wo, noise=False)
    b = denim.components(u, v, wi, wo)
    assert not np.array_equal(a["specular_warp"], b["specular_warp"])


def test_perlin_continuous_bounded_zero_on_lattice():
    t = np.linspace(-20.0, 20.0, 400_001)
    n = perlin_1d(t, 4, 99)
    assert np.all(np.abs(n) <= 1.0)
    assert np.all(perlin_1d(np.arange(-20, 21).astype(float), 4, 99) == 0.0)
    # Lipschitz bound from the fade polynomial: |dn/dt| <= 2 max(|d(f(1-s))/df| + |d((f-1)s)/df|)
    f = np.linspace(0, 1, 100_001)
    s = f**3 * (10 - 15 * f + 6 * f**2)
    bound = 2.0 * (np.abs(np.gradient(f * (1 - s), f)) + np.abs(np.gradient((f - 1) * s, f))).max()
    assert np.abs(np.diff(n)).max() <= bound * (t[1] - t[0]) * 1.001
    assert abs(n.mean()) < 0.1 and n.std() > 0.1
    assert np.array_equal(perlin_1d(t[:1000].astype(np.float32), 4, 99),
                          perlin_1d(t[:1000].astype(np.float32).astype(np.float64), 4, 99))


def test_perlin_umax_modulation_along_yarns():
    """Shantung (period 500 cells, dUmax 20, 20, 10, 10 deg): successive warp segments along one warp yarn
    change umax smoothly; the modulation is bounded by the dUmax sums; lining's short period varies more."""
    weave = get_preset("silk-shantung")
    texture = IrawanTexture(weave, seed=1)
    seg = weave.segments[0]  # warp, centre (0.3333, 0.25)
    tiles = np.arange(-400, 400)
    pts = texture.locate(np.full(tiles.size, seg.center_u), seg.center_v + tiles)
    assert np.all(pts.segment == 0)
    offsets = texture.umax_offsets(pts)
    assert np.all(np.abs(offsets) <= 40.0 + 1e-9)
    # P changes by at most bound * (8 cells / 500 cells) per tile step; weft noise term is constant here
    f = np.linspace(0, 1, 100_001)
    s = f**3 * (10 - 15 * f + 6 * f**2)
    bound = 2.0 * (np.abs(np.gradient(f * (1 - s), f)) + np.abs(np.gradient((f - 1) * s, f))).max()
    assert np.abs(np.diff(offsets)).max() <= 20.0 * bound * 8 / 500 * 1.001
    assert np.ptp(offsets) > 5.0  # it does vary along the yarn
    # the crossing-weft term: a weft segment in the same column gets the warp yarn's noise (weft<-warp)
    wi, wo = directions(PAIRS[:1])
    comps = texture.components(np.full(4, seg.center_u), seg.center_v + np.array([0, 37, -91, 250]), wi, wo)
    assert np.all(np.isfinite(comps["specular_warp"]))


def test_direction_shapes_broadcast_or_raise():
    from clothlab.errors import ParameterError

    texture = IrawanTexture(get_preset("polyester-lining"))
    u, v = np.linspace(0, 1, 50), np.linspace(0.3, 2, 50)
    wi = spherical_to_vector(30, 0)
    wo = spherical_to_vector(np.full(50, 30.0), np.linspace(150, 210, 50))
    a = texture.components(u, v, wi, wo, normalised=False)
    b = texture.components(u, v, np.tile(wi, (50, 1)), wo, normalised=False)
    for key in a:
        assert np.array_equal(a[key], b[key])
    with pytest.raises(ParameterError, match=r"wi \(3, 3\)"):
        texture.components(u, v, np.zeros((3, 3)), wo)


# ------------------------------------------------------------------------------ clothlab eval with u, v


def _eval_csv(path, rows, header="theta_i,phi_i,theta_o,phi_o,u,v"):
    path.write_text(header + "\n" + "".join(",".join(repr(float(x)) for x in row) + "\n" for row in rows))
    return path


def _read_csv(path):
    import csv

    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}


def test_eval_with_u_v_is_the_texture_model_at_those_points(tmp_path, capsys):
    """``clothlab eval`` with u, v columns against IrawanTexture.evaluate / .components called directly
    (fit directory: f_r per channel; fabric.yaml: the components), at points across tile edges and at
    negative coordinates; and the same directions without u, v give the reflectance model instead."""
    from pathlib import Path

    from clothlab.cli import main
    from clothlab.config import load_config
    from clothlab.fit.store import load_fitted
    from clothlab.weave.presets import resolve_weave

    root = Path(__file__).resolve().parents[1]
    rng = np.random.default_rng(11)
    n = 40
    rows = np.column_stack([rng.uniform(0, 80, n), rng.uniform(0, 360, n), rng.uniform(0, 80, n),
                            rng.uniform(0, 360, n), rng.uniform(-2.5, 3.5, n), rng.uniform(-1.5, 2.5, n)])
    csv_path = _eval_csv(tmp_path / "points.csv", rows)
    wi, wo = spherical_to_vector(rows[:, 0], rows[:, 1]), spherical_to_vector(rows[:, 2], rows[:, 3])

    fit_dir = root / "fits" / "polyester-lining"
    assert main(["eval", str(fit_dir), str(csv_path), "-o", str(tmp_path / "fit.csv")]) == 0
    out = _read_csv(tmp_path / "fit.csv")
    np.testing.assert_array_equal(out["u"], rows[:, 4])
    np.testing.assert_array_equal(out["v"], rows[:, 5])
    model, params, coefficients, channels = load_fitted(fit_dir)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        expected = IrawanTexture(model.weave, model.quadrature).evaluate(rows[:, 4], rows[:, 5], wi, wo,
                                                                        coefficients, params)
        reflectance = model.evaluate(wi, wo, coefficients, params)
    got = np.column_stack([out[c] for c in channels])
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-15)

    # without u, v: the reflectance model, which differs from the texture at single points
    _eval_csv(tmp_path / "angles.csv", rows[:, :4], header="theta_i,phi_i,theta_o,phi_o")
    assert main(["eval", str(fit_dir), str(tmp_path / "angles.csv"), "-o", str(tmp_path / "refl.csv")]) == 0
    refl = np.column_stack([_read_csv(tmp_path / "refl.csv")[c] for c in channels])
    assert "u" not in _read_csv(tmp_path / "refl.csv")
    np.testing.assert_allclose(refl, reflectance, rtol=1e-9, atol=1e-15)
    assert np.max(np.abs(refl - got) / np.maximum(refl, 1e-12)) > 0.1

    # a fabric.yaml: the texture components (unit coefficients) with the configured parameters
    config_path = root / "measurements" / "polyester-lining" / "fabric.yaml"
    assert main(["eval", str(config_path), str(csv_path), "-o", str(tmp_path / "cfg.csv")]) == 0
    out = _read_csv(tmp_path / "cfg.csv")
    cfg = load_config(config_path)
    texture = IrawanTexture(resolve_weave(cfg.model.weave, cfg.base_dir),
                            Quadrature(cfg.model.quadrature.rule, cfg.model.quadrature.nodes))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        comps = texture.components(rows[:, 4], rows[:, 5], wi, wo, dict(cfg.model.params))
    for name in ("diffuse", "specular_warp", "specular_weft"):
        np.testing.assert_allclose(out[name], comps[name], rtol=1e-12, atol=1e-15)
    capsys.readouterr()


def test_eval_with_u_v_and_a_source_without_texture_is_a_clear_error(tmp_path, capsys):
    from pathlib import Path

    from clothlab.cli import main

    root = Path(__file__).resolve().parents[1]
    csv_path = _eval_csv(tmp_path / "points.csv", [[30, 0, 30, 180, 0.25, 0.5]])
    assert main(["eval", str(root / "fits" / "polyester-lining-oren-nayar"), str(csv_path)]) == 2
    err = capsys.readouterr().err
    assert "field 'u'" in err and "irawan" in err and "oren-nayar" in err and str(csv_path) in err
    assert err.count("\n") == 1  # one line, no traceback
    # u without v is named too
    half = _eval_csv(tmp_path / "half.csv", [[30, 0, 30, 180, 0.25]], header="theta_i,phi_i,theta_o,phi_o,u")
    assert main(["eval", str(root / "fits" / "polyester-lining"), str(half)]) == 2
    assert "both columns u and v" in capsys.readouterr().err
