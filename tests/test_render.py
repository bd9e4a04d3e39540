"""Renderer: geometry vs hand-computed rays, LoD policy (texture near, reflectance far, continuous blend),
supersampling convergence, scene-file errors, EXR/PNG output, the Kang wiring."""

from pathlib import Path

import numpy as np
import pytest

from clothlab.errors import ConfigError, ResultExistsError
from clothlab.models.components import combine
from clothlab.models.irawan.texture import IrawanTexture
from clothlab.render import compare_lod, load_scene, render, render_to_files, save_render, scene_from_dict
from clothlab.render.geometry import make_surface
from clothlab.render.scene import Patch
from clothlab.render.shade import FabricModels, lod_weight
from clothlab.studies.render_lod import receding_plane_scene

REPO = Path(__file__).resolve().parents[1]
LIGHT = np.array([0.3, -0.2, 1.0])


def head_on(height=3.0, resolution=(16, 12), fov=20.0, warp_angle=30.0, **fabric):
    return scene_from_dict({
        "patch": {"size_mm": [50, 50], "tile_mm": [1.0, 2.0], "warp_angle_deg": warp_angle},
        "camera": {"position": [0, 0, height], "look_at": [0, 0, 0], "up": [0, 1, 0], "fov_deg": fov,
                   "resolution": list(resolution)},
        "light": {"type": "directional", "direction": LIGHT.tolist(), "intensity": 2.0},
        "fabric": {"weave": "preset:cotton-denim", **fabric},
    })


def oblique(distance, resolution=(12, 9), fov=30.0):
    return scene_from_dict({
        "patch": {"size_mm": [20000, 20000], "tile_mm": [1.0, 2.0]},
        "camera": {"position": [0, -distance / np.sqrt(2), distance / np.sqrt(2)], "fov_deg": fov,
                   "resolution": list(resolution)},
        "light": {"type": "directional", "direction": LIGHT.tolist()},
    })


def test_head_on_close_view_is_the_texture_model_at_the_pixel_centres():
    scene = head_on()
    w, h = scene.camera.resolution
    # pixel-centre rays by hand: camera looks down -z with up +y, so image right = +x and image down = -y
    half = np.tan(np.deg2rad(10.0))
    cols, rows = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    x_img, y_img = (cols - w / 2) * 2 * half / h, (rows - h / 2) * 2 * half / h
    X, Y = 3.0 * x_img.ravel(), -3.0 * y_img.ravel()  # hits on z = 0
    a = np.deg2rad(30.0)
    weft, warp = np.array([np.cos(a), np.sin(a), 0.0]), np.array([-np.sin(a), np.cos(a), 0.0])
    u, v = (X * np.cos(a) + Y * np.sin(a)) / 1.0, (-X * np.sin(a) + Y * np.cos(a)) / 2.0
    wo = np.stack([-X, -Y, np.full_like(X, 3.0)], axis=1)
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    light = LIGHT / np.linalg.norm(LIGHT)
    frame = np.stack([weft, warp, [0.0, 0.0, 1.0]])
    wi_f, wo_f = np.broadcast_to(frame @ light, wo.shape), wo @ frame.T
    fabric = FabricModels.build(scene.fabric)
    texture = IrawanTexture(fabric.weave, seed=0)
    expected = combine(texture.components(u, v, wi_f, wo_f, fabric.params), fabric.coefficients)
    expected = (expected * 2.0 * wi_f[:, 2:3]).reshape(h, w, -1)
    assert np.any(expected[..., 0] > 2 * expected[..., 0].min())  # the view shows highlight structure
    for shader in ("im-texture", "im-lod"):
        result = render(scene, shader=shader)
        np.testing.assert_allclose(result.image, expected, rtol=1e-9, atol=1e-12)
        assert result.stats["texture_pixel_fraction"] == 1.0
    assert result.stats["footprint_max_tiles"] < scene.lod.f0
    assert result.stats["reflectance_evaluations"] == 0


def test_far_lod_is_the_reflectance_model_and_never_runs_the_texture_model(monkeypatch):
    scene = oblique(3000.0)
    reflectance = render(scene, shader="im-reflectance", spp=4)

    def forbidden(*args, **kwargs):
        raise AssertionError("the texture model ran in a far view")

    monkeypatch.setattr(IrawanTexture, "components", forbidden)
    lod = render(scene, shader="im-lod", spp=4)
    assert lod.stats["footprint_min_tiles"] > scene.lod.f1
    assert lod.stats["texture_evaluations"] == 0 and lod.stats["texture_pixel_fraction"] == 0.0
    assert lod.stats["reflectance_evaluations"] == lod.stats["shaded_pixels"]  # once per pixel
    np.testing.assert_array_equal(lod.image, reflectance.image)
    assert lod.image.min() > 0.0


def test_a_zero_coefficient_or_missing_yarn_type_is_not_computed(monkeypatch):
    seen = []
    original = IrawanTexture.components

    def spy(self, *args, need=None, **kwargs):
        seen.append(tuple(need))
        return original(self, *args, need=need, **kwargs)

    monkeypatch.setattr(IrawanTexture, "components", spy)
    scene = head_on(resolution=(4, 3), coefficients={"kd": [0.2, 0.2, 0.2], "ks_warp": [0.3, 0.2, 0.1],
                                                     "ks_weft": [0, 0, 0]})
    render(scene, shader="im-texture")
    assert seen == [("diffuse", "specular_warp")]


def test_blend_is_continuous_in_distance():
    """A 1-pixel camera looking at one fixed surface point from a receding position: the pixel value
    moves from the texture value to the reflectance value with no jump at f0 or f1."""
    scene = oblique(1.0, resolution=(1, 1), fov=1.0)
    fabric = FabricModels.build(scene.fabric)
    values, footprints = [], []
    for d in np.geomspace(1.0, 100.0, 300):
        s = scene.__class__(**{**scene.__dict__, "camera": scene.camera.at_distance(d)})
        result = render(s, shader="im-lod", fabric=fabric)
        values.append(result.image[0, 0, 2])
        footprints.append(result.stats["footprint_min_tiles"])
    values, footprints = np.array(values), np.array(footprints)
    assert footprints[0] < scene.lod.f0 / 2 and footprints[-1] > 2 * scene.lod.f1
    texture = render(scene, shader="im-texture", fabric=fabric).image[0, 0, 2]
    reflectance = render(scene, shader="im-reflectance", fabric=fabric).image[0, 0, 2]
    gap = abs(texture - reflectance)
    assert gap > 0.1 * reflectance  # the two models differ here, so a jump would show
    assert values[0] == pytest.approx(texture, rel=1e-12) and values[-1] == pytest.approx(reflectance, rel=1e-12)
    assert np.max(np.abs(np.diff(values))) < 0.03 * gap
    # the weight itself: 0 / 1 at the thresholds, continuous across them
    f0, f1 = scene.lod.f0, scene.lod.f1
    eps = 1e-9
    assert lod_weight(f0, f0, f1) == 0.0 and lod_weight(f1, f0, f1) == 1.0
    assert lod_weight(f0 * (1 + eps), f0, f1) < 1e-12 and lod_weight(f1 * (1 - eps), f0, f1) > 1 - 1e-12


def test_supersampled_texture_converges_to_the_reflectance_model_far_away():
    scene = oblique(2000.0)
    reflectance = render(scene, shader="im-reflectance").image
    errors = {}
    for spp in (4, 64):
        texture = render(scene, shader="im-texture", spp=spp).image
        errors[spp] = np.abs(texture - reflectance).sum() / reflectance.sum()
        mean_error = abs(texture.mean() - reflectance.mean()) / reflectance.mean()
    assert errors[64] < errors[4] and errors[64] < 0.08
    assert mean_error < 0.01


def test_compare_lod_reports_time_error_and_texture_use_by_distance():
    scene = receding_plane_scene((16, 12))
    rows = compare_lod(scene, [10.0, 1000.0], shaders=("im-lod", "im-texture"), spp=4, reference_spp=16)
    near, far = rows
    assert near["im-lod"]["texture_pixel_fraction"] > 0.5 and far["im-lod"]["texture_evaluations"] == 0
    assert far["im-lod"]["relative_error"] < far["im-texture"]["relative_error"]
    assert all(np.isfinite(r[s]["seconds"]) for r in rows for s in ("im-lod", "im-texture"))


def test_kang_lod_equals_full_detail_below_one_fibre_ridge_and_differs_far():
    near = head_on(height=0.25, resolution=(6, 4))
    lod, full = render(near, shader="kang-lod"), render(near, shader="kang-texture")
    # eq. 5: alpha = 0 while footprint * cells * N_xi <= 1 (6 cells, N_xi = 6 by default)
    assert lod.stats["footprint_max_tiles"] * 6 * 6 <= 1.0
    np.testing.assert_array_equal(lod.image, full.image)
    assert lod.stats["kang_evaluations"] == lod.stats["shaded_samples"] > 0
    far = oblique(3000.0, resolution=(4, 3))
    assert not np.allclose(render(far, shader="kang-lod").image, render(far, shader="kang-texture").image)


def test_cylinder_hits_normals_and_texture_coordinates():
    patch = Patch(shape="cylinder", size_mm=(30.0, 10.0), center=(0.0, 0.0, 0.0), tile_mm=(2.0, 1.0),
                  radius_mm=10.0)
    surface = make_surface(patch)
    theta = np.array([-0.5, 0.0, 0.8, 1.6])  # the last is outside the 30 mm arc (|r theta| > 15)
    x = 10.0 * np.sin(theta)
    origins_z = 50.0
    hits = [surface.intersect(np.array([xi, 2.0, origins_z]), np.array([[0.0, 0.0, -1.0]])) for xi in x]
    assert [bool(h.hit[0]) for h in hits] == [True, True, True, False]
    for h, t in zip(hits[:3], theta[:3], strict=True):
        np.testing.assert_allclose(h.normal[0], [np.sin(t), 0.0, np.cos(t)], atol=1e-12)
        np.testing.assert_allclose(h.position[0], [10 * np.sin(t), 2.0, 10 * np.cos(t)], atol=1e-9)
        assert h.u[0] == pytest.approx(10.0 * t / 2.0) and h.v[0] == pytest.approx(2.0)
        np.testing.assert_allclose(np.cross(h.weft[0], h.warp[0]), h.normal[0], atol=1e-12)


def test_cylinder_scene_lit_from_below_is_black():
    """The patch spans |theta| <= 1.5 rad, so every normal has n_z > 0: light from straight below is
    back-facing everywhere (black), light from above lights it."""
    def scene(direction):
        return scene_from_dict({
            "patch": {"shape": "cylinder", "size_mm": [30, 20], "radius_mm": 10, "tile_mm": 1.0},
            "camera": {"position": [0, -40, 40], "look_at": [0, 0, 10], "fov_deg": 20,
                       "resolution": [16, 12]},
            "light": {"type": "directional", "direction": direction},
        })

    above, below = render(scene([0, 0, 1]), shader="im-lod"), render(scene([0, 0, -1]), shader="im-lod")
    assert above.stats["covered_pixels"] == below.stats["covered_pixels"] > 50
    assert above.image.max() > 0.0 and below.image.max() == 0.0 and below.stats["shaded_samples"] == 0


@pytest.mark.parametrize("change, field", [
    ({"camera": {"position": [0, 0, 10], "fov_deg": -5}}, "camera.fov_deg"),
    ({"camera": {"position": [0, 0, 10], "resolution": [16]}}, "camera.resolution"),
    ({"camera": {"position": [0, 0, 10], "up": [0, 0, 1]}}, "camera.up"),
    ({"camera": {"look_at": [0, 0, 0]}}, "camera.position"),
    ({"light": {"type": "spot"}}, "light.type"),
    ({"light": {"type": "point"}}, "light.position"),
    ({"patch": {"size_mm": [10, 10]}}, "patch.tile_mm"),
    ({"patch": {"size_mm": [10, 10], "tile_mm": 1, "shape": "cylinder"}}, "patch.radius_mm"),
    ({"patch": {"size_mm": [10, -1], "tile_mm": 1}}, "patch.size_mm"),
    ({"patch": {"size_mm": [10, 10], "tile_mm": 1, "colour": "red"}}, "patch.colour"),
    ({"lod": {"f0": 0.5, "f1": 0.2}}, "lod.f1"),
    ({"render": {"spp": 0}}, "render.spp"),
    ({"fabric": {"coefficients": {"kd": "blue"}}}, "fabric.coefficients.kd"),
    ({"fabric": {"fit": "no/such/dir"}}, "fabric.fit"),
])
def test_scene_errors_name_the_field(tmp_path, change, field):
    import yaml

    data = {"patch": {"size_mm": [10, 10], "tile_mm": 1}, "camera": {"position": [0, -10, 10]},
            "light": {"direction": [0, 0, 1]}}
    data.update(change)
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError) as info:
        load_scene(path)
    assert info.value.field == field and str(path) in str(info.value)


def test_unknown_preset_and_bad_yaml_are_clear(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text("patch: [unclosed\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_scene(path)
    scene = scene_from_dict({"patch": {"size_mm": [10, 10], "tile_mm": 1}, "camera": {"position": [0, -5, 5]},
                             "light": {"direction": [0, 0, 1]}, "fabric": {"weave": "preset:burlap"}})
    with pytest.raises(ConfigError, match="unknown weave preset"):
        render(scene)
    with pytest.raises(ConfigError, match="unknown shader"):
        render(scene, shader="phong")


def test_example_scene_file_is_the_benchmark_scene():
    example = load_scene(REPO / "measurements" / "scenes" / "receding_plane.yaml")
    bench = receding_plane_scene()
    assert (example.patch, example.camera, example.light, example.lod, example.spp) == (
        bench.patch, bench.camera, bench.light, bench.lod, bench.spp)


@pytest.mark.parametrize("pixel_type, rtol", [("float", 1e-6), ("half", 1e-3)])
def test_saved_exr_round_trips_and_png_is_srgb(tmp_path, pixel_type, rtol):
    from clothlab.btf.images import read_image

    result = render(head_on(resolution=(8, 6)), shader="im-texture")
    exr, png = save_render(result, tmp_path / "out" / "view", pixel_type=pixel_type, exposure=1.0)
    back, info = read_image(exr)
    assert info.channel_names == ("R", "G", "B") and back.shape == result.image.shape
    np.testing.assert_allclose(back, result.image, rtol=rtol, atol=1e-7)
    encoded, _ = read_image(png, encoding="linear")  # the stored codes / 255
    linear = np.clip(result.image * 2.0, 0, 1)
    srgb = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)
    np.testing.assert_allclose(encoded, srgb, atol=0.51 / 255)
    with pytest.raises(ResultExistsError):
        save_render(result, tmp_path / "out" / "view")
    save_render(result, tmp_path / "out" / "view", force=True)
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["view.exr", "view.png"]  # no temp files


def test_render_to_files_writes_and_refuses_to_overwrite(tmp_path, capsys):
    import yaml

    scene = tmp_path / "scene.yaml"
    scene.write_text(yaml.safe_dump({"patch": {"size_mm": [40, 40], "tile_mm": [1, 2]},
                                     "camera": {"position": [0, -20, 20], "resolution": [8, 6]},
                                     "light": {"direction": [0, 0, 1]}, "render": {"spp": 1}}))
    result, exr, png = render_to_files(scene, tmp_path / "r", "im-lod", 2, False)
    assert (exr, png) == (tmp_path / "r.exr", tmp_path / "r.png") and exr.is_file() and png.is_file()
    assert result.spp == 2 and result.image.shape[:2] == (6, 8)
    assert capsys.readouterr().out == ""  # the CLI prints, the renderer returns
    with pytest.raises(ResultExistsError):
        render_to_files(scene, tmp_path / "r", "im-lod", 2, False)
    assert render_to_files(scene, tmp_path / "r", "kang-lod", 1, True)[0].shader == "kang-lod"


def test_blend_pixels_evaluate_reflectance_once_and_texture_at_a_share_of_their_samples():
    """In the blend range a pixel evaluates the reflectance model once (not at every sample) and the texture
    model at ceil(sum (1 - b)) of its samples, weighted so that its total texture weight is the full
    blend's; pixels wholly in the texture range keep every sample at weight 1."""
    from clothlab.render.shade import blend_texture_samples

    rng = np.random.default_rng(3)
    for spp in (1, 4, 9):
        pixel = np.repeat(np.arange(200), spp)
        b = np.clip(rng.uniform(-0.3, 1.3, pixel.size), 0.0, 1.0)
        b[pixel < 20] = 0.0  # texture-range pixels
        perm = rng.permutation(pixel.size)  # the order of the samples does not matter
        index, weight = blend_texture_samples(pixel[perm], b[perm])
        p, bb = pixel[perm], b[perm]
        texture_range = bb < 1.0
        full = np.bincount(p[texture_range], 1.0 - bb[texture_range], minlength=200)
        np.testing.assert_allclose(np.bincount(p[index], weight, minlength=200), full, atol=1e-12)
        counts = np.bincount(p[index], minlength=200)
        m = np.bincount(p[texture_range], minlength=200)
        np.testing.assert_array_equal(counts, np.where(m > 0, np.clip(np.ceil(full - 1e-9), 1, m), 0))
        assert np.all(bb[index] < 1.0)
        assert np.all(weight[p[index] < 20] == 1.0) and np.all(counts[:20] == spp)

    scene = oblique(6.0, resolution=(16, 12))  # footprints inside (f0, f1): every pixel blends
    lod = render(scene, shader="im-lod", spp=4)
    s = lod.stats
    assert scene.lod.f0 < s["footprint_min_tiles"] and s["footprint_max_tiles"] < scene.lod.f1
    assert s["blend_pixel_fraction"] == 1.0
    assert s["reflectance_evaluations"] == s["shaded_pixels"]
    assert s["texture_evaluations"] < s["shaded_samples"]
    reference = render(scene, shader="im-texture", spp=64).image
    texture = render(scene, shader="im-texture", spp=4).image
    assert np.abs(lod.image - reference).sum() / reference.sum() < 0.15
    assert abs(lod.image.mean() - texture.mean()) / texture.mean() < 0.05


def test_receding_plane_error_bound_and_monotone_cost_at_a_tiny_resolution(tmp_path):
    """The benchmark's statements on a 16 x 12 image: the LoD error within ERROR_BOUND at every distance;
    from the first distance with no pixel in the texture range on, the model evaluations per image never
    increase; beyond f1 one reflectance evaluation per pixel; flat rows of scalars; the plot is written."""
    from clothlab.studies.render_lod import ERROR_BOUND, render_benchmark

    distances = (1.0, 2.0, 3.0, 4.0, 6.0, 8.0, 16.0, 64.0, 256.0)
    result = render_benchmark(resolution=(16, 12), distances=distances, reference_spp=16, repeats=1,
                              shaders=("im-lod", "im-texture", "kang-lod", "kang-texture"),
                              figures_dir=tmp_path)
    rows, f0, f1 = result["rows"], result["settings"]["lod_f0_tiles"], result["settings"]["lod_f1_tiles"]
    assert [r["distance_mm"] for r in rows] == list(distances)
    assert all(not isinstance(v, dict | list) for r in rows for v in r.values())  # shown on the HTML page
    errors = [r["im_lod_relative_error"] for r in rows]
    assert max(errors) <= ERROR_BOUND and result["within_bound"] is True
    cost = [r["im_lod_model_evaluations"] for r in rows]
    assert rows[0]["footprint_max_tiles"] < f0 and rows[0]["im_lod_reflectance_evaluations"] == 0  # texture only
    start = next(i for i, r in enumerate(rows) if r["footprint_min_tiles"] > f0)
    assert 0 < start < len(rows) - 3 and result["trend"]["trend_from_mm"] == distances[start]
    assert all(cost[i + 1] <= cost[i] for i in range(start, len(rows) - 1))
    assert cost[-1] < cost[start] and cost[-1] * 4 == rows[-1]["im_texture_model_evaluations"]
    # blend pixels are cheap: the cost falls across the blend range itself, below always-texture's by 6 mm
    # (footprints 0.21..0.37 tile), not only where the reflectance model takes over
    mid = distances.index(6.0)
    assert rows[mid]["footprint_max_tiles"] < f1 and cost[mid] < cost[start]
    assert all(cost[i] < rows[i]["im_texture_model_evaluations"] for i in range(mid, len(rows)))
    for r in rows:
        assert r["im_texture_model_evaluations"] == r["im_texture_texture_evaluations"] == 4 * 16 * 12
        if r["footprint_min_tiles"] >= f1:
            assert r["im_lod_texture_evaluations"] == 0 and r["im_lod_reflectance_evaluations"] == 16 * 12
    assert result["lod_cost_falls"] is True
    # the counts are deterministic: a second run gives the same
    again = render_benchmark(resolution=(16, 12), distances=distances[:4], reference_spp=4, repeats=1,
                             shaders=("im-lod", "im-texture"))
    assert [r["im_lod_model_evaluations"] for r in again["rows"]] == cost[:4]
    assert (tmp_path / "render_lod.png").read_bytes()[:4] == b"\x89PNG" and result["figure"].endswith("render_lod.png")


def test_fabric_fits_are_checked_by_texture_capability():
    """fabric.fit needs a model whose texture the im-* shaders blend with its reflectance; fabric.kang.fit one
    whose texture takes the pixel footprint.  Each refusal names the field and the fit's kind."""
    from clothlab.render.scene import Fabric, KangSpec

    fits = REPO / "fits"
    for fit, field, kind in ((fits / "polyester-lining-oren-nayar", "fabric.fit", "oren-nayar"),
                             (fits / "polyester-lining-kang", "fabric.fit", "kang")):
        with pytest.raises(ConfigError, match=f"of kind '{kind}'") as info:
            FabricModels.build(Fabric(fit=fit))
        assert info.value.field == field
    fabric = FabricModels.build(Fabric(fit=fits / "polyester-lining"))
    assert fabric.reflectance.kind == "irawan" and fabric.need
    fabric.spec = Fabric(fit=fits / "polyester-lining", kang=KangSpec(fit=fits / "polyester-lining"))
    with pytest.raises(ConfigError, match="of kind 'irawan'") as info:
        fabric.kang()
    assert info.value.field == "fabric.kang.fit"


def test_an_spp_override_is_memory_checked_before_any_work(tmp_path):
    """`render --spp N` is held to the same memory bound as the scene's own render.spp (issue 11): the
    estimate is refused with the option to change, before a sample is drawn or a file is written."""
    import yaml

    from clothlab.errors import ConfigError
    from clothlab.render.scene import MAX_RENDER_BYTES, render_bytes

    scene = tmp_path / "scene.yaml"
    scene.write_text(yaml.safe_dump({"patch": {"size_mm": [40, 40], "tile_mm": [1, 2]},
                                     "camera": {"position": [0, -20, 20], "resolution": [64, 48]},
                                     "light": {"direction": [0, 0, 1]}, "render": {"spp": 1}}))
    too_many = MAX_RENDER_BYTES // render_bytes((64, 48), 1) + 1
    with pytest.raises(ConfigError, match=r"--spp") as info:
        render_to_files(scene, tmp_path / "r", "im-lod", int(too_many), False)
    assert str(scene) in str(info.value)
    assert not list(tmp_path.glob("r.*"))
