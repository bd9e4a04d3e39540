"""Fuzzing the input families that landed after issue 11's suite: the generic text importer and its options,
the MERL / UTIA / RGL-EPFL binary readers, the table header ``azimuth_offset``, fabric.yaml's ``select:``
section and the fit options added with it, and ``simulate --sampling`` / ``--orientation``.

Text families start from a valid file (or option set) and replace one field, line or option with a value
drawn from a pool of known-bad spellings or arbitrary text; binary families start from a valid file and
truncate it at any offset, overwrite a byte, a header field or a payload value (NaN, inf, denormal,
negative, 1e308), or replace the file with something else.  Every outcome must be one of

- a :class:`~clothlab.errors.ClothlabError` naming the file and a line, a byte offset or a dotted field (for
  a command-line option: the option), as one line, or
- a result that passes an independent validity check (finite numbers in range, unit upper-hemisphere
  directions, the declared conventions applied),

and the allocation peak of a binary read stays bounded (a header claiming huge dimensions is refused before
anything is allocated; :mod:`tracemalloc` sees numpy's buffers).  Any other exception fails the test.

The default run draws ``CLOTHLAB_FUZZ_EXAMPLES`` (default 25) cases per family (a few seconds in all); each
family prints its outcome counts (``pytest -s``); ``--runslow`` adds a child run of 1,000 per family.
Reproducers of what these families found are in ``tests/fuzz_corpus/`` (``import--``, ``ok--``, ``merl--``,
``bsdf--``, ``measurement--``, ``select--``, ``sampling--``, ``cli--`` files) with their tests at the end.
"""

from __future__ import annotations

import collections
import math
import os
import re
import struct
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_fuzz_inputs import mutate_lines  # one line-level mutation for every fuzz family

from clothlab.errors import ClothlabError

EXAMPLES = int(os.environ.get("CLOTHLAB_FUZZ_EXAMPLES", "25"))
SETTINGS = settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow,
                                           HealthCheck.data_too_large])

BAD_TOKENS = [
    "0_1", "1_000.5", "nan", "NaN", ".nan", "inf", "-inf", ".inf", "infinity", "1e-320", "4.9e-324", "-1e-310",
    "1e308", "1e31", "1e300", "1e400", "2020-02-30", "12:30:00", "", " ", "\u0661", "0x10", "0o7", "1e", "--1",
    "9" * 5000, "1" + "0" * 400, "a\x00b", "1,2", "1;2", "1\t2", "'1'", "\"1\"", "[1]", "{a: 1}", "*a", "-0", "0",
    "1", "91", "-1", ".5", "1.", "+1", "720", "-400", "359.9", "360", "361", "1e-30", "true", "null", "~",
    "\ufeff1", "#", "# 1", "x", "R", "theta_i", "\r", "\u00e9",
]
TOKENS = st.one_of(st.sampled_from(BAD_TOKENS), st.text(max_size=12),
                   st.floats(allow_nan=True, allow_infinity=True).map(repr))

SPECIAL_FLOATS = [math.nan, -math.nan, math.inf, -math.inf, 1e-320, -1e-320, 5e-324, 2.2e-308, -1.0, -1e-3,
                  1e308, -1e308, 1e31, 1e30, 0.0, -0.0, 1.0]
SPECIAL_INTS = [0, 1, -1, 2, 3, 90, 180, 4096, 4097, 2**16, 2**31 - 1, -2**31, 2**30, 2**63 - 1, 2**64 - 1, 2**32,
                12, 255]
DECIMAL = r"[+-]?([0-9]+(\.[0-9]*)?|\.[0-9]+)([eE][+-]?[0-9]+)?"  # the documented notation, written here again
DIGITS = r"[0-9]+"
BYTES_LIMIT = 96 << 20
"""Allocation peak allowed while reading one fuzzed binary file (the valid files are at most 2 MB)."""


# ---------------------------------------------------------------------------------------------------------
# Outcome checks

def named(exc: ClothlabError, paths=(), options=()) -> bool:
    """True when ``exc`` names one of ``paths`` and a place in it (line, byte offset or field), or names one of
    the command-line ``options`` as its field."""
    text = str(exc)
    if "\n" in text.strip():
        return False
    if exc.path is None:
        return exc.field is not None and any(exc.field == o or exc.field.endswith(o) for o in options)
    if not any(str(p) in exc.path for p in paths):
        return False
    return exc.line is not None or exc.field is not None or "byte offset" in exc.detail


def outcome(counts, fn, *args, paths=(), options=(), **kwargs):
    """Run ``fn``; count and return ('refused', exc) or ('accepted', result); other exceptions propagate."""
    try:
        result = fn(*args, **kwargs)
    except ClothlabError as exc:
        assert named(exc, paths, options), (type(exc).__name__, str(exc), exc.path, exc.line, exc.field)
        counts["refused (named)"] += 1
        return "refused", exc
    counts["accepted (valid)"] += 1
    return "accepted", result


def report(family: str, counts) -> None:
    print(f"\nfuzz {family}: {sum(counts.values())} cases: {dict(counts)}")


def bounded(fn, *args, **kwargs):
    """``fn(*args)`` with its allocation peak (numpy buffers included) checked against :data:`BYTES_LIMIT`."""
    tracemalloc.start()
    try:
        return fn(*args, **kwargs)
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        assert peak <= BYTES_LIMIT, f"allocation peak {peak} bytes reading a fuzzed file"


def unit_upper(theta_deg, phi_deg) -> None:
    """Directions from (theta, phi) in degrees, computed here: unit length and in the upper hemisphere."""
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    v = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)
    assert np.allclose(np.linalg.norm(v, axis=-1), 1.0, atol=1e-12)
    assert (v[..., 2] >= -1e-12).all()


def valid_measurement(m, channels=None) -> None:
    """An accepted measurement: >= 2 rows, clothlab's convention, finite normal values >= 0, unique pairs."""
    assert m.n >= 2
    for a in (m.theta_i, m.theta_o, m.phi_i, m.phi_o):
        assert a.shape == (m.n,) and np.isfinite(a).all()
    for a in (m.theta_i, m.theta_o):
        assert (a >= 0).all() and (a <= 90).all()
    for a in (m.phi_i, m.phi_o):
        assert (a >= 0).all() and (a < 360).all()
    unit_upper(m.theta_i, m.phi_i)
    unit_upper(m.theta_o, m.phi_o)
    v = m.values
    assert v.shape == (m.n, len(m.channels)) and len(m.channels) >= 1
    assert np.isfinite(v).all() and (v >= 0).all() and (v <= 1e30 * 2).all()
    tiny = np.finfo(np.float64).tiny
    assert not ((v > 0) & (v < tiny / 4)).any()
    if m.sigma is not None:
        assert np.isfinite(m.sigma).all() and (m.sigma > 0).all()
    assert len(set(m.channels)) == len(m.channels)
    assert (v > 0).any(axis=0).all(), "a channel holds no reflected light"
    assert all(isinstance(c, str) and c and not any(ch in c for ch in " ,#'\"\n") for c in m.channels)
    if channels is not None:
        assert tuple(m.channels) == tuple(channels)
    keys = set(zip(m.theta_i.tolist(), m.phi_i.tolist(), m.theta_o.tolist(), m.phi_o.tolist(), strict=True))
    assert len(keys) == m.n


def replace_field(line: str, col: int, token: str, sep: str) -> str:
    fields = line.split(sep) if sep != " " else line.split()
    fields[col % len(fields)] = token
    return (sep if sep != " " else " ").join(fields)


def encode(text: str) -> bytes:
    return text.encode("utf-8", "surrogatepass")


# ---------------------------------------------------------------------------------------------------------
# The generic text importer (clothlab import, clothlab.io.generic)

ROWS = [(10.0 * k % 85, 30.0 * k % 360, (17.0 * k + 5) % 85, (45.0 * k + 10) % 360, 0.1 + 0.01 * k, 0.2, 0.3)
        for k in range(8)]
LAB_COMMENT = "% lab export, gonio 2"


def lab_lines(sep: str = ";") -> list[str]:
    return (["# exported by the lab", "ti;pi;tv;pv;red;green;blue".replace(";", sep)]
            + [sep.join(repr(v) for v in r) for r in ROWS])


def valid_written(written, m, channels=None) -> None:
    """An accepted import: a valid measurement, written as a clothlab table that reads back the same."""
    from clothlab.io.table import read_table

    valid_measurement(m, channels)
    back = read_table(written)
    assert back.channels == m.channels
    for a, b in ((back.theta_i, m.theta_i), (back.phi_i, m.phi_i), (back.theta_o, m.theta_o),
                 (back.phi_o, m.phi_o), (back.values, m.values)):
        np.testing.assert_array_equal(a, b)


LAB_COLUMNS = "theta_i=ti,phi_i=pi,theta_o=tv,phi_o=pv,R=red,G=green,B=blue"


def test_fuzz_generic_text(tmp_path):
    """One field, line or the separator of a lab's table mutated; read with a fixed mapping."""
    from clothlab.io.generic import import_table

    (tmp_path / "base.txt").write_text("\n".join(lab_lines()) + "\n")
    valid_written(*import_table(tmp_path / "base.txt", tmp_path / "base.csv", columns=LAB_COLUMNS), ("R", "G", "B"))
    counts = collections.Counter()
    path, out = tmp_path / "lab.txt", tmp_path / "out.csv"

    @SETTINGS
    @given(data=st.data())
    def run(data):
        sep = data.draw(st.sampled_from([";", ",", "\t", " "]))
        lines = lab_lines(sep)
        token = data.draw(TOKENS)
        op = data.draw(st.integers(0, 5))
        if op <= 1:
            row = data.draw(st.integers(2 - op, len(lines) - 1))  # op 1 also mutates the header row
            lines[row] = replace_field(lines[row], data.draw(st.integers(0, 6)), token, sep)
        elif op == 2:
            lines = mutate_lines(lines, data.draw(st.integers(0, 3)), data.draw(st.integers(0, len(lines) - 1)),
                                 token)
        elif op == 3:  # a stray separator or comment character inside a row
            row = data.draw(st.integers(1, len(lines) - 1))
            at = data.draw(st.integers(0, len(lines[row])))
            lines[row] = lines[row][:at] + data.draw(st.sampled_from([";", ",", "\t", " ", "#", "%", '"'])) \
                + lines[row][at:]
        elif op == 4:  # line endings and encodings
            lines = [line + data.draw(st.sampled_from(["\r", " ", "\t", ""])) for line in lines]
        else:
            lines = lines[: data.draw(st.integers(0, len(lines)))]
        path.write_bytes(encode("\n".join(lines) + data.draw(st.sampled_from(["\n", "", "\n\n"]))))
        delimiter = data.draw(st.sampled_from(["auto", {";": "semicolon", ",": "comma", "\t": "tab",
                                                        " ": "whitespace"}[sep]]))
        kind, result = outcome(counts, import_table, path, out, overwrite=True, columns=LAB_COLUMNS,
                               delimiter=delimiter, paths=(path,), options=("columns", "delimiter"))
        if kind == "accepted":
            valid_written(*result, ("R", "G", "B"))

    run()
    report("import/text", counts)


OPTION_VALUES = {
    "columns": [LAB_COLUMNS, "theta_i,phi_i,theta_o,phi_o,R,G,B", "theta_i,phi_i,theta_o,phi_o,R,-,-",
                "-,theta_i,phi_i,theta_o,phi_o,R", "theta_i,phi_i,theta_o,phi_o", "theta_i=ti,phi_i=pi",
                "theta_i,phi_i,theta_o,phi_o,R,G,B,X", "theta_i,theta_i,theta_o,phi_o,R", "theta_i=ti,phi_i",
                "theta_i=,phi_i=pi,theta_o=tv,phi_o=pv,R=red", "theta_i,phi_i,theta_o,phi_o,sigma_R,R",
                "theta_i,phi_i,theta_o,phi_o,R,sigma_R,G", ",", "", None, ["theta_i", 1], [],
                "theta_i=ti,phi_i=pi,theta_o=tv,phi_o=pv,R=nope", "theta_i,phi_i,theta_o,phi_o,R R"],
    "delimiter": ["auto", "whitespace", "comma", "semicolon", "tab", ";", "", None, 1],
    "comment": ["#", "%", "", "!", "1", "-", ".", "e", "##", None, 5, "\x00", ";", " "],
    "header": ["auto", "yes", "no", "", True, None],
    "angle_unit": ["deg", "rad", "grad", "", None, 0, "DEG"],
    "azimuth_zero": ["weft", "warp", "x", "y", "z", "", None],
    "azimuth_sense": ["ccw", "cw", "CW", "clockwise", "", None],
    "azimuth_offset": [0.0, 0, 90, -90.5, 359.9, 360, -360, 360.0001, 1e308, math.nan, math.inf, -math.inf,
                       True, "90", None, [90], 1e-320, 10**400],
    "quantity": ["brdf", "reflectance_factor", "cosine_weighted", "dsf", "", None],
    "channels": [None, "R,G,B", "grey,g2,g3", "1e3,2,no", "a,a,b", "R,G", "R,G,B,A", ",,", "", "x y,z,w",
                 ["r", "g", "b"], "R,,B", "theta_i,G,B", "r#,g,b"],
}
VALID_OPTIONS = {
    "columns": (LAB_COLUMNS, "theta_i,phi_i,theta_o,phi_o,R,G,B", "theta_i,phi_i,theta_o,phi_o,R,-,-"),
    "delimiter": ("auto",), "comment": ("#", "%", ""), "header": ("auto", "yes", "no"),
    "angle_unit": ("deg", "rad"), "azimuth_zero": ("weft", "warp", "x", "y"), "azimuth_sense": ("ccw", "cw"),
    "azimuth_offset": (0.0, 0, 90, -90.5, 359.9, 360, -360), "quantity": ("brdf", "reflectance_factor",
                                                                        "cosine_weighted"),
    "channels": (None, "R,G,B", "grey,g2,g3", "1e3,2,no"),
}
LAB_TABLES = {
    "semicolon header": "\n".join(lab_lines(";")),
    "tabs no header": "\n".join(lab_lines("\t")[2:]),
    "percent comments": LAB_COMMENT + "\n" + "\n".join(lab_lines(",")[1:]),
    "grazing rows": "\n".join(lab_lines(",")[:2] + ["89.99999999999,0,90,10,0.1,0.2,0.3", "90,5,10,0,0.1,0.2,0.3"]
                              + lab_lines(",")[2:]),
}


TABLE_OPTIONS = {
    "semicolon header": {"columns": LAB_COLUMNS}, "tabs no header": {"columns": "theta_i,phi_i,theta_o,phi_o,R,G,B"},
    "percent comments": {"columns": LAB_COLUMNS, "comment": "%"}, "grazing rows": {"columns": LAB_COLUMNS},
}


def test_fuzz_generic_options(tmp_path):
    """Every option of ``clothlab import`` drawn from valid and bad values, over a few lab tables."""
    from clothlab.io.generic import import_table

    counts = collections.Counter()
    path, out = tmp_path / "lab.csv", tmp_path / "out.csv"

    @SETTINGS
    @given(data=st.data())
    def run(data):
        table = data.draw(st.sampled_from(sorted(LAB_TABLES)))
        path.write_text(LAB_TABLES[table] + "\n")
        options = dict(TABLE_OPTIONS[table])  # what the table needs, unless drawn below
        for name, pool in OPTION_VALUES.items():
            if data.draw(st.integers(0, 2)) != 0:
                continue
            choice = data.draw(st.integers(0, 9))  # mostly valid values, so that accepted results are checked
            pool = list(VALID_OPTIONS[name]) if choice < 6 else pool
            options[name] = data.draw(TOKENS) if choice == 9 else data.draw(st.sampled_from(pool))
        kind, result = outcome(counts, import_table, path, out, overwrite=True, **options, paths=(path,),
                               options=tuple(OPTION_VALUES))
        if kind == "accepted":
            valid_written(*result)
            check_conventions(result[1], table, options)
        elif table == "tabs no header" and options.get("header", "auto") != "yes" and all(
                any(v == g and type(v) is type(g) for g in VALID_OPTIONS[n]) for n, v in options.items()) \
                and options.get("angle_unit", "deg") == "deg" and options["columns"] != LAB_COLUMNS:
            raise AssertionError(f"valid options refused: {options}: {result}")  # nothing good is lost

    run()
    report("import/options", counts)


def check_conventions(m, table: str, options: dict) -> None:
    """The accepted measurement holds the table's rows converted as the options declare (recomputed here)."""
    rows = np.array(ROWS)
    if table == "grazing rows" or options.get("columns") not in (LAB_COLUMNS, TABLE_OPTIONS["tabs no header"][
            "columns"]) or m.n != len(rows) or options.get("channels") is not None:
        return
    unit = options.get("angle_unit", "deg")
    angles = rows[:, :4] if unit == "deg" else np.degrees(rows[:, :4])
    offset = float(options.get("azimuth_offset", 0.0))
    sense = options.get("azimuth_sense", "ccw")
    zero = options.get("azimuth_zero", "weft")
    for col, phi in ((1, m.phi_i), (3, m.phi_o)):
        file_phi = angles[:, col]
        ccw = file_phi if sense == "ccw" else -file_phi
        ccw = ccw + (90.0 if zero in ("warp", "y") else 0.0)
        expected = np.mod(ccw + offset, 360.0)
        diff = np.abs(np.mod(phi - expected + 180.0, 360.0) - 180.0)
        near_normal = angles[:, col - 1] == 0.0
        assert (diff[~near_normal] < 1e-6).all(), (options, phi, expected)
    scale = {"brdf": 1.0, "reflectance_factor": 1.0 / math.pi}.get(options.get("quantity", "brdf"))
    if scale is not None:
        np.testing.assert_allclose(m.values[:, 0], rows[:, 4] * scale, rtol=1e-12)


MEASUREMENT_YAML = {
    "text": ("lab.csv", "{columns: 'theta_i=ti,phi_i=pi,theta_o=tv,phi_o=pv,R=red,G=green,B=blue', delimiter: "
                        "semicolon, comment: '#', header: auto, angle_unit: deg, azimuth_zero: weft, "
                        "azimuth_sense: ccw, azimuth_offset: 12.5, quantity: brdf, channels: [r, g, b]}"),
    "merl": ("m.binary", "{theta_step: 15, phi_step: 30, theta_max: 80}"),
    "utia": ("u.bin", "{azimuth_zero: warp, azimuth_sense: cw, azimuth_offset: -20, quantity: brdf, "
                      "negative: error}"),
}
MEASUREMENT_VALUES = ["'theta_i=ti,phi_i=pi,theta_o=tv,phi_o=pv,R=red,G=green,B=blue'", "semicolon", "'#'", "auto",
                      "deg", "weft", "ccw", "12.5", "brdf", "[r, g, b]", "r", "15", "30", "80", "warp", "cw", "-20",
                      "error", "text", "merl", "utia"]


def test_fuzz_measurement_options_in_fabric_yaml(tmp_path):
    """``measurement.format: text | merl | utia`` with ``measurement.options`` mutated: refused at the option's
    line in fabric.yaml (or naming the measurement file and place), or a valid measurement."""
    from clothlab.config import load_config
    from clothlab.io.loader import load_measurement

    (tmp_path / "lab.csv").write_text("\n".join(lab_lines(";")) + "\n")
    merl_file(tmp_path / "m.binary")
    utia_file(tmp_path / "u.bin")
    counts = collections.Counter()
    path = tmp_path / "f.yaml"

    def load(path):
        cfg = load_config(path)
        return load_measurement(cfg.measurement.path, cfg.measurement.format, **cfg.measurement.options)

    for fmt, (name, options) in MEASUREMENT_YAML.items():  # the unmutated files are valid
        path.write_text(f"name: x\nmeasurement:\n  path: {name}\n  format: {fmt}\n  options: {options}\n"
                        "model: {kind: irawan, weave: preset:cotton-denim}\n")
        valid_measurement(load(path))

    @SETTINGS
    @given(fmt=st.sampled_from(sorted(MEASUREMENT_YAML)), old=st.sampled_from(MEASUREMENT_VALUES),
           token=st.one_of(TOKENS, st.sampled_from(["[]", "{}", "[1, 2]", "0.5", "45", "89.9", "-360", "x,y,z",
                                                    "'theta_i,phi_i,theta_o,phi_o,R'", "tab", "'%'", "zero"])),
           nth=st.integers(0, 3))
    def run(fmt, old, token, nth):
        name, options = MEASUREMENT_YAML[fmt]
        text = (f"name: x\nmeasurement:\n  path: {name}\n  format: {fmt}\n  options: {options}\n"
                "model: {kind: irawan, weave: preset:cotton-denim}\n")
        if old in text:
            pieces = text.split(old)
            k = 1 + nth % (len(pieces) - 1)
            text = old.join(pieces[:k]) + token + old.join(pieces[k:])
        path.write_bytes(encode(text))
        kind, m = outcome(counts, load, path, paths=(path, tmp_path / name))
        if kind == "accepted":
            valid_measurement(m)

    run()
    report("measurement.options (text/merl/utia)", counts)


# ---------------------------------------------------------------------------------------------------------
# Binary formats

def _f8(data: bytearray, offset: int, value: float) -> None:
    struct.pack_into("<d", data, offset, value)


OTHER_FILES = {
    "empty": b"", "text table": b"theta_i,phi_i,theta_o,phi_o,R\n10,0,10,180,0.1\n",
    "png": b"\x89PNG\r\n\x1a\n" + b"\0" * 64,
    "zip": b"PK\x03\x04" + b"\0" * 100, "one byte": b"\x01", "utf16": "hello".encode("utf-16"),
    "tensor magic only": b"tensor_file\x00", "nul": b"\0" * 4096, "ff": b"\xff" * 4096,
}


def byte_mutation(data: bytes, draw, fields: list[tuple[int, str]], payload: tuple[int, int, int]) -> bytes:
    """One mutation of ``data``: truncate, overwrite a byte, a header field (offset, struct format) or an
    aligned payload value ((start, itemsize, count)), append bytes, or something else entirely."""
    out = bytearray(data)
    op = draw(st.integers(0, 6))
    if op == 0:
        return bytes(out[: draw(st.integers(0, max(len(out) - 1, 0)))])
    if op == 1:
        at = draw(st.one_of(st.integers(0, min(len(out) - 1, 256)), st.integers(0, len(out) - 1)))
        out[at] = draw(st.one_of(st.integers(0, 255), st.just(out[at] ^ 0x80)))
        return bytes(out)
    if op == 2 and fields:  # one to three header fields overwritten
        for offset, fmt in draw(st.lists(st.sampled_from(fields), min_size=1, max_size=3)):
            size = struct.calcsize(fmt)
            if fmt[-1] in "dfe":
                value = draw(st.sampled_from(SPECIAL_FLOATS))
            else:
                value = draw(st.sampled_from(SPECIAL_INTS)) % (1 << (8 * size))
                if fmt[-1].islower():
                    value = value - (1 << (8 * size)) if value >= 1 << (8 * size - 1) else value
            struct.pack_into(fmt, out, offset, value)
        return bytes(out)
    if op in (2, 3):
        start, itemsize, count = payload
        k = draw(st.integers(0, count - 1))
        value = draw(st.sampled_from(SPECIAL_FLOATS))
        struct.pack_into({8: "<d", 4: "<f", 2: "<e"}[itemsize], out, start + itemsize * k,
                         value if itemsize == 8 or abs(value) < 6e4 or not math.isfinite(value) else math.inf)
        return bytes(out)
    if op == 4:
        if draw(st.booleans()):  # a run of payload values overwritten (a whole channel, or most of the file)
            start, itemsize, count = payload
            first = draw(st.integers(0, count - 1))
            size = draw(st.sampled_from([count // 3, count, count - first]))
            value = draw(st.sampled_from([0.0, -1.0, 1e-320, 1e31]))
            run = np.full(min(size, count - first), value, dtype={8: "<f8", 4: "<f4", 2: "<f2"}[itemsize])
            out[start + itemsize * first: start + itemsize * first + run.nbytes] = run.tobytes()
            return bytes(out)
        return bytes(out) + draw(st.binary(min_size=1, max_size=16))
    if op == 5:
        return draw(st.sampled_from(sorted(OTHER_FILES.values())))
    return draw(st.binary(max_size=64)) + bytes(out[draw(st.integers(0, 64)):])


MERL_SMALL = (3, 4, 8)


def merl_file(path: Path) -> bytes:
    from clothlab.io.merl import write_merl

    rng = np.random.default_rng(3)
    stored = rng.uniform(1.0, 3000.0, size=(3, *MERL_SMALL))
    stored[0, 0, 0, 1] = -1.0  # one unmeasured bin
    write_merl(stored, path, overwrite=True)
    return path.read_bytes()


def test_fuzz_merl(tmp_path):
    from clothlab.io.loader import load_measurement

    base = merl_file(tmp_path / "base.binary")
    valid_measurement(load_measurement(tmp_path / "base.binary"), ("R", "G", "B"))
    count = 3 * int(np.prod(MERL_SMALL))
    fields = [(0, "<i"), (4, "<i"), (8, "<i"), (0, "<q")]
    counts = collections.Counter()
    path = tmp_path / "m.binary"

    @SETTINGS
    @given(data=st.data())
    def run(data):
        path.write_bytes(byte_mutation(base, data.draw, fields, (12, 8, count)))
        fmt = data.draw(st.sampled_from(["auto", "merl"]))
        kind, m = outcome(counts, bounded, load_measurement, path, fmt, paths=(path,))
        if kind == "accepted":
            valid_measurement(m, ("R", "G", "B"))
            assert m.provenance["isotropic"] is True

    run()
    report("merl", counts)


def utia_file(path: Path) -> bytes:
    from clothlab.io.utia import UTIA_SHAPE, write_utia

    rng = np.random.default_rng(4)
    write_utia(rng.uniform(0.01, 2.0, UTIA_SHAPE), path, overwrite=True)
    return path.read_bytes()


def test_fuzz_utia(tmp_path):
    from clothlab.io.loader import load_measurement
    from clothlab.io.utia import UTIA_BYTES

    base = utia_file(tmp_path / "base.bin")
    valid_measurement(load_measurement(tmp_path / "base.bin"), ("R", "G", "B"))
    counts = collections.Counter()
    path = tmp_path / "u.bin"

    @SETTINGS
    @given(data=st.data())
    def run(data):
        path.write_bytes(byte_mutation(base, data.draw, [], (0, 8, UTIA_BYTES // 8)))
        options = {}
        for name, pool in (("negative", ["error", "zero", "clip", None]), ("azimuth_zero", ["weft", "warp", "q"]),
                           ("azimuth_sense", ["ccw", "cw", 1]),
                           ("azimuth_offset", [0.0, 45.0, -400.0, math.nan, "7", True, 360.0]),
                           ("quantity", ["brdf", "cosine_weighted", "reflectance_factor", "dsf"])):
            if data.draw(st.integers(0, 3)) == 0:
                options[name] = data.draw(st.sampled_from(pool))
        fmt = data.draw(st.sampled_from(["auto", "utia"]))
        kind, m = outcome(counts, bounded, load_measurement, path, fmt, **options, paths=(path,),
                          options=tuple(options))
        if kind == "accepted":
            valid_measurement(m, ("R", "G", "B"))

    run()
    report("utia", counts)


def tensor_fields():
    rng = np.random.default_rng(5)
    return {"theta_i": np.linspace(0.0, 1.2, 4).astype(np.float32),
            "phi_i": np.linspace(0.0, 3.0, 3).astype(np.float32),
            "ndf": rng.uniform(0.1, 2.0, (4, 6)).astype(np.float32),
            "rgb": rng.uniform(0.0, 1.0, (4, 3, 2, 3)).astype(np.float32),
            "valid": np.ones((2, 3), np.uint8),
            "description": np.frombuffer(b"fuzz fabric", np.uint8).copy()}


def tensor_layout(data: bytes):
    """(header fields as (offset, struct format), payload spans as (start, itemsize, count)) of a tensor file,
    parsed here independently of clothlab's reader."""
    fields = [(12, "<B"), (13, "<B"), (14, "<I")]
    spans = []
    pos = 18
    for _ in range(struct.unpack_from("<I", data, 14)[0]):
        fields.append((pos, "<H"))
        (length,) = struct.unpack_from("<H", data, pos)
        pos += 2 + length
        fields += [(pos, "<H"), (pos + 2, "<B"), (pos + 3, "<Q")]
        (ndim,) = struct.unpack_from("<H", data, pos)
        code = data[pos + 2]
        (offset,) = struct.unpack_from("<Q", data, pos + 3)
        pos += 11
        shape = struct.unpack_from(f"<{ndim}Q", data, pos)
        fields += [(pos + 8 * i, "<Q") for i in range(ndim)]
        pos += 8 * ndim
        if code in (9, 10, 11):
            spans.append((offset, {9: 2, 10: 4, 11: 8}[code], int(np.prod(shape))))
    return fields, spans


def test_fuzz_tensor_file(tmp_path):
    from clothlab.io.loader import load_measurement
    from clothlab.io.rglbsdf import NON_NEGATIVE_FIELDS, read_tensor_file, write_tensor_file

    write_tensor_file(tensor_fields(), tmp_path / "base.bsdf")
    base = (tmp_path / "base.bsdf").read_bytes()
    assert set(read_tensor_file(tmp_path / "base.bsdf")) == set(tensor_fields())
    fields, spans = tensor_layout(base)
    counts = collections.Counter()
    path = tmp_path / "t.bsdf"

    @SETTINGS
    @given(data=st.data())
    def run(data):
        payload = data.draw(st.sampled_from(spans))
        mutated = byte_mutation(base, data.draw, fields, payload)
        path.write_bytes(mutated)
        if data.draw(st.integers(0, 3)) == 0:  # the whole loader: always refused (the warp is not inverted)
            kind, _ = outcome(counts, bounded, load_measurement, path, data.draw(st.sampled_from(["auto", "bsdf"])),
                              paths=(path,))
            assert kind == "refused"
            return
        kind, result = outcome(counts, bounded, read_tensor_file, path, paths=(path,))
        if kind == "accepted":
            ends = []
            for f in result.values():
                assert isinstance(f.name, str) and f.name
                nbytes = f.data.dtype.itemsize * f.data.size
                assert 0 <= f.offset and f.offset + nbytes <= len(mutated)
                ends.append((f.offset, f.offset + nbytes))
                if f.data.dtype.kind == "f":
                    x = f.data.astype(np.float64)
                    assert np.isfinite(x).all() and (np.abs(x) <= 1e30).all()
                if f.name in NON_NEGATIVE_FIELDS:
                    assert (f.data >= 0).all()
            ends.sort()
            assert all(a[1] <= b[0] for a, b in zip(ends, ends[1:], strict=False)), ends  # no two fields overlap

    run()
    report("bsdf tensor file", counts)


# ---------------------------------------------------------------------------------------------------------
# The table header azimuth_offset

TABLE_HEADER = ["# clothlab-table: 1", "# angle_unit: {unit}", "# quantity: brdf", "# azimuth_zero: weft",
                "# azimuth_sense: {sense}", "# azimuth_offset: {offset}", "# channels: [R, G, B]",
                "theta_i,phi_i,theta_o,phi_o,R,G,B"]


def header_table(offset: str, unit: str = "deg", sense: str = "ccw") -> str:
    rows = [[math.radians(v) if unit == "rad" and i < 4 else v for i, v in enumerate(r)] for r in ROWS]
    head = [line.format(unit=unit, sense=sense, offset=offset) for line in TABLE_HEADER]
    return "\n".join(head + [",".join(repr(v) for v in r) for r in rows]) + "\n"


def test_fuzz_table_azimuth_offset(tmp_path):
    from clothlab.io.table import read_table

    (tmp_path / "base.csv").write_text(header_table("0"))
    reference = read_table(tmp_path / "base.csv")
    counts = collections.Counter()
    path = tmp_path / "t.csv"

    @SETTINGS
    @given(token=st.one_of(TOKENS, st.floats(-720, 720).map(repr)), unit=st.sampled_from(["deg", "rad"]),
           sense=st.sampled_from(["ccw", "cw"]), sidecar=st.booleans())
    def run(token, unit, sense, sidecar):
        text = header_table(token, unit, sense)
        side = tmp_path / "t.csv.yaml"
        if sidecar:  # the offset in a sidecar header instead
            lines = text.split("\n")
            side.write_bytes(encode(f"azimuth_offset: {token}\n"))
            text = "\n".join(line for line in lines if "azimuth_offset" not in line)
        elif side.exists():
            side.unlink()
        path.write_bytes(encode(text))
        kind, m = outcome(counts, read_table, path, paths=(path, side))
        if kind == "accepted":
            valid_measurement(m, ("R", "G", "B"))
            offset = float(m.provenance.get("source_header", {}).get("azimuth_offset", 0.0))
            assert abs(offset) <= 360.0
            np.testing.assert_allclose(m.theta_i, reference.theta_i, atol=1e-9)
            sign = 1.0 if sense == "ccw" else -1.0
            for got, ref in ((m.phi_i, reference.phi_i), (m.phi_o, reference.phi_o)):
                expected = np.mod(sign * ref + offset, 360.0)
                assert (np.abs(np.mod(got - expected + 180.0, 360.0) - 180.0) < 1e-6).all()

    run()
    report("table azimuth_offset", counts)


# ---------------------------------------------------------------------------------------------------------
# fabric.yaml: select and the fit options added with it

FABRIC = """\
name: fuzz
measurement: {path: m.csv, format: clothlab}
model:
  kind: irawan
  weave: preset:cotton-denim
  params: {alpha: 0.05, orientation: 10}
  options: {filament_arc: shortened}
fit:
  free: [alpha, orientation]
  bounds: {orientation: [-80, 95]}
  loss: huber
  loss_scale: 0.25
  cv_folds: 3
  cv_scheme: grouped
  cv_refit: local
  valid_geometry: true
  optimizer: {global: null, local: LN_BOBYQA, max_evals: 100, starts: 2, design: lhs, box_check: false}
select:
  weaves: [preset:cotton-denim, w.wv]
  kinds: [irawan, irawan+oren-nayar]
  orientation_starts: 3
  max_evals: 50
  cv_folds: 4
"""
FABRIC_VALUES = ["shortened", "[-80, 95]", "-80", "95", "10", "huber", "0.25", "grouped", "local", "true", "lhs",
                 "false", "preset:cotton-denim", "w.wv", "irawan", "irawan+oren-nayar", "3", "50", "4",
                 "[irawan, irawan+oren-nayar]", "[preset:cotton-denim, w.wv]", "[alpha, orientation]",
                 "orientation"]

FABRIC_ALTERNATIVES = [
    "full", "cauchy", "l1", "squared", "sobol", "none", "random", "neutral", "leave-one-direction-out", "auto",
    "irawan+lambert", "kang", "lambert", "oren-nayar", "surface", "preset:silk-charmeuse", "preset:Cotton Denim",
    "pattern:plain", "pattern:nope", "8", "9", "2", "-360", "360", "360.5", "[-360, 360]", "[90, -90]", "[]",
    "[irawan, irawan]", "[preset:cotton-denim, preset:cotton-denim]", "[w.wv, ./w.wv]", "missing.wv", "1.5",
    "0.0", "2147483647", "2147483648", "[alpha]", "[orientation, orientation]", "{a: 1}", "yes", "no", "False",
]


def test_fuzz_fabric_select_and_fit_options(tmp_path):
    from clothlab.config import load_config
    from clothlab.config.choices import CV_REFITS, CV_SCHEMES, LOSSES, START_DESIGNS
    from clothlab.fit.select import candidates, settings_from_config
    from clothlab.models.registry import MODEL_KINDS

    (tmp_path / "m.csv").write_text(header_table("0"))
    (tmp_path / "w.wv").write_text((Path(__file__).parent.parent / "clothlab/weave/data/cotton-twill.wv").read_text())
    (tmp_path / "fabric.yaml").write_text(FABRIC)
    cfg = load_config(tmp_path / "fabric.yaml")
    assert cfg.select.orientation_starts == 3 and len(cfg.select.weaves) == 2  # the unmutated file is valid
    counts = collections.Counter()
    path = tmp_path / "f.yaml"

    def check(cfg):
        s = cfg.select
        assert 1 <= s.orientation_starts <= 8 and 1 <= s.max_evals <= 2**31 - 1
        assert s.cv_folds == 0 or s.cv_folds >= 2
        assert s.kinds and all(k in MODEL_KINDS for k in s.kinds)
        assert all(isinstance(w, str) and (w.startswith("preset:") or Path(w).is_file()) for w in s.weaves)
        assert len(set(s.weaves)) == len(s.weaves) and len(set(s.kinds)) == len(s.kinds)
        settings = settings_from_config(cfg)
        assert len(candidates(settings)) >= 1
        f = cfg.fit
        assert f.loss in LOSSES and f.cv_scheme in CV_SCHEMES and f.cv_refit in CV_REFITS
        assert math.isfinite(f.loss_scale) and f.loss_scale > 0
        assert f.cv_folds == 0 or f.cv_folds >= 2
        assert f.optimizer.design in START_DESIGNS and isinstance(f.optimizer.box_check, bool)
        assert isinstance(f.valid_geometry, bool)
        assert cfg.model.options.get("filament_arc", "full") in ("full", "shortened")
        for name, (lo, hi) in f.bounds.items():
            assert math.isfinite(lo) and math.isfinite(hi) and lo < hi
            if name == "orientation":
                assert -360 <= lo < hi <= 360
        for name, value in cfg.model.params.items():
            assert isinstance(value, float) and math.isfinite(value), name
        if "orientation" in cfg.model.params:
            assert -360 <= cfg.model.params["orientation"] <= 360

    @SETTINGS
    @given(old=st.sampled_from(FABRIC_VALUES), token=st.one_of(TOKENS, st.sampled_from(FABRIC_ALTERNATIVES)),
           nth=st.integers(0, 3))
    def run(old, token, nth):
        pieces = FABRIC.split(old)
        k = 1 + nth % (len(pieces) - 1)
        path.write_bytes(encode(old.join(pieces[:k]) + token + old.join(pieces[k:])))
        kind, result = outcome(counts, load_config, path, paths=(path,))
        if kind == "accepted":
            check(result)

    run()
    report("fabric.yaml select/fit options", counts)


# ---------------------------------------------------------------------------------------------------------
# simulate --sampling / --orientation

SAMPLING_CSV = ["# pairs", "theta_i,phi_i,theta_o,phi_o", "10,0,20,180", "30,45.5,40,200", "0,0,60,90", "45,350,5,10"]


def valid_sampling(result) -> None:
    (ti, pi_, to, po), described = result
    assert isinstance(described, str) and described
    n = len(ti)
    assert n >= 1 and all(len(a) == n for a in (pi_, to, po))
    assert len(set(zip(ti.tolist(), pi_.tolist(), to.tolist(), po.tolist(), strict=True))) == n  # no pair twice
    for t, p in ((ti, pi_), (to, po)):
        assert np.isfinite(t).all() and np.isfinite(p).all()
        assert (t >= 0).all() and (t < 90).all() and (p >= 0).all() and (p < 360).all()
        unit_upper(t, p)


def test_fuzz_simulate_sampling(tmp_path):
    from clothlab.simulate.sampling import parse_sampling

    (tmp_path / "pairs.csv").write_text("\n".join(SAMPLING_CSV) + "\n")
    valid_sampling(parse_sampling(str(tmp_path / "pairs.csv")))
    counts = collections.Counter()
    path = tmp_path / "s.csv"

    @SETTINGS
    @given(data=st.data())
    def run(data):
        seed = data.draw(st.sampled_from([0, 1, 2**32 - 1, 2**63, 2**64, -1, 10**40]))
        if data.draw(st.booleans()):
            n = data.draw(st.one_of(st.sampled_from(["1", "7", "0", "-3", "1_0", " 5", "5 ", "\u0665", "+4", "0x5",
                                                     "4.0", "", "1e3", "10000001", "9" * 40]), TOKENS))
            tail = data.draw(st.sampled_from(["", ":uniform", ":cosine", ":Cosine", ":", ":uniform:x"]))
            spec = data.draw(st.sampled_from(["random:", "Random:", "random::"])) + n + tail
            if n.strip().isdigit() and len(n) < 12 and int(n) > 2000 and n.isascii():
                spec = "random:2000" + tail  # keep the draws small; the bound itself is tested below
        else:
            lines = list(SAMPLING_CSV)
            token = data.draw(TOKENS)
            if data.draw(st.booleans()):
                row = data.draw(st.integers(1, len(lines) - 1))
                lines[row] = replace_field(lines[row], data.draw(st.integers(0, 3)), token, ",")
            else:
                lines = mutate_lines(lines, data.draw(st.integers(0, 3)), data.draw(st.integers(0, len(lines) - 1)),
                                     token)
            path.write_bytes(encode("\n".join(lines) + "\n"))
            spec = str(path)
        kind, result = outcome(counts, parse_sampling, spec, seed, paths=(path,),
                               options=("--sampling", "--sampling-seed"))
        if kind == "accepted":
            valid_sampling(result)
            assert isinstance(seed, int) and 0 <= seed < 2**64
            if spec.startswith("random:"):  # N in plain digits, and exactly N pairs drawn
                count = spec.split(":")[1]
                assert re.fullmatch(DIGITS, count) and len(result[0][0]) == int(count), spec

    run()
    report("simulate --sampling", counts)


def test_fuzz_simulate_command_options(tmp_path, capsys):
    """``clothlab simulate`` end to end with drawn --orientation / seeds / noise / coefficient values: exit 0
    with a valid table, or exit 2 with one line naming the option (argparse's own usage errors included)."""
    from clothlab.cli.main import main
    from clothlab.io.table import read_table

    counts = collections.Counter()
    out = tmp_path / "sim.csv"
    numbers = st.one_of(st.sampled_from(["0", "10", "-30.5", "360", "-360", "361", "1_0", "nan", "inf", "-inf",
                                         "1e308", "1e-320", "\u0661", "0x1", "", " 7", "1,2"]), TOKENS)
    flags = {"--orientation": numbers, "--sampling-seed": numbers, "--seed": numbers, "--noise-mult": numbers,
             "--noise-add": numbers, "--kd": numbers, "--ks-warp": numbers, "--ks-weft": numbers,
             "--channels": st.sampled_from(
                 ["grey", "R,G,B", "a,a", ",", "", "x y", "R,G,B,A,B"])}

    @SETTINGS
    @given(data=st.data())
    def run(data):
        argv = ["simulate", "preset:cotton-denim", "-o", str(out), "--force", "--sampling=random:6", "--nodes", "3"]
        chosen = [f for f in flags if data.draw(st.integers(0, 2)) == 0] or ["--orientation"]
        for flag in chosen:
            argv.append(f"{flag}={data.draw(flags[flag])}")
        try:
            rc = main(argv)
        except SystemExit as exc:  # argparse: a usage error naming the option
            rc = exc.code
        err = capsys.readouterr().err
        assert "Traceback" not in err
        if rc == 0:
            for item in argv[8:]:  # every number given was in plain decimal notation (no 1_0, no nan)
                flag, value = item.split("=", 1)
                if flag in ("--orientation", "--noise-mult", "--noise-add", "--kd", "--ks-warp", "--ks-weft"):
                    assert all(re.fullmatch(DECIMAL, v.strip()) for v in value.split(",")), item
                elif flag in ("--seed", "--sampling-seed"):
                    assert re.fullmatch(DIGITS, value.strip()), item
            counts["accepted (valid)"] += 1
            m = read_table(out)
            valid_measurement(m)
            assert m.n == 6
        else:
            assert rc == 2, err
            last = [line for line in err.splitlines() if line.strip()][-1]
            assert "error:" in last and any(flag in last or flag.lstrip("-").replace("-", "_") in last
                                            for flag in chosen), (argv, err)
            counts["refused (named)"] += 1

    run()
    report("simulate options", counts)


def test_random_sampling_is_bounded_before_drawing():
    from clothlab.errors import ConfigError
    from clothlab.simulate.sampling import MAX_RANDOM, parse_sampling

    with pytest.raises(ConfigError) as info:
        parse_sampling(f"random:{MAX_RANDOM + 1}")
    assert info.value.field == "--sampling"


# ---------------------------------------------------------------------------------------------------------
# The corpus of what these families found (tests/fuzz_corpus/): each is refused through the CLI with exit 2
# and one line naming the place, or (``ok--``) accepted as valid.

CORPUS = Path(__file__).parent / "fuzz_corpus"
IMPORT_ARGS = {  # the options each import reproducer is read with, and the place its refusal must name
    "import--one-row.txt": (["--columns=theta_i,phi_i,theta_o,phi_o,R,G,B"], ":3"),
    "import--only-comments.txt": ([], ":3"),
    "import--channels-with-space.txt": (["--columns=" + LAB_COLUMNS, "--channels=x y,g,b"], "--channels"),
    "import--channel-count.txt": (["--columns=" + LAB_COLUMNS, "--channels=a,b"], "--channels"),
    "import--percent-comments-hide-no-header.txt": (["--columns=" + LAB_COLUMNS, "--comment=%"], ":1"),
    "ok--import-trailing-skipped-columns.txt": (["--columns=theta_i,phi_i,theta_o,phi_o,R,-,-",
                                                 "--delimiter=tab"], None),
    "ok--import-no-comment-char.txt": (["--comment="], None),
    "ok--import-channel-named-like-a-number.txt": (["--header=yes"], None),  # the header quotes '1e3'

}


def corpus(prefix: str) -> list[str]:
    return sorted(p.name for p in CORPUS.glob(f"{prefix}*"))


def refused_once(rc: int, err: str, *named) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert rc == 2 and "Traceback" not in err, err
    assert lines[-1].startswith(("clothlab: error: ", "clothlab ")) and "error: " in lines[-1], err
    assert all(str(n) in lines[-1] for n in named), (named, err)
    return lines[-1]


@pytest.mark.parametrize("name", corpus("import--") + corpus("ok--import-"))
def test_corpus_import(tmp_path, capsys, name):
    from clothlab.cli.main import main
    from clothlab.io.table import read_table

    args, place = IMPORT_ARGS[name]
    source = tmp_path / name
    source.write_bytes((CORPUS / name).read_bytes())
    rc = main(["import", str(source), "-o", str(tmp_path / "out.csv"), *args])
    err = capsys.readouterr().err
    if name.startswith("ok--"):
        assert rc == 0, err
        valid_measurement(read_table(tmp_path / "out.csv"))
    else:
        refused_once(rc, err, place if place.startswith("--") else f"{source}{place}")
        assert not (tmp_path / "out.csv").exists()


@pytest.mark.parametrize("name", corpus("merl--") + corpus("bsdf--"))
def test_corpus_binary(tmp_path, name):
    from clothlab.errors import InputError
    from clothlab.io.loader import load_measurement

    path = tmp_path / name
    path.write_bytes((CORPUS / name).read_bytes())
    with pytest.raises(InputError) as info:
        bounded(load_measurement, path)
    assert named(info.value, (path,)), str(info.value)


def test_corpus_azimuth_just_above_zero_stays_below_a_turn(tmp_path):
    from clothlab.io.loader import load_measurement

    name = "ok--table-cw-azimuth-just-above-zero.csv"
    (tmp_path / name).write_bytes((CORPUS / name).read_bytes())
    m = load_measurement(tmp_path / name)
    valid_measurement(m, ("R",))
    assert m.phi_i[0] == 0.0 and m.phi_o[1] == 0.0  # -1e-15 deg wraps to 0, not to 360


@pytest.mark.parametrize("name", corpus("measurement--") + corpus("select--"))
def test_corpus_fabric_yaml(tmp_path, capsys, monkeypatch, name):
    """Refused by ``clothlab fit`` / ``clothlab select`` at the value's line in fabric.yaml, before any fit."""
    import clothlab.fit.runner as runner
    from clothlab.cli.main import main

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(runner, "run_fit", lambda *a, **k: pytest.fail("a bad fabric.yaml was accepted"))
    (tmp_path / "lab.csv").write_text("\n".join(lab_lines(";")) + "\n")
    utia_file(tmp_path / "u.bin")
    for weave in CORPUS.glob("weave--*.wv"):  # damaged weave files a selection may name
        (tmp_path / weave.name).write_bytes(weave.read_bytes())
    path = tmp_path / name
    path.write_bytes((CORPUS / name).read_bytes())
    first = path.read_text().splitlines()[0]
    rc = main(["select" if name.startswith("select--") else "fit", str(path)])
    if first.startswith("# expect-file: "):  # the fault is in another file, named at its line
        refused_once(rc, capsys.readouterr().err, f"{tmp_path / first.split(': ', 1)[1]}:")
        return
    line = refused_once(rc, capsys.readouterr().err, f"{path}:")
    assert "field '" in line and ("measurement.options." in line or "select." in line), line


@pytest.mark.parametrize("name", corpus("cli--"))
def test_corpus_command_lines(tmp_path, capsys, monkeypatch, name):
    """Each ``cli--*.args`` file: one argument per line after a ``# expect: <option> | ok`` line."""
    from clothlab.cli.main import main
    from clothlab.io.table import read_table

    monkeypatch.chdir(tmp_path)
    lines = (CORPUS / name).read_text(encoding="utf-8").splitlines()
    expect = lines[0].removeprefix("# expect: ").split()[0]
    try:
        rc = main(lines[1:])
    except SystemExit as exc:  # argparse's own usage error
        rc = exc.code
    err = capsys.readouterr().err
    if expect == "ok":
        assert rc == 0, err
        valid_measurement(read_table(tmp_path / "out.csv"))
    else:
        refused_once(rc, err, expect)
        assert not (tmp_path / "out.csv").exists()


def test_fuzz_select_command_options(tmp_path, capsys):
    """``clothlab select``'s --weaves / --kinds / --orientation-starts / --candidate-evals / --candidate-cv drawn
    from valid and bad values: the settings a selection would run, or a refusal naming the option."""
    from clothlab.cli.main import build_parser
    from clothlab.cli.select import _settings
    from clothlab.config import load_config
    from clothlab.fit.select import candidates
    from clothlab.models.registry import MODEL_KINDS

    (tmp_path / "m.csv").write_text(header_table("0"))
    (tmp_path / "w.wv").write_text((Path(__file__).parent.parent / "clothlab/weave/data/cotton-twill.wv").read_text())
    (tmp_path / "fabric.yaml").write_text(FABRIC)
    cfg = load_config(tmp_path / "fabric.yaml")
    parser = build_parser()
    counts = collections.Counter()
    values = {
        "--weaves": ["cotton-denim", "preset:silk-charmeuse", f"{tmp_path / 'w.wv'}", "nope", "missing.wv",
                     "cotton-denim,cotton-denim", "", ",", "pattern:plain", "pattern:nope", "Cotton Denim,w"],
        "--kinds": ["irawan", "irawan,irawan+oren-nayar", "kang", "irawan,irawan", "", "nope", ",", "lambert"],
        "--orientation-starts": ["1", "8", "9", "0", "-1", "1_0", "\u0662", " 2", "2.0", "99999999999999999999"],
        "--candidate-evals": ["1", "600", "0", "2147483648", "1_0", "1e3", "+5"],
        "--candidate-cv": ["0", "1", "2", "5", "-2", "1_0", "\u0665"],
    }

    @SETTINGS
    @given(data=st.data())
    def run(data):
        argv = ["select", str(tmp_path / "fabric.yaml")]
        chosen = [f for f in values if data.draw(st.booleans())]
        for flag in chosen:
            argv.append(f"{flag}={data.draw(st.one_of(st.sampled_from(values[flag]), TOKENS))}")
        try:
            args = parser.parse_args(argv)
        except SystemExit as exc:  # argparse: one usage error naming the option
            err = capsys.readouterr().err
            lines = err.strip().splitlines()  # clothlab's format: one line naming the option, no usage block
            assert exc.code == 2 and len(lines) == 1 and lines[0].startswith("clothlab: error: field '"), err
            assert any(f"field '{flag}'" in lines[0] for flag in chosen), err
            counts["refused (named)"] += 1
            return
        kind, settings = outcome(counts, _settings, cfg, args, options=tuple(values))
        if kind == "accepted":
            assert settings.kinds and all(k in MODEL_KINDS for k in settings.kinds)
            assert len(set(settings.kinds)) == len(settings.kinds) and len(set(settings.weaves)) == len(settings.weaves)
            assert all(w.startswith(("preset:", "pattern:")) or Path(w).is_file() for w in settings.weaves)
            assert 1 <= settings.orientation_starts <= 8 and 1 <= settings.max_evals <= 2**31 - 1
            assert settings.cv_folds == 0 or settings.cv_folds >= 2
            assert len(candidates(settings)) >= 1
            for item in argv[2:]:  # every count given was in plain digits
                flag, value = item.split("=", 1)
                if flag.startswith(("--orientation", "--candidate")):
                    assert re.fullmatch(DIGITS, value.strip()), item

    run()
    report("select options", counts)


@pytest.mark.parametrize("case", ["merl dims", "tensor shape", "tensor count"])
def test_huge_headers_are_refused_before_allocating(tmp_path, case):
    """A header claiming the largest dimensions it can spell is refused from the header alone: the allocation
    peak of the read stays within a few times the (tiny) file."""
    from clothlab.errors import InputError
    from clothlab.io.loader import load_measurement
    from clothlab.io.rglbsdf import write_tensor_file

    if case == "merl dims":
        path = tmp_path / "h.binary"
        path.write_bytes(struct.pack("<3i", 4096, 4096, 4096) + b"\0" * 64)
    else:
        path = tmp_path / "h.bsdf"
        write_tensor_file({"ndf": np.ones((2, 3), np.float32)}, path)
        data = bytearray(path.read_bytes())
        if case == "tensor count":
            struct.pack_into("<I", data, 14, 2**32 - 1)
        else:
            struct.pack_into("<2Q", data, 18 + 2 + 3 + 2 + 1 + 8, 2**40, 2**40)
        path.write_bytes(bytes(data))
    tracemalloc.start()
    try:
        with pytest.raises(InputError) as info:
            load_measurement(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert named(info.value, (path,)) and "byte offset" in info.value.detail, str(info.value)
    assert peak < 4 << 20, peak


@pytest.mark.parametrize("name", corpus("sampling--"))
def test_corpus_sampling_files(tmp_path, capsys, monkeypatch, name):
    """``simulate --sampling FILE`` refuses the file at its line, before the output table is written."""
    from clothlab.cli.main import main

    monkeypatch.chdir(tmp_path)
    path = tmp_path / name
    path.write_bytes((CORPUS / name).read_bytes())
    rc = main(["simulate", "preset:cotton-denim", "-o", "out.csv", f"--sampling={path}", "--nodes=3"])
    refused_once(rc, capsys.readouterr().err, f"{path}:")
    assert not (tmp_path / "out.csv").exists()


@pytest.mark.slow
def test_fuzz_loaders_thousands(tmp_path):
    """Every family above with 1,000 cases, in a child pytest (``--runslow``)."""
    import subprocess
    import sys

    repo = str(Path(__file__).parent.parent)
    env = dict(os.environ, CLOTHLAB_FUZZ_EXAMPLES="1000",
               PYTHONPATH=os.pathsep.join([repo, *filter(None, [os.environ.get("PYTHONPATH")])]))
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-s", __file__, "-k", "not thousands",
                           "-p", "no:cacheprovider"], env=env, capture_output=True, text=True, cwd=tmp_path)
    print(done.stdout[-4000:])
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]


def test_fuzz_import_reader_options(tmp_path, capsys):
    """``clothlab import FILE --format merl|utia|clothlab --option KEY=VALUE``: a table written that reads back
    valid, or exit 2 with one line naming the option (or the file and its place)."""
    from clothlab.cli.main import main
    from clothlab.io.table import read_table

    sources = {"merl": tmp_path / "m.binary", "utia": tmp_path / "u.bin", "clothlab": tmp_path / "t.csv"}
    merl_file(sources["merl"])
    utia_file(sources["utia"])
    sources["clothlab"].write_text(header_table("0"))
    keys = ["theta_step", "phi_step", "theta_max", "azimuth_zero", "azimuth_sense", "azimuth_offset", "quantity",
            "negative", "columns", "bogus", "", " ", "=", "theta_step ", "a\x00b"]
    values = st.one_of(TOKENS, st.sampled_from(["7.5", "15", "30", "80", "89.9", "0.5", "warp", "cw", "-45", "zero",
                                                "brdf", "[1", "{a: [", "&a 1", "*a", "!!str 5", "1e400", ".inf"]))
    counts = collections.Counter()
    out = tmp_path / "out.csv"

    own = {"merl": {"theta_step": "15", "phi_step": "30", "theta_max": "80"},
           "utia": {"azimuth_zero": "warp", "azimuth_sense": "cw", "azimuth_offset": "-45", "negative": "zero"},
           "clothlab": {}}

    # each case converts a full-size MERL / UTIA file (~0.7 s): the default run draws a third as many
    @settings(SETTINGS, max_examples=EXAMPLES if "CLOTHLAB_FUZZ_EXAMPLES" in os.environ else 8)
    @given(data=st.data())
    def run(data):
        fmt = data.draw(st.sampled_from(sorted(sources)))
        options = [(key, value) for key, value in own[fmt].items() if data.draw(st.booleans())]
        options += data.draw(st.lists(st.tuples(st.sampled_from(keys), values), max_size=2 if fmt == "clothlab"
                                      else 1))
        argv = ["import", str(sources[fmt]), "-o", str(out), "--force", f"--format={fmt}"]
        argv += [f"--option={key}={value}" for key, value in options]
        try:
            rc = main(argv)
        except SystemExit as exc:
            rc = exc.code
        err = capsys.readouterr().err
        assert "Traceback" not in err
        if rc == 0:
            counts["accepted (valid)"] += 1
            valid_measurement(read_table(out))
        else:
            lines = [line for line in err.splitlines() if line.strip()]
            assert rc == 2 and len(lines) == 1 and lines[0].startswith("clothlab: error: "), err
            assert "field '" in lines[0] or "byte offset" in lines[0] or f"{sources[fmt]}:" in lines[0], err
            counts["refused (named)"] += 1

    run()
    report("import --format --option", counts)
