"""UTIA anisotropic BRDF ``.bin`` files (Filip & Vavra 2014, "Template-based sampling of anisotropic BRDFs";
docs/formats.md, "UTIA").

Layout, as the database's own reader (J. Filip's TBDRF) indexes it: little-endian float64, three planes R,
G, B, each [theta_i 6][phi_i 48][theta_v 6][phi_v 48]; theta = 0, 15, ..., 75 deg, phi = 0, 7.5, ...,
352.5 deg; flat index = plane * 82944 + 288 * (48 * i_theta_i + i_phi_i) + 48 * i_theta_v + i_phi_v, so a
file holds exactly 3 * 82944 * 8 = 1,990,656 bytes.  The values are linear RGB with sRGB primaries and are
read as BRDF values (``quantity`` says otherwise); a negative value is refused unless ``negative='zero'``.

Conventions are converted once, at loading: the file's azimuths are taken from ``azimuth_zero`` in
``azimuth_sense`` (defaults weft, ccw: the database does not say where the warp lies) and rotated by
``azimuth_offset`` degrees, as for a clothlab table (:func:`clothlab.io.table.rows_to_measurement`).

:func:`read_utia` returns the measured grid itself: 1 + 5 * 48 = 241 distinct incident directions times
241 exitant ones (58,081 pairs).  At theta = 0 the 48 azimuths name one direction; their 48 stored values
are averaged.  :func:`lookup_utia` interpolates the grid quadrilinearly at any directions (azimuths wrap,
polar angles beyond 75 deg clamp to 75), the interpolation the database's reader uses.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clothlab.atomic import atomic_write_bytes
from clothlab.errors import ConfigError, InputError, ResultExistsError
from clothlab.io.binary import check_size, check_values, read_binary
from clothlab.io.measurement import Measurement
from clothlab.io.table import (
    RawRows,
    check_azimuth_offset,
    check_choice,
    conventions_provenance,
    convert_rows,
    file_azimuth_offset,
)

THETA_STEP, PHI_STEP = 15.0, 7.5
N_THETA, N_PHI = 6, 48
UTIA_SHAPE = (3, N_THETA, N_PHI, N_THETA, N_PHI)
UTIA_BYTES = 8 * int(np.prod(UTIA_SHAPE))
"""1,990,656: the size of every UTIA BRDF file."""
UTIA_CHANNELS = ("R", "G", "B")
NEGATIVE = ("error", "zero")
_WHAT = "UTIA BRDF .bin file"


@dataclass(frozen=True)
class UtiaTable:
    """The UTIA grid: ``brdf`` (3, 6, 48, 6, 48) indexed [channel, theta_i, phi_i, theta_v, phi_v]."""

    brdf: np.ndarray
    path: str | None = None


def _name(k: int) -> str:
    c, ti, pi, tv, pv = np.unravel_index(k, UTIA_SHAPE)
    return (f"{UTIA_CHANNELS[c]}[theta_i={THETA_STEP * ti:g}, phi_i={PHI_STEP * pi:g}, "
            f"theta_v={THETA_STEP * tv:g}, phi_v={PHI_STEP * pv:g}]")


def read_utia_table(path, *, negative: str = "error") -> UtiaTable:
    """The UTIA grid of ``path``, or InputError naming the byte offset of the first bad value."""
    if negative not in NEGATIVE:
        raise InputError(f"unknown negative {negative!r}; expected one of {' | '.join(NEGATIVE)}",
                         path=path, field="negative")
    data = read_binary(path, what=_WHAT)
    check_size(data, UTIA_BYTES, path=path, what=_WHAT)
    flat = np.frombuffer(data, dtype="<f8").astype(np.float64)
    check_values(flat, path=path, offset=0, itemsize=8, name=_name, allow_negative=negative == "zero")
    brdf = np.maximum(flat, 0.0).reshape(UTIA_SHAPE)
    plane = UTIA_BYTES // 3
    for c, channel in enumerate(UTIA_CHANNELS):  # a channel that reflects nothing is not a measurement
        if not brdf[c].any():
            raise InputError(f"every value of channel {channel} (byte offsets {c * plane} to {(c + 1) * plane}) is 0"
                             f"{' or negative' if negative == 'zero' else ''}: a measurement holds reflected light",
                             path=path, field=channel)
    return UtiaTable(brdf, str(path))


def write_utia(brdf: np.ndarray, path, *, overwrite: bool = False) -> Path:
    """Write a (3, 6, 48, 6, 48) grid in the exact UTIA layout, atomically."""
    brdf = np.asarray(brdf, dtype=np.float64)
    if brdf.shape != UTIA_SHAPE:
        raise ValueError(f"expected a UTIA grid of shape {UTIA_SHAPE}, got {brdf.shape}")
    path = Path(path)
    if path.exists() and not overwrite:
        raise ResultExistsError(f"{path} already exists; pass overwrite=True (--force) to replace it", path=path)
    return atomic_write_bytes(path, np.ascontiguousarray(brdf, dtype="<f8").tobytes())


def _axis(angle, step: float, n: int, periodic: bool):
    """Lower node, upper node and the upper weight of a linear interpolation along one grid axis."""
    if periodic:
        x = np.mod(angle, step * n) / step
        lo = np.minimum(np.floor(x), n - 1)
        return lo.astype(np.int64), ((lo + 1) % n).astype(np.int64), x - lo
    x = np.clip(angle, 0.0, step * (n - 1)) / step
    lo = np.minimum(np.floor(x), n - 2)
    return lo.astype(np.int64), (lo + 1).astype(np.int64), x - lo


def lookup_utia(table: UtiaTable, theta_i, phi_i, theta_v, phi_v) -> np.ndarray:
    """(N, 3) quadrilinear interpolation of the grid at angles in the file's own convention (degrees)."""
    axes = [_axis(np.asarray(theta_i, float), THETA_STEP, N_THETA, False),
            _axis(np.asarray(phi_i, float), PHI_STEP, N_PHI, True),
            _axis(np.asarray(theta_v, float), THETA_STEP, N_THETA, False),
            _axis(np.asarray(phi_v, float), PHI_STEP, N_PHI, True)]
    out = 0.0
    for corner in range(16):
        index, weight = [], 1.0
        for axis, (lo, hi, w) in enumerate(axes):
            upper = (corner >> axis) & 1
            index.append(hi if upper else lo)
            weight = weight * (w if upper else 1.0 - w)
        out = out + weight[:, None] * table.brdf[:, index[0], index[1], index[2], index[3]].T
    return out


def _directions():
    """(theta, phi, i_theta, i_phi) of the 241 distinct grid directions (theta = 0 once, phi 0)."""
    thetas, phis, it, ip = [0.0], [0.0], [0], [0]
    for i in range(1, N_THETA):
        for j in range(N_PHI):
            thetas.append(THETA_STEP * i)
            phis.append(PHI_STEP * j)
            it.append(i)
            ip.append(j)
    return np.array(thetas), np.array(phis), np.array(it), np.array(ip)


def check_options(*, azimuth_zero: str = "weft", azimuth_sense: str = "ccw", azimuth_offset: float = 0.0,
                  quantity: str = "brdf", negative: str = "error") -> None:
    """InputError / ConfigError (``field`` = the option) unless :func:`read_utia`'s options are valid."""
    for name, value in (("quantity", quantity), ("azimuth_zero", azimuth_zero), ("azimuth_sense", azimuth_sense)):
        check_choice(name, value)
    check_azimuth_offset(azimuth_offset, error=ConfigError)
    if not isinstance(negative, str) or negative not in NEGATIVE:
        raise ConfigError(f"unknown negative {negative!r}; expected one of {' | '.join(NEGATIVE)}", field="negative")


def read_utia(path, *, azimuth_zero: str = "weft", azimuth_sense: str = "ccw", azimuth_offset: float = 0.0,
              quantity: str = "brdf", negative: str = "error") -> Measurement:
    """Load a UTIA BRDF file as a measurement of its 241 x 241 grid directions (degrees, BRDF in 1/sr)."""
    conventions = {"angle_unit": "deg", "quantity": quantity, "azimuth_zero": azimuth_zero,
                   "azimuth_sense": azimuth_sense}
    for name, value in conventions.items():
        check_choice(name, value, error=InputError, path=path)
    azimuth_offset = check_azimuth_offset(azimuth_offset, path=path)
    table = read_utia_table(path, negative=negative)
    grid = table.brdf.mean(axis=2, keepdims=True).repeat(N_PHI, axis=2)  # theta_i = 0: one direction
    grid[:, 1:] = table.brdf[:, 1:]
    normal_v = grid.mean(axis=4, keepdims=True).repeat(N_PHI, axis=4)
    normal_v[:, :, :, 1:] = grid[:, :, :, 1:]
    theta, phi, it, ip = _directions()
    n = len(theta)
    a, b = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a, b = a.ravel(), b.ravel()
    values = normal_v[:, it[a], ip[a], it[b], ip[b]].T
    angles = np.stack([theta[a], phi[a], theta[b], phi[b]], axis=1)
    raw = RawRows(path=str(path), lines=np.zeros(len(a), dtype=np.int64), angles=angles, values=values,
                  channels=UTIA_CHANNELS, angle_names=("theta_i", "phi_i", "theta_v", "phi_v"))
    # theta_i <= 75 deg on this grid, so a cosine-weighted value always converts (cos theta_i > 0)
    theta_i, phi_i, theta_o, phi_o, brdf, _ = convert_rows(
        raw, **conventions, azimuth_offset=file_azimuth_offset(azimuth_offset, angle_unit="deg",
                                                               azimuth_sense=azimuth_sense))
    provenance = {"source_format": "utia", "sample_name": Path(path).stem, "colour_primaries": "sRGB (linear)",
                  "normal_direction_averaged": True, **conventions_provenance(conventions, azimuth_offset)}
    return Measurement(theta_i, phi_i, theta_o, phi_o, brdf, UTIA_CHANNELS, None, provenance, str(path))
