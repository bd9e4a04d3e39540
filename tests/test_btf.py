"""BTF stacks: names and manifests, image reading with error states, sRGB decoding, period estimation,
unit-tile averaging, the simulated-stack writer round trip and the streaming memory benchmark (quick)."""

from __future__ import annotations

import numpy as np
import pytest

from clothlab.btf import BtfStack, average_tiles, estimate_period, parse_angles, write_btf_stack
from clothlab.btf.images import read_image
from clothlab.btf.period import autocorrelation, lattice_vectors
from clothlab.errors import InputError, ResultExistsError
from clothlab.studies.btf_memory import btf_memory_benchmark

oiio = pytest.importorskip("OpenImageIO")


def _write(path, pixels, pixel_type="uint8"):
    path.parent.mkdir(parents=True, exist_ok=True)
    buf = oiio.ImageBuf(np.ascontiguousarray(pixels))
    assert buf.write(str(path), pixel_type), buf.geterror()
    return path


def _srgb_decode_reference(codes, bits):
    """Independent decoding through colour-science."""
    import colour

    return colour.cctf_decoding(codes / (2**bits - 1), function="sRGB")


# ------------------------------------------------------------------------------------------------ names


def test_parse_angles_bonn_utia_and_decimals():
    assert parse_angles("00008 tl000 pl000 tv030 pv030.jpg") == (0.0, 0.0, 30.0, 30.0)
    assert parse_angles("tl075_pl345_tv060_pv018.exr") == (75.0, 345.0, 60.0, 18.0)
    assert parse_angles("tl022.5_pl007.5_tv000_pv000.exr") == (22.5, 7.5, 0.0, 0.0)
    assert parse_angles("IMG_0001.png") is None


def test_directory_names_bonn_and_utia(tmp_path):
    grey = np.full((8, 8, 3), 128, np.uint8)
    _write(tmp_path / "bonn" / "tv030_pv030" / "00008 tl000 pl000 tv030 pv030.jpg", grey)
    _write(tmp_path / "bonn" / "tv030_pv030" / "00009 tl015 pl120 tv030 pv030.jpg", grey)
    stack = BtfStack.open(tmp_path / "bonn")
    assert sorted(map(tuple, stack.angles.tolist())) == [(0, 0, 30, 30), (15, 120, 30, 30)]
    _write(tmp_path / "utia" / "tv000_pv000" / "tl045_pl020_tv000_pv000.png", grey)
    horizontal = BtfStack.open(tmp_path / "utia", warp_axis="horizontal")
    # image right = warp: the names' azimuth 20 deg from the warp is clothlab 110 deg (from the weft)
    assert horizontal.angles.tolist() == [[45.0, 110.0, 0.0, 90.0]]


@pytest.mark.parametrize("kind", ["yaml", "csv"])
def test_manifest_azimuth_convention(tmp_path, kind):
    grey = np.full((8, 8, 3), 100, np.uint8)
    _write(tmp_path / "a.png", grey)
    _write(tmp_path / "b.png", grey)
    rows = [("a.png", 30, 10, 0, 0), ("b.png", 60, 100, 45, 270)]
    if kind == "yaml":
        text = "warp_axis: vertical\nazimuth: {zero: warp, sense: cw}\nimages:\n" + "".join(
            f"  - {{file: {f}, theta_i: {a}, phi_i: {b}, theta_o: {c}, phi_o: {d}}}\n" for f, a, b, c, d in rows)
        (tmp_path / "manifest.yaml").write_text(text)
    else:
        text = "# azimuth_zero: warp\n# azimuth_sense: cw\nfile,theta_i,phi_i,theta_o,phi_o\n" + "".join(
            f"{f},{a},{b},{c},{d}\n" for f, a, b, c, d in rows)
        (tmp_path / "manifest.csv").write_text(text)
    stack = BtfStack.open(tmp_path)
    # clockwise from the warp (clothlab 90 deg): phi_clothlab = 90 - phi
    expected = [[30, 80, 0, 90], [60, 350, 45, 180]]
    np.testing.assert_allclose(stack.angles, expected)


# ------------------------------------------------------------------------------------------------ errors


def test_unparsable_name_names_the_file(tmp_path):
    _write(tmp_path / "tv000_pv000" / "tl000_pl000_tv000_pv000.png", np.zeros((4, 4, 3), np.uint8))
    _write(tmp_path / "tv000_pv000" / "photo_7.png", np.zeros((4, 4, 3), np.uint8))
    with pytest.raises(InputError, match="photo_7.png.*angles"):
        BtfStack.open(tmp_path)


def test_missing_image_in_manifest_names_the_file(tmp_path):
    _write(tmp_path / "a.png", np.zeros((4, 4, 3), np.uint8))
    (tmp_path / "manifest.csv").write_text("file,theta_i,phi_i,theta_o,phi_o\na.png,0,0,0,0\ngone.png,30,0,0,0\n")
    with pytest.raises(InputError, match="gone.png.*not found"):
        BtfStack.open(tmp_path)


def _grid(root, views, lights, naming="utia"):
    grey = np.full((4, 4, 3), 90, np.uint8)
    paths = []
    for k, (tv, pv) in enumerate(views):
        for j, (tl, pl) in enumerate(lights):
            if naming == "utia":
                name = f"tv{tv:03d}_pv{pv:03d}/tl{tl:03d}_pl{pl:03d}_tv{tv:03d}_pv{pv:03d}.png"
            else:
                index = k * len(lights) + j
                name = f"tv{tv:03d}_pv{pv:03d}/{index:05d} tl{tl:03d} pl{pl:03d} tv{tv:03d} pv{pv:03d}.png"
            paths.append(_write(root / name, grey))
    return paths


LIGHTS3 = [(0, 0), (30, 60), (60, 120)]
VIEWS2 = [(0, 0), (30, 90)]


def test_missing_image_in_a_name_based_grid_names_the_expected_file(tmp_path):
    paths = _grid(tmp_path / "utia", VIEWS2, LIGHTS3)
    assert len(BtfStack.open(tmp_path / "utia")) == 6  # complete: opens
    paths[4].unlink()  # view (30, 90), light (30, 60)
    with pytest.raises(InputError) as info:
        BtfStack.open(tmp_path / "utia")
    expected = tmp_path / "utia" / "tv030_pv090" / "tl030_pl060_tv030_pv090.png"
    assert info.value.path == str(expected) and "missing image" in str(info.value)
    assert "tv030_pv090/tl030_pl060_tv030_pv090.png" in str(info.value) and "2-view x 3-light" in str(info.value)
    # a scattered sampling is allowed where asked for (or with a manifest)
    assert len(BtfStack.open(tmp_path / "utia", grid=False)) == 5


def test_missing_bonn_image_and_missing_view_directory(tmp_path):
    paths = _grid(tmp_path / "bonn", VIEWS2, LIGHTS3, naming="bonn")
    paths[2].unlink()  # view (0, 0), light (60, 120): the Bonn index is not known, shown as #####
    with pytest.raises(InputError, match=r"tv000_pv000/##### tl060 pl120 tv000 pv000\.png"):
        BtfStack.open(tmp_path / "bonn")
    # and a view with no image at all, in a stack that claims the full 81 x 81 sampling (> half of it)
    from clothlab.btf.names import check_grid, utia_directions

    grid = utia_directions()
    assert len(grid) == 81 and len(set(grid)) == 81
    root = tmp_path / "full"
    raw = [(root / f"tv{tv:03.0f}_pv{pv:03.0f}" / f"tl{tl:03.0f}_pl{pl:03.0f}_tv{tv:03.0f}_pv{pv:03.0f}.png",
            (tl, pl, tv, pv)) for tv, pv in grid for tl, pl in grid]
    check_grid(root, raw)  # complete
    gone = (75.0, 165.0)
    partial = [r for r in raw if r[1][2:] != gone]
    with pytest.raises(InputError, match="81 x 81") as info:
        check_grid(root, partial)
    assert info.value.path == str(root / "tv075_pv165" / "tl000_pl000_tv075_pv165.png")
    assert "80 more image(s) missing" in str(info.value)
    # a few complete views of the database are a grid of their own
    check_grid(root, [r for r in raw if r[1][2:] in grid[:3]])


def test_inconsistent_sizes_and_channels(tmp_path):
    _write(tmp_path / "s" / "tl000_pl000_tv000_pv000.png", np.zeros((8, 8, 3), np.uint8))
    _write(tmp_path / "s" / "tl030_pl000_tv000_pv000.png", np.zeros((8, 9, 3), np.uint8))
    with pytest.raises(InputError, match=r"tl030_pl000_tv000_pv000.png.*9 x 8 px"):
        BtfStack.open(tmp_path / "s")
    _write(tmp_path / "c" / "tl000_pl000_tv000_pv000.png", np.zeros((8, 8, 3), np.uint8))
    _write(tmp_path / "c" / "tl030_pl000_tv000_pv000.png", np.zeros((8, 8, 4), np.uint8))
    with pytest.raises(InputError, match=r"tl030_pl000_tv000_pv000.png.*4 channel"):
        BtfStack.open(tmp_path / "c")


def test_duplicate_angle_sets(tmp_path):
    _write(tmp_path / "tv030_pv030" / "00001 tl000 pl000 tv030 pv030.png", np.zeros((4, 4, 3), np.uint8))
    _write(tmp_path / "tv030_pv030" / "00002 tl000 pl000 tv030 pv030.png", np.zeros((4, 4, 3), np.uint8))
    with pytest.raises(InputError, match="duplicate angle set"):
        BtfStack.open(tmp_path)


def test_corrupt_file_names_the_file(tmp_path):
    _write(tmp_path / "tl000_pl000_tv000_pv000.png", np.zeros((4, 4, 3), np.uint8))
    (tmp_path / "tl030_pl000_tv000_pv000.png").write_bytes(b"this is not an image" * 10)
    with pytest.raises(InputError, match="tl030_pl000_tv000_pv000.png.*cannot open"):
        BtfStack.open(tmp_path)


@pytest.mark.parametrize("suffix,pixel_type", [(".png", "uint8"), (".exr", "half"), (".jpg", "uint8")])
def test_truncated_file_is_an_error_even_if_pixels_come_back(tmp_path, suffix, pixel_type):
    rng = np.random.default_rng(3)
    pixels = rng.random((64, 64, 3)).astype(np.float32)
    if pixel_type == "uint8":
        pixels = (pixels * 255).astype(np.uint8)
    good = _write(tmp_path / f"tl000_pl000_tv000_pv000{suffix}", pixels, pixel_type)
    bad = tmp_path / f"tl030_pl000_tv000_pv000{suffix}"
    data = good.read_bytes()
    bad.write_bytes(data[: int(len(data) * 0.6)])
    if suffix == ".jpg":  # the property the check guards against: the reader still returns pixels
        inp = oiio.ImageInput.open(str(bad))
        assert inp.read_image("float") is not None
        inp.geterror()
        inp.close()
    stack = BtfStack.open(tmp_path)  # the header alone reads fine
    index = [e.path for e in stack.entries].index(bad)
    with pytest.raises(InputError, match=r"tl030_pl000_tv000_pv000.*(truncated or corrupt)"):
        stack.image(index)
    with pytest.raises(InputError, match="tl030_pl000_tv000_pv000"):
        stack.tile_averages(period=(8, 8))


# ------------------------------------------------------------------------------------------- decoding


def test_srgb_decoding_8_and_16_bit_and_linear_exr(tmp_path):
    codes8 = np.arange(256, dtype=np.uint8).reshape(16, 16, 1).repeat(3, axis=2)
    out, _ = read_image(_write(tmp_path / "a.png", codes8))
    np.testing.assert_allclose(out, _srgb_decode_reference(codes8.astype(float), 8), atol=2e-7)
    codes16 = (np.arange(256, dtype=np.uint16) * 257 + 3).reshape(16, 16, 1).repeat(3, axis=2)
    out16, info = read_image(_write(tmp_path / "b.png", codes16, "uint16"))
    assert info.pixel_type == "uint16"
    np.testing.assert_allclose(out16, _srgb_decode_reference(codes16.astype(float), 16), atol=2e-7)
    linear = np.linspace(0, 4, 16 * 16 * 3, dtype=np.float32).reshape(16, 16, 3)
    outf, _ = read_image(_write(tmp_path / "c.exr", linear, "float"))
    np.testing.assert_array_equal(outf, linear)


def test_crop(tmp_path):
    rng = np.random.default_rng(0)
    pixels = rng.integers(0, 256, (20, 30, 3)).astype(np.uint8)
    _write(tmp_path / "tl000_pl000_tv000_pv000.png", pixels)
    full = BtfStack.open(tmp_path).image(0)
    cropped = BtfStack.open(tmp_path, crop=(5, 2, 10, 12))
    assert (cropped.width, cropped.height) == (10, 12)
    np.testing.assert_array_equal(cropped.image(0), full[2:14, 5:15])
    with pytest.raises(InputError, match="crop"):
        BtfStack.open(tmp_path, crop=(25, 0, 10, 10))


# ------------------------------------------------------------------------------------- period and tiles


def _pattern(x, y, px, py):
    """Smooth weave-like pattern periodic with (px, 0) and (0, py); mean 1."""
    u, v = 2 * np.pi * x / px, 2 * np.pi * y / py
    return 1 + 0.5 * np.cos(u) * np.cos(v) + 0.3 * np.cos(u + v) + 0.2 * np.sin(u - 2 * v)


@pytest.mark.parametrize("px,py", [(21.3, 17.6), (32.0, 32.0), (12.25, 40.7)])
def test_estimate_period_subpixel(px, py):
    y, x = np.mgrid[0:256, 0:256].astype(float)
    rng = np.random.default_rng(1)
    image = _pattern(x, y, px, py)[..., None] * [1.0, 0.7, 0.4] + rng.normal(0, 0.1, (256, 256, 3))
    period = estimate_period(image)
    assert abs(period.px - px) < 0.02 and abs(period.py - py) < 0.02


def test_lattice_vectors_of_a_sheared_lattice():
    true = np.array([[14.0, 0.0], [5.0, 16.0]])  # rows (dx, dy): a twill-like sheared lattice
    recip = np.linalg.inv(true).T  # rows b_k with a_j . b_k = delta_jk
    y, x = np.mgrid[0:256, 0:256].astype(float)
    r = np.stack([x, y], axis=-1)
    phase = 2 * np.pi * r @ recip.T
    image = np.cos(phase[..., 0]) + np.cos(phase[..., 1]) + 0.5 * np.cos(phase[..., 0] + phase[..., 1])
    found = lattice_vectors(autocorrelation(image))
    coefficients = found @ np.linalg.inv(true)  # found vectors in the true basis
    np.testing.assert_allclose(coefficients, np.round(coefficients), atol=0.02)
    assert abs(abs(np.linalg.det(found)) - abs(np.linalg.det(true))) < 0.02 * abs(np.linalg.det(true))


def test_average_tiles_recovers_the_pattern():
    px, py = 21.3, 17.6
    y, x = np.mgrid[0:256, 0:256].astype(float)
    rng = np.random.default_rng(2)
    image = _pattern(x, y, px, py)[..., None] + rng.normal(0, 0.05, (256, 256, 1))
    tile = average_tiles(image, (px, py))
    ny, nx = tile.shape[:2]
    assert (nx, ny) == (21, 18)
    jj, ii = np.mgrid[0:ny, 0:nx]
    expected = _pattern(ii * px / nx, jj * py / ny, px, py)
    # bilinear error <= h^2/8 |f''| ~ 0.02 here; noise / sqrt(~160 tiles) ~ 0.004
    np.testing.assert_allclose(tile[..., 0], expected, atol=0.03)
    with pytest.raises(InputError, match="no whole"):
        average_tiles(image[:20, :20], (px, py))


# ---------------------------------------------------------------------------------- writer round trip


def _evaluate(u, v, wi, wo):
    """Periodic pattern (1 tile) whose channel brightness depends on the directions."""
    base = _pattern(u, v, 1.0, 1.0)
    return np.stack([base * (0.2 + wi[2]), base * (0.1 + 0.5 * wo[2]), base * (0.3 + 0.1 * wi[0] * wo[1])], -1)


DIRECTIONS = np.array([[0, 0, 0, 0], [30, 22.5, 0, 0], [45, 90, 30, 180], [60, 300, 75, 15], [75, 7.5, 45, 90]])


def _expected_image(row, size, repeats):
    from clothlab.frames import spherical_to_vector

    width, height = size
    u = (np.arange(width) + 0.5) / width * repeats[0]
    v = (height - np.arange(height) - 0.5) / height * repeats[1]
    uu, vv = np.meshgrid(u, v)
    return _evaluate(uu, vv, spherical_to_vector(row[0], row[1]), spherical_to_vector(row[2], row[3]))


@pytest.mark.parametrize("manifest,naming", [(True, "utia"), (False, "utia"), (False, "bonn")])
def test_write_load_round_trip(tmp_path, manifest, naming):
    size, repeats = (96, 80), (4, 5)
    out = write_btf_stack(tmp_path / "stack", _evaluate, directions=DIRECTIONS, size=size, tile_repeats=repeats,
                          naming=naming, manifest=manifest)
    assert (out / "manifest.yaml").exists() == manifest
    stack = BtfStack.open(out)
    assert (stack.width, stack.height, stack.channels) == (96, 80, 3)
    order = np.lexsort(stack.angles.T[::-1])
    np.testing.assert_allclose(stack.angles[order], DIRECTIONS[np.lexsort(DIRECTIONS.T[::-1])], atol=1e-9)
    for index, entry in enumerate(stack.entries):
        row = np.array(entry.angles)
        expected = _expected_image(row, size, repeats)
        np.testing.assert_allclose(stack.image(index), expected, rtol=1e-3, atol=1e-4)  # EXR half
    # tile averaging over the stack: 24 x 16 px tiles; each tile is the pattern at the tile grid
    result = stack.tile_averages()
    assert abs(result.period.px - 24) < 0.05 and abs(result.period.py - 16) < 0.05
    tiles = stack.tile_averages(period=(24, 16)).tiles
    for index, entry in enumerate(stack.entries):
        # tile row j (from the top) samples v = 1 - (j + 0.5) / 16 per tile; column i samples u = (i + 0.5) / 24
        expected = _expected_image(np.array(entry.angles), (24, 16), (1, 1))
        np.testing.assert_allclose(tiles[index], expected, rtol=2e-3, atol=2e-4)
    assert result.peak_traced_mb > 0 and result.summary()["images"] == len(DIRECTIONS)


def test_writer_refuses_to_overwrite_and_png_mode(tmp_path):
    target = tmp_path / "stack"
    write_btf_stack(target, _evaluate, directions=DIRECTIONS[:2], size=16, tile_repeats=1)
    with pytest.raises(ResultExistsError, match="overwrite=True"):
        write_btf_stack(target, _evaluate, directions=DIRECTIONS[:2], size=16, tile_repeats=1)
    dim = lambda u, v, wi, wo: 0.4 * _evaluate(u, v, wi, wo)  # noqa: E731  (kept inside [0, 1])
    write_btf_stack(target, dim, directions=DIRECTIONS, size=(32, 24), tile_repeats=2, exr=False,
                    overwrite=True)
    stack = BtfStack.open(target)
    assert len(stack) == len(DIRECTIONS) and stack.info.pixel_type == "uint16"
    for index, entry in enumerate(stack.entries):
        expected = 0.4 * _expected_image(np.array(entry.angles), (32, 24), (2, 2))
        np.testing.assert_allclose(stack.image(index), expected, atol=1e-4)  # 16-bit sRGB quantisation


def test_writer_checks_evaluate_and_directions(tmp_path):
    with pytest.raises(InputError, match="evaluate returned shape"):
        write_btf_stack(tmp_path / "a", lambda u, v, wi, wo: np.ones(5), directions=DIRECTIONS, size=8,
                        tile_repeats=1)
    with pytest.raises(InputError, match="polar angles"):
        write_btf_stack(tmp_path / "b", _evaluate, directions=[[95, 0, 0, 0]], size=8, tile_repeats=1)
    assert not (tmp_path / "a").exists()  # nothing half-written


# ------------------------------------------------------------------------------------------- benchmark


def test_memory_benchmark_quick(tmp_path):
    figures = btf_memory_benchmark(quick=True, directory=tmp_path)
    assert figures["n_images"] == 200 and figures["passed"]
    assert figures["max_rss_mb"] < 2048 and figures["images_per_second"] > 0
    # streaming: far less traced memory than the decoded stack (200 x 256 x 256 x 3 float32 = 150 MB)
    assert figures["peak_traced_mb"] < 60
