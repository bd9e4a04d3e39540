"""ASTM E1392 and pab-opto loaders, and format detection by load_measurement."""

from __future__ import annotations

import math

import numpy as np
import pytest

from clothlab.errors import InputError
from clothlab.io.astm import read_astm, write_astm
from clothlab.io.loader import FORMATS, detect_format, load_measurement
from clothlab.io.measurement import Measurement
from clothlab.io.pabopto import read_pabopto
from clothlab.io.table import write_table


def unit_vector(theta_deg, phi_deg):
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return [math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)]


# ------------------------------------------------------------------------------------------------- ASTM

ASTM_TEXT = """\
SOURCE unit-test gonioreflectometer
SAMPLE twill
NUM_POINTS 3
VARS theta_i,phi_i,theta_s,phi_s,R,G,B
0.5235987755982988,0,0.5235987755982988,-1.5707963267948966,0.1,0.2,0.3
0.7853981633974483,-3.0,0.2,1.0,0.4,0.5,0.6
0,0,1.2,3.0,0.7,0.8,0.9
"""


def test_astm_reads_radians_and_wraps_negative_azimuths(tmp_path):
    path = tmp_path / "a.astm"
    path.write_text(ASTM_TEXT)
    m = read_astm(path)
    assert m.channels == ("R", "G", "B")
    np.testing.assert_allclose(m.theta_i, [30.0, 45.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(m.phi_o, [270.0, math.degrees(1.0), math.degrees(3.0)], atol=1e-12)
    np.testing.assert_allclose(m.phi_i[1], math.degrees(2 * math.pi - 3.0), atol=1e-12)
    np.testing.assert_array_equal(m.values[2], [0.7, 0.8, 0.9])
    assert m.provenance["astm_keywords"] == {"SOURCE": "unit-test gonioreflectometer", "SAMPLE": "twill"}


def test_astm_options_convert_units_and_conventions(tmp_path):
    path = tmp_path / "d.astm"
    path.write_text("NUM_POINTS 1\nVARS theta_i,phi_i,theta_s,phi_s,Y\n30,0,60,0,0.5\n")
    m = read_astm(path, angle_unit="deg", azimuth_zero="warp", quantity="reflectance_factor")
    np.testing.assert_allclose(m.wi[0], unit_vector(30, 90), atol=1e-15)
    np.testing.assert_allclose(m.values[0, 0], 0.5 / math.pi, rtol=1e-15)
    assert m.provenance["source_header"]["azimuth_zero"] == "warp"


def test_astm_round_trip(tmp_path):
    path = tmp_path / "a.astm"
    path.write_text(ASTM_TEXT)
    m = read_astm(path)
    back = read_astm(write_astm(m, tmp_path / "b.astm"))
    np.testing.assert_allclose(back.wi, m.wi, atol=1e-14)
    np.testing.assert_allclose(back.wo, m.wo, atol=1e-14)
    np.testing.assert_array_equal(back.values, m.values)
    assert back.provenance == m.provenance


@pytest.mark.parametrize("text, line, field, fragment", [
    (ASTM_TEXT.replace("NUM_POINTS 3", "NUM_POINTS 4"), 3, "NUM_POINTS", "NUM_POINTS says 4 but the file has 3"),
    (ASTM_TEXT.replace("NUM_POINTS 3", "NUM_POINTS three"), 3, "NUM_POINTS", "not an integer"),
    (ASTM_TEXT.replace("theta_s,phi_s", "theta_s,phi_x"), 4, "VARS", "phi_s exactly once"),
    (ASTM_TEXT.replace(",0.5,0.6", ",-0.5,0.6"), 6, "G", "negative"),
    (ASTM_TEXT.replace(",0.8,", ",0.8x,"), 7, "G", "not a number"),
    (ASTM_TEXT.replace(",0.8,0.9", ",0.8"), 7, "B", "row has 6 fields"),
    (ASTM_TEXT.replace("0,0,1.2", "1.6,0,1.2"), 7, "theta_i", "outside"),
    (ASTM_TEXT + "COMMENT late\n", 8, None, "after the data rows"),
])
def test_astm_errors_name_line_and_field(tmp_path, text, line, field, fragment):
    path = tmp_path / "bad.astm"
    path.write_text(text)
    with pytest.raises(InputError) as info:
        read_astm(path)
    assert fragment in str(info.value)
    assert info.value.line == line
    assert info.value.field == field
    assert f"bad.astm:{line}" in str(info.value)


def test_astm_missing_vars(tmp_path):
    path = tmp_path / "bad.astm"
    path.write_text("NUM_POINTS 1\n0,0,0,0,1\n")
    with pytest.raises(InputError, match="VARS is missing"):
        read_astm(path)


# ---------------------------------------------------------------------------------------------- pab-opto

def write_pab(path, theta_i, phi_i, rows, *, kind="BSDF", upphi=None, colorimetry=None, sample="twill",
              incident_angle=False, count=None):
    """A pab-opto file as the instrument writes it (test helper, written from the format description)."""
    lines = []
    if sample is not None:
        lines.append(f'#sample_name "{sample}"')
    lines.append(f"#datapoints_in_file {len(rows) if count is None else count}")
    if colorimetry:
        lines.append(f"#colorimetry: {colorimetry}")
    lines.append(f"#format: theta phi {kind}")
    if incident_angle:
        lines.append(f"#incident_angle {theta_i} {phi_i}")
    else:
        lines += [f"#intheta {theta_i}", f"#inphi {phi_i}"]
    if upphi is not None:
        lines.append(f"#upphi {upphi}")
    lines += [" ".join(repr(float(x)) for x in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


EXITANT = [(10.0, 0.0), (30.0, 45.0), (50.0, 200.0), (70.0, 330.0), (85.0, 90.0)]
INCIDENT = [(0.0, 0.0), (30.0, 0.0), (60.0, 120.0)]


def bsdf(theta_i, phi_i, theta_o, phi_o):
    return 0.1 + 0.001 * theta_i + 0.002 * theta_o + 0.0001 * phi_o


def pab_directory(directory, *, kind="BSDF", upphi=None, **kw):
    directory.mkdir()
    for k, (ti, pi) in enumerate(INCIDENT):
        rows = []
        for to, po in EXITANT:
            value = bsdf(ti, pi, to, po)
            if kind == "DSF":
                value *= math.cos(math.radians(to))
            rows.append((to, po, value))
        write_pab(directory / f"inc{k}.txt", ti, pi, rows, kind=kind, upphi=upphi, **kw)
    return directory


def test_pabopto_directory_merges_files_with_upphi_mapping(tmp_path):
    m = read_pabopto(pab_directory(tmp_path / "d", upphi=30.0))
    assert m.channels == ("Y",) and m.n == len(INCIDENT) * len(EXITANT)
    expected_wi, expected_wo, expected_values = [], [], []
    for ti, pi in INCIDENT:
        for to, po in EXITANT:
            expected_wi.append(unit_vector(ti, pi - 30.0 + 90.0))  # warp (= sample up) at clothlab phi 90
            expected_wo.append(unit_vector(to, po - 30.0 + 90.0))
            expected_values.append([bsdf(ti, pi, to, po)])
    np.testing.assert_allclose(m.wi, expected_wi, atol=1e-14)
    np.testing.assert_allclose(m.wo, expected_wo, atol=1e-14)
    np.testing.assert_allclose(m.values, expected_values, rtol=1e-15)
    assert m.provenance["sample_name"] == "twill"
    assert m.provenance["transmission_rows_skipped"] == 0


def test_pabopto_sample_up_weft(tmp_path):
    m = read_pabopto(pab_directory(tmp_path / "d"), up="weft")
    np.testing.assert_allclose(m.wo[:len(EXITANT)], [unit_vector(t, p) for t, p in EXITANT], atol=1e-14)


def test_pabopto_dsf_is_bsdf_times_cos_theta_o(tmp_path):
    from_bsdf = read_pabopto(pab_directory(tmp_path / "bsdf"))
    from_dsf = read_pabopto(pab_directory(tmp_path / "dsf", kind="DSF"))
    np.testing.assert_allclose(from_dsf.values, from_bsdf.values, rtol=1e-13)
    np.testing.assert_array_equal(from_dsf.theta_o, from_bsdf.theta_o)


def test_pabopto_incident_angle_line_and_list_of_files(tmp_path):
    rows = [(to, po, 0.2) for to, po in EXITANT]
    a = write_pab(tmp_path / "a.txt", 40, 10, rows)
    b = write_pab(tmp_path / "b.txt", 40, 10, rows, incident_angle=True)
    np.testing.assert_array_equal(read_pabopto([a]).wi, read_pabopto(b).wi)


def test_pabopto_xyz_and_transmission_rows_skipped(tmp_path):
    rows = [(20.0, 0.0, 0.1, 0.2, 0.3), (120.0, 180.0, 0.4, 0.5, 0.6), (45.0, 90.0, 0.7, 0.8, 0.9)]
    m = read_pabopto(write_pab(tmp_path / "x.txt", 10, 0, rows, colorimetry="CIE-XYZ"))
    assert m.channels == ("X", "Y", "Z")
    np.testing.assert_array_equal(m.values, [[0.1, 0.2, 0.3], [0.7, 0.8, 0.9]])
    assert m.provenance["transmission_rows_skipped"] == 1


def test_pabopto_back_side_file_is_rejected(tmp_path):
    path = write_pab(tmp_path / "back.txt", 150, 0, [(20.0, 0.0, 0.1)])
    with pytest.raises(InputError, match="back side") as info:
        read_pabopto(path)
    assert info.value.line == 4 and info.value.field == "intheta"


@pytest.mark.parametrize("make, fragment, line", [
    (lambda p: write_pab(p, 10, 0, [(20.0, 0.0, 0.1)], count=2), "datapoints_in_file says 2", 2),
    (lambda p: write_pab(p, 10, 0, [(20.0, 0.0, 0.1)], kind="radiance"), "format 'theta phi radiance'", 3),
    (lambda p: write_pab(p, 10, 0, [(20.0, 0.0, -0.1)]), "negative", 6),
    (lambda p: write_pab(p, 10, 0, [(90.0, 0.0, 0.1)], kind="DSF"), "cos(theta) = 0", 6),
    (lambda p: write_pab(p, 10, 0, [(20.0, 0.0)]), "row has 2 fields, expected 3", 6),
])
def test_pabopto_errors(tmp_path, make, fragment, line):
    path = make(tmp_path / "bad.txt")
    with pytest.raises(InputError) as info:
        read_pabopto(path)
    assert fragment in str(info.value)
    assert info.value.line == line


def test_pabopto_mixed_samples_and_duplicates(tmp_path):
    rows = [(20.0, 0.0, 0.1)]
    a = write_pab(tmp_path / "a.txt", 10, 0, rows, sample="one")
    b = write_pab(tmp_path / "b.txt", 20, 0, rows, sample="two")
    with pytest.raises(InputError, match="different samples"):
        read_pabopto([a, b])
    c = write_pab(tmp_path / "c.txt", 10, 0, rows, sample="one")
    with pytest.raises(InputError, match="duplicate") as info:
        read_pabopto([a, c])
    assert "a.txt:" in str(info.value) and info.value.path == str(c)


# ------------------------------------------------------------------------------------------------ loader

def sample_measurement():
    return Measurement([0.0, 30.0], [0.0, 45.0], [30.0, 60.0], [180.0, 10.0], [[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]],
                       ("R", "G", "B"))


def test_detects_each_format(tmp_path):
    table = write_table(sample_measurement(), tmp_path / "t.csv")
    astm = tmp_path / "a.txt"
    astm.write_text(ASTM_TEXT)
    pab = pab_directory(tmp_path / "pab")
    assert detect_format(table) == "clothlab"
    assert detect_format(astm) == "astm"
    assert detect_format(pab) == "pabopto"
    assert detect_format(pab / "inc0.txt") == "pabopto"
    np.testing.assert_array_equal(load_measurement(table).values, sample_measurement().values)
    assert load_measurement(astm).n == 3
    assert load_measurement(pab).n == len(INCIDENT) * len(EXITANT)
    assert set(FORMATS) == {"clothlab", "astm", "pabopto", "text", "merl", "utia", "bsdf"}


def test_detects_table_with_sidecar(tmp_path):
    text = write_table(sample_measurement(), tmp_path / "t.csv").read_text()
    (tmp_path / "s.csv").write_text("\n".join(x for x in text.splitlines() if not x.startswith("#")) + "\n")
    (tmp_path / "s.csv.yaml").write_text("\n".join(x[2:] for x in text.splitlines() if x.startswith("#")))
    assert detect_format(tmp_path / "s.csv") == "clothlab"
    np.testing.assert_array_equal(load_measurement(tmp_path / "s.csv").values, sample_measurement().values)


def test_explicit_format_and_options(tmp_path):
    path = tmp_path / "deg.dat"
    path.write_text("NUM_POINTS 2\nVARS theta_i,phi_i,theta_s,phi_s,Y\n30,0,60,0,0.5\n30,0,50,0,0.5\n")
    m = load_measurement(path, format="astm", angle_unit="deg")
    np.testing.assert_allclose(m.theta_o, [60.0, 50.0])
    with pytest.raises(InputError, match="option 'angle_units'") as info:
        load_measurement(path, angle_units="deg")
    assert info.value.field == "angle_units"
    with pytest.raises(InputError, match="unknown measurement format 'bonn'"):
        load_measurement(path, format="bonn")


@pytest.mark.parametrize("content, fragment", [
    (None, "not found"),
    ("", "empty"),
    ("  \n\n", "empty"),
    ("a,b,c\n1,2,3\n", "unknown measurement format"),
])
def test_loader_errors(tmp_path, content, fragment):
    path = tmp_path / "m.csv"
    if content is not None:
        path.write_text(content)
    with pytest.raises(InputError, match=fragment) as info:
        load_measurement(path)
    assert info.value.path == str(path)
