"""Issue 23 item 4: neural-lod's per-pixel estimator choice (clothlab.surrogate.estimator_choice,
clothlab.render.neural_lod) - the pick is the cheapest candidate meeting the target (checked by brute force),
the sidecar field is schema-checked, a footprint finds its bin, and neural-lod renders by the stored choice
(each pixel's estimator evaluated independently here) or, without one, by its documented default."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from clothlab.errors import InputError
from clothlab.surrogate.estimator_choice import NEAR_BEST, estimator_at, mc_fit, pick, rechoose


def _options(rng, n):
    kinds = rng.choice(["mc", "surrogate", "reflectance"], n)
    return [{"estimator": str(k), "samples": int(rng.integers(1, 64)) if k == "mc" else 0,
             "us": float(rng.uniform(0.1, 50.0)), "relative_rmse": float(rng.uniform(0.0, 0.5))} for k in kinds]


def test_the_pick_is_the_cheapest_candidate_that_meets_the_target():
    rng = np.random.default_rng(0)
    for _ in range(300):
        options, target = _options(rng, int(rng.integers(1, 10))), float(rng.uniform(0.0, 0.4))
        chosen = pick(options, target)
        meeting = [c for c in options if c["relative_rmse"] <= target]
        if meeting:
            assert chosen["relative_rmse"] <= target
            assert all(chosen["us"] <= c["us"] for c in meeting)
        else:  # nothing meets it: the cheapest of those within NEAR_BEST of the most accurate
            near = [c for c in options if c["relative_rmse"] <= NEAR_BEST * min(o["relative_rmse"] for o in options)]
            assert chosen in near and all(chosen["us"] <= c["us"] for c in near)


def test_the_mc_fit_recovers_a_power_law_and_a_linear_cost():
    k = np.array([1, 2, 4, 8, 16, 32])
    us, mse = mc_fit(k, 0.3 + 0.4 * k, 2.0 * k ** -1.5)
    assert np.allclose(us, 0.3 + 0.4 * k) and np.allclose(mse, 2.0 * k ** -1.5)
    _, flat = mc_fit(k, 1.0 + k, np.linspace(1.0, 2.0, k.size))  # rising MSE (noise): never rising with k
    assert np.all(np.diff(flat) <= 1e-15)


def _choice():
    candidates = [{"estimator": "mc", "samples": 2, "us": 1.0, "relative_rmse": 0.05},
                  {"estimator": "surrogate", "samples": 0, "us": 1.5, "relative_rmse": 0.08},
                  {"estimator": "reflectance", "samples": 0, "us": 0.3, "relative_rmse": 0.5}]
    bins = [(0.01, 0.1, candidates[0]), (0.1, 1.0, candidates[1]), (1.0, 5.0, candidates[2])]
    return {"error_target": 0.15, "measured": "test",
            "bins": [{"lo": lo, "hi": hi, **c, "candidates": candidates} for lo, hi, c in bins]}


def test_a_footprint_finds_its_bin_and_rechoose_applies_another_target():
    choice = _choice()
    index, samples = estimator_at(choice, [0.001, 0.01, 0.05, 0.1, 0.99, 1.0, 4.9, 7.0, np.inf])
    assert index.tolist() == [0, 0, 0, 1, 1, 2, 2, 2, 2]
    assert samples.tolist() == [2, 2, 2, 0, 0, 0, 0, 0, 0]
    loose = rechoose(choice, 1.0)  # everything meets it: the cheapest everywhere (R)
    assert {b["estimator"] for b in loose["bins"]} == {"reflectance"}


@pytest.mark.parametrize("change, field", [
    (lambda c: c["bins"][1].update(estimator="magic"), "estimator_choice.bins[1].estimator"),
    (lambda c: c["bins"][0].update(samples=0), "estimator_choice.bins[0].samples"),
    (lambda c: c["bins"][1].update(lo=0.05), "estimator_choice.bins[1]"),
    (lambda c: c.update(error_target=-1), "estimator_choice.error_target"),
    (lambda c: c.update(bins=[]), "estimator_choice.bins"),
])
def test_the_sidecar_field_is_schema_checked(tmp_path, change, field):
    from clothlab.models.neural.model import SHIPPED
    from clothlab.surrogate.serialise import read_sidecar

    sidecar = json.loads((SHIPPED / "silk-shantung.json").read_text(encoding="utf-8"))
    sidecar["estimator_choice"] = _choice()
    good = tmp_path / "good.json"
    good.write_text(json.dumps(sidecar), encoding="utf-8")
    assert read_sidecar(good)["estimator_choice"]["bins"][2]["estimator"] == "reflectance"
    change(sidecar["estimator_choice"])
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(sidecar), encoding="utf-8")
    with pytest.raises(InputError) as caught:
        read_sidecar(bad)
    assert caught.value.field == field


def _scene(distance, resolution=(12, 9)):
    from clothlab.studies.render_lod import receding_plane_scene

    scene = receding_plane_scene(resolution)
    scene = replace(scene, fabric=replace(scene.fabric, noise=False, weave="preset:silk-shantung"))
    return replace(scene, camera=scene.camera.at_distance(distance))


def _samples_of(scene, fabric, shader="im-reflectance", spp=1, seed=None):
    """The shading samples of a render of ``scene`` (the renderer's own geometry, captured)."""
    import importlib

    rendering = importlib.import_module("clothlab.render.render")  # the module (the package exports a function)
    box = {}
    original = rendering.shade

    def grab(shader, fabric_, samples, lod, counter):
        box["s"] = samples
        return original(shader, fabric_, samples, lod, counter)
    rendering.shade = grab
    try:
        rendering.render(scene, shader=shader, spp=spp, seed=seed, fabric=fabric)
    finally:
        rendering.shade = original
    return box["s"]


def _plane_uv(scene, px, py):
    """(u, v) tiles where the rays through pixel positions px, py meet the receding plane (flat, z = 0,
    warp along world y), intersected here by hand; and the ray directions."""
    from clothlab.render.camera import PinholeCamera

    camera = PinholeCamera(scene.camera)
    d = camera.directions(np.ravel(px), np.ravel(py))
    point = camera.eye + (-camera.eye[2] / d[:, 2])[:, None] * d
    return point[:, :2] / np.asarray(scene.patch.tile_mm), d


def _centre_by_hand(scene):
    """Per pixel of the receding plane: the surface point through the pixel's centre - (u, v) tiles, wi, wo,
    the (u, v) steps to the centres one pixel right and one pixel down, and the footprint: the longer step
    (geometry's definition)."""
    w, h = scene.camera.resolution
    cols, rows = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    centre, d = _plane_uv(scene, cols, rows)
    steps = np.stack([_plane_uv(scene, cols + 1.0, rows)[0] - centre, _plane_uv(scene, cols, rows + 1.0)[0] - centre],
                     axis=1)
    size = np.linalg.norm(steps, axis=2).max(axis=1)
    light = np.asarray(scene.light.direction) / np.linalg.norm(scene.light.direction)
    return centre, size, np.broadcast_to(light, d.shape), -d, steps


@pytest.mark.parametrize("spp", [4, 9, 7])
def test_neural_lod_shades_each_pixel_box_at_the_pixel_centre_whatever_the_jitter(spp):
    """At spp > 1 a pixel's box (shade.pixel_boxes) is the pixel centre's surface point, footprint and
    directions - not the mean of its jittered samples nor its first (corner) sample - checked against the
    plane intersected by hand."""
    from clothlab.render.shade import FabricModels, pixel_boxes

    scene = _scene(20.0)
    fabric = FabricModels.build(scene.fabric)
    samples = _samples_of(scene, fabric, "neural-lod", spp)
    first, back, centre, size, wi, wo, steps = pixel_boxes(samples)
    pixel = samples.pixel[first]
    assert pixel.size == scene.camera.resolution[0] * scene.camera.resolution[1]  # every pixel sees the plane
    want_centre, want_size, want_wi, want_wo, want_steps = _centre_by_hand(scene)
    assert np.allclose(centre, want_centre[pixel], rtol=0.0, atol=1e-9)
    assert np.allclose(size, want_size[pixel], rtol=1e-9)
    assert np.allclose(steps, want_steps[pixel], rtol=1e-9, atol=1e-12)
    assert np.allclose(wi, want_wi[pixel], atol=1e-12) and np.allclose(wo, want_wo[pixel], atol=1e-12)
    # the samples themselves are off the centre (so the check above is not vacuous)
    count = np.bincount(back)
    mean = np.column_stack([np.bincount(back, samples.u) / count, np.bincount(back, samples.v) / count])
    assert np.abs(mean - want_centre[pixel]).max() > 1e-3 * np.median(want_size)
    assert np.abs(samples.wo[first] - want_wo[pixel]).max() > 1e-6


def test_a_filtered_pixel_does_not_depend_on_the_jitter(monkeypatch):
    """With every pixel a box estimator (MC-2, the network, R) and a directional light on a plane (the same
    irradiance and cosine at every sample), the neural-lod image is the same at 1 spp and at 4 or 9 spp from
    any seed: more samples do not move the filtered value."""
    import clothlab.render.neural_lod as policy
    from clothlab.render.render import render
    from clothlab.render.shade import FabricModels

    scene = _scene(20.0)
    fabric = FabricModels.build(scene.fabric)
    f = _samples_of(scene, fabric).footprint
    split = float(np.sqrt(f.min() * f.max()))
    choice = _choice()
    bins = choice["bins"]
    choice["bins"] = [dict(bins[0], lo=0.0, hi=split * 0.95), dict(bins[1], lo=split * 0.95, hi=split * 1.05),
                      dict(bins[2], lo=split * 1.05, hi=1e6)]
    monkeypatch.setattr(policy, "estimator_choice", lambda weave: choice)
    one = render(scene, shader="neural-lod", spp=1, fabric=fabric)
    assert one.stats["neural_evaluations"] > 0 and one.stats["texture_evaluations"] > 0
    for spp, seed in ((4, 1), (4, 123), (9, 5)):
        many = render(scene, shader="neural-lod", spp=spp, seed=seed, fabric=fabric)
        assert np.allclose(many.image, one.image, rtol=1e-12, atol=0.0)


def test_mc_pixels_average_the_texture_over_the_pixels_own_footprint(monkeypatch):
    """An ``mc`` pixel's points lie in the pixel's image on the surface (the quadrilateral of its four
    corners' rays, intersected by hand; first order: within 2 % of a step), and the estimate is near the
    supersampled pixel (im-texture 256 spp: about as near as im-texture at 64 spp), where the square box of
    side f (what the network learns) is not."""
    import clothlab.render.neural_lod as policy
    from clothlab.render.render import relative_error, render
    from clothlab.render.shade import Counter, FabricModels, pixel_boxes

    scene = _scene(4.0, (40, 30))  # footprints ~0.01-0.02 tile; a pixel spans 0.75 deg of view (the close-up's 0.6)
    fabric = FabricModels.build(scene.fabric)
    choice = {"error_target": 0.08, "bins": [{"lo": 0.0, "hi": 1e6, "estimator": "mc", "samples": 64}]}
    monkeypatch.setattr(policy, "estimator_choice", lambda weave: choice)
    seen = []
    original = fabric.texture.components

    def spy(u, v, *args, **kwargs):
        seen.append(np.column_stack([u, v]))
        return original(u, v, *args, **kwargs)
    monkeypatch.setattr(fabric.texture, "components", spy)
    own = render(scene, shader="neural-lod", spp=1, fabric=fabric)
    points = np.concatenate(seen).reshape(-1, 64, 2)  # one pixel's 64 points after another, pixels in order
    w, h = scene.camera.resolution
    cols, rows = np.meshgrid(np.arange(w), np.arange(h))
    corners = np.stack([_plane_uv(scene, cols + dx, rows + dy)[0] for dx, dy in ((0, 0), (1, 0), (1, 1), (0, 1))],
                       axis=1)  # (pixels, 4, 2), counter-clockwise or clockwise
    step = np.linalg.norm(corners[:, 1] - corners[:, 0], axis=1)
    inside = np.ones(points.shape[:2], dtype=bool)
    for a in range(4):  # the same side of every edge as the quadrilateral's centre
        e0, e1 = corners[:, a], corners[:, (a + 1) % 4]
        mid = corners.mean(axis=1)

        def side(x, e0=e0, e1=e1):
            return (e1[:, None, 0] - e0[:, None, 0]) * (x[..., 1] - e0[:, None, 1]) - \
                   (e1[:, None, 1] - e0[:, None, 1]) * (x[..., 0] - e0[:, None, 0])
        length = np.linalg.norm(e1 - e0, axis=1)[:, None]
        inside &= side(points) * np.sign(side(mid[:, None, :])) >= -0.02 * step[:, None] * length
    assert inside.all()
    monkeypatch.setattr(fabric.texture, "components", original)
    reference = render(scene, shader="im-texture", spp=256, fabric=fabric)
    mask = reference.coverage >= 1.0
    samples = _samples_of(scene, fabric, "neural-lod")
    first, back, centre, size, wi, wo, _ = pixel_boxes(samples)
    square = policy.pixel_values(fabric, None, choice, centre, size, wi, wo, Counter())[back]  # no steps: the box
    box = own.image.copy().reshape(-1, own.image.shape[-1])
    box[samples.pixel] = square * wi[back, 2:3] * scene.light.intensity
    err_own = relative_error(own.image, reference.image, mask)
    err_box = relative_error(box.reshape(own.image.shape), reference.image, mask)
    err_64 = relative_error(render(scene, shader="im-texture", spp=64, seed=9, fabric=fabric).image, reference.image,
                            mask)
    # measured: 0.0040 against im-texture's 0.0030 at 64 spp (its directions vary over the pixel, the
    # estimate's are the centre's) and the square box's 0.0122
    assert err_own < 2.0 * err_64 and err_box > 2.0 * err_own, (err_own, err_64, err_box)


def test_neural_lod_shades_each_pixel_by_its_bins_estimator(monkeypatch):
    """With a stored choice, each pixel (1 spp: one sample) is its bin's estimator at the pixel's box: MC-2 of
    the texture, the network's query or the network's configured R, computed here from the models."""
    import clothlab.render.neural_lod as policy
    from clothlab.models.components import combine
    from clothlab.render import shade
    from clothlab.render.shade import FabricModels, neural_model
    from clothlab.surrogate.labels import TextureMonteCarloLabels

    scene = _scene(20.0)
    fabric = FabricModels.build(scene.fabric)
    samples = _samples_of(scene, fabric)
    f = samples.footprint
    split = float(np.sqrt(f.min() * f.max()))
    choice = _choice()
    bins = choice["bins"]
    choice["bins"] = [dict(bins[0], lo=0.0, hi=split * 0.95), dict(bins[1], lo=split * 0.95, hi=split * 1.05),
                      dict(bins[2], lo=split * 1.05, hi=1e6)]
    monkeypatch.setattr(policy, "estimator_choice", lambda weave: choice)
    counter = shade.Counter()
    values = shade.neural_lod_values(fabric, samples, counter, scene.lod)
    near, far = f < split * 0.95, f >= split * 1.05
    mid = ~near & ~far
    assert near.any() and mid.any() and far.any()
    c, wi, wo = np.column_stack([samples.u, samples.v]), samples.wi, samples.wo
    network = neural_model(fabric)
    mc = TextureMonteCarloLabels(fabric.texture, fabric.params, samples=2, seed=policy.MC_SEED + 2, noise=False)
    texture = mc(wi[near], wo[near], c[near], f[near])
    names = fabric.texture.component_names
    expected = np.empty_like(values)
    expected[near] = combine({n: texture[:, i] for i, n in enumerate(names)}, fabric.coefficients)
    expected[mid] = combine(network.query(c[mid], f[mid], wi[mid], wo[mid], fabric.params), fabric.coefficients)
    expected[far] = combine(network.exact_model().components(wi[far], wo[far], fabric.params, warn=False),
                            fabric.coefficients)
    assert np.allclose(values, expected, rtol=1e-9, atol=1e-12)
    assert counter["texture_points"] == 2 * near.sum() and counter["neural_points"] == mid.sum()
    assert counter["reflectance_points"] == far.sum()


def test_a_sidecar_without_a_choice_keeps_the_documented_default(monkeypatch):
    """No ``estimator_choice``: neural-lod is the session-10 policy (the network over 0.12-0.5 tile, im-lod
    elsewhere): near, where no pixel reaches 0.12 tile, the image is im-lod's exactly."""
    import clothlab.render.neural_lod as policy
    from clothlab.render.render import render
    from clothlab.render.shade import FabricModels

    monkeypatch.setattr(policy, "estimator_choice", lambda weave: None)
    scene = _scene(1.5)
    fabric = FabricModels.build(scene.fabric)
    neural = render(scene, shader="neural-lod", spp=2, fabric=fabric)
    im_lod = render(scene, shader="im-lod", spp=2, fabric=fabric)
    assert neural.stats["neural_evaluations"] == 0
    assert np.array_equal(neural.image, im_lod.image)
