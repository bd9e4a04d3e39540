"""clothlab's own measurement table: exact round trips, conversions, validation messages, fuzzing."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from clothlab.errors import ConfigError, InputError, ResultExistsError
from clothlab.io.measurement import Measurement
from clothlab.io.table import read_table, write_table

VALID = """\
# clothlab-table: 1
# angle_unit: deg
# quantity: brdf
# azimuth_zero: weft
# azimuth_sense: ccw
# channels: [R, G, B]
# provenance: {instrument: test gonio, reference_standard: Spectralon, sample_name: twill, simulated: true}
theta_i,phi_i,theta_o,phi_o,R,G,B,sigma_R,sigma_G,sigma_B
0,0,30,180,0.10,0.20,0.30,0.01,0.01,0.01
30,90,30,270,0.11,0.21,0.31,0.01,0.02,0.03
60,45,15,0,0.12,0.22,0.32,0.01,0.02,0.03
75,300,60,120,0.5,0.4,0.3,0.05,0.04,0.03
"""
COLUMNS = VALID.splitlines()[7].split(",")

# Rows used by the conversion tests: theta_i, phi_i, theta_o, phi_o (clothlab convention, deg) and R, G, B.
ROWS = [
    (0.0, 0.0, 30.0, 180.0, 0.10, 0.20, 0.30),
    (30.0, 90.0, 30.0, 270.0, 0.11, 0.21, 0.31),
    (60.0, 45.0, 15.0, 0.0, 0.12, 0.22, 0.32),
    (75.0, 300.0, 60.0, 120.0, 0.5, 0.4, 0.3),
    (45.0, 10.0, 89.0, 350.0, 0.05, 0.06, 0.07),
]


def header(**overrides) -> str:
    keys = {"angle_unit": "deg", "quantity": "brdf", "azimuth_zero": "weft", "azimuth_sense": "ccw"}
    keys.update(overrides)
    lines = ["# clothlab-table: 1"] + [f"# {k}: {v}" for k, v in keys.items()] + ["# channels: [R, G, B]"]
    return "\n".join(lines) + "\ntheta_i,phi_i,theta_o,phi_o,R,G,B\n"


def table_text(rows, **overrides) -> str:
    return header(**overrides) + "".join(",".join(repr(float(x)) for x in row) + "\n" for row in rows)


def write(tmp_path, text, name="t.csv"):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def assert_same(a: Measurement, b: Measurement):
    for name in ("theta_i", "phi_i", "theta_o", "phi_o", "values"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert (a.sigma is None) == (b.sigma is None)
    if a.sigma is not None:
        assert np.array_equal(a.sigma, b.sigma)
    assert a.channels == b.channels
    assert a.provenance == b.provenance


def random_measurement(rng, n=50, channels=("R", "G", "B"), sigma=True, provenance=None):
    theta_i = rng.uniform(0, 90, n)
    theta_i[:2] = [0.0, 90.0]
    return Measurement(
        theta_i, rng.uniform(0, 360, n), rng.uniform(0, 90, n), rng.uniform(0, 360, n),
        np.concatenate([rng.uniform(0, 2, (n - 3, len(channels))),
                        np.array([[0.0], [1e-300], [0.1]]).repeat(len(channels), 1)]),
        channels, rng.uniform(1e-3, 0.1, (n, len(channels))) if sigma else None,
        provenance if provenance is not None else {}, None)


# ---------------------------------------------------------------------------------------------- reading

def test_reads_the_documented_layout(tmp_path):
    m = read_table(write(tmp_path, VALID))
    assert m.channels == ("R", "G", "B")
    assert m.n == 4
    np.testing.assert_array_equal(m.theta_o, [30, 30, 15, 60])
    np.testing.assert_array_equal(m.values[1], [0.11, 0.21, 0.31])
    np.testing.assert_array_equal(m.sigma[3], [0.05, 0.04, 0.03])
    assert m.provenance == {"instrument": "test gonio", "reference_standard": "Spectralon",
                            "sample_name": "twill", "simulated": True}
    assert m.source == str(tmp_path / "t.csv")


def test_columns_in_any_order_and_blank_lines(tmp_path):
    lines = VALID.splitlines()
    order = [7, 4, 0, 1, 2, 3, 5, 6, 9, 8]  # a permutation of the 10 columns
    shuffled = [",".join(line.split(",")[i] for i in order) for line in lines[7:]]
    text = "\n".join(lines[:7] + shuffled[:2] + [""] + shuffled[2:]) + "\n\n"
    assert_same(read_table(write(tmp_path, text)), read_table(write(tmp_path, VALID, "ref.csv")))


def test_crlf_line_endings(tmp_path):
    path = tmp_path / "t.csv"
    path.write_bytes(VALID.replace("\n", "\r\n").encode())
    assert_same(read_table(path), read_table(write(tmp_path, VALID, "ref.csv")))


# ----------------------------------------------------------------------------------------- conversions

def reference(tmp_path):
    return read_table(write(tmp_path, table_text(ROWS), "ref.csv"))


def test_cosine_weighted_is_brdf_times_cos_theta_i(tmp_path):
    rows = [(*r[:4], *(v * math.cos(math.radians(r[0])) for v in r[4:])) for r in ROWS]
    m = read_table(write(tmp_path, table_text(rows, quantity="cosine_weighted")))
    np.testing.assert_allclose(m.values, reference(tmp_path).values, rtol=1e-14)
    np.testing.assert_allclose(m.values, [r[4:] for r in ROWS], rtol=1e-14)


def test_reflectance_factor_is_pi_brdf(tmp_path):
    rows = [(*r[:4], *(v * math.pi for v in r[4:])) for r in ROWS]
    m = read_table(write(tmp_path, table_text(rows, quantity="reflectance_factor")))
    np.testing.assert_allclose(m.values, [r[4:] for r in ROWS], rtol=1e-14)


def test_sigma_is_converted_like_the_values(tmp_path):
    text = VALID.replace("quantity: brdf", "quantity: reflectance_factor")
    m = read_table(write(tmp_path, text))
    np.testing.assert_allclose(m.sigma[3], np.array([0.05, 0.04, 0.03]) / math.pi, rtol=1e-15)


def test_radians_equal_degrees(tmp_path):
    rows = [(*(math.radians(a) for a in r[:4]), *r[4:]) for r in ROWS]
    m = read_table(write(tmp_path, table_text(rows, angle_unit="rad")))
    ref = reference(tmp_path)
    np.testing.assert_allclose(m.theta_i, ref.theta_i, atol=1e-12)
    np.testing.assert_allclose(m.wi, ref.wi, atol=1e-14)
    np.testing.assert_allclose(m.wo, ref.wo, atol=1e-14)


def test_warp_zero_gives_the_same_vectors_with_phi_shifted_by_90(tmp_path):
    rows = [(r[0], (r[1] - 90.0) % 360.0, r[2], (r[3] - 90.0) % 360.0, *r[4:]) for r in ROWS]
    m = read_table(write(tmp_path, table_text(rows, azimuth_zero="warp")))
    ref = reference(tmp_path)
    np.testing.assert_allclose(m.wi, ref.wi, atol=1e-14)
    np.testing.assert_allclose(m.wo, ref.wo, atol=1e-14)
    # phi = 0 in a warp-zero file points along the warp, clothlab's +y
    single = read_table(write(tmp_path, table_text([(40.0, 0.0, 20.0, 0.0, 1, 1, 1)], azimuth_zero="warp"),
                              "one.csv"))
    np.testing.assert_allclose(single.wi[0], [0.0, math.sin(math.radians(40)), math.cos(math.radians(40))],
                               atol=1e-15)


def test_clockwise_sense_mirrors_the_azimuth(tmp_path):
    rows = [(r[0], (-r[1]) % 360.0, r[2], (-r[3]) % 360.0, *r[4:]) for r in ROWS]
    m = read_table(write(tmp_path, table_text(rows, azimuth_sense="cw")))
    ref = reference(tmp_path)
    np.testing.assert_allclose(m.wi, ref.wi, atol=1e-14)
    np.testing.assert_allclose(m.wo, ref.wo, atol=1e-14)


def test_source_conventions_recorded_only_when_converted(tmp_path):
    assert "source_header" not in reference(tmp_path).provenance
    m = read_table(write(tmp_path, table_text(ROWS, azimuth_zero="warp", quantity="reflectance_factor")))
    assert m.provenance["source_header"] == {"angle_unit": "deg", "quantity": "reflectance_factor",
                                             "azimuth_zero": "warp", "azimuth_sense": "ccw"}


def test_negative_azimuths_are_wrapped(tmp_path):
    m = read_table(write(tmp_path, table_text([(30.0, -90.0, 30.0, -180.0, 1, 1, 1)])))
    np.testing.assert_array_equal([m.phi_i[0], m.phi_o[0]], [270.0, 180.0])


# ------------------------------------------------------------------------------------------ round trips

def test_round_trip_is_exact_with_sigma_and_provenance(tmp_path):
    provenance = {"instrument": "gonio ü", "reference_standard": "Spectralon", "sample_name": "silk: satin",
                  "simulated": True, "seed": 12345, "noise": {"relative": 0.1, "levels": [1e-5, 2.5, None]},
                  "note": "line one\nline two # not a comment"}
    m = random_measurement(np.random.default_rng(3), provenance=provenance)
    back = read_table(write_table(m, tmp_path / "out" / "brdf.csv"))
    assert_same(m, back)


def test_round_trip_without_sigma_single_channel(tmp_path):
    m = random_measurement(np.random.default_rng(4), channels=("Y",), sigma=False)
    assert_same(m, read_table(write_table(m, tmp_path / "y.csv")))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_round_trip_exact_for_arbitrary_floats(tmp_path, data):
    n = data.draw(st.integers(1, 6))
    theta = st.floats(0, 90)
    phi = st.floats(0, 360, exclude_max=True)
    value = st.floats(0, 1e30, allow_subnormal=False)  # the declared range of a value (denormals refused)
    anchor = (45.5, 90.5, 45.5, 270.5)  # one row at a large angle: a deg table of tiny angles is refused
    rows = data.draw(st.lists(st.tuples(theta, phi, theta, phi, value, value).filter(lambda r: r[:4] != anchor),
                              min_size=n, max_size=n, unique_by=lambda r: r[:4]))
    a = np.array([*rows, (*anchor, 0.1, 0.2)])
    m = Measurement(a[:, 0], a[:, 1], a[:, 2], a[:, 3], a[:, 4:], ("a", "b"))
    assert_same(m, read_table(write_table(m, tmp_path / "h.csv", overwrite=True)))


@pytest.mark.parametrize("options", [
    {"quantity": "cosine_weighted", "angle_unit": "rad", "azimuth_zero": "warp", "azimuth_sense": "cw"},
    {"quantity": "reflectance_factor", "azimuth_zero": "warp"},
])
def test_round_trip_in_other_conventions(tmp_path, options):
    m = random_measurement(np.random.default_rng(5), provenance={"sample_name": "x"})
    m = m.subset(m.theta_i < 89.0)  # cosine-weighted values cannot be converted back at 90 deg
    path = write_table(m, tmp_path / "c.csv", **options)
    back = read_table(path)
    np.testing.assert_allclose(back.wi, m.wi, atol=1e-13)
    np.testing.assert_allclose(back.wo, m.wo, atol=1e-13)
    np.testing.assert_allclose(back.values, m.values, rtol=1e-13)
    np.testing.assert_allclose(back.sigma, m.sigma, rtol=1e-13)
    assert back.provenance["source_header"]["quantity"] == options["quantity"]
    assert back.provenance["sample_name"] == "x"


def test_write_refuses_to_overwrite(tmp_path):
    m = read_table(write(tmp_path, VALID))
    path = write_table(m, tmp_path / "o.csv")
    with pytest.raises(ResultExistsError, match="overwrite"):
        write_table(m, path)
    write_table(m.subset(np.arange(2)), path, overwrite=True)
    assert read_table(path).n == 2


def test_write_rejects_invalid_measurement_and_writes_nothing(tmp_path):
    m = read_table(write(tmp_path, VALID))
    values = m.values.copy()
    values[2, 1] = np.nan
    bad = Measurement(m.theta_i, m.phi_i, m.theta_o, m.phi_o, values, m.channels)
    with pytest.raises(InputError, match="not finite") as info:
        write_table(bad, tmp_path / "bad.csv")
    assert info.value.field == "G"
    assert not (tmp_path / "bad.csv").exists()
    assert [p.name for p in tmp_path.iterdir()] == ["t.csv"]


def test_write_rejects_unknown_keyword(tmp_path):
    m = read_table(write(tmp_path, VALID))
    with pytest.raises(ConfigError, match="quantity"):
        write_table(m, tmp_path / "x.csv", quantity="radiance")


# ------------------------------------------------------------------------------------------- sidecars

def headerless(text=VALID):
    return "\n".join(line for line in text.splitlines() if not line.startswith("#")) + "\n"


def sidecar_yaml(text=VALID):
    return "\n".join(line[2:] for line in text.splitlines() if line.startswith("#")) + "\n"


@pytest.mark.parametrize("sidecar_name", ["t.csv.yaml", "t.yaml"])
def test_sidecar_header_equals_in_file_header(tmp_path, sidecar_name):
    (tmp_path / sidecar_name).write_text(sidecar_yaml())
    assert_same(read_table(write(tmp_path, headerless())), read_table(write(tmp_path, VALID, "ref.csv")))


def test_sidecar_agreeing_with_file_header_is_fine(tmp_path):
    (tmp_path / "t.csv.yaml").write_text(sidecar_yaml())
    assert read_table(write(tmp_path, VALID)).n == 4


def test_conflicting_sidecar_is_an_error(tmp_path):
    (tmp_path / "t.csv.yaml").write_text(sidecar_yaml().replace("quantity: brdf", "quantity: cosine_weighted"))
    with pytest.raises(InputError, match="sidecar") as info:
        read_table(write(tmp_path, VALID))
    assert info.value.line == 3 and info.value.field == "quantity"
    assert "t.csv.yaml:3" in str(info.value)


def test_two_sidecars_are_an_error(tmp_path):
    (tmp_path / "t.csv.yaml").write_text(sidecar_yaml())
    (tmp_path / "t.yaml").write_text(sidecar_yaml())
    with pytest.raises(InputError, match="two sidecar"):
        read_table(write(tmp_path, headerless()))


def test_error_in_sidecar_names_the_sidecar_line(tmp_path):
    (tmp_path / "t.csv.yaml").write_text(sidecar_yaml().replace("azimuth_sense: ccw", "azimuth_sense: up"))
    with pytest.raises(InputError) as info:
        read_table(write(tmp_path, headerless()))
    assert info.value.path == str(tmp_path / "t.csv.yaml")
    assert info.value.line == 5 and info.value.field == "azimuth_sense"


# ----------------------------------------------------------------------------------------- validation

def set_field(line_no, column, new):
    def change(lines):
        fields = lines[line_no - 1].split(",")
        fields[COLUMNS.index(column)] = new
        lines[line_no - 1] = ",".join(fields)
    return change


def set_line(line_no, new):
    def change(lines):
        lines[line_no - 1] = new
    return change


def insert_line(line_no, new):
    def change(lines):
        lines.insert(line_no - 1, new)
    return change


def delete_line(line_no):
    def change(lines):
        del lines[line_no - 1]
    return change


CASES = {
    "nan": (set_field(10, "G", "nan"), 10, "G", "value nan is not finite"),
    "inf": (set_field(11, "phi_o", "inf"), 11, "phi_o", "value inf is not finite"),
    "negative": (set_field(12, "G", "-0.02"), 12, "G", "value -0.02 is negative; BRDF values must be >= 0"),
    "theta_i above 90": (set_field(9, "theta_i", "90.5"), 9, "theta_i", "outside [0, 90.0] deg"),
    "theta_o negative": (set_field(11, "theta_o", "-1"), 11, "theta_o", "outside [0, 90.0] deg"),
    "phi not finite": (set_field(10, "phi_i", "-inf"), 10, "phi_i", "not finite"),
    "duplicate": (set_line(12, "30,90,30,270,0.5,0.4,0.3,0.05,0.04,0.03"), 12, "theta_i,phi_i,theta_o,phi_o",
                  "as line 10"),
    "duplicate after wrapping": (set_line(12, "0,360,30,-180,0.5,0.4,0.3,0.05,0.04,0.03"), 12,
                                 "theta_i,phi_i,theta_o,phi_o", "as line 9"),
    "missing column": (set_line(8, "theta_i,phi_i,theta_o,phi_o,R,G,sigma_R,sigma_G,sigma_B"), 8, "B",
                       "required column 'B' is missing"),
    "unknown column": (set_line(8, "theta_i,phi_i,theta_o,phi_o,R,G,B,sigma_R,sigma_G,error_B"), 8, "error_B",
                       "unknown column 'error_B'"),
    "partial sigma": (set_line(8, "theta_i,phi_i,theta_o,phi_o,R,G,B,sigma_R,sigma_G"), 8, "sigma_B",
                      "all channels or none"),
    "duplicate column": (set_line(8, "theta_i,phi_i,theta_o,phi_o,R,G,B,sigma_R,sigma_G,R"), 8, "R",
                         "appears twice"),
    "unknown unit": (set_line(2, "# angle_unit: grad"), 2, "angle_unit", "unknown angle unit 'grad'"),
    "unknown quantity": (set_line(3, "# quantity: radiance"), 3, "quantity", "unknown quantity 'radiance'"),
    "unknown azimuth zero": (set_line(4, "# azimuth_zero: bias"), 4, "azimuth_zero", "expected one of"),
    "unknown azimuth sense": (set_line(5, "# azimuth_sense: up"), 5, "azimuth_sense", "ccw | cw"),
    "too few fields": (set_line(11, "60,45,15,0,0.12,0.22,0.32,0.01,0.02"), 11, "sigma_B",
                       "row has 9 fields, expected 10"),
    "too many fields": (set_line(11, "60,45,15,0,0.12,0.22,0.32,0.01,0.02,0.03,7"), 11, None,
                        "row has 11 fields, expected 10"),
    "non-numeric": (set_field(10, "R", "0.1x"), 10, "R", "value '0.1x' is not a number"),
    "empty field": (set_field(10, "R", " "), 10, "R", "empty field"),
    "sigma zero": (set_field(9, "sigma_G", "0"), 9, "sigma_G", "must be > 0"),
    "sigma negative": (set_field(9, "sigma_R", "-0.01"), 9, "sigma_R", "must be > 0"),
    "unknown header key": (insert_line(6, "# colour_space: sRGB"), 6, "colour_space",
                           "unknown header key 'colour_space'"),
    "header key twice": (insert_line(6, "# quantity: brdf"), 6, "quantity", "declared twice"),
    "unsupported version": (set_line(1, "# clothlab-table: 2"), 1, "clothlab-table", "version 2"),
    "comment after header": (insert_line(10, "# a note"), 10, None, "header block"),
    "bad channel name": (set_line(6, "# channels: [R, G, sigma_B]"), 6, "channels", "bad channel name"),
    "grazing cosine-weighted": (lambda lines: (set_line(3, "# quantity: cosine_weighted")(lines),
                                               set_field(12, "theta_i", "90")(lines)),
                                12, "theta_i", "cos(theta_i) = 0"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_validation_error_names_line_and_column(tmp_path, case):
    change, line, column, fragment = CASES[case]
    lines = VALID.splitlines()
    change(lines)
    path = write(tmp_path, "\n".join(lines) + "\n", "brdf.csv")
    with pytest.raises(InputError) as info:
        read_table(path)
    error = info.value
    message = str(error)
    assert fragment in message
    assert error.line == line
    assert f"brdf.csv:{line}" in message
    assert error.field == column
    if column is not None:
        assert f"'{column}'" in message


def test_missing_header_key(tmp_path):
    lines = VALID.splitlines()
    del lines[2]
    with pytest.raises(InputError, match="'quantity'.*missing") as info:
        read_table(write(tmp_path, "\n".join(lines)))
    assert info.value.field == "quantity"


def test_no_header_at_all(tmp_path):
    with pytest.raises(InputError, match="no clothlab-table header") as info:
        read_table(write(tmp_path, headerless()))
    assert info.value.line == 1


@pytest.mark.parametrize("text, line", [(header(), 7), (VALID.split("theta_i,")[0], 7)])
def test_empty_table(tmp_path, text, line):
    with pytest.raises(InputError, match="empty table") as info:
        read_table(write(tmp_path, text))
    assert info.value.line == line


def test_invalid_yaml_header_names_a_header_line(tmp_path):
    text = VALID.replace("# provenance: {instrument: test gonio,", "# provenance: {instrument: [test gonio,")
    with pytest.raises(InputError, match="not valid YAML") as info:
        read_table(write(tmp_path, text))
    assert info.value.line is not None and 1 <= info.value.line <= 7


def test_not_utf8(tmp_path):
    path = tmp_path / "t.csv"
    path.write_bytes(VALID.encode().replace(b"0.21", b"0.2\xff"))
    with pytest.raises(InputError, match="UTF-8") as info:
        read_table(path)
    assert info.value.line == 10


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="not found"):
        read_table(tmp_path / "nope.csv")


# --------------------------------------------------------------------------------------------- fuzzing

JUNK = ",#:-.e \t\n0123456789nafiNxyz[]{}'\"_\x00é\r"


@st.composite
def corruption(draw):
    text = VALID
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["delete", "insert", "replace", "drop_line", "dup_line", "swap", "truncate"]))
        lines = text.split("\n")
        if kind in ("drop_line", "dup_line", "swap"):
            i = draw(st.integers(0, len(lines) - 1))
            j = draw(st.integers(0, len(lines) - 1))
            if kind == "drop_line":
                del lines[i]
            elif kind == "dup_line":
                lines.insert(j, lines[i])
            else:
                lines[i], lines[j] = lines[j], lines[i]
            text = "\n".join(lines)
            continue
        if not text:
            continue
        pos = draw(st.integers(0, len(text) - 1))
        if kind == "delete":
            text = text[:pos] + text[pos + draw(st.integers(1, 5)):]
        elif kind == "insert":
            text = text[:pos] + draw(st.text(JUNK, min_size=1, max_size=4)) + text[pos:]
        elif kind == "replace":
            text = text[:pos] + draw(st.sampled_from(JUNK)) + text[pos + 1:]
        else:
            text = text[:pos]
    return text.encode("utf-8", errors="surrogatepass")


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=corruption(), invalid_byte=st.booleans())
def test_corrupted_files_give_input_error_or_a_valid_measurement(tmp_path, data, invalid_byte):
    if invalid_byte:
        data = data[: len(data) // 2] + b"\xfe" + data[len(data) // 2:]
    path = tmp_path / "fuzz.csv"
    path.write_bytes(data)
    try:
        m = read_table(path)
    except InputError as error:
        assert str(error).startswith(str(path))
        return
    assert m.n >= 1
    assert np.all(np.isfinite(m.values)) and np.all(m.values >= 0)
    assert np.all((m.theta_i >= 0) & (m.theta_i <= 90) & (m.theta_o >= 0) & (m.theta_o <= 90))


# ---------------------------------------------------------------------------------------- azimuth_offset

@pytest.mark.parametrize("options", [
    {"azimuth_offset": 45.0},
    {"azimuth_offset": -37.5, "azimuth_zero": "warp", "azimuth_sense": "cw", "angle_unit": "rad"},
    {"azimuth_offset": 360.0, "azimuth_sense": "cw"},
])
def test_azimuth_offset_round_trip(tmp_path, options):
    m = random_measurement(np.random.default_rng(9), provenance={"sample_name": "x"})
    path = write_table(m, tmp_path / "o.csv", **options)
    assert f"# azimuth_offset: {options['azimuth_offset']}" in path.read_text(encoding="utf-8")
    back = read_table(path)
    np.testing.assert_allclose(back.wi, m.wi, atol=1e-13)
    np.testing.assert_allclose(back.wo, m.wo, atol=1e-13)
    np.testing.assert_array_equal(back.values, m.values)
    assert back.provenance["source_header"]["azimuth_offset"] == options["azimuth_offset"]


@pytest.mark.parametrize("sense", ["ccw", "cw"])
def test_azimuth_offset_is_added_once_counter_clockwise(tmp_path, sense):
    """phi_clothlab = phi(zero, sense) + offset: the file's weft azimuth 0 ends at +offset."""
    rows = [(30.0, 0.0, 40.0, 100.0, 0.1, 0.2, 0.3), (50.0, 10.0, 20.0, 350.0, 0.2, 0.3, 0.4)]
    plain = read_table(write(tmp_path, table_text(rows, azimuth_sense=sense), "p.csv"))
    text = table_text(rows, azimuth_sense=sense).replace("# channels:", "# azimuth_offset: 45\n# channels:")
    turned = read_table(write(tmp_path, text, "t.csv"))
    np.testing.assert_allclose(np.mod(turned.phi_i - plain.phi_i, 360.0), 45.0, atol=1e-12)
    np.testing.assert_allclose(np.mod(turned.phi_o - plain.phi_o, 360.0), 45.0, atol=1e-12)
    np.testing.assert_array_equal(turned.theta_o, plain.theta_o)


def test_zero_azimuth_offset_is_not_written_and_reads_exactly(tmp_path):
    m = random_measurement(np.random.default_rng(2))
    path = write_table(m, tmp_path / "z.csv")
    assert "azimuth_offset" not in path.read_text(encoding="utf-8")
    assert_same(read_table(path), m)


@pytest.mark.parametrize("value, words", [
    ("'45'", "must be a number"), ("true", "must be a number"), (".nan", "not a finite angle"),
    ("400", "not a finite angle"), ("[1]", "must be a number"),
])
def test_bad_azimuth_offset_names_line_and_field(tmp_path, value, words):
    text = table_text(ROWS).replace("# channels:", f"# azimuth_offset: {value}\n# channels:")
    with pytest.raises(InputError, match=words) as info:
        read_table(write(tmp_path, text))
    assert info.value.field == "azimuth_offset" and info.value.line == 6


def test_write_rejects_bad_azimuth_offset(tmp_path):
    with pytest.raises(ConfigError, match="azimuth_offset"):
        write_table(random_measurement(np.random.default_rng(1)), tmp_path / "x.csv", azimuth_offset=float("nan"))
    assert not (tmp_path / "x.csv").exists()


@pytest.mark.parametrize("sense", ["ccw", "cw"])
@pytest.mark.parametrize("zero", ["weft", "warp"])
def test_azimuth_conversions_stay_in_one_turn(zero, sense):
    """np.mod(-1e-14, 360) is 360.0: the conversions map such an angle to 0, never to a full turn."""
    from clothlab.frames import azimuth_from_clothlab, azimuth_to_clothlab

    phi = np.array([0.0, 1e-14, -1e-14, 90.0 - 1e-14, 270.0 + 1e-13, 360.0 - 1e-13, 359.99999999999994])
    for convert in (azimuth_to_clothlab, azimuth_from_clothlab):
        out = convert(phi, zero=zero, sense=sense)
        assert np.all((out >= 0.0) & (out < 360.0))
        back = azimuth_from_clothlab(azimuth_to_clothlab(phi, zero=zero, sense=sense), zero=zero, sense=sense)
        assert np.allclose(np.cos(np.radians(back)), np.cos(np.radians(phi)), atol=1e-12)


def test_a_number_longer_than_the_strict_limit_is_refused_by_the_fast_path_too(tmp_path):
    """A row of plain digits whose field exceeds strict.MAX_NUMBER_CHARS (64) is refused at its line and column,
    as the strict per-field parse refuses it (the fast float() path once read an 82-character field)."""
    from clothlab.errors import InputError
    from clothlab.io.table import read_table
    from clothlab.untrusted import MAX_NUMBER_CHARS

    long_value = "0." + "1" * (MAX_NUMBER_CHARS - 1)  # 65 characters, plain decimal
    shipped_table = Path(__file__).resolve().parents[1] / "measurements" / "cotton-twill" / "clean.csv"
    shipped = shipped_table.read_text(encoding="utf-8").splitlines()
    header = [line for line in shipped if line.startswith("#")] + ["theta_i,phi_i,theta_o,phi_o,R,G,B"]
    path = tmp_path / "t.csv"
    path.write_text("\n".join(header + ["10,0,20,0,0.1,0.1,0.1", f"10,0,30,0,0.1,{long_value},0.1"]) + "\n",
                    encoding="utf-8")
    with pytest.raises(InputError) as info:
        read_table(path)
    assert info.value.line == len(header) + 2 and "G" in str(info.value)
