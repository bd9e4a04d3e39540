"""RGL-EPFL .bsdf tensor files (io/rglbsdf.py): container round trip, validation at byte offsets, and the
documented refusal to map warped samples to directions."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from clothlab.cli.main import main
from clothlab.errors import InputError
from clothlab.io.loader import detect_format, load_measurement
from clothlab.io.rglbsdf import read_tensor_file, write_tensor_file

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


def test_measurement_load_is_refused_with_the_reason(tmp_path, capsys):
    path = write_tensor_file(fields(), tmp_path / "cloth.bsdf")
    assert detect_format(path) == "bsdf"
    with pytest.raises(InputError, match="warp") as info:
        load_measurement(path)
    assert "rgb[1, 5, 3, 4, 4]" in str(info.value)
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
