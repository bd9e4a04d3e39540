"""The neural-lod shader's documented default (clothlab.render.shade; a network whose sidecar has no
estimator_choice): texture model where the pixel resolves the yarns, the
shipped network once per pixel between ~0.12 and ~0.5 tile (im-lod elsewhere), the reflectance model beyond;
checked on a
head-on view of silk shantung at three heights against the other shaders and against the network queried
by hand."""

import numpy as np
import pytest

from clothlab.models.components import combine
from clothlab.models.irawan.texture import IrawanTexture
from clothlab.models.neural.model import NeuralModel
from clothlab.render import render, scene_from_dict
from clothlab.render.shade import NEURAL_FALL, NEURAL_RISE, FabricModels, network_weight

LIGHT = [0.3, -0.2, 1.0]


@pytest.fixture(autouse=True)
def documented_default(monkeypatch):
    """These tests check neural-lod's documented default, what a network without measured crossovers gets
    (the shipped sidecars carry them: tests/test_neural_estimator_choice.py checks that policy)."""
    import clothlab.render.neural_lod as policy

    monkeypatch.setattr(policy, "estimator_choice", lambda weave: None)


def head_on_dict(height, resolution=(8, 6), fov=20.0):
    return {
        "patch": {"size_mm": [4000, 4000], "tile_mm": [1.0, 2.0], "warp_angle_deg": 30.0},
        "camera": {"position": [0, 0, height], "look_at": [0, 0, 0], "up": [0, 1, 0], "fov_deg": fov,
                   "resolution": list(resolution)},
        "light": {"type": "directional", "direction": LIGHT, "intensity": 2.0},
        "fabric": {"weave": "preset:silk-shantung"},
    }


def head_on(height, resolution=(8, 6), fov=20.0):
    return scene_from_dict(head_on_dict(height, resolution, fov))


def test_near_is_the_texture_model_and_far_the_reflectance_model(monkeypatch):
    near = head_on(0.3)
    lod = render(near, shader="neural-lod", spp=4)
    assert lod.stats["footprint_max_tiles"] < NEURAL_RISE[0]
    np.testing.assert_array_equal(lod.image, render(near, shader="im-texture", spp=4).image)
    assert lod.stats["neural_evaluations"] == 0 and lod.stats["texture_pixel_fraction"] == 1.0

    def forbidden(*args, **kwargs):
        raise AssertionError("a model ran outside its footprint range")

    far = head_on(400.0)
    reflectance = render(far, shader="im-reflectance", spp=4)
    monkeypatch.setattr(IrawanTexture, "components", forbidden)
    monkeypatch.setattr(NeuralModel, "query", forbidden)
    lod = render(far, shader="neural-lod", spp=4)
    assert lod.stats["footprint_min_tiles"] > NEURAL_FALL[1]
    np.testing.assert_array_equal(lod.image, reflectance.image)


def test_between_it_is_one_network_query_per_pixel_for_the_pixel_footprint(monkeypatch):
    """Footprints inside the network's range: no texture sample; one query per pixel at the pixel's centre,
    with the pixel footprint and the reflectance model's components at its directions as the residual base;
    the image is that query's f_r times E cos(theta_i) (flat patch, directional light), the same at 4 spp as
    at 1 (where the one sample is the centre)."""
    scene = head_on(5.5)  # pixel footprints ~0.29 tile
    calls = []
    original = NeuralModel.query

    def spy(self, centre, size, wi, wo, params=None, *, reference=None):
        out = original(self, centre, size, wi, wo, params, reference=reference)
        calls.append((np.array(centre), np.array(size), np.array(wi), np.array(wo), reference, out))
        return out

    def forbidden(*args, **kwargs):
        raise AssertionError("the texture model ran")

    monkeypatch.setattr(NeuralModel, "query", spy)
    monkeypatch.setattr(IrawanTexture, "components", forbidden)
    result = render(scene, shader="neural-lod", spp=4)
    lo, hi = result.stats["footprint_min_tiles"], result.stats["footprint_max_tiles"]
    assert NEURAL_RISE[1] < lo and hi < NEURAL_FALL[0]
    (centre, size, wi, wo, reference, out), = calls
    h, w = scene.camera.resolution[1], scene.camera.resolution[0]
    assert len(centre) == h * w == result.stats["neural_evaluations"]
    assert np.all((size >= lo) & (size <= hi))
    fabric = FabricModels.build(scene.fabric)
    exact = fabric.reflectance.components(wi, wo, fabric.params)
    np.testing.assert_allclose(reference, np.column_stack([exact[k] for k in fabric.reflectance.component_names]),
                               rtol=1e-12)
    expected = combine(out, fabric.coefficients) * 2.0 * wi[:, 2:3]
    np.testing.assert_allclose(result.image.reshape(h * w, -1), expected, rtol=1e-12)
    assert np.ptp(centre[:, 0]) > 0.5  # the pixels look at different places of the tile
    one = render(scene, shader="neural-lod", spp=1)  # one sample, at the pixel's centre: the same query
    np.testing.assert_allclose(one.image, result.image, rtol=1e-12)
    assert one.image.min() > 0.0


@pytest.mark.parametrize("height", [5.23, 16.88])  # footprints ~0.139 / ~0.447 tile: mid-rise / mid-fall
def test_in_the_transition_bands_a_share_w_of_the_pixels_is_the_networks_and_the_rest_im_lods(height,
                                                                                                monkeypatch):
    """Head-on view: every pixel has the same footprint f, hence the same network weight w (0 < w < 1).  Each
    pixel of neural-lod is exactly im-lod's or the network's (rendered alone), and the network's share of the
    pixels is w (the dither is evenly spread)."""
    import clothlab.render.shade as shade

    scene = head_on(height, resolution=(16, 12))
    im_lod = render(scene, shader="im-lod", spp=4)
    f = im_lod.stats["footprint_min_tiles"]
    w = float(network_weight(np.array([f]))[0])
    assert 0.3 < w < 0.7 and im_lod.stats["footprint_max_tiles"] < 1.001 * f
    mixed = render(scene, shader="neural-lod", spp=4)
    monkeypatch.setattr(shade, "network_weight", lambda footprint: np.ones_like(footprint))
    network = render(scene, shader="neural-lod", spp=4)
    # (the float32 decoder's products may round differently in another batch size: rtol 1e-5)
    is_network = np.all(np.isclose(mixed.image, network.image, rtol=1e-5, atol=0.0), axis=-1)
    is_im_lod = np.all(np.isclose(mixed.image, im_lod.image, rtol=1e-5, atol=0.0), axis=-1)
    assert np.all(is_network | is_im_lod) and not np.any(is_network & is_im_lod)
    assert abs(is_network.mean() - w) < 0.03
    assert mixed.stats["neural_evaluations"] == is_network.sum()


def test_neural_lod_needs_the_weaves_network():
    from clothlab.errors import ConfigError

    scene = scene_from_dict({
        "patch": {"size_mm": [100, 100], "tile_mm": [1.0, 2.0]},
        "camera": {"position": [0, 0, 2.0], "look_at": [0, 0, 0], "up": [0, 1, 0], "fov_deg": 20,
                   "resolution": [4, 3]},  # pixel footprints ~0.25 tile: the network's range
        "light": {"type": "directional", "direction": LIGHT},
        "fabric": {"weave": "pattern:plain"},
    })
    with pytest.raises(ConfigError, match="shipped"):
        render(scene, shader="neural-lod")


def test_neural_lod_benchmark_rows_compare_error_at_equal_shading_cpu(tmp_path):
    """The bench's neural-lod table: per view im-lod is run at square spp counts until its shading CPU reaches
    neural-lod's; the equal-CPU error is at most the error of every im-lod row that costs no more than
    neural-lod, and the verdict follows it; near and far (the documented default: im-lod there) the images
    agree ("same")."""
    from clothlab.studies.render_lod import EQUAL_CPU_SPP, TIE, neural_lod_benchmark, neural_lod_lines

    f = neural_lod_benchmark(True, figures_dir=tmp_path, resolution=(8, 6), distances=(0.8, 3.5, 640.0),
                             reference_spp=4, repeats=1)
    near, mid, far = f["rows"]
    assert not f["settings"]["noise"] and not f["settings"]["estimator_choice"]
    for r in f["rows"]:
        assert r["im_reference_error"] > 0.0  # two references from different seeds differ
        sweep, t = r["im_lod_sweep"], r["neural_lod_shading_cpu_seconds"]
        assert [k["spp"] for k in sweep] == list(EQUAL_CPU_SPP[:len(sweep)])
        assert sweep[-1]["shading_cpu_s"] >= t or len(sweep) == len(EQUAL_CPU_SPP)
        assert all(k["shading_cpu_s"] < t for k in sweep[1:-1])  # it stopped at the first that reached it
        assert r["equal_time_relative_error"] <= min([k["relative_error"] for k in sweep if k["shading_cpu_s"] <= t]
                                                     or [np.inf]) + 1e-15
        assert r["equal_time_relative_error"] >= min(k["relative_error"] for k in sweep) - 1e-15
        if r["verdict"] != "same":
            e_n, e_i = r["neural_lod_relative_error"], r["equal_time_relative_error"]
            assert r["verdict"] == ("tie" if abs(e_n - e_i) <= TIE * e_i else "better" if e_n < e_i else "worse")
    # near and far both shaders are the same model (texture / reflectance): the same image, the same error
    for r in (near, far):
        assert r["verdict"] == "same" and r["neural_lod_neural_evaluations"] == 0
        assert r["neural_lod_relative_error"] == pytest.approx(r["im_lod_relative_error"], rel=1e-9)
    assert mid["neural_lod_neural_evaluations"] > 0 and f["network_used_mm"] == [3.5] == f["differs_mm"]
    assert (tmp_path / "neural_lod.png").stat().st_size > 0 and "neural-lod" in "\n".join(neural_lod_lines(f))


def test_im_lods_error_at_equal_cpu_is_its_lower_envelope_interpolated_log_log():
    """error_at_cpu: a power law e = 0.2 t^-0.5 is recovered exactly between its rows; a row dearer but worse
    than a cheaper one does not count (a larger budget can buy the cheaper spp); outside the rows, the
    nearest row with a note."""
    from clothlab.studies.render_lod import error_at_cpu

    t = np.array([0.01, 0.04, 0.16, 0.64])
    e = 0.2 * t ** -0.5
    for x in (0.02, 0.1, 0.5):
        assert error_at_cpu(t[::-1], e[::-1], x) == (pytest.approx(0.2 * x ** -0.5, rel=1e-12), "")
    bumpy = e.copy()
    bumpy[2] = 10.0  # the 0.16 s row is worse than the 0.04 s one
    assert error_at_cpu(t, bumpy, 0.16)[0] == pytest.approx(e[1], rel=1e-12)
    assert error_at_cpu(t, e, 0.001) == (pytest.approx(e[0]), "im-lod's cheapest costs more")
    assert error_at_cpu(t, e, 5.0) == (pytest.approx(e[-1]), "im-lod's dearest costs less")


def test_scene_noise_switch_turns_the_texture_noise_off():
    """fabric.noise: false renders the noise-free texture (what the networks learn); a non-boolean is refused
    naming the field."""
    from clothlab.errors import ConfigError

    near = head_on(0.3)
    off = scene_from_dict({**head_on_dict(0.3), "fabric": {"weave": "preset:silk-shantung", "noise": False}})
    on, quiet = render(near, shader="im-texture", spp=1), render(off, shader="im-texture", spp=1)
    fabric = FabricModels.build(off.fabric)
    texture = fabric.texture
    u, v = 0.37, 1.21
    wi, wo = np.array([[0.3, -0.2, 0.93]]), np.array([[0.0, 0.1, 0.99]])
    plain, noisy = (texture.components(u, v, wi, wo, fabric.params, noise=n) for n in (False, True))
    assert any(not np.allclose(plain[k], noisy[k]) for k in plain)  # the noise changes this point
    assert not np.allclose(on.image, quiet.image)
    with pytest.raises(ConfigError, match="fabric.noise"):
        scene_from_dict({**head_on_dict(0.3), "fabric": {"weave": "preset:silk-shantung", "noise": "no"}})


def test_in_its_footprint_range_the_network_beats_im_lod_on_the_noise_free_receding_plane():
    """Pixel footprints 0.25-0.45 tile (the network's range): against the supersampled noise-free texture,
    neural-lod's relative L1 error is below im-lod's (texture / reflectance blend) - the point of the shader
    (bench: the same by distance, with times)."""
    from dataclasses import replace

    from clothlab.render.render import relative_error
    from clothlab.studies.render_lod import receding_plane_scene

    scene = receding_plane_scene((16, 12))
    scene = replace(scene, fabric=replace(scene.fabric, noise=False), camera=scene.camera.at_distance(7.0))
    fabric = FabricModels.build(scene.fabric)
    reference = render(scene, shader="im-texture", spp=64, seed=5, fabric=fabric)
    mask = reference.coverage >= 1.0
    neural = render(scene, shader="neural-lod", spp=4, fabric=fabric)
    im_lod = render(scene, shader="im-lod", spp=4, fabric=fabric)
    assert NEURAL_RISE[0] < neural.stats["footprint_min_tiles"]
    assert neural.stats["footprint_max_tiles"] < NEURAL_FALL[1]
    err_neural = relative_error(neural.image, reference.image, mask)
    err_im = relative_error(im_lod.image, reference.image, mask)
    assert err_neural < 0.8 * err_im, (err_neural, err_im)


def test_forget_directions_drops_the_memos_a_repeated_render_would_reuse():
    """Benchmarks time every render cold: after FabricModels.forget_directions the IM reflectance model keeps
    no direction memo (it would make a repeat of the same view cheaper), and the image is unchanged."""
    scene = head_on(5.5)
    fabric = FabricModels.build(scene.fabric)
    first = render(scene, shader="neural-lod", spp=4, fabric=fabric)
    assert fabric.reflectance._directions is not None
    fabric.forget_directions()
    assert fabric.reflectance._directions is None and not fabric.reflectance._memo
    np.testing.assert_array_equal(render(scene, shader="neural-lod", spp=4, fabric=fabric).image, first.image)
