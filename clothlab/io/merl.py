"""MERL ``.binary`` isotropic BRDF tables (Matusik, Pfister, Brand & McMillan 2003; docs/formats.md, "MERL").

Layout: little-endian int32 ``dims[3]`` = (n_theta_h, n_theta_d, n_phi_d) = (90, 90, 180), then
float64 ``[3][n_theta_h][n_theta_d][n_phi_d]`` (all red, then green, then blue).  A BRDF value (1/sr) is
the stored number times the channel scale (1/1500, 1.15/1500, 1.66/1500); a negative number marks a bin
that was not measured.  Bins are in Rusinkiewicz's (1998) half/difference angles:

- theta_h index = floor(sqrt(theta_h / (pi/2)) * n_theta_h)  (non-linear: dense near the specular peak),
- theta_d index = floor(theta_d / (pi/2) * n_theta_d),
- phi_d index = floor(phi_d / pi * n_phi_d), phi_d taken into [0, pi) by adding pi when negative
  (reciprocity, which also makes phi_d and phi_d + pi the same bin),

each clamped to its range; flat index = phi_d + n_phi_d * (theta_d + n_theta_d * theta_h).  Other ``dims``
(a reduced-resolution file) use the same formulas with their own counts and are recorded in the provenance.

The table is isotropic: the BRDF depends on phi_o - phi_i only, so a MERL measurement of cloth constrains
the reflectance averaged over the fabric's orientation.  The loaded measurement says so with
``provenance['isotropic'] = True``; the right model for it is the cloth model averaged over orientation
(the fitter reads the flag).

Two ways in: :func:`lookup_merl` samples the table at any directions; :func:`read_merl` (the loader behind
``measurement.format: merl``) converts it once, at loading, to a :class:`Measurement` at a regular set of
direction pairs (:func:`merl_directions`): MERL holds 1.46 million bins, a fit wants a few thousand
directions, and an isotropic table needs phi_i = 0 only.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clothlab.atomic import atomic_write_bytes
from clothlab.errors import ConfigError, InputError, ResultExistsError
from clothlab.frames import spherical_to_vector
from clothlab.io.binary import array_at, check_size, check_values, read_binary
from clothlab.io.measurement import Measurement
from clothlab.io.table import MIN_ROWS

MERL_DIMS = (90, 90, 180)
"""(n_theta_h, n_theta_d, n_phi_d) of the MERL database's files."""
MERL_SCALE = (1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0)
"""Stored number -> BRDF (1/sr), per channel R, G, B."""
MERL_CHANNELS = ("R", "G", "B")
HEADER_BYTES = 12
MAX_DIM = 4096
"""Largest bin count along one MERL axis accepted (a header beyond it is not a MERL file)."""
DEFAULT_THETA_STEP = 7.5
DEFAULT_PHI_STEP = 10.0
DEFAULT_THETA_MAX = 85.0
_WHAT = "MERL .binary file"


@dataclass(frozen=True)
class MerlTable:
    """A MERL table in memory: ``brdf`` (3, n_theta_h, n_theta_d, n_phi_d), 1/sr, negative = not measured."""

    brdf: np.ndarray
    path: str | None = None

    @property
    def dims(self) -> tuple[int, int, int]:
        return tuple(int(n) for n in self.brdf.shape[1:])


def _bin_name(dims):
    plane = dims[0] * dims[1] * dims[2]

    def name(k: int) -> str:
        channel, rest = divmod(k, plane)
        h, rest = divmod(rest, dims[1] * dims[2])
        d, p = divmod(rest, dims[2])
        return f"{MERL_CHANNELS[channel]}[theta_h={h}, theta_d={d}, phi_d={p}]"

    return name


def read_merl_table(path) -> MerlTable:
    """The MERL table of ``path`` (values scaled to 1/sr), or InputError naming the byte offset."""
    data = read_binary(path, what=_WHAT)
    if len(data) < HEADER_BYTES:
        raise InputError(f"truncated {_WHAT}: the file ends at byte offset {len(data)}, the int32 dims header "
                         f"alone needs {HEADER_BYTES} bytes", path=path, field="dims")
    dims = tuple(int(n) for n in array_at(data, 0, "<i4", 3, path=path, what=_WHAT))
    if any(n < 1 or n > MAX_DIM for n in dims):
        raise InputError(f"dims header {dims} at byte offset 0 is not a MERL header: expected three int32 "
                         f"bin counts in [1, {MAX_DIM}], e.g. {MERL_DIMS}", path=path, field="dims")
    count = 3 * dims[0] * dims[1] * dims[2]
    check_size(data, HEADER_BYTES + 8 * count, path=path, what=f"{_WHAT} with dims {dims}")
    raw = array_at(data, HEADER_BYTES, "<f8", count, path=path, what=_WHAT)
    # negative = not measured (allowed); NaN, infinities and absurd magnitudes are refused
    check_values(raw, path=path, offset=HEADER_BYTES, itemsize=8, name=_bin_name(dims), allow_negative=True)
    brdf = raw.reshape(3, *dims) * np.asarray(MERL_SCALE)[:, None, None, None]
    plane = 8 * dims[0] * dims[1] * dims[2]
    for c, channel in enumerate(MERL_CHANNELS):  # a channel that reflects nothing is not a measurement
        if not (brdf[c] > 0.0).any():
            start = HEADER_BYTES + c * plane
            raise InputError(f"no measured bin of channel {channel} holds light: every value from byte offset "
                             f"{start} to {start + plane} is 0 or negative (negative: not measured)", path=path,
                             field=channel)
    return MerlTable(brdf, str(path))


def write_merl(stored: np.ndarray, path, *, overwrite: bool = False) -> Path:
    """Write stored numbers ``stored`` (3, n_theta_h, n_theta_d, n_phi_d) in the exact MERL layout, atomically.

    ``stored`` are the file's numbers (BRDF / :data:`MERL_SCALE`), so a write followed by
    :func:`read_merl_table` gives ``stored * MERL_SCALE``.
    """
    stored = np.asarray(stored, dtype=np.float64)
    if stored.ndim != 4 or stored.shape[0] != 3:
        raise ValueError(f"expected stored numbers of shape (3, n_theta_h, n_theta_d, n_phi_d), got {stored.shape}")
    path = Path(path)
    if path.exists() and not overwrite:
        raise ResultExistsError(f"{path} already exists; pass overwrite=True (--force) to replace it", path=path)
    header = np.asarray(stored.shape[1:], dtype="<i4").tobytes()
    return atomic_write_bytes(path, header + np.ascontiguousarray(stored, dtype="<f8").tobytes())


def half_diff_angles(wi: np.ndarray, wo: np.ndarray):
    """Rusinkiewicz (1998) half/difference angles (theta_h, phi_h, theta_d, phi_d), radians, of unit vectors
    (..., 3).  The difference vector is wi in the frame (t, b, h) of the half vector h, where
    t = d h / d theta_h and b = z x h / |z x h| (MERL's rotations of wi by -phi_h about z, then -theta_h about y).
    """
    h = wi + wo
    h = h / np.linalg.norm(h, axis=-1, keepdims=True)
    theta_h = np.arccos(np.clip(h[..., 2], -1.0, 1.0))
    phi_h = np.arctan2(h[..., 1], h[..., 0])
    ct, st, cp, sp = np.cos(theta_h), np.sin(theta_h), np.cos(phi_h), np.sin(phi_h)
    t = np.stack([ct * cp, ct * sp, -st], axis=-1)
    b = np.stack([-sp, cp, np.zeros_like(cp)], axis=-1)
    dx, dy = np.sum(wi * t, axis=-1), np.sum(wi * b, axis=-1)
    dz = np.sum(wi * h, axis=-1)
    theta_d = np.arccos(np.clip(dz, -1.0, 1.0))
    phi_d = np.arctan2(dy, dx)
    return theta_h, phi_h, theta_d, phi_d


def merl_bins(theta_h, theta_d, phi_d, dims=MERL_DIMS):
    """(i_theta_h, i_theta_d, i_phi_d) integer bins of half/difference angles (radians), MERL's mapping."""
    n_h, n_d, n_p = dims
    half_pi = np.pi / 2.0
    i_h = np.floor(np.sqrt(np.clip(theta_h, 0.0, None) / half_pi) * n_h)
    i_d = np.floor(theta_d / half_pi * n_d)
    phi = np.where(phi_d < 0.0, phi_d + np.pi, phi_d)
    i_p = np.floor(phi / np.pi * n_p)
    return (np.clip(i_h, 0, n_h - 1).astype(np.int64), np.clip(i_d, 0, n_d - 1).astype(np.int64),
            np.clip(i_p, 0, n_p - 1).astype(np.int64))


def lookup_merl(table: MerlTable, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """(N, 3) BRDF (1/sr) of ``table`` at unit direction pairs (N, 3) in the surface frame; NaN where the
    bin was not measured (negative in the file)."""
    theta_h, _, theta_d, phi_d = half_diff_angles(np.asarray(wi, float), np.asarray(wo, float))
    i_h, i_d, i_p = merl_bins(theta_h, theta_d, phi_d, table.dims)
    values = table.brdf[:, i_h, i_d, i_p].T
    return np.where(values >= 0.0, values, np.nan)


def merl_directions(theta_step: float = DEFAULT_THETA_STEP, phi_step: float = DEFAULT_PHI_STEP,
                    theta_max: float = DEFAULT_THETA_MAX):
    """Direction pairs (theta_i, phi_i, theta_o, phi_o), degrees, at which :func:`read_merl` samples a table.

    theta_i and theta_o run over step/2, 3 step/2, ... <= theta_max (no normal direction, whose azimuth is
    undefined); phi_i = 0 (the table is isotropic); phi_o over 0, phi_step, ..., 180 (phi_o and -phi_o are
    the same by isotropy).  The defaults give 11 x 11 x 19 = 2,299 pairs out to 78.75 deg.
    """
    for name, value, low, high in (("theta_step", theta_step, 0.5, 45.0), ("phi_step", phi_step, 0.5, 90.0),
                                   ("theta_max", theta_max, 1.0, 89.9)):
        if isinstance(value, bool) or not isinstance(value, int | float) or not low <= value <= high:
            raise ConfigError(f"{name} must be a number of degrees in [{low}, {high}], got {value!r}", field=name)
    if theta_step / 2.0 > theta_max:
        raise ConfigError(f"theta_max {theta_max} is below the first polar angle theta_step / 2 = "
                          f"{theta_step / 2.0}", field="theta_max")
    thetas = np.arange(theta_step / 2.0, theta_max + 1e-9, theta_step)
    phis = np.arange(0.0, 180.0 + 1e-9, phi_step)
    ti, to, po = np.meshgrid(thetas, thetas, phis, indexing="ij")
    ti, to, po = ti.ravel(), to.ravel(), po.ravel()
    return ti, np.zeros_like(ti), to, po


def sample_merl(table: MerlTable, theta_i, phi_i, theta_o, phi_o, *, provenance=None) -> Measurement:
    """A :class:`Measurement` of ``table`` at direction pairs (degrees, clothlab convention); pairs whose
    bin was not measured in some channel are dropped and counted in ``provenance['merl_unmeasured_pairs']``."""
    theta_i, phi_i, theta_o, phi_o = (np.asarray(a, dtype=np.float64) for a in (theta_i, phi_i, theta_o, phi_o))
    values = lookup_merl(table, spherical_to_vector(theta_i, phi_i), spherical_to_vector(theta_o, phi_o))
    keep = np.isfinite(values).all(axis=1)
    if keep.sum() < MIN_ROWS:
        raise InputError(f"{int(keep.sum())} of the {len(keep)} sampled direction pairs fall in bins measured in "
                         f"every channel; a measurement needs at least {MIN_ROWS} (a negative value in the file "
                         "marks a bin not measured): sample more densely", path=table.path, field="theta_step")
    for c, channel in enumerate(MERL_CHANNELS):
        if not (values[keep, c] > 0.0).any():
            raise InputError(f"channel {channel} is 0 at every sampled direction pair: the file's positive "
                             f"values of {channel} lie in bins no sampled pair reaches; sample more densely",
                             path=table.path, field="theta_step")
    info = {"source_format": "merl", "isotropic": True, "merl_dims": list(table.dims),
            "merl_unmeasured_pairs": int((~keep).sum()), **(provenance or {})}
    return Measurement(theta_i[keep], phi_i[keep], theta_o[keep], phi_o[keep], values[keep], MERL_CHANNELS,
                       None, info, table.path)


def check_options(*, theta_step: float = DEFAULT_THETA_STEP, phi_step: float = DEFAULT_PHI_STEP,
                  theta_max: float = DEFAULT_THETA_MAX) -> None:
    """ConfigError (``field`` = the option) unless :func:`read_merl`'s sampling options are valid."""
    merl_directions(theta_step, phi_step, theta_max)


def read_merl(path, *, theta_step: float = DEFAULT_THETA_STEP, phi_step: float = DEFAULT_PHI_STEP,
              theta_max: float = DEFAULT_THETA_MAX) -> Measurement:
    """Load a MERL ``.binary`` file as a measurement at :func:`merl_directions` (degrees, BRDF in 1/sr).

    The provenance records ``isotropic: true``, the sampling and the count of unmeasured pairs dropped.
    """
    try:
        directions = merl_directions(theta_step, phi_step, theta_max)
    except ConfigError as exc:
        raise InputError(exc.detail, path=path, field=exc.field) from None
    table = read_merl_table(path)
    sampling = {"theta_step": float(theta_step), "phi_step": float(phi_step), "theta_max": float(theta_max)}
    return sample_merl(table, *directions, provenance={"merl_sampling": sampling,
                                                      "sample_name": Path(path).name.split(".")[0]})
