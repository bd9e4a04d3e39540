"""The Mitsuba 3 bridge (clothlab.mitsuba, docs/mitsuba.md): sampler, chi-square, furnace, reciprocity, parity
with ``clothlab render`` and the CLI.  Tests needing Mitsuba skip when it is not installed; those needing the
vectorised variant skip when libLLVM is too old for it (docs/mitsuba.md "Variants")."""

from __future__ import annotations

import math

import numpy as np
import pytest

from clothlab.errors import ClothlabError, ConfigError
from clothlab.mitsuba.sampling import LobeSampler
from clothlab.models.registry import MODEL_KINDS


def _hemisphere_grid(n):
    z = (np.arange(n) + 0.5) / n
    phi = (np.arange(2 * n) + 0.5) * math.pi / n
    zz, pp = np.meshgrid(z, phi, indexing="ij")
    s = np.sqrt(1.0 - zz * zz)
    return np.stack([s * np.cos(pp), s * np.sin(pp), zz], axis=-1).reshape(-1, 3), 2.0 * math.pi / (2 * n * n)


def _peaked_lobe(w, view):
    """A narrow anisotropic lobe around the mirror direction of ``view`` (a stand-in for a yarn highlight)."""
    mirror = view * np.array([-1.0, -1.0, 1.0])
    return np.exp(40.0 * (np.einsum("ij,ij->i", w, mirror) - 1.0)) * (1.0 + w[:, 0] ** 2)


@pytest.mark.parametrize("theta", [0.0, 40.0, 75.0, 88.0])
def test_sampler_density_integrates_to_one(theta):
    sampler = LobeSampler(_peaked_lobe)
    grid, dw = _hemisphere_grid(400)
    view = np.broadcast_to([math.sin(math.radians(theta)), 0.0, math.cos(math.radians(theta))], grid.shape)
    assert sampler.pdf(view, grid).sum() * dw == pytest.approx(1.0, abs=2e-3)


def test_sampler_samples_follow_its_density():
    """A histogram of samples over the sampler's own cells matches the integrated density (chi-square-like)."""
    sampler = LobeSampler(_peaked_lobe)
    rng = np.random.default_rng(5)
    n = 200_000
    view = np.broadcast_to([0.5, 0.2, math.sqrt(1 - 0.29)], (n, 3))
    w, pdf = sampler.sample(view, rng.random(n), rng.random((n, 2)))
    assert np.all(w[:, 2] > 0.0) and np.all(pdf > 0.0)
    assert np.allclose(np.linalg.norm(w, axis=1), 1.0)
    grid, dw = _hemisphere_grid(256)
    density = sampler.pdf(np.broadcast_to(view[0], grid.shape), grid) * dw
    coarse = lambda d: (np.clip((d[:, 2] * 8).astype(int), 0, 7) * 16  # noqa: E731
                        + np.clip((np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * math.pi) / (2 * math.pi) * 16).astype(int),
                                  0, 15))
    expected = np.bincount(coarse(grid), density, minlength=128) * n
    observed = np.bincount(coarse(w), minlength=128)
    big = expected > 50
    assert np.all(np.abs(observed[big] - expected[big]) < 5 * np.sqrt(expected[big]) + 1e-3 * n)


def _one_fit_per_kind():
    """One shipped fit directory (fits/) per model kind found there."""
    import json
    from pathlib import Path

    found = {}
    for path in sorted((Path(__file__).resolve().parents[1] / "fits").glob("*/fit.json")):
        found.setdefault(json.loads(path.read_text())["model"]["kind"], path.parent)
    return sorted(found.items())


@pytest.mark.parametrize("kind, path", _one_fit_per_kind(), ids=lambda v: v if isinstance(v, str) else v.name)
def test_fit_directory_material_is_the_fit(kind, path):
    """A fit directory as a material evaluates to the fitted model's f_r (fit.store.load_fitted + Model.evaluate)
    in the reflectance policy, and its texture policy is the renderer's for that kind."""
    from clothlab.fit.store import load_fitted
    from clothlab.mitsuba.material import load_material

    model, params, coefficients, _ = load_fitted(path)
    material = load_material(fit=path, lod="reflectance")
    assert material.kind == kind
    rng = np.random.default_rng(7)
    z1, z2 = rng.uniform(0.1, 1, 50), rng.uniform(0.1, 1, 50)
    p1, p2 = rng.uniform(0, 2 * math.pi, 50), rng.uniform(0, 2 * math.pi, 50)
    wi = np.stack([np.sqrt(1 - z1 ** 2) * np.cos(p1), np.sqrt(1 - z1 ** 2) * np.sin(p1), z1], axis=1)
    wo = np.stack([np.sqrt(1 - z2 ** 2) * np.cos(p2), np.sqrt(1 - z2 ** 2) * np.sin(p2), z2], axis=1)
    assert np.allclose(material.values(wi, wo), model.evaluate(wi, wo, coefficients, params), rtol=1e-12, atol=0)
    expected = ("reflectance" if not model.has_texture else
                "footprint-texture" if model.texture_filters else "im-lod")
    assert load_material(fit=path).policy == expected


def test_cli_without_mitsuba_is_a_user_error(tmp_path, monkeypatch, capsys):
    import sys

    from clothlab.cli.main import main

    monkeypatch.setitem(sys.modules, "mitsuba", None)  # as if not installed
    scene = tmp_path / "scene.yaml"
    scene.write_text("patch: {shape: flat, size_mm: [100, 100], tile_mm: [1, 2]}\n"
                     "camera: {position: [0, -60, 60], resolution: [4, 3]}\nlight: {direction: [0, 0, 1]}\n")
    assert main(["render", str(scene), "--renderer", "mitsuba", "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("clothlab: error:") and "clothlab[mitsuba]" in err and len(err.strip().splitlines()) == 1


def test_material_requires_one_source():
    from clothlab.mitsuba.material import load_material

    with pytest.raises(ConfigError, match="exactly one"):
        load_material()
    with pytest.raises(ConfigError, match="lod"):
        load_material(preset="cotton-denim", lod="blurry")
    with pytest.raises(ClothlabError, match="not found"):
        load_material(fit="no/such/fit")


# ---------------------------------------------------------------------------------------------- Mitsuba


@pytest.fixture(scope="module")
def mi():
    return pytest.importorskip("mitsuba")


@pytest.fixture(scope="module")
def llvm(mi):
    from clothlab.mitsuba import use_variant

    try:
        use_variant("llvm_ad_rgb")
    except ConfigError as exc:
        pytest.skip(f"no vectorised Mitsuba variant here: {exc}")
    return mi


KINDS = tuple(MODEL_KINDS)  # every kind the registry offers, at the cotton-denim preset
CHI2_ANGLES = (0.0, 60.0, 87.0)


@pytest.mark.parametrize("kind", KINDS)
def test_chi2_every_kind(llvm, kind):
    from clothlab.mitsuba.checks import chi2_check, plugin_dict

    bsdf = plugin_dict(preset="cotton-denim", kind=kind)
    for theta in CHI2_ANGLES:  # 1 % significance over all the tests of this parametrisation (Mitsuba's rule)
        result = chi2_check(bsdf, theta, sample_count=20_000, test_count=len(KINDS) * len(CHI2_ANGLES))
        assert result["passed"], (kind, theta, result["messages"])


@pytest.mark.parametrize("kind", KINDS)
def test_weight_is_eval_over_pdf_and_furnace(llvm, kind):
    from clothlab.mitsuba.checks import furnace_check, plugin_dict, weight_check

    bsdf = plugin_dict(preset="cotton-denim", kind=kind)
    w = weight_check(bsdf, 70.0, n=4000)
    assert w["max_relative_difference"] < 1e-4 and w["pdf_relative_difference"] < 1e-5
    assert w["sampled_share"] > 0.99
    f = furnace_check(bsdf, 50.0, n=40_000, grid=96)
    plugin, error, model = (np.asarray(f[k]) for k in ("plugin_albedo", "plugin_standard_error", "model_albedo"))
    # the plugin's energy is the model's own (no more): agreement within the Monte-Carlo error and the
    # midpoint rule's (a few 1e-3 at 96 x 192 for the narrow lobes)
    assert np.all(plugin <= model + 5 * error + 5e-3 * np.maximum(model, 0.05))
    assert np.all(np.abs(plugin - model) <= 5 * error + 5e-3 * np.maximum(model, 0.05))


@pytest.mark.parametrize("kind, path", _one_fit_per_kind(), ids=lambda v: v if isinstance(v, str) else v.name)
def test_plugin_loads_fit_directories(llvm, kind, path):
    """``fit: fits/<name>`` in the plugin dict: the sampler passes the chi-square test at 45 deg and eval is the
    fit's f_r cos."""
    import mitsuba as mi

    from clothlab.mitsuba.checks import _si, _vec, chi2_check, direction, plugin_dict

    bsdf = plugin_dict(fit=str(path), lod="reflectance")
    assert chi2_check(bsdf, 45.0, sample_count=20_000, test_count=6)["passed"]
    plugin = mi.load_dict(bsdf)
    view = np.asarray(direction(45.0, 17.0))
    light = np.array([[0.3, -0.2, 0.9], [-0.5, 0.1, 0.6]])
    light /= np.linalg.norm(light, axis=1, keepdims=True)
    value = np.asarray(plugin.eval(mi.BSDFContext(), _si(2, view), _vec(light)).numpy()).reshape(3, -1).T
    expected = plugin.material.values(light, np.tile(view, (2, 1))) * light[:, 2:3]
    assert np.allclose(value, expected, rtol=1e-5)


@pytest.mark.parametrize("kind", [k for k in KINDS if k != "neural"])  # the network is fitted, not reciprocal
def test_reciprocity(llvm, kind):
    from clothlab.mitsuba.checks import plugin_dict, reciprocity_check

    assert reciprocity_check(plugin_dict(preset="cotton-denim", kind=kind), n=400) < 1e-4


def test_orientation_turns_both_models_alike(llvm):
    """A fit's ``orientation``: the reflectance model through the plugin is clothlab's oriented model, and the
    texture model sees the weave turned the same way - orientation 30 deg at warp angle 10 deg renders as
    orientation 0 at warp angle 40 deg, point for point (im-lod's texture and reflectance agree on the weave)."""
    import mitsuba as mi

    from clothlab.mitsuba.checks import _rgb, _si, _vec
    from clothlab.mitsuba.material import material_from_model
    from clothlab.mitsuba.plugin import add_material, forget_material
    from clothlab.models.registry import build_model
    from clothlab.render.scene import DEFAULT_CHANNELS, DEFAULT_COEFFICIENTS
    from clothlab.weave.presets import get_preset

    model = build_model("irawan", get_preset("cotton-denim"))
    rng = np.random.default_rng(13)
    z = rng.uniform(0.2, 1.0, (2, 100))
    p = rng.uniform(0.0, 2 * math.pi, (2, 100))
    view, light = (np.stack([np.sqrt(1 - z[k] ** 2) * np.cos(p[k]), np.sqrt(1 - z[k] ** 2) * np.sin(p[k]), z[k]],
                            axis=1) for k in (0, 1))

    def evaluate(orientation, angle, lod):
        material = material_from_model(model, {"orientation": orientation}, DEFAULT_COEFFICIENTS, DEFAULT_CHANNELS,
                                       lod=lod)
        key = add_material(material)
        try:
            plugin = mi.load_dict({"type": "clothlab", "material": key, "warp_angle_deg": angle,
                                   "uv_size_mm": "7 5", "tile_mm": "1 2"})
            si = _si(100, view)
            return _rgb(plugin.eval(mi.BSDFContext(), si, _vec(light))) / light[:, 2:3]
        finally:
            forget_material(key)

    expected = model.evaluate(light, view, DEFAULT_COEFFICIENTS, {"orientation": 30.0})
    assert np.allclose(evaluate(30.0, 0.0, "reflectance"), expected, rtol=1e-5)
    assert not np.allclose(evaluate(0.0, 0.0, "reflectance"), expected, rtol=1e-2)
    assert np.allclose(evaluate(30.0, 10.0, "texture"), evaluate(0.0, 40.0, "texture"), rtol=1e-4, atol=1e-7)


def test_importance_transport_is_the_adjoint(llvm):
    """In importance transport si.wi is the light side: eval_importance(a, b) / cos b = eval_radiance(b, a) / cos a,
    checked on the non-reciprocal kind (neural), where swapping the roles changes the value."""
    import mitsuba as mi

    from clothlab.mitsuba.checks import _rgb, _si, _vec, plugin_dict

    plugin = mi.load_dict(plugin_dict(preset="cotton-denim", kind="neural", lod="reflectance"))
    rng = np.random.default_rng(11)
    z = rng.uniform(0.2, 1.0, (2, 200))
    p = rng.uniform(0.0, 2 * math.pi, (2, 200))
    a, b = (np.stack([np.sqrt(1 - z[k] ** 2) * np.cos(p[k]), np.sqrt(1 - z[k] ** 2) * np.sin(p[k]), z[k]], axis=1)
            for k in (0, 1))
    radiance = _rgb(plugin.eval(mi.BSDFContext(), _si(200, b), _vec(a))) / a[:, 2:3]
    importance = _rgb(plugin.eval(mi.BSDFContext(mi.TransportMode.Importance), _si(200, a), _vec(b))) / b[:, 2:3]
    swapped = _rgb(plugin.eval(mi.BSDFContext(), _si(200, a), _vec(b))) / b[:, 2:3]
    assert np.allclose(importance, radiance, rtol=1e-5)
    assert not np.allclose(swapped, radiance, rtol=1e-2)


def _scene(position, resolution, spp, fabric=None, fov=30, size=2000):
    """A flat patch large enough that no pixel sees its edge (an edge pixel's coverage depends on where its
    samples fall, which differs between the two renderers' samplers)."""
    from clothlab.render import scene_from_dict

    return scene_from_dict({
        "patch": {"shape": "flat", "size_mm": [size, size], "tile_mm": [1.0, 2.0], "warp_angle_deg": 20},
        "camera": {"position": position, "look_at": [0, 0, 0], "fov_deg": fov, "resolution": resolution},
        "light": {"type": "directional", "direction": [0.3, -0.2, 1], "intensity": 1.0},
        "fabric": fabric or {"weave": "preset:cotton-denim"}, "render": {"spp": spp}}, base_dir=".")


def test_ray_parity_with_clothlab_render(llvm):
    """At clothlab's pixel-centre rays (spp 1) the plugin's value is clothlab render's, pixel for pixel, for the
    im-lod blend (camera distance where the footprint spans texture, blend and reflectance) - geometry, frame,
    texture coordinates and footprint all agree."""
    import drjit as dr
    import mitsuba as mi

    from clothlab.mitsuba.material import material_from_scene
    from clothlab.mitsuba.plugin import add_material, forget_material
    from clothlab.mitsuba.scene import scene_dict
    from clothlab.render import render
    from clothlab.render.camera import PinholeCamera

    scene = _scene([0, -8, 5], (24, 18), 1, size=100)
    reference = render(scene, shader="im-lod")
    assert reference.stats["blend_pixel_fraction"] > 0.3 and reference.stats["reflectance_only_pixel_fraction"] > 0.1
    key = add_material(material_from_scene(scene, "im-lod"))
    try:
        m = mi.load_dict(scene_dict(scene, key, spp=1))
        camera = PinholeCamera(scene.camera)
        px, py = camera.pixel_samples(1, None)
        d = camera.directions(px.reshape(-1), py.reshape(-1))
        ray = mi.Ray3f(mi.Point3f(*[mi.Float(np.full(len(d), c)) for c in camera.eye]),
                       mi.Vector3f(mi.Float(d[:, 0]), mi.Float(d[:, 1]), mi.Float(d[:, 2])))
        si = m.ray_intersect(ray)
        light = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])
        wo = si.to_local(mi.Vector3f(*[float(c) for c in light]))
        value = m.shapes()[0].bsdf().eval(mi.BSDFContext(), si, wo, si.is_valid())
        dr.eval(value)
        ours = np.asarray(value.numpy(), dtype=np.float64).reshape(3, -1).T.reshape(reference.image.shape)
    finally:
        forget_material(key)
    mask = reference.coverage >= 1.0
    # float32 in Mitsuba: texture coordinates to ~1e-6 tile; measured max relative difference 5e-5
    assert np.allclose(ours[mask], reference.image[mask], rtol=2e-4, atol=1e-7)


@pytest.mark.parametrize("case", ["reflectance", "texture"])
def test_image_parity_with_clothlab_render(llvm, case):
    """The same scene rendered by clothlab and by Mitsuba: mean relative difference per pixel <= 1 %, p99 <= 5 %
    (reflectance model far away at 4 spp; texture model close up, footprint ~0.05 tile, at 256 spp)."""
    from clothlab.mitsuba.scene import render_scene
    from clothlab.render import render

    if case == "reflectance":
        scene = _scene([0, -300, 300], (16, 12), 4)
    else:
        scene = _scene([0, -6, 6], (16, 12), 256, fov=10)
    shader = "im-reflectance" if case == "reflectance" else "im-texture"
    a = render(scene, shader=shader)
    b = render_scene(scene, shader=shader)
    assert b.stats["plugin_calls"] <= 2  # the whole wavefront in one model call
    mask = a.coverage >= 1.0
    rel = np.abs(b.image[mask] - a.image[mask]) / np.abs(a.image[mask])
    assert rel.mean() <= 0.01 and np.percentile(rel, 99) <= 0.05, (rel.mean(), np.percentile(rel, 99))


def test_scalar_variant_renders_the_same(mi):
    """scalar_rgb through ``mi.render`` (one plugin call per sample) renders the reflectance model as clothlab
    does (Monte-Carlo noise of 1 spp over large pixels aside)."""
    from clothlab.mitsuba.scene import render_scene
    from clothlab.render import render

    scene = _scene([0, -300, 300], (6, 4), 1)
    b = render_scene(scene, shader="im-reflectance", variant="scalar_rgb", wavefront=False)
    a = render(scene, shader="im-reflectance")
    mask = a.coverage >= 1.0
    assert not b.stats["wavefront"] and b.stats["plugin_calls"] > 1 and b.stats["lanes_per_call"] == 1.0
    rel = np.abs(b.image[mask] - a.image[mask]) / np.abs(a.image[mask])
    assert rel.mean() <= 0.01, rel


def test_scalar_wavefront_matches_clothlab_sample_for_sample(mi):
    """The scalar wavefront (Mitsuba's rays at clothlab's sample positions, the plugin once for all samples):
    the texture model's image equals ``clothlab render``'s up to float32 (the same samples, not just the same
    expectation); one plugin call."""
    from clothlab.mitsuba.scene import render_scene
    from clothlab.render import render

    scene = _scene([0, -6, 6], (12, 9), 4, fov=10)
    b = render_scene(scene, shader="im-texture", variant="scalar_rgb")
    a = render(scene, shader="im-texture")
    assert b.stats["wavefront"] and b.stats["plugin_calls"] == 1
    mask = a.coverage >= 1.0
    rel = np.abs(b.image[mask] - a.image[mask]) / np.abs(a.image[mask])
    assert np.median(rel) < 1e-4 and np.percentile(rel, 95) < 1e-3, (np.median(rel), np.percentile(rel, 95))


def test_cylinder_and_unknown_variant_refused(mi):
    from clothlab.mitsuba import use_variant
    from clothlab.mitsuba.scene import render_scene
    from clothlab.render import scene_from_dict

    scene = scene_from_dict({"patch": {"shape": "cylinder", "radius_mm": 20, "size_mm": [40, 40], "tile_mm": 1},
                             "camera": {"position": [0, -60, 60], "resolution": [4, 3]},
                             "light": {"direction": [0, 0, 1]}}, base_dir=".")
    with pytest.raises(ConfigError, match="flat patch"):
        render_scene(scene, variant="scalar_rgb")
    with pytest.raises(ConfigError, match="no usable Mitsuba variant"):
        use_variant("no_such_variant")


def test_cli_render_with_mitsuba(llvm, tmp_path, capsys):
    from clothlab.cli.main import main

    scene = tmp_path / "scene.yaml"
    scene.write_text("patch: {shape: flat, size_mm: [100, 100], tile_mm: [1, 2]}\n"
                     "camera: {position: [0, -60, 60], resolution: [8, 6]}\n"
                     "light: {direction: [0.3, -0.2, 1]}\nfabric: {weave: preset:cotton-denim}\nrender: {spp: 1}\n")
    assert main(["render", str(scene), "--renderer", "mitsuba", "-o", str(tmp_path / "out")]) == 0
    assert (tmp_path / "out.exr").is_file() and (tmp_path / "out.png").is_file()
    assert "Mitsuba 3" in capsys.readouterr().out
    assert main(["render", str(scene), "--renderer", "mitsuba", "-o", str(tmp_path / "out")]) == 2
