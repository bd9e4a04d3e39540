"""UTIA anisotropic BRDF .bin files (io/utia.py): exact layout round trip, conventions converted once,
quadrilinear lookup, bad files naming the byte offset."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from clothlab.cli.main import main
from clothlab.errors import InputError
from clothlab.io.loader import detect_format, load_measurement
from clothlab.io.utia import lookup_utia, read_utia, read_utia_table, write_utia

FUZZ = settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
THETA = np.arange(6) * 15.0
PHI = np.arange(48) * 7.5


def brdf_function(c, ti, pi_, tv, pv):
    """A test BRDF of the four angles (deg) whose value at theta = 0 does not depend on that azimuth."""
    a = np.sin(np.deg2rad(ti)) * np.cos(np.deg2rad(pi_ - 30.0))
    b = np.sin(np.deg2rad(tv)) * np.sin(np.deg2rad(2.0 * pv))
    return 0.2 + 0.05 * c + 0.1 * a + 0.07 * b + 0.01 * a * b


def grid():
    c, ti, pi_, tv, pv = np.meshgrid(np.arange(3), THETA, PHI, THETA, PHI, indexing="ij")
    return brdf_function(c, ti, pi_, tv, pv)


@pytest.fixture(scope="module")
def utia_file(tmp_path_factory):
    return write_utia(grid(), tmp_path_factory.mktemp("utia") / "m001_fabric.bin")


def test_exact_layout_round_trip(utia_file):
    raw = np.frombuffer(utia_file.read_bytes(), "<f8")
    assert raw.size * 8 == 1_990_656
    g = grid()
    # the published index: plane * 82944 + 288 * (48 * i_theta_i + i_phi_i) + 48 * i_theta_v + i_phi_v
    for p, ti, pi_, tv, pv in [(0, 0, 0, 0, 0), (2, 5, 47, 5, 47), (1, 3, 10, 2, 33)]:
        assert raw[p * 82944 + 288 * (48 * ti + pi_) + 48 * tv + pv] == g[p, ti, pi_, tv, pv]
    m = read_utia(utia_file)
    assert m.n == 241 * 241 and m.channels == ("R", "G", "B")
    expected = np.stack([brdf_function(c, m.theta_i, m.phi_i, m.theta_o, m.phi_o) for c in range(3)], axis=1)
    np.testing.assert_allclose(m.values, expected, rtol=1e-13, atol=1e-15)
    assert m.provenance["source_format"] == "utia" and "source_header" not in m.provenance


def test_conventions_converted_once(utia_file):
    """A file measured clockwise from the warp, with a 20 deg offset: clothlab phi = 90 - phi_file + 20."""
    ref = read_utia(utia_file)
    m = read_utia(utia_file, azimuth_zero="warp", azimuth_sense="cw", azimuth_offset=20.0)
    np.testing.assert_array_equal(m.values, ref.values)
    expected = np.mod(90.0 - ref.phi_o + 20.0, 360.0)
    np.testing.assert_allclose(np.cos(np.deg2rad(m.phi_o - expected)), 1.0, atol=1e-13)
    assert m.provenance["source_header"]["azimuth_offset"] == 20.0


def test_quadrilinear_lookup(utia_file):
    table = read_utia_table(utia_file)
    g = grid()
    # at the nodes: the stored values
    np.testing.assert_array_equal(lookup_utia(table, [30.0], [15.0], [60.0], [352.5])[0], g[:, 2, 2, 4, 47])
    # between nodes: the mean of the 16 corners (weights 1/2 along each axis); phi wraps 352.5 -> 0
    got = lookup_utia(table, [37.5], [356.25], [7.5], [3.75])[0]
    corners = [g[:, a, b, c, d] for a in (2, 3) for b in (47, 0) for c in (0, 1) for d in (0, 1)]
    np.testing.assert_allclose(got, np.mean(corners, axis=0), rtol=1e-14)
    # beyond 75 deg the polar angle clamps to 75
    np.testing.assert_array_equal(lookup_utia(table, [85.0], [0.0], [0.0], [0.0]), lookup_utia(table, [75.0], [0.0],
                                                                                               [0.0], [0.0]))


def test_loader_detects_utia_and_imports(utia_file, tmp_path, capsys):
    assert detect_format(utia_file) == "utia"
    assert load_measurement(utia_file, azimuth_sense="cw").provenance["source_header"]["azimuth_sense"] == "cw"
    with pytest.raises(InputError, match="azimuth_sense"):
        load_measurement(utia_file, azimuth_sense="up")


def _one_bad(tmp_path, index, value):
    g = grid()
    g.reshape(-1)[index] = value
    return write_utia(g, tmp_path / "bad.bin", overwrite=True)


@FUZZ
@given(cut=st.integers(0, 1_990_656 + 64).filter(lambda n: n != 1_990_656))
def test_wrong_size_refused_at_byte_offset(tmp_path, utia_file, cut):
    data = utia_file.read_bytes()
    path = tmp_path / "cut.bin"
    path.write_bytes(data[:cut] if cut < len(data) else data + b"\0" * (cut - len(data)))
    with pytest.raises(InputError, match="byte offset") as info:
        read_utia_table(path)
    assert str(path) in str(info.value)


@FUZZ
@given(index=st.integers(0, 3 * 82944 - 1), value=st.sampled_from([np.nan, np.inf, -0.5]))
def test_nan_or_negative_names_byte_offset(tmp_path, index, value):
    path = _one_bad(tmp_path, index, value)
    with pytest.raises(InputError, match="not finite" if not value < 0 else "negative") as info:
        read_utia_table(path)
    assert f"byte offset {8 * index} " in str(info.value)


def test_negative_zero_option_and_cli_exit_2(tmp_path, capsys):
    path = _one_bad(tmp_path, 5, -0.5)
    assert read_utia_table(path, negative="zero").brdf.reshape(-1)[5] == 0.0
    assert main(["import", str(path), "--format", "utia", "-o", str(tmp_path / "o.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "byte offset 40" in err[0]
    assert main(["import", str(path), "--format", "utia", "--option", "negative=zero", "-o",
                 str(tmp_path / "o.csv")]) == 0
