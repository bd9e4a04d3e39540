"""MERL .binary tables (io/merl.py): exact layout round trip, the real 90 x 90 x 180 indexing against an
analytic table, conversion at loading, the isotropic flag, bad files naming the byte offset."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from clothlab.cli.main import main
from clothlab.config import load_config
from clothlab.errors import ConfigError, InputError
from clothlab.io.loader import detect_format, load_measurement
from clothlab.io.merl import (
    MERL_DIMS,
    lookup_merl,
    merl_directions,
    read_merl,
    read_merl_table,
    write_merl,
)
from clothlab.io.table import read_table

FUZZ = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
SCALE = np.array([1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0])  # the format's published channel scales


def small_stored(rng, dims=(4, 3, 6)):
    stored = rng.uniform(0.0, 3000.0, size=(3, *dims))
    stored[1, 0, 1, 2] = -1.0  # one unmeasured bin
    return stored


def test_exact_layout_round_trip(tmp_path):
    """Written in the byte layout (int32 dims, float64 R then G then B) -> read -> stored * scale."""
    rng = np.random.default_rng(0)
    stored = small_stored(rng)
    path = write_merl(stored, tmp_path / "s.binary")
    raw = path.read_bytes()
    assert np.frombuffer(raw[:12], "<i4").tolist() == [4, 3, 6]
    np.testing.assert_array_equal(np.frombuffer(raw[12:], "<f8")[:6], stored[0, 0, 0])  # phi_d fastest
    assert len(raw) == 12 + 8 * stored.size
    table = read_merl_table(path)
    assert table.dims == (4, 3, 6)
    np.testing.assert_array_equal(table.brdf, stored * SCALE[:, None, None, None])


def _directions_from_half_diff(theta_h, phi_h, theta_d, phi_d):
    """wi, wo from half/difference angles with scipy rotations: wi = Rz(phi_h) Ry(theta_h) d (Rusinkiewicz
    1998; the inverse of MERL's std_coords_to_half_diff_coords), wo = the mirror of wi about h."""
    d = np.stack([np.sin(theta_d) * np.cos(phi_d), np.sin(theta_d) * np.sin(phi_d), np.cos(theta_d)], axis=1)
    rot = Rotation.from_euler("ZY", np.stack([phi_h, theta_h], axis=1))  # intrinsic: Rz then Ry
    wi = rot.apply(d)
    h = rot.apply(np.array([0.0, 0.0, 1.0]))
    wo = 2.0 * np.sum(wi * h, axis=1, keepdims=True) * h - wi
    return wi, wo


def analytic(th, td, pd):
    """A smooth test BRDF in half/difference angles (radians), stored numbers per channel."""
    base = 100.0 + 900.0 * np.exp(-8.0 * th) * (1.0 + 0.3 * np.cos(td)) + 50.0 * np.sin(pd) ** 2
    return np.stack([base, 0.5 * base + 10.0 * td, base + 5.0 * pd])


def test_full_size_indexing_against_analytic_table(tmp_path):
    """The real 90 x 90 x 180 layout: each bin holds the analytic function at its centre; directions built
    independently at bin centres (any phi_h, phi_d or phi_d - pi) look up exactly those values."""
    n_h, n_d, n_p = MERL_DIMS
    ih, jd, kp = np.meshgrid(np.arange(n_h), np.arange(n_d), np.arange(n_p), indexing="ij")
    centre_h = ((ih + 0.5) / n_h) ** 2 * (np.pi / 2)  # theta_h bins are uniform in sqrt(theta_h / (pi/2))
    centre_d = (jd + 0.5) / n_d * (np.pi / 2)
    centre_p = (kp + 0.5) / n_p * np.pi
    stored = analytic(centre_h, centre_d, centre_p)
    path = write_merl(stored, tmp_path / "full.binary")
    assert path.stat().st_size == 12 + 3 * 90 * 90 * 180 * 8
    table = read_merl_table(path)
    rng = np.random.default_rng(7)
    i, j, k = rng.integers(0, n_h, 4000), rng.integers(0, n_d, 4000), rng.integers(0, n_p, 4000)
    th, td, pd = ((i + 0.5) / n_h) ** 2 * (np.pi / 2), (j + 0.5) / n_d * (np.pi / 2), (k + 0.5) / n_p * np.pi
    pd = np.where(rng.random(4000) < 0.5, pd, pd - np.pi)  # reciprocity: phi_d and phi_d - pi share a bin
    wi, wo = _directions_from_half_diff(th, rng.uniform(-np.pi, np.pi, 4000), td, pd)
    above = (wi[:, 2] > 1e-6) & (wo[:, 2] > 1e-6)
    assert above.sum() > 1000
    got = lookup_merl(table, wi[above], wo[above])
    expected = (analytic(th, td, np.where(pd < 0, pd + np.pi, pd)) * SCALE[:, None]).T[above]
    np.testing.assert_allclose(got, expected, rtol=1e-12)
    # a mirror pair has h = normal: theta_h bin 0, theta_d = theta_i, phi_d = phi_i (phi_h = 0)
    theta, phi = 0.6, 2.5
    w = np.array([[np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]])
    mirror = w * np.array([-1.0, -1.0, 1.0])
    j, k = int(theta / (np.pi / 2) * n_d), int(phi / np.pi * n_p)
    np.testing.assert_array_equal(lookup_merl(table, w, mirror)[0], table.brdf[:, 0, j, k])


def test_read_merl_converts_once_isotropic_flag_and_unmeasured(tmp_path):
    rng = np.random.default_rng(1)
    stored = small_stored(rng)
    stored[:, 3] = -1.0  # the largest theta_h bin unmeasured: the pairs falling there are dropped
    path = write_merl(stored, tmp_path / "fabric.binary")
    m = read_merl(path, theta_step=15.0, phi_step=30.0)
    ti, pi_, to, po = merl_directions(15.0, 30.0)
    assert len(ti) == 6 * 6 * 7
    assert m.provenance["isotropic"] is True and m.provenance["source_format"] == "merl" and m.isotropic
    dropped = m.provenance["merl_unmeasured_pairs"]
    assert dropped > 0 and m.n == len(ti) - dropped
    assert (m.phi_i == 0).all() and set(np.unique(m.theta_i)) <= set(ti)
    from clothlab.frames import spherical_to_vector
    np.testing.assert_array_equal(m.values, lookup_merl(read_merl_table(path), spherical_to_vector(
        m.theta_i, m.phi_i), spherical_to_vector(m.theta_o, m.phi_o)))
    assert (m.values >= 0).all()


def test_default_sampling_is_a_few_thousand_pairs():
    ti, pi_, to, po = merl_directions()
    assert len(ti) == 11 * 11 * 19 == 2299
    assert ti.min() == 3.75 and ti.max() == 78.75 and po.max() == 180.0
    with pytest.raises(ConfigError, match="theta_step"):
        merl_directions(theta_step=0.0)


def test_loader_detects_merl_and_fabric_yaml_points_at_it(tmp_path, capsys):
    rng = np.random.default_rng(2)
    path = write_merl(small_stored(rng), tmp_path / "red-fabric.binary")
    assert detect_format(path) == "merl"
    m = load_measurement(path, theta_step=30.0)
    assert m.provenance["isotropic"] is True
    with pytest.raises(InputError, match="theta_stepp"):
        load_measurement(path, theta_stepp=30.0)
    with pytest.raises(InputError, match="theta_step must be") as info:
        load_measurement(path, theta_step="coarse")
    assert info.value.field == "theta_step" and str(path) in str(info.value)
    assert load_measurement(write_merl(small_stored(rng), tmp_path / "b.binary"), "merl").subset([0, 1]).isotropic
    (tmp_path / "fabric.yaml").write_text(
        "name: red\nmeasurement:\n  path: red-fabric.binary\n  format: merl\n  options: {theta_step: 15}\n"
        "model:\n  kind: irawan\n  weave: preset:Polyester_Lining\n", encoding="utf-8")
    cfg = load_config(tmp_path / "fabric.yaml")
    assert cfg.measurement.format == "merl" and cfg.measurement.options == {"theta_step": 15}
    out = tmp_path / "t.csv"
    assert main(["import", str(path), "--format", "merl", "--option", "theta_step=15", "-o", str(out)]) == 0
    back = read_table(out)
    assert back.provenance["isotropic"] is True and back.n == load_measurement(path, theta_step=15).n


@FUZZ
@given(cut=st.integers(0, 12 + 8 * 3 * 4 * 3 * 6 - 1))
def test_truncated_file_names_byte_offset(tmp_path, cut):
    path = write_merl(small_stored(np.random.default_rng(0)), tmp_path / "t.binary", overwrite=True)
    path.write_bytes(path.read_bytes()[:cut])
    with pytest.raises(InputError, match="truncated") as info:
        read_merl_table(path)
    assert "byte offset" in str(info.value) or "bytes" in str(info.value)
    assert str(path) in str(info.value)


@FUZZ
@given(dims=st.tuples(st.integers(-5, 5000), st.integers(-5, 5000), st.integers(-5, 5000)))
def test_wrong_dims_header_refused(tmp_path, dims):
    stored = small_stored(np.random.default_rng(0))
    path = write_merl(stored, tmp_path / "t.binary", overwrite=True)
    if tuple(dims) == stored.shape[1:]:
        return
    path.write_bytes(np.asarray(dims, "<i4").tobytes() + path.read_bytes()[12:])
    with pytest.raises(InputError, match="dims|truncated|trailing") as info:
        read_merl_table(path)
    assert str(path) in str(info.value)


@FUZZ
@given(index=st.integers(0, 3 * 4 * 3 * 6 - 1), bad=st.sampled_from([np.nan, np.inf, -np.inf]))
def test_nan_names_its_byte_offset_and_bin(tmp_path, index, bad):
    stored = small_stored(np.random.default_rng(0))
    stored.reshape(-1)[index] = bad
    path = write_merl(stored, tmp_path / "t.binary", overwrite=True)
    with pytest.raises(InputError, match="not finite") as info:
        read_merl_table(path)
    assert f"byte offset {12 + 8 * index} " in str(info.value)
    c, h, d, p = np.unravel_index(index, stored.shape)
    assert info.value.field == f"{'RGB'[c]}[theta_h={h}, theta_d={d}, phi_d={p}]"


def test_negative_means_unmeasured_but_all_negative_is_refused(tmp_path, capsys):
    path = write_merl(-np.ones((3, 2, 2, 2)), tmp_path / "t.binary")
    with pytest.raises(InputError, match="no measured bin"):
        read_merl_table(path)
    assert main(["import", str(path), "--format", "merl", "-o", str(tmp_path / "o.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0]


def test_detection_sends_a_broken_binary_to_its_reader(tmp_path):
    """A truncated .binary is still detected as MERL, so the message names the byte offset; text is not."""
    path = write_merl(small_stored(np.random.default_rng(0)), tmp_path / "cut.binary")
    path.write_bytes(path.read_bytes()[:100])
    with pytest.raises(InputError, match="ends at byte offset 100"):
        load_measurement(path)
    text = tmp_path / "table.binary"
    text.write_text("NUM_POINTS 2\nVARS theta_i,phi_i,theta_s,phi_s,R\n0.1,0,0.2,1,0.5\n0.2,0,0.2,1,0.5\n")
    assert detect_format(text) == "astm"
