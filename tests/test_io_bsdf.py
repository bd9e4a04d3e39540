"""RGL-EPFL .bsdf tensor files (io/rglbsdf.py): container round trip, validation at byte offsets, and the
conversion to a clothlab table by the format's own evaluation (closed-form cases; agreement with Mitsuba 3's
``measured`` plugin: tests/test_rgl_mitsuba.py)."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rgl_synthetic import synthetic_fields, write_synthetic

from clothlab.cli.main import main
from clothlab.errors import InputError
from clothlab.io.loader import detect_format, load_measurement
from clothlab.io.rglbsdf import eval_rgl, read_rgl_bsdf, read_tensor_file, write_tensor_file
from clothlab.io.table import read_table

FUZZ = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def fields():
    rng = np.random.default_rng(4)
    return {
        "description": np.frombuffer(b"a woven sample", dtype=np.uint8).copy(),
        "theta_i": np.linspace(0.0, 1.5, 5, dtype=np.float32),
        "phi_i": np.array([0.0], dtype=np.float32),
        "ndf": rng.uniform(0, 2, size=(8, 8)).astype(np.float32),
        "rgb": rng.uniform(0, 1, size=(1, 5, 3, 4, 4)).astype(np.float32),
        "valid": np.array([1, 0, 1], dtype=np.int64),
        "jacobian": np.array([1], dtype=np.uint8),
        "sigma": rng.uniform(0.5, 1, size=(4, 4)),
    }


def test_container_round_trip_in_the_exact_layout(tmp_path):
    original = fields()
    path = write_tensor_file(original, tmp_path / "cloth.bsdf")
    data = path.read_bytes()
    assert data[:12] == b"tensor_file\0" and data[12:14] == bytes([1, 0])
    assert struct.unpack_from("<I", data, 14)[0] == len(original)
    # first field header: uint16 name length, name, uint16 ndim, uint8 dtype (1 = uint8), uint64 offset, shape
    n = struct.unpack_from("<H", data, 18)[0]
    assert data[20:20 + n] == b"description"
    ndim, code, offset = struct.unpack_from("<HBQ", data, 20 + n)
    assert (ndim, code) == (1, 1) and data[offset:offset + 14] == b"a woven sample"
    back = read_tensor_file(path)
    assert list(back) == list(original)
    for name, array in original.items():
        assert back[name].data.dtype == array.dtype
        np.testing.assert_array_equal(back[name].data, array)


def test_file_without_the_warp_fields_is_refused_naming_the_missing_one(tmp_path, capsys):
    path = write_tensor_file(fields(), tmp_path / "cloth.bsdf")  # a container, but no vndf / luminance
    assert detect_format(path) == "bsdf"
    with pytest.raises(InputError, match="field 'vndf' is missing") as info:
        load_measurement(path)
    assert info.value.field == "vndf"
    assert main(["import", str(path), "--format", "bsdf", "-o", str(tmp_path / "o.csv")]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


@FUZZ
@given(data=st.data())
def test_truncated_file_names_byte_offset(tmp_path, data):
    path = write_tensor_file(fields(), tmp_path / "t.bsdf", overwrite=True)
    raw = path.read_bytes()
    # cut anywhere before the end of the last field's data (the writer pads it to 8 bytes)
    last = read_tensor_file(path)["sigma"]
    cut = data.draw(st.integers(0, last.offset + last.data.nbytes - 1))
    path.write_bytes(raw[:cut])
    with pytest.raises(InputError, match="truncated|not a tensor file") as info:
        read_tensor_file(path)
    assert "byte offset" in str(info.value)


@FUZZ
@given(magic=st.binary(min_size=12, max_size=12).filter(lambda b: b != b"tensor_file\0"))
def test_wrong_magic_refused(tmp_path, magic):
    path = write_tensor_file(fields(), tmp_path / "t.bsdf", overwrite=True)
    path.write_bytes(magic + path.read_bytes()[12:])
    with pytest.raises(InputError, match="not a tensor file") as info:
        read_tensor_file(path)
    assert info.value.field == "magic" and "byte offset 0" in str(info.value)


@FUZZ
@given(name=st.sampled_from(["theta_i", "ndf", "rgb", "sigma"]), data=st.data(),
       bad=st.sampled_from(["nan", "inf", "negative"]))
def test_nan_and_negative_name_field_and_byte_offset(tmp_path, name, data, bad):
    f = fields()
    k = data.draw(st.integers(0, f[name].size - 1))
    f[name].reshape(-1)[k] = {"nan": np.nan, "inf": np.inf, "negative": -0.25}[bad]
    path = write_tensor_file(f, tmp_path / "t.bsdf", overwrite=True)
    if bad == "negative" and name == "theta_i":  # angles may be negative; densities and reflectances not
        assert read_tensor_file(path)["theta_i"].data.reshape(-1)[k] == np.float32(-0.25)
        return
    raw = path.read_bytes()
    with pytest.raises(InputError, match="not finite" if bad != "negative" else "negative") as info:
        read_tensor_file(path)
    start = raw.index(name.encode()) + len(name)
    ndim, _, data_offset = struct.unpack_from("<HBQ", raw, start)
    assert f"byte offset {data_offset + f[name].itemsize * k} " in str(info.value)
    assert info.value.field.startswith(name)


def test_overlapping_or_unknown_dtype_refused(tmp_path):
    path = write_tensor_file({"a": np.zeros(4), "b": np.ones(2)}, tmp_path / "t.bsdf")
    raw = bytearray(path.read_bytes())
    start = raw.index(b"b") + 1
    ndim, code, offset = struct.unpack_from("<HBQ", raw, start)
    struct.pack_into("<Q", raw, start + 3, offset - 8)  # field b now starts inside field a
    path.write_bytes(bytes(raw))
    with pytest.raises(InputError, match="inside field 'a'"):
        read_tensor_file(path)
    struct.pack_into("<Q", raw, start + 3, offset)
    raw[start + 2] = 42
    path.write_bytes(bytes(raw))
    with pytest.raises(InputError, match=f"dtype code 42 at byte offset {start + 2}"):
        read_tensor_file(path)


def _uniform_fields(value=0.3, ndf=2.0, sigma=0.8, jacobian=1):
    """A file whose every table is constant: the warp is the identity and f cos = value D / (4 sigma)."""
    f = synthetic_fields(jacobian=jacobian)
    for name, v in (("ndf", ndf), ("sigma", sigma), ("vndf", 1.0), ("rgb", value)):
        f[name] = np.full_like(f[name], v)
    return f


def _half_vector_theta(m):
    wi, wo = m.wi, m.wo
    h = wi + wo
    return np.arccos(h[:, 2] / np.linalg.norm(h, axis=1))


@pytest.mark.parametrize("jacobian", [1, 0])
def test_uniform_file_converts_to_value_times_d_over_4_sigma_cos(tmp_path, jacobian):
    path = write_tensor_file(_uniform_fields(jacobian=jacobian), tmp_path / "u.bsdf")
    m = load_measurement(path, "bsdf", theta_step=15.0, phi_step=30.0)
    factor = 2.0 / (4.0 * 0.8) if jacobian else 1.0
    expected = np.float32(0.3) * factor / np.cos(np.radians(m.theta_o))
    np.testing.assert_allclose(m.values, np.repeat(expected[:, None], 3, axis=1), rtol=1e-6)
    # incident directions are the file's nodes (deg) up to theta_max, exitant on the regular grid
    nodes = np.degrees(np.linspace(0.0, 1.45, 6).astype(np.float32).astype(float))
    assert set(np.round(m.theta_i, 6)) == set(np.round(nodes, 6))
    assert set(m.theta_o) == {7.5, 22.5, 37.5, 52.5, 67.5, 82.5} and set(m.phi_o) == set(range(0, 360, 30))
    # five phi_i nodes from -180 to 180 deg: four azimuths (-180 and 180 are one), one at normal incidence
    assert len(np.unique(np.round(m.phi_i[m.theta_i > 0], 3))) == 4 and set(m.phi_i[m.theta_i == 0]) == {0.0}
    assert m.provenance["source_format"] == "bsdf" and m.provenance["isotropic"] is False


def test_warp_inversion_matches_the_closed_form_conditional_cdf(tmp_path):
    """vndf density a + b x (x = the polar coordinate of the half vector), rgb equal to its x coordinate: the
    reflectance is the warp's sample x = F(u) = (a u + b u^2 / 2) / (a + b / 2), u = sqrt(theta_h / (pi/2))."""
    f = _uniform_fields(ndf=4.0, sigma=1.0)
    a, b = 0.5, 2.0
    ny, nx = f["vndf"].shape[2:]
    f["vndf"][:] = (a + b * np.linspace(0.0, 1.0, nx))[None, None, None, :]
    n = f["rgb"].shape[-1]
    f["rgb"][:] = np.linspace(0.0, 1.0, n)[None, None, None, None, :]
    path = write_tensor_file(f, tmp_path / "lin.bsdf")
    m = load_measurement(path, "bsdf", theta_step=10.0, phi_step=45.0)
    u = np.sqrt(_half_vector_theta(m) / (math.pi / 2))
    expected = (a * u + b * u * u / 2) / (a + b / 2)
    np.testing.assert_allclose(m.values[:, 0] * np.cos(np.radians(m.theta_o)), expected, rtol=2e-6, atol=1e-7)


def test_values_interpolate_linearly_between_incident_nodes(tmp_path):
    """Between two theta_i nodes the (uniform-warp) reflectance is the linear blend of the nodes' values."""
    f = _uniform_fields(ndf=4.0, sigma=1.0)
    levels = np.arange(1.0, 7.0, dtype=np.float32) / 10.0
    f["rgb"][:] = levels[None, :, None, None, None]
    table = read_rgl_bsdf(write_tensor_file(f, tmp_path / "ti.bsdf"))
    theta = np.linspace(0.0, 1.45, 6).astype(np.float32).astype(float)
    t = 0.5 * (theta[2] + theta[3]) + 0.1 * (theta[3] - theta[2])
    wi = np.array([[math.sin(t), 0.0, math.cos(t)]])
    wo = np.array([[-0.3, 0.2, math.sqrt(1 - 0.13)]])
    w = (t - theta[2]) / (theta[3] - theta[2])
    np.testing.assert_allclose(eval_rgl(table, wi, wo)[0], (1 - w) * levels[2] + w * levels[3], rtol=1e-6)
    assert np.all(eval_rgl(table, wi * [1, 1, -1], wo) == 0.0)  # below the surface: nothing


def test_isotropic_and_spectral_files_and_the_cli_table(tmp_path, capsys):
    iso = write_synthetic(tmp_path / "iso.bsdf", isotropic=True)
    m = load_measurement(iso)  # detected from the magic
    assert m.isotropic and set(m.phi_i) == {0.0}
    spectral = write_synthetic(tmp_path / "spec.bsdf", spectral=True)
    out = tmp_path / "spec.csv"
    assert main(["import", str(spectral), "--format", "bsdf", "-o", str(out), "--option", "theta_step=15",
                 "--option", "phi_step=45"]) == 0
    assert "channels 450nm, 550nm, 600nm, 650nm" in capsys.readouterr().out
    back, direct = read_table(out), load_measurement(spectral, "bsdf", theta_step=15.0, phi_step=45.0)
    assert back.channels == ("450nm", "550nm", "600nm", "650nm") and back.n == direct.n
    np.testing.assert_allclose(back.values, direct.values, rtol=1e-12)
    assert back.provenance["bsdf_grid"]["samples"] == [8, 8]


@pytest.mark.parametrize("option, value", [("theta_step", "0"), ("phi_step", "200"), ("theta_max", "nan"),
                                           ("exitant", "nodes")])
def test_bad_sampling_option_exits_2_naming_it(tmp_path, capsys, option, value):
    path = write_synthetic(tmp_path / "s.bsdf")
    assert main(["import", str(path), "--format", "bsdf", "-o", str(tmp_path / "o.csv"), "--option",
                 f"{option}={value}"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and option in err and not (tmp_path / "o.csv").exists()


@pytest.mark.parametrize("damage, field", [
    ("sigma_zero", "sigma"), ("vndf_shape", "vndf"), ("theta_order", "theta_i"), ("phi_span", "phi_i"),
    ("vndf_empty", "vndf"), ("rgb_int", "rgb")])
def test_inconsistent_tables_refused_naming_the_field(tmp_path, damage, field):
    f = synthetic_fields()
    if damage == "sigma_zero":
        f["sigma"][2, 3] = 0.0
    elif damage == "vndf_shape":
        f["vndf"] = f["vndf"][:, :4]
    elif damage == "theta_order":
        f["theta_i"][3] = f["theta_i"][2]
    elif damage == "phi_span":
        f["phi_i"] = np.linspace(-math.pi, -2.5, 5).astype(np.float32)
    elif damage == "vndf_empty":
        f["vndf"][1, 2] = 0.0
    else:
        f["rgb"] = (f["rgb"] * 100).astype(np.int32)
    path = write_tensor_file(f, tmp_path / "bad.bsdf")
    with pytest.raises(InputError) as info:
        load_measurement(path, "bsdf")
    assert info.value.field == field
    if damage == "sigma_zero":
        offset = read_tensor_file(path)["sigma"].offset + 4 * (2 * 6 + 3)
        assert f"byte offset {offset} " in str(info.value)


@FUZZ
@given(data=st.data())
def test_fuzzed_complete_file_is_converted_or_refused_naming_the_file(tmp_path, data):
    """Bytes of a complete measured file overwritten anywhere: the loader either refuses with an InputError
    naming the file, or converts it to finite, non-negative BRDF values at the promised directions."""
    path = write_synthetic(tmp_path / "f.bsdf", n=4)
    raw = bytearray(path.read_bytes())
    for _ in range(data.draw(st.integers(1, 4))):
        k = data.draw(st.integers(0, len(raw) - 1))
        raw[k] = data.draw(st.integers(0, 255))
    path.write_bytes(bytes(raw))
    try:
        m = load_measurement(path, "bsdf", theta_step=30.0, phi_step=60.0)
    except InputError as exc:
        assert exc.path is not None and path.name in str(exc)
        assert len(str(exc).splitlines()) == 1
        return
    assert np.isfinite(m.values).all() and (m.values >= 0.0).all() and (m.values <= 1e30).all()
    assert m.n > 0 and (m.theta_o <= 85.0).all() and (m.theta_i <= 85.0).all()


def test_sample_directions_carry_the_files_own_samples(tmp_path):
    """exitant=samples: at each incident node every converted value (times cos theta_o, with D / (4 sigma)
    constant) is one of the file's stored samples of that node: the warp maps the sample grid to these
    directions and back (on the regular grid the values interpolate between samples instead)."""
    f = synthetic_fields(n=6)
    f["ndf"][:], f["sigma"][:] = 4.0, 1.0
    path = write_tensor_file(f, tmp_path / "s.bsdf")
    m = load_measurement(path, "bsdf", exitant="samples", theta_max=89.9)
    assert m.provenance["bsdf_sampling"]["exitant"] == "the file's sample directions"
    theta = np.degrees(f["theta_i"].astype(float))
    phi = np.degrees(f["phi_i"].astype(float)) % 360.0
    checked = 0
    for j in (1, 2, 3):
        for k in (1, 2, 3):  # nodes off the phi = +-180 seam
            rows = np.isclose(m.theta_i, theta[j]) & np.isclose(m.phi_i, phi[k])
            values = m.values[rows] * np.cos(np.radians(m.theta_o[rows]))[:, None]
            stored = f["rgb"][k, j].reshape(3, -1).T.astype(float)  # (n * n, 3)
            nearest = np.abs(values[:, None, :] - stored[None, :, :]).max(axis=2).min(axis=1)
            assert np.all(nearest < 1e-6), nearest.max()
            assert rows.sum() >= 10  # of 36: one for the 6 samples at h = n, others reflect below the surface
            checked += rows.sum()
    assert checked > 120
    grid = load_measurement(path, "bsdf", theta_max=89.9)  # the grid's values interpolate: not all stored
    rows = np.isclose(grid.theta_i, theta[2]) & np.isclose(grid.phi_i, phi[2])
    values = grid.values[rows] * np.cos(np.radians(grid.theta_o[rows]))[:, None]
    stored = f["rgb"][2, 2].reshape(3, -1).T.astype(float)
    assert np.median(np.abs(values[:, None, :] - stored[None]).max(axis=2).min(axis=1)) > 1e-3
