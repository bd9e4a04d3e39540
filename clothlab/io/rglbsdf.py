"""RGL-EPFL ``.bsdf`` files: the "tensor file" container of Dupuy & Jakob 2018 ("An adaptive
parameterization for efficient material acquisition and rendering"; docs/formats.md, "RGL-EPFL .bsdf").

Container layout (little-endian), as the format's public readers document it:

- 12 bytes magic ``b"tensor_file\\0"``, then uint8 version major, minor = (1, 0), then uint32 field count;
- per field: uint16 name length, the name (UTF-8), uint16 ndim, uint8 dtype code (1 uint8, 2 int8,
  3 uint16, 4 int16, 5 uint32, 6 int32, 7 uint64, 8 int64, 9 float16, 10 float32, 11 float64), uint64 byte
  offset of the data from the start of the file, uint64 shape[ndim];
- the C-ordered data of each field at its offset.

:func:`read_tensor_file` reads and validates the container (every field inside the file, no overlap, no
NaN in a float field, no negative value in a density or reflectance field).  A measured BSDF holds
``theta_i`` / ``phi_i`` (the incident nodes, radians), ``ndf`` and ``sigma`` (2-D), ``vndf`` and ``luminance``
(per incident node a 2-D density), ``rgb`` (or ``spectra`` with ``wavelengths``), ``jacobian`` and
``description``: reflectance samples on a unit-square grid warped by the material's visible-normal
distribution.  :func:`eval_rgl` evaluates it as the format's reference evaluation does (the inverse of the
VNDF warp at the half vector's coordinates, bilinear interpolation, D / (4 sigma)); :func:`read_bsdf`
(``measurement.format: bsdf``, ``clothlab import --format bsdf``) converts a file with it to a measurement at
the file's incident nodes and a regular exitant grid.  See docs/formats.md, "RGL-EPFL .bsdf".
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clothlab.atomic import atomic_write_bytes
from clothlab.errors import ConfigError, InputError, ResultExistsError
from clothlab.frames import spherical_to_vector
from clothlab.io.binary import array_at, check_values, read_binary
from clothlab.io.measurement import Measurement
from clothlab.io.table import MAX_VALUE

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
            with np.errstate(invalid="ignore"):  # a signalling NaN warns in the cast; check_values names it
                wide = array.astype(np.float64)
            check_values(wide, path=path, offset=offset, itemsize=itemsize,
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


# ---------------------------------------------------------------------------------------------------------
# Evaluation (Dupuy & Jakob 2018, sec. 5-6, as the format's reference evaluation defines it; docs/formats.md)
# ---------------------------------------------------------------------------------------------------------

DEFAULT_THETA_STEP = 7.5
DEFAULT_PHI_STEP = 10.0
DEFAULT_THETA_MAX = 85.0
MAX_ROWS = 2_000_000
"""Most direction pairs :func:`read_bsdf` writes (incident nodes x exitant grid)."""
REQUIRED = ("theta_i", "phi_i", "ndf", "sigma", "vndf", "luminance", "jacobian")
"""Fields every measured .bsdf holds (besides ``rgb``, or ``spectra`` with ``wavelengths``)."""


@dataclass(frozen=True)
class _Warp:
    """A parameterised piecewise-bilinear 2-D density on [0, 1]^2 (one slice per (phi_i, theta_i) node), each
    slice normalised, with its cumulative tables: ``density`` and ``conditional`` (x-cumulative, trapezoid)
    (P0, P1, ny, nx), ``marginal`` (y-cumulative of the row integrals) (P0, P1, ny)."""

    density: np.ndarray
    conditional: np.ndarray
    marginal: np.ndarray


@dataclass(frozen=True)
class RglBsdf:
    """A measured RGL-EPFL BSDF in memory (float64).

    theta_i, phi_i : the incident nodes (radians) the tables are conditioned on.
    ndf, sigma : (ny, nx) the microfacet distribution D(u_m) and projected area sigma(u_i) on the unit square.
    vndf : the visible-normal warp;  values : (P0, P1, C, ny, nx) the reflectance samples on the warped grid.
    jacobian : whether values are multiplied by D / (4 sigma) at evaluation (the file's ``jacobian`` flag).
    reduction : 1, or 2 / 4 when an anisotropic file holds half / a quarter of the azimuths (by symmetry).
    """

    theta_i: np.ndarray
    phi_i: np.ndarray
    ndf: np.ndarray
    sigma: np.ndarray
    vndf: _Warp
    values: np.ndarray
    channels: tuple[str, ...]
    jacobian: bool
    isotropic: bool
    reduction: int
    description: str
    path: str | None = None


def _warp(data: np.ndarray, *, path) -> _Warp:
    """The normalised density and cumulative tables of a (P0, P1, ny, nx) piecewise-bilinear density."""
    steps = 0.5 * (data[..., :-1] + data[..., 1:])
    conditional = np.concatenate([np.zeros(data.shape[:-1] + (1,)), np.cumsum(steps, axis=-1)], axis=-1)
    rows = conditional[..., -1]
    marginal = np.concatenate([np.zeros(rows.shape[:-1] + (1,)),
                               np.cumsum(0.5 * (rows[..., :-1] + rows[..., 1:]), axis=-1)], axis=-1)
    total = marginal[..., -1]
    if not (total > 0.0).all():
        k = np.argwhere(~(total > 0.0))[0]
        raise InputError(f"vndf slice [phi_i {k[0]}, theta_i {k[1]}] holds no density (all 0): the warp is "
                         "undefined there", path=path, field="vndf")
    return _Warp(data / total[..., None, None], conditional / total[..., None, None], marginal / total[..., None])


def _shape_error(name, found, expected, path):
    return InputError(f"field {name!r} has shape {found}, expected {expected}", path=path, field=name)


def bsdf_from_fields(fields: dict[str, TensorField], path=None) -> RglBsdf:
    """An :class:`RglBsdf` from a tensor file's fields, or InputError naming the missing or misshapen field."""
    spectral = "wavelengths" in fields
    value_name = "spectra" if spectral else "rgb"
    for name in (*REQUIRED, value_name):
        if name not in fields:
            raise InputError(f"field {name!r} is missing; a measured .bsdf holds {', '.join(REQUIRED)} and rgb "
                             f"(or spectra with wavelengths); this file holds {', '.join(fields)}", path=path,
                             field=name)
    for name in (*REQUIRED, value_name, "wavelengths"):
        if name in fields and name != "jacobian" and fields[name].data.dtype.kind != "f":
            raise InputError(f"field {name!r} holds {fields[name].data.dtype} values, expected floating point",
                             path=path, field=name)
    arr = {name: f.data.astype(np.float64) for name, f in fields.items() if f.data.dtype.kind == "f"}
    theta_i, phi_i = arr["theta_i"], arr["phi_i"]
    for name, nodes in (("theta_i", theta_i), ("phi_i", phi_i)):
        if nodes.ndim != 1 or len(nodes) < 1:
            raise _shape_error(name, list(nodes.shape), "[n] with n >= 1", path)
        if (np.diff(nodes) <= 0.0).any():
            k = int(np.flatnonzero(np.diff(nodes) <= 0.0)[0])
            raise InputError(f"field {name!r} is not increasing at index {k + 1} ({nodes[k]!r} then "
                             f"{nodes[k + 1]!r})", path=path, field=name)
    if theta_i[0] < 0.0 or theta_i[-1] > math.pi / 2:
        raise InputError(f"field 'theta_i' runs over [{theta_i[0]:.6g}, {theta_i[-1]:.6g}] rad, outside "
                         "[0, pi/2]", path=path, field="theta_i")
    if phi_i[0] < -math.pi - 1e-6 or phi_i[-1] > math.pi + 1e-6:
        raise InputError(f"field 'phi_i' runs over [{phi_i[0]:.6g}, {phi_i[-1]:.6g}] rad, outside [-pi, pi]",
                         path=path, field="phi_i")
    n0, n1 = len(phi_i), len(theta_i)
    for name in ("ndf", "sigma"):
        if arr[name].ndim != 2 or min(arr[name].shape) < 2:
            raise _shape_error(name, list(arr[name].shape), "[ny, nx], both >= 2", path)
    if not (arr["sigma"] > 0.0).all():
        k = int(np.flatnonzero(~(np.ravel(arr["sigma"]) > 0.0))[0])
        raise InputError(f"value {float(np.ravel(arr['sigma'])[k])!r} at byte offset "
                         f"{fields['sigma'].offset + fields['sigma'].data.itemsize * k} of field 'sigma' is not "
                         "positive (a projected area divides the reflectance)", path=path, field="sigma")
    for name in ("vndf", "luminance"):
        a = arr[name]
        if a.ndim != 4 or a.shape[:2] != (n0, n1) or min(a.shape[2:]) < 2:
            raise _shape_error(name, list(a.shape), f"[{n0} (phi_i), {n1} (theta_i), ny >= 2, nx >= 2]", path)
    values = arr[value_name]
    if spectral:
        wavelengths = arr["wavelengths"]
        if wavelengths.ndim != 1:
            raise _shape_error("wavelengths", list(wavelengths.shape), "[n]", path)
        channels = tuple(f"{w:g}nm" for w in wavelengths)
    else:
        channels = ("R", "G", "B")
    n_c = len(channels)
    if values.ndim != 5 or values.shape[:3] != (n0, n1, n_c) or values.shape[3:] != arr["luminance"].shape[2:]:
        raise _shape_error(value_name, list(values.shape),
                           f"[{n0} (phi_i), {n1} (theta_i), {n_c} (channels), "
                           f"{', '.join(map(str, arr['luminance'].shape[2:]))} (as luminance)]", path)
    if len(set(channels)) != n_c:
        raise InputError("field 'wavelengths' repeats a wavelength", path=path, field="wavelengths")
    jacobian = fields["jacobian"].data
    if jacobian.shape != (1,) or jacobian.dtype.kind not in "ui":
        raise _shape_error("jacobian", f"{list(jacobian.shape)} of {jacobian.dtype}", "[1] of an integer type",
                           path)
    isotropic = n0 <= 2
    reduction = 1 if isotropic else int(round(2 * math.pi / (phi_i[-1] - phi_i[0])))
    if reduction not in (1, 2, 4):
        raise InputError(f"field 'phi_i' spans {phi_i[-1] - phi_i[0]:.6g} rad: expected 2 pi, pi or pi/2 (a "
                         f"full, half or quarter period), found 1/{reduction} of one", path=path, field="phi_i")
    description = ""
    if "description" in fields:
        description = bytes(np.asarray(fields["description"].data, dtype=np.uint8).ravel()).decode(
            "utf-8", errors="replace")
    return RglBsdf(theta_i, phi_i, arr["ndf"], arr["sigma"], _warp(arr["vndf"], path=path), values, channels,
                   bool(jacobian[0]), isotropic, reduction, description, None if path is None else str(path))


def read_rgl_bsdf(path) -> RglBsdf:
    """The measured BSDF of an RGL-EPFL ``.bsdf`` file, or InputError naming the fault."""
    return bsdf_from_fields(read_tensor_file(path), path)


def _theta2u(theta):
    """The format's polar-angle coordinate u = sqrt(theta / (pi/2)) (dense near the pole)."""
    return np.sqrt(np.maximum(theta, 0.0) * (2.0 / math.pi))


def _phi2u(phi):
    return (phi + math.pi) / (2.0 * math.pi)


def _elevation(w):
    return np.arctan2(np.hypot(w[..., 0], w[..., 1]), w[..., 2])


def _node_weights(nodes: np.ndarray, p: np.ndarray):
    """(index, weight) of linear interpolation over sorted ``nodes``: ``nodes[i] <= p < nodes[i + 1]``, the
    weight of node i + 1 clamped to [0, 1] (a single node: index 0, weight 0)."""
    if len(nodes) == 1:
        return np.zeros(p.shape, dtype=np.int64), np.zeros(p.shape)
    i = np.clip(np.searchsorted(nodes, p, side="right") - 1, 0, len(nodes) - 2)
    w = np.clip((p - nodes[i]) / (nodes[i + 1] - nodes[i]), 0.0, 1.0)
    return i, w


def _blend(table: np.ndarray, params, *index):
    """``table[phi_i, theta_i, *index]`` linearly interpolated over the two incident parameters."""
    (ia, wa), (ib, wb) = params
    ia1, ib1 = np.minimum(ia + 1, table.shape[0] - 1), np.minimum(ib + 1, table.shape[1] - 1)
    return ((1.0 - wa) * ((1.0 - wb) * table[(ia, ib, *index)] + wb * table[(ia, ib1, *index)])
            + wa * ((1.0 - wb) * table[(ia1, ib, *index)] + wb * table[(ia1, ib1, *index)]))


def _cell(u, n):
    """Grid cell index in [0, n - 2] and the fraction within it of unit coordinates u on n nodes."""
    s = np.clip(u, 0.0, 1.0) * (n - 1)
    k = np.minimum(np.floor(s).astype(np.int64), n - 2)
    return k, s - k


def _bilinear(corner, ux, uy, shape):
    """Bilinear interpolation on an (ny, nx) node grid over [0, 1]^2; ``corner(y, x)`` fetches node values."""
    x, fx = _cell(ux, shape[1])
    y, fy = _cell(uy, shape[0])
    return ((1.0 - fy) * ((1.0 - fx) * corner(y, x) + fx * corner(y, x + 1))
            + fy * ((1.0 - fx) * corner(y + 1, x) + fx * corner(y + 1, x + 1)))


def invert_warp(warp: _Warp, params, ux, uy):
    """The unit-square sample that the warp maps to the point (ux, uy): the conditional CDF in x at the point's
    row, then the marginal CDF in y, of the bilinear density interpolated over the incident parameters (the
    inverse of marginal-then-conditional inversion sampling)."""
    ny, nx = warp.density.shape[2:]
    x, fx = _cell(ux, nx)
    y, fy = _cell(uy, ny)
    d = lambda yy, xx: _blend(warp.density, params, yy, xx)  # noqa: E731
    c0 = (1.0 - fy) * d(y, x) + fy * d(y + 1, x)
    c1 = (1.0 - fy) * d(y, x + 1) + fy * d(y + 1, x + 1)
    below = (1.0 - fy) * _blend(warp.conditional, params, y, x) + fy * _blend(warp.conditional, params, y + 1, x)
    r0, r1 = _blend(warp.conditional, params, y, nx - 1), _blend(warp.conditional, params, y + 1, nx - 1)
    row = (1.0 - fy) * r0 + fy * r1
    sx = fx * (c0 + 0.5 * fx * (c1 - c0)) + below  # in units of the row's total (cell widths)
    sx = np.where(row > 0.0, sx / np.where(row > 0.0, row, 1.0), ux)
    sy = _blend(warp.marginal, params, y) + fy * (r0 + 0.5 * fy * (r1 - r0))
    return sx, sy


def _mulsign_neg(a, s):
    """a * -sign(s), the sign taken from the sign bit (+0 counts as positive)."""
    return np.where(np.signbit(s), a, -a)


def eval_rgl(table: RglBsdf, wi, wo) -> np.ndarray:
    """(N, C) f_r(wi, wo) cos(theta_o) of ``table`` at unit direction pairs (N, 3) in the sample's frame (the
    quantity the format's evaluation returns; 0 unless both directions lie above the surface).

    Reflectance = values at the sample that the VNDF warp maps to the half vector's coordinates
    u_m = (sqrt(theta_m / (pi/2)), (phi_m + pi) / 2 pi) (phi_m - phi_i for an isotropic file), interpolated
    bilinearly and over (phi_i, theta_i), times D(u_m) / (4 sigma(u_i)) when the file's jacobian flag is set.
    """
    wi, wo = np.array(wi, dtype=np.float64, ndmin=2), np.array(wo, dtype=np.float64, ndmin=2)
    active = (wi[:, 2] > 0.0) & (wo[:, 2] > 0.0)
    if table.reduction >= 2:  # the file holds half (180-deg rotation) / a quarter (two mirrors) of the azimuths
        sy = wi[:, 1].copy()
        sx = wi[:, 0].copy() if table.reduction == 4 else sy
        for w in (wi, wo):
            w[:, 0], w[:, 1] = _mulsign_neg(w[:, 0], sx), _mulsign_neg(w[:, 1], sy)
    m = wi + wo
    m /= np.maximum(np.linalg.norm(m, axis=1, keepdims=True), 1e-300)
    theta_i, phi_i = _elevation(wi), np.arctan2(wi[:, 1], wi[:, 0])
    theta_m, phi_m = _elevation(m), np.arctan2(m[:, 1], m[:, 0])
    um_x = _theta2u(theta_m)
    um_y = _phi2u(phi_m - phi_i if table.isotropic else phi_m)
    um_y = um_y - np.floor(um_y)
    params = (_node_weights(table.phi_i, phi_i), _node_weights(table.theta_i, theta_i))
    sx, sy = invert_warp(table.vndf, params, um_x, um_y)
    shape = table.values.shape[3:]
    out = np.empty((len(wi), len(table.channels)))
    for c in range(len(table.channels)):
        out[:, c] = _bilinear(lambda y, x, c=c: _blend(table.values, params, c, y, x), sx, sy, shape)
    if table.jacobian:
        ndf = _bilinear(lambda y, x: table.ndf[y, x], um_x, um_y, table.ndf.shape)
        sigma = _bilinear(lambda y, x: table.sigma[y, x], _theta2u(theta_i), _phi2u(phi_i), table.sigma.shape)
        out *= (ndf / (4.0 * sigma))[:, None]
    out[~active] = 0.0
    return out


def lookup_rgl(table: RglBsdf, wi, wo) -> np.ndarray:
    """(N, C) BRDF (1/sr) of ``table`` at unit direction pairs (N, 3): :func:`eval_rgl` / cos(theta_o)."""
    wo = np.array(wo, dtype=np.float64, ndmin=2)
    value = eval_rgl(table, wi, wo)
    cos_o = wo[:, 2]
    return np.where(cos_o[:, None] > 0.0, value / np.where(cos_o > 0.0, cos_o, 1.0)[:, None], 0.0)


def rgl_directions(table: RglBsdf, theta_step: float = DEFAULT_THETA_STEP, phi_step: float = DEFAULT_PHI_STEP,
                   theta_max: float = DEFAULT_THETA_MAX):
    """Direction pairs (degrees, clothlab convention) at which :func:`read_bsdf` converts a file.

    Incident: the file's own (theta_i, phi_i) nodes with theta_i <= theta_max (its measured incident
    directions; one azimuth at normal incidence; phi_i = 0 only for an isotropic file).  Exitant:
    theta_o = step/2, 3 step/2, ... <= theta_max, phi_o = 0, phi_step, ... < 360.
    """
    for name, value, low, high in (("theta_step", theta_step, 0.5, 45.0), ("phi_step", phi_step, 0.5, 90.0),
                                   ("theta_max", theta_max, 1.0, 89.9)):
        if isinstance(value, bool) or not isinstance(value, int | float) or not low <= value <= high:
            raise ConfigError(f"{name} must be a number of degrees in [{low}, {high}], got {value!r}", field=name)
    if theta_step / 2.0 > theta_max:
        raise ConfigError(f"theta_max {theta_max} is below the first exitant polar angle theta_step / 2 = "
                          f"{theta_step / 2.0}", field="theta_max")
    incident = _incident_nodes(table, theta_max)
    thetas = np.arange(theta_step / 2.0, theta_max + 1e-9, theta_step)
    phis = np.arange(0.0, 360.0 - 1e-9, phi_step)
    rows = len(incident) * len(thetas) * len(phis)
    if rows > MAX_ROWS:
        raise ConfigError(f"{rows} direction pairs ({len(incident)} incident nodes x {len(thetas) * len(phis)} "
                          f"exitant directions) exceed {MAX_ROWS}; raise theta_step / phi_step", field="phi_step")
    inc = np.asarray(incident)
    k, to, po = np.meshgrid(np.arange(len(inc)), thetas, phis, indexing="ij")
    k = k.ravel()
    return inc[k, 0], inc[k, 1], to.ravel(), po.ravel()


def _sample_slice(density, conditional, marginal, ux, uy):
    """The point to which one warp slice maps unit-square samples (ux, uy): the marginal CDF in y inverted,
    then the conditional CDF in x at that row (the forward map that :func:`invert_warp` undoes); within a
    cell the CDF is quadratic, f = 2 d / (c0 + sqrt(c0^2 + 2 d (c1 - c0)))."""
    ny, nx = density.shape
    row = np.clip(np.searchsorted(marginal, uy, side="left") - 1, 0, ny - 2)
    r0, r1 = conditional[row, -1], conditional[row + 1, -1]
    d = np.maximum(uy - marginal[row], 0.0)
    root = np.sqrt(np.maximum(r0 * r0 + 2.0 * d * (r1 - r0), 0.0))
    fy = np.clip(np.where(r0 + root > 0.0, 2.0 * d / np.where(r0 + root > 0.0, r0 + root, 1.0), 0.0), 0.0, 1.0)
    target = ux * ((1.0 - fy) * r0 + fy * r1)
    rows = (1.0 - fy)[:, None] * conditional[row] + fy[:, None] * conditional[row + 1]
    col = np.clip((rows < target[:, None]).sum(axis=1) - 1, 0, nx - 2)
    dx = np.maximum(target - rows[np.arange(len(col)), col], 0.0)
    c0 = (1.0 - fy) * density[row, col] + fy * density[row + 1, col]
    c1 = (1.0 - fy) * density[row, col + 1] + fy * density[row + 1, col + 1]
    root = np.sqrt(np.maximum(c0 * c0 + 2.0 * dx * (c1 - c0), 0.0))
    fx = np.clip(np.where(c0 + root > 0.0, 2.0 * dx / np.where(c0 + root > 0.0, c0 + root, 1.0), 0.0), 0.0, 1.0)
    return (col + fx) / (nx - 1), (row + fy) / (ny - 1)


def _incident_nodes(table: RglBsdf, theta_max: float) -> list[tuple[float, float]]:
    """(theta_i, phi_i) degrees of the file's incident nodes with theta_i <= theta_max (one azimuth at normal
    incidence; phi_i = 0 only for an isotropic file)."""
    azimuths: list[float] = []
    for p in np.degrees(table.phi_i) % 360.0:  # -180 and 180 deg (float32 -pi, pi) are one azimuth: kept once
        if all(abs((float(p) - q + 180.0) % 360.0 - 180.0) > 1e-3 for q in azimuths):
            azimuths.append(float(p))
    incident = []
    for t in np.degrees(table.theta_i):
        if t > theta_max + 1e-9:
            continue
        phis = [0.0] if table.isotropic or t == 0.0 else sorted(azimuths)
        incident += [(float(t), p) for p in phis]
    if not incident:
        raise ConfigError(f"no incident node of the file lies at or below theta_max {theta_max} deg (the first "
                          f"is {np.degrees(table.theta_i[0]):.6g} deg)", field="theta_max")
    return incident


def rgl_sample_directions(table: RglBsdf, theta_max: float = DEFAULT_THETA_MAX):
    """Direction pairs (degrees, clothlab convention) where the file holds its reflectance samples: at each
    incident node (:func:`_incident_nodes`), every node of the sample grid mapped through the VNDF warp to a
    half vector h and reflected, wo = 2 (wi . h) h - wi; pairs with theta_o > theta_max (or wo below the
    surface) are left out, repeated pairs (e.g. all azimuths of h = n) kept once."""
    ny, nx = table.values.shape[3:]
    gx, gy = np.meshgrid(np.linspace(0.0, 1.0, nx), np.linspace(0.0, 1.0, ny))
    gx, gy = gx.ravel(), gy.ravel()
    rows = []
    for t, p in _incident_nodes(table, theta_max):
        ti, pi_ = math.radians(t), math.radians(p if p <= 180.0 else p - 360.0)
        (ia, wa), (ib, wb) = (_node_weights(table.phi_i, np.array([pi_])), _node_weights(table.theta_i,
                                                                                         np.array([ti])))
        params = ((ia, wa), (ib, wb))
        tables = [_blend(a, params)[0] for a in (table.vndf.density, table.vndf.conditional, table.vndf.marginal)]
        umx, umy = _sample_slice(*tables, gx, gy)
        theta_m, phi_m = umx * umx * (math.pi / 2.0), (2.0 * umy - 1.0) * math.pi
        if table.isotropic:
            phi_m = phi_m + pi_
        h = np.stack([np.sin(theta_m) * np.cos(phi_m), np.sin(theta_m) * np.sin(phi_m), np.cos(theta_m)], axis=1)
        wi = spherical_to_vector(t, p)
        wo = 2.0 * (h @ wi)[:, None] * h - wi
        theta_o = np.degrees(np.arctan2(np.hypot(wo[:, 0], wo[:, 1]), wo[:, 2]))
        phi_o = np.where(theta_o > 0.0, np.degrees(np.arctan2(wo[:, 1], wo[:, 0])) % 360.0, 0.0)
        keep = (wo[:, 2] > 0.0) & (theta_o <= theta_max)
        rows.append(np.stack([np.full(keep.sum(), t), np.full(keep.sum(), p), theta_o[keep], phi_o[keep]], axis=1))
    pairs = np.concatenate(rows)
    _, first = np.unique(np.round(pairs, 9), axis=0, return_index=True)
    pairs = pairs[np.sort(first)]
    if len(pairs) > MAX_ROWS:
        raise ConfigError(f"{len(pairs)} sample direction pairs exceed {MAX_ROWS}", field="exitant")
    return pairs[:, 0], pairs[:, 1], pairs[:, 2], pairs[:, 3]


EXITANT_CHOICES = ("grid", "samples")
"""``exitant`` option of :func:`read_bsdf`: the regular grid (:func:`rgl_directions`) or the file's own sample
directions (:func:`rgl_sample_directions`)."""


def check_options(*, theta_step: float = DEFAULT_THETA_STEP, phi_step: float = DEFAULT_PHI_STEP,
                  theta_max: float = DEFAULT_THETA_MAX, exitant: str = "grid") -> None:
    """ConfigError (``field`` = the option) unless :func:`read_bsdf`'s sampling options are valid."""
    if exitant not in EXITANT_CHOICES:
        raise ConfigError(f"exitant must be one of {' | '.join(EXITANT_CHOICES)}, got {exitant!r}", field="exitant")
    probe = RglBsdf(np.zeros(1), np.zeros(1), np.ones((2, 2)), np.ones((2, 2)), None, np.zeros(0), (), True,
                    True, 1, "")
    rgl_directions(probe, theta_step, phi_step, theta_max)


def read_bsdf(path, *, theta_step: float = DEFAULT_THETA_STEP, phi_step: float = DEFAULT_PHI_STEP,
              theta_max: float = DEFAULT_THETA_MAX, exitant: str = "grid") -> Measurement:
    """Convert an RGL-EPFL ``.bsdf`` file (``measurement.format: bsdf``) to a measurement: the BRDF (1/sr) by
    the format's own evaluation (:func:`lookup_rgl`) at :func:`rgl_directions`.

    ``exitant="samples"``: at the file's own sample directions (:func:`rgl_sample_directions`) instead of the
    regular grid.  The file's x axis is taken as the weft (phi = 0); its incident direction as clothlab's
    theta_i, phi_i.
    """
    try:
        check_options(theta_step=theta_step, phi_step=phi_step, theta_max=theta_max, exitant=exitant)
    except ConfigError as exc:
        raise InputError(exc.detail, path=path, field=exc.field) from None
    table = read_rgl_bsdf(path)
    try:
        theta_i, phi_i, theta_o, phi_o = (rgl_sample_directions(table, theta_max) if exitant == "samples" else
                                          rgl_directions(table, theta_step, phi_step, theta_max))
    except ConfigError as exc:
        raise InputError(exc.detail, path=path, field=exc.field) from None
    values = lookup_rgl(table, spherical_to_vector(theta_i, phi_i), spherical_to_vector(theta_o, phi_o))
    for c, channel in enumerate(table.channels):
        bad = np.flatnonzero(~(np.abs(values[:, c]) <= MAX_VALUE))
        if len(bad):  # e.g. a huge ndf over a tiny sigma
            k = int(bad[0])
            raise InputError(f"channel {channel} converts to {values[k, c]!r} (beyond {MAX_VALUE:g}) at theta_i "
                             f"{theta_i[k]:g}, phi_i {phi_i[k]:g}, theta_o {theta_o[k]:g}, phi_o {phi_o[k]:g} deg",
                             path=path, field=channel)
        if not (values[:, c] > 0.0).any():
            raise InputError(f"channel {channel} is 0 at every converted direction pair", path=path,
                             field=channel)
    info = {"source_format": "bsdf", "isotropic": table.isotropic,
            "sample_name": Path(path).name.split(".")[0],
            "bsdf_description": table.description,
            "bsdf_sampling": ({"exitant": "the file's sample directions", "theta_max": float(theta_max)}
                              if exitant == "samples" else
                              {"exitant": "grid", "theta_step": float(theta_step), "phi_step": float(phi_step),
                               "theta_max": float(theta_max)}) | {"incident": "the file's theta_i / phi_i nodes"},
            "bsdf_grid": {"phi_i": len(table.phi_i), "theta_i": len(table.theta_i),
                          "samples": list(table.values.shape[3:]), "reduction": table.reduction,
                          "jacobian": table.jacobian},
            "bsdf_frame": "file x axis = weft (phi 0); file wi = incident"}
    return Measurement(theta_i, phi_i, theta_o, phi_o, values, table.channels, None, info, str(path))
