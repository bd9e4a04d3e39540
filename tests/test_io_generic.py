"""The generic text importer (`clothlab import`, io/generic.py): column mapping, delimiters, conventions,
atomic output, bad files naming line and column."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from clothlab.cli.main import main
from clothlab.errors import ConfigError, InputError
from clothlab.io.generic import read_generic
from clothlab.io.loader import load_measurement
from clothlab.io.table import read_table

FUZZ = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def upper_hemisphere(rng, n):
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2]) + 0.05
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def cw_from_warp_radians(w):
    """(theta, phi) of fabric-frame vectors, phi from the warp (+y) turning clockwise seen from above (towards
    the weft +x), radians - computed here from the vectors, not by clothlab."""
    return np.arccos(w[:, 2]), np.mod(np.arctan2(w[:, 0], w[:, 1]), 2.0 * np.pi)


def write_whitespace_table(path, wi, wo, values, comment="%"):
    ti, pi_ = cw_from_warp_radians(wi)
    to, po = cw_from_warp_radians(wo)
    lines = [f"{comment} exported by a gonioreflectometer", f"{comment} theta_i phi_i theta_o phi_o grey"]
    lines += ["  ".join(repr(float(x)) for x in row) + "\t" for row in zip(ti, pi_, to, po, values, strict=True)]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def test_whitespace_radians_clockwise_reproduce_directions(tmp_path, capsys):
    """Must show (issue 14): radians + clockwise azimuth from the warp -> the same direction vectors, 1e-12."""
    rng = np.random.default_rng(3)
    wi, wo = upper_hemisphere(rng, 300), upper_hemisphere(rng, 300)
    values = rng.uniform(0.05, 2.0, 300)
    source = tmp_path / "lab.txt"
    write_whitespace_table(source, wi, wo, values)
    options = dict(columns="theta_i,phi_i,theta_o,phi_o,grey", comment="%", angle_unit="rad",
                   azimuth_zero="warp", azimuth_sense="cw", delimiter="whitespace")
    m = read_generic(source, **options)
    assert np.abs(m.wi - wi).max() < 1e-12 and np.abs(m.wo - wo).max() < 1e-12
    np.testing.assert_array_equal(m.values[:, 0], values)
    assert m.channels == ("grey",)
    assert m.provenance["source_header"]["azimuth_sense"] == "cw"
    # the same through the command line, then through the written clothlab table
    out = tmp_path / "table.csv"
    assert main(["import", str(source), "-o", str(out), "--columns", "theta_i,phi_i,theta_o,phi_o,grey",
                 "--comment", "%", "--angle-unit", "rad", "--azimuth-zero", "warp", "--azimuth-sense", "cw"]) == 0
    assert "300 direction pairs" in capsys.readouterr().out
    back = read_table(out)
    assert np.abs(back.wi - wi).max() < 1e-12 and np.abs(back.wo - wo).max() < 1e-12
    np.testing.assert_array_equal(back.values[:, 0], values)


def test_header_names_semicolons_quantity_and_channel_names(tmp_path):
    text = ("ti;pi;tv;pv;red;green;extra\n"
            "30;0;45;180;0.3;0.6;9\n"
            "60;90;20;10;0.9;1.2;9\n")
    path = tmp_path / "lab.csv"
    path.write_text(text, encoding="utf-8")
    m = read_generic(path, columns="theta_i=ti,phi_i=pi,theta_o=tv,phi_o=pv,r=red,g=green",
                     quantity="reflectance_factor", channels="R,G")
    assert m.channels == ("R", "G")
    np.testing.assert_allclose(m.values, np.array([[0.3, 0.6], [0.9, 1.2]]) / math.pi, rtol=1e-15)
    np.testing.assert_array_equal(m.theta_o, [45.0, 20.0])
    # cosine-weighted values are divided by cos(theta_i) once
    c = read_generic(path, columns="theta_i=ti,phi_i=pi,theta_o=tv,phi_o=pv,red=red", quantity="cosine_weighted")
    np.testing.assert_allclose(c.values[:, 0], [0.3 / math.cos(math.radians(30)), 0.9 / math.cos(math.radians(60))],
                               rtol=1e-14)


def test_header_row_names_the_columns_and_sigma(tmp_path):
    path = tmp_path / "lab.csv"
    path.write_text("theta_i,phi_i,theta_o,phi_o,Y,sigma_Y\n10,0,20,30,0.5,0.01\n40,10,20,60,0.7,0.02\n",
                    encoding="utf-8")
    m = read_generic(path)
    assert m.channels == ("Y",)
    np.testing.assert_array_equal(m.sigma[:, 0], [0.01, 0.02])


def test_azimuth_offset_rotates_once(tmp_path):
    """Offset delta: the file's phi = 0 lies at clothlab -delta; vectors rotated by +delta about the normal."""
    rng = np.random.default_rng(5)
    wi, wo = upper_hemisphere(rng, 40), upper_hemisphere(rng, 40)
    delta = 37.0
    rot = np.deg2rad(-delta)  # the file's azimuths are the true ones minus delta
    c, s = math.cos(rot), math.sin(rot)

    def file_deg(w):
        x, y = c * w[:, 0] - s * w[:, 1], s * w[:, 0] + c * w[:, 1]
        return np.rad2deg(np.arccos(w[:, 2])), np.mod(np.rad2deg(np.arctan2(y, x)), 360.0)

    rows = zip(*file_deg(wi), *file_deg(wo), rng.uniform(0.1, 1, 40), strict=True)
    path = tmp_path / "t.csv"
    path.write_text("".join(",".join(repr(float(x)) for x in r) + "\n" for r in rows), encoding="utf-8")
    m = read_generic(path, columns="theta_i,phi_i,theta_o,phi_o,Y", azimuth_offset=delta)
    assert np.abs(m.wi - wi).max() < 1e-12 and np.abs(m.wo - wo).max() < 1e-12
    assert m.provenance["source_header"]["azimuth_offset"] == delta


def test_import_refuses_overwrite_without_force(tmp_path, capsys):
    source = tmp_path / "lab.csv"
    source.write_text("theta_i,phi_i,theta_o,phi_o,Y\n10,0,20,30,0.5\n40,10,20,60,0.7\n", encoding="utf-8")
    out = tmp_path / "t.csv"
    out.write_text("keep me\n", encoding="utf-8")
    assert main(["import", str(source), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--force" in err[0] and str(out) in err[0]
    assert out.read_text(encoding="utf-8") == "keep me\n"
    assert main(["import", str(source), "-o", str(out), "--force"]) == 0
    assert read_table(out).n == 2


def test_fabric_yaml_format_text_reads_through_the_loader(tmp_path):
    path = tmp_path / "lab.dat"
    path.write_text("5 0 10 180 0.2\n25 0 10 180 0.3\n", encoding="utf-8")
    m = load_measurement(path, "text", columns="theta_i,phi_i,theta_o,phi_o,grey")
    assert m.n == 2 and m.channels == ("grey",)
    with pytest.raises(InputError, match="delimiter"):
        load_measurement(path, "text", columns="theta_i,phi_i,theta_o,phi_o,grey", delimiter="pipe")


@pytest.mark.parametrize("columns, words", [
    ("theta_i,phi_i,theta_o,R", "phi_o"),
    ("theta_i,phi_i,theta_o,phi_o", "no value channel"),
    ("theta_i,phi_i,theta_o,phi_o,R,R", "twice"),
    ("theta_i=a,phi_i,theta_o,phi_o,R", "mixes"),
])
def test_bad_column_maps_are_config_errors(tmp_path, columns, words):
    path = tmp_path / "t.csv"
    path.write_text("1,2,3,4,5\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=words) as info:
        read_generic(path, columns=columns)
    assert info.value.field == "columns"


GOOD_ROWS = ["10 0 20 30 0.5", "40 10 20 60 0.7", "50 20 30 90 0.9", "70 200 60 120 0.4"]


@FUZZ
@given(row=st.integers(0, 3), fault=st.sampled_from(["truncated", "nan", "negative", "theta"]),
       column=st.integers(0, 4))
def test_bad_rows_name_line_and_column(tmp_path, row, fault, column):
    rows = [r.split() for r in GOOD_ROWS]
    if fault == "truncated":
        column = max(column, 1)  # an emptied row would be a blank line
        rows[row] = rows[row][:column]
        expect = "fields"
    elif fault == "nan":
        rows[row][column] = "nan"
        expect = "not finite"
    elif fault == "negative":
        column = 4
        rows[row][column] = "-0.25"
        expect = "negative"
    else:
        column = 0 if column < 2 else 2
        rows[row][column] = "95"
        expect = "outside"
    path = tmp_path / "bad.txt"
    path.write_text("# header comment\n" + "\n".join(" ".join(r) for r in rows) + "\n", encoding="utf-8")
    names = ("theta_i", "phi_i", "theta_o", "phi_o", "Y")
    with pytest.raises(InputError, match=expect) as info:
        read_generic(path, columns=",".join(names))
    assert info.value.line == row + 2
    assert str(path) in str(info.value)
    assert info.value.field == names[column]


def test_bad_file_exits_2_with_one_line(tmp_path, capsys):
    path = tmp_path / "bad.txt"
    path.write_text("10 0 20 30 0.5\n40 10 20 60 nan\n", encoding="utf-8")
    assert main(["import", str(path), "-o", str(tmp_path / "t.csv"), "--columns",
                 "theta_i,phi_i,theta_o,phi_o,Y"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{path}:2" in err[0] and "'Y'" in err[0]
    assert not (tmp_path / "t.csv").exists()


@pytest.mark.parametrize("offset", ["nan", "inf", "1_0", "ten"])
def test_cli_azimuth_offset_is_a_plain_finite_number(tmp_path, capsys, offset):
    source = tmp_path / "lab.csv"
    source.write_text("theta_i,phi_i,theta_o,phi_o,Y\n10,0,20,30,0.5\n40,10,20,60,0.7\n", encoding="utf-8")
    with pytest.raises(SystemExit) as info:
        main(["import", str(source), "-o", str(tmp_path / "t.csv"), "--azimuth-offset", offset])
    assert info.value.code == 2 and "--azimuth-offset" in capsys.readouterr().err
    assert not (tmp_path / "t.csv").exists()
