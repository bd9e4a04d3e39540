"""RGL-EPFL ``.bsdf`` files: the "tensor file" container of Dupuy & Jakob 2018 ("An adaptive
parameterization for efficient material acquisition and rendering"; docs/formats.md, "RGL-EPFL .bsdf").

Container layout (little-endian), as the format's public readers document it:

- 12 bytes magic ``b"tensor_file\\0"``, then uint8 version major, minor = (1, 0), then uint32 field count;
- per field: uint16 name length, the name (UTF-8), uint16 ndim, uint8 dtype code (1 uint8, 2 int8,
  3 uint16, 4 int16, 5 uint32, 6 int32, 7 uint64, 8 int64, 9 float16, 10 float32, 11 float64), uint64 byte
  offset of the data from the start of the file, uint64 shape[ndim];
- the C-ordered data of each field at its offset.

:func:`read_tensor_file` reads and validates the container (every field inside the file, no overlap, no
NaN in a float field, no negative value in a density or reflectance field).  A measured BSDF holds fields
such as ``theta_i``, ``phi_i``, ``ndf``, ``sigma``, ``vndf``, ``luminance``, ``rgb`` / ``spectra`` and
``description``: reflectance samples on a grid in a domain warped by the material's visible-normal
distribution.  Turning a sample into a direction pair needs the inverse of that adaptive warp (a
piecewise-bilinear 2-D distribution interpolated over theta_i, phi_i), which clothlab does not implement,
so :func:`read_bsdf` (``measurement.format: bsdf``) validates the file and then refuses with a message
saying so.  See docs/formats.md for what is missing.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clothlab.atomic import atomic_write_bytes
from clothlab.errors import InputError, ResultExistsError
from clothlab.io.binary import array_at, check_values, read_binary
from clothlab.io.measurement import Measurement

MAGIC = b"tensor_file\x00"
VERSION = (1, 0)
DTYPES = {1: "<u1", 2: "<i1", 3: "<u2", 4: "<i2", 5: "<u4", 6: "<i4", 7: "<u8", 8: "<i8", 9: "<f2", 10: "<f4",
          11: "<f8"}
"""Tensor-file dtype codes (Mitsuba's Struct::Type numbering) -> little-endian numpy types."""
NON_NEGATIVE_FIELDS = ("ndf", "sigma", "vndf", "luminance", "rgb", "spectra", "jacobian")
"""Fields holding densities or reflectance samples, which must be >= 0."""
MAX_FIELDS = 1024
MAX_NDIM = 16
MAX_NAME_CHARS = 128
"""Longest field name read (the format's own names are a few characters)."""
_WHAT = "tensor file"


@dataclass(frozen=True)
class TensorField:
    """One named array of a tensor file and where it was stored."""

    name: str
    data: np.ndarray
    offset: int
    dtype_code: int


class _Cursor:
    """Reads the header sequentially; a short read names the byte offset and what was being read."""

    def __init__(self, data: bytes, path):
        self.data, self.path, self.pos = data, path, 0

    def take(self, fmt: str, what: str):
        size = struct.calcsize(fmt)
        if self.pos + size > len(self.data):
            raise InputError(f"truncated {_WHAT}: {what} at byte offset {self.pos} needs {size} bytes, the file "
                             f"ends at byte offset {len(self.data)}", path=self.path)
        values = struct.unpack_from(fmt, self.data, self.pos)
        self.pos += size
        return values if len(values) > 1 else values[0]


def read_tensor_file(path) -> dict[str, TensorField]:
    """The fields of a tensor file, in file order, or InputError naming the byte offset of the fault."""
    data = read_binary(path, what=_WHAT)
    cur = _Cursor(data, path)
    magic = data[:12]
    if magic != MAGIC:
        raise InputError(f"not a tensor file: the 12 bytes at byte offset 0 are {magic!r}, expected {MAGIC!r}",
                         path=path, field="magic")
    cur.pos = 12
    version = cur.take("<BB", "the version")
    if tuple(version) != VERSION:
        raise InputError(f"tensor file version {version[0]}.{version[1]} at byte offset 12; this clothlab reads "
                         f"{VERSION[0]}.{VERSION[1]}", path=path, field="version")
    count = cur.take("<I", "the field count")
    if not 1 <= count <= MAX_FIELDS:
        raise InputError(f"field count {count} at byte offset 14 is outside [1, {MAX_FIELDS}]", path=path,
                         field="field_count")
    fields: dict[str, TensorField] = {}
    spans = []
    for _ in range(count):
        start = cur.pos
        length = cur.take("<H", "a field name length")
        raw_name = cur.take(f"<{length}s", "a field name") if length else b""
        try:
            name = raw_name.decode("utf-8")
        except UnicodeDecodeError:
            raise InputError(f"field name at byte offset {start + 2} is not UTF-8", path=path) from None
        if len(name) > MAX_NAME_CHARS or not name.isprintable():  # a damaged length swallows header bytes
            raise InputError(f"field name at byte offset {start + 2} ({length} bytes, length at byte offset "
                             f"{start}) is not a printable name of at most {MAX_NAME_CHARS} characters", path=path)
        if not name or name in fields:
            raise InputError(f"field name {name!r} at byte offset {start + 2} is empty or repeated", path=path,
                             field=name or None)
        ndim = cur.take("<H", f"the ndim of field {name!r}")
        code_at = cur.pos
        code = cur.take("<B", f"the dtype of field {name!r}")
        if code not in DTYPES:
            raise InputError(f"unknown dtype code {code} at byte offset {code_at} (field {name!r}); expected "
                             f"1..11", path=path, field=name)
        offset = cur.take("<Q", f"the data offset of field {name!r}")
        if ndim > MAX_NDIM:
            raise InputError(f"field {name!r} has {ndim} dimensions (at most {MAX_NDIM})", path=path, field=name)
        shape_at = cur.pos
        raw_shape = cur.take(f"<{ndim}Q", f"the shape of field {name!r}") if ndim else ()
        shape = (raw_shape,) if ndim == 1 else tuple(raw_shape)  # Python integers: exact
        for k, n in enumerate(shape):  # no axis longer than the file has bytes (even of an empty field)
            if n > len(data):
                raise InputError(f"field {name!r} shape[{k}] = {n} at byte offset {shape_at + 8 * k} exceeds the "
                                 f"file's {len(data)} bytes", path=path, field=name)
        fields[name] = TensorField(name, np.empty(0), int(offset), code)
        spans.append((name, int(offset), shape, code))
    header_end = cur.pos
    ordered = sorted(spans, key=lambda s: s[1])
    previous_end, previous_name = header_end, "the header"
    for name, offset, shape, code in ordered:
        itemsize = np.dtype(DTYPES[code]).itemsize
        count_items = math.prod(shape)  # exact (Python integers); 1 for a scalar field
        if offset < previous_end:
            raise InputError(f"field {name!r} starts at byte offset {offset}, inside {previous_name} (which ends "
                             f"at byte offset {previous_end})", path=path, field=name)
        if offset + itemsize * count_items > len(data):
            raise InputError(f"truncated {_WHAT}: field {name!r} needs bytes {offset} to "
                             f"{offset + itemsize * count_items}, the file ends at byte offset {len(data)}",
                             path=path, field=name)
        array = array_at(data, offset, DTYPES[code], count_items, path=path, what=_WHAT).reshape(shape)
        if array.dtype.kind == "f":
            check_values(array.astype(np.float64), path=path, offset=offset, itemsize=itemsize,
                         name=lambda k, n=name, s=shape: f"{n}{[int(i) for i in np.unravel_index(k, s)] if s else ''}",
                         allow_negative=name not in NON_NEGATIVE_FIELDS)
        elif name in NON_NEGATIVE_FIELDS and (array < 0).any():
            k = int(np.flatnonzero(np.ravel(array) < 0)[0])
            raise InputError(f"value {int(np.ravel(array)[k])} at byte offset {offset + itemsize * k} of field "
                             f"{name!r} is negative", path=path, field=name)
        fields[name] = TensorField(name, array, offset, code)
        previous_end, previous_name = offset + itemsize * count_items, f"field {name!r}"
    return fields


def write_tensor_file(fields: dict[str, np.ndarray], path, *, overwrite: bool = False) -> Path:
    """Write arrays (numpy dtypes of :data:`DTYPES`) as a tensor file, data 8-byte aligned, atomically."""
    codes = {np.dtype(t).newbyteorder("="): c for c, t in DTYPES.items()}
    path = Path(path)
    if path.exists() and not overwrite:
        raise ResultExistsError(f"{path} already exists; pass overwrite=True (--force) to replace it", path=path)
    arrays = {name: np.asarray(a) for name, a in fields.items()}
    header_size = 12 + 2 + 4 + sum(2 + len(n.encode()) + 2 + 1 + 8 + 8 * a.ndim for n, a in arrays.items())
    offset = (header_size + 7) // 8 * 8
    header, body = [MAGIC, struct.pack("<BBI", *VERSION, len(arrays))], []
    for name, array in arrays.items():
        code = codes.get(array.dtype.newbyteorder("="))
        if code is None:
            raise ValueError(f"field {name!r}: dtype {array.dtype} has no tensor-file code")
        encoded = name.encode()
        header.append(struct.pack(f"<H{len(encoded)}sHBQ", len(encoded), encoded, array.ndim, code, offset))
        header.append(struct.pack(f"<{array.ndim}Q", *array.shape))
        blob = np.ascontiguousarray(array, dtype=DTYPES[code]).tobytes()
        padded = blob + b"\0" * ((-len(blob)) % 8)
        body.append(padded)
        offset += len(padded)
    head = b"".join(header)
    head += b"\0" * ((header_size + 7) // 8 * 8 - len(head))
    return atomic_write_bytes(path, head + b"".join(body))


def read_bsdf(path) -> Measurement:
    """Validate an RGL-EPFL ``.bsdf`` file, then refuse: its samples cannot be placed at direction pairs
    without inverting the adaptive VNDF warp, which clothlab does not implement (docs/formats.md)."""
    fields = read_tensor_file(path)
    listing = ", ".join(f"{f.name}{list(f.data.shape)}" for f in fields.values())
    raise InputError(
        f"RGL-EPFL .bsdf file read (fields {listing}), but clothlab cannot convert it to direction pairs: its "
        "samples lie on a grid warped by the material's visible-normal distribution, and inverting that warp "
        "is not implemented; export the BRDF at chosen directions with the RGL tools and import the table "
        "(`clothlab import`)", path=path, field="format")
