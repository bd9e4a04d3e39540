"""Network inputs: the material vector (normalised parameters + pattern descriptor), the one-blob encoding
of the footprint (Chen, Wang & Wang 2024, sec. 4.2; Mueller et al. 2019, "Neural Importance Sampling",
sec. 4.3) and the direction features.

Pattern descriptor.  The paper encodes the tile's normal and orientation maps with a ResNet-18; numpy cannot
train that in minutes, so the map is summarised by its low-frequency periodic Fourier coefficients instead.
In the Irawan-Marschner and surface models the orientation map of a tile is the warp / weft indicator of the
weave pattern (which yarn lies on top), and the normal map follows from it plus the per-yarn-type geometry
(psi, umax, kappa, w, l) that is already in the parameter vector.  So the descriptor is the 2-D DFT of the
indicator (+1 warp, -1 weft) sampled on the tile, for frequencies |k_u|, |k_v| <= ``order`` (one half-plane,
real and imaginary parts; the DC term is the warp / weft balance).  It is periodic, translation-aware
(phases tell where warp floats are, which the position query needs) and as long as ~(2 order + 1)^2.

One-blob (Mueller et al.): a value t in [0, 1] becomes ``bins`` channels exp(-d^2 / (2 sigma^2)) at the bin
centres (i + 0.5) / bins, sigma = 1 / bins; for the periodic footprint position d is the wrapped distance.
The footprint size (tiles) enters as t = ln(1 + s / S0) / ln(1 + S_MAX / S0) (finer bins at small sizes,
where the value varies most).  Three inputs x 8 bins = the paper's 24 channels.
"""

from __future__ import annotations

import math

import numpy as np

from clothlab.params import ParamTable

BLOB_BINS = 8
SIZE_S0 = 0.05  # tiles: scale of the size coordinate
SIZE_MAX = 5.0  # tiles: the largest footprint of Table 2
PATTERN_ORDER = 2
PATTERN_RESOLUTION = 32


def one_blob(t: np.ndarray, bins: int = BLOB_BINS, periodic: bool = False) -> np.ndarray:
    """(N, bins) one-blob encoding of t (N,) in [0, 1] (periodic: t modulo 1, wrapped distances)."""
    t = np.asarray(t, dtype=np.float64)[:, None]
    centres = (np.arange(bins) + 0.5) / bins
    d = t - centres
    if periodic:
        d = d - np.round(d)
    return np.exp(-0.5 * np.square(d * bins))


def size_coordinate(size) -> np.ndarray:
    """Footprint size (tiles) -> [0, 1] (clipped at S_MAX)."""
    s = np.clip(np.asarray(size, dtype=np.float64), 0.0, SIZE_MAX)
    return np.log1p(s / SIZE_S0) / math.log1p(SIZE_MAX / SIZE_S0)


def spatial_features(centre: np.ndarray, size: np.ndarray, bins: int = BLOB_BINS,
                     size_bins: int | None = None) -> np.ndarray:
    """(N, 2 bins + size_bins): one-blob of the footprint centre u, v (tiles, periodic; ``bins`` each) and of
    the size (tiles; ``size_bins``, default ``bins``)."""
    centre = np.asarray(centre, dtype=np.float64)
    return np.concatenate([one_blob(np.mod(centre[:, 0], 1.0), bins, True),
                           one_blob(np.mod(centre[:, 1], 1.0), bins, True),
                           one_blob(size_coordinate(size), bins if size_bins is None else size_bins)], axis=1)


def yarn_features(weave, centre: np.ndarray, extent: dict, bins: int = BLOB_BINS) -> np.ndarray:
    """(N, 1 + 2 bins) yarn-local position of the footprint centre (tiles): 1 on weft segments (else 0), then
    the one-blob of the across- and along-yarn coordinates (Irawan & Marschner 2012, sec. 7.2: x, y in cells
    from the segment centre, :func:`clothlab.weave.lookup.locate_segments`) divided by the half width and
    half length ``extent[kind] = (w / 2, l / 2)`` (cells) and mapped from [-1, 1] to [0, 1] (clipped).

    Not in the paper: its decoder sees only the position one-blob.  The IM texture's value at a point is a
    function of these local coordinates and the directions (the yarn normal and tangent follow from them),
    shared by every segment of a type, so the network can pool what it learns over the segments of a tile
    (docs/notes/neural-log.md: the ablation at footprints below 0.12 tile)."""
    from clothlab.weave.lookup import locate_segments

    centre = np.asarray(centre, dtype=np.float64)
    seg, x, y = locate_segments(weave, centre[:, 0], centre[:, 1])
    kinds = [s.kind for s in weave.segments]
    half = np.array([extent[k] for k in kinds], dtype=np.float64)[seg]
    weft = np.array([k == "weft" for k in kinds], dtype=np.float64)[seg]
    t = [np.clip(0.5 * (c / h + 1.0), 0.0, 1.0) for c, h in ((x, half[:, 0]), (y, half[:, 1]))]
    return np.concatenate([weft[:, None], one_blob(t[0], bins), one_blob(t[1], bins)], axis=1)


def yarn_extent(params: dict) -> dict:
    """{kind: (w / 2, l / 2)} (cells) from the IM yarn parameters ``<kind>.w``, ``<kind>.l``."""
    return {k: (0.5 * float(params[f"{k}.w"]), 0.5 * float(params[f"{k}.l"])) for k in ("warp", "weft")}


def n_yarn_features(bins: int) -> int:
    return 1 + 2 * bins if bins else 0


def direction_features(wi: np.ndarray, wo: np.ndarray, half_vector: bool = True) -> np.ndarray:
    """(N, 5) wi (x, y, z) and wo (x, y) (sec. 4.2), plus the unit half vector (x, y, z) if ``half_vector``."""
    wi, wo = np.asarray(wi, dtype=np.float64), np.asarray(wo, dtype=np.float64)
    parts = [wi, wo[:, :2]]
    if half_vector:
        h = wi + wo
        parts.append(h / np.maximum(np.linalg.norm(h, axis=1, keepdims=True), 1e-12))
    return np.concatenate(parts, axis=1)


def n_direction_features(half_vector: bool) -> int:
    return 8 if half_vector else 5


def normalised_parameters(params: dict, table: ParamTable, names) -> np.ndarray:
    """Each parameter mapped by its declared transform and fit bounds to [0, 1] at the bounds:
    (T(x) - T(lo)) / (T(hi) - T(lo)), T = log for log-declared parameters (docs/design.md principle 4)."""
    out = []
    for name in names:
        spec = table[name]
        lo, hi = (float(spec.to_internal(b)) for b in spec.bounds)
        out.append((float(spec.to_internal(float(params[name]))) - lo) / (hi - lo) if hi > lo else 0.0)
    return np.array(out)


def pattern_descriptor(weave, order: int = PATTERN_ORDER, resolution: int = PATTERN_RESOLUTION) -> np.ndarray:
    """Low-frequency Fourier coefficients of the tile's warp (+1) / weft (-1) indicator (module docstring).

    Sampled at cell-aligned points of one tile (``resolution`` or a little more points per axis, a whole
    number per weave cell, so the DC term is exactly the cell balance); returns the real and imaginary parts of
    the normalised DFT for k_v = 0, 0 < k_u <= order and 0 < k_v <= order, |k_u| <= order, after the real DC
    term: 1 + 2 (order + order (2 order + 1)) values."""
    from clothlab.weave.lookup import locate_segments

    n_u, n_v = (cells * -(-resolution // cells) for cells in (weave.tile_width, weave.tile_height))
    u, v = np.meshgrid((np.arange(n_u) + 0.5) / n_u, (np.arange(n_v) + 0.5) / n_v, indexing="ij")
    seg, _, _ = locate_segments(weave, u, v)
    weft = np.array([s.kind == "weft" for s in weave.segments])[seg]
    coeffs = np.fft.fft2(np.where(weft, -1.0, 1.0)) / (n_u * n_v)
    values = [coeffs[0, 0].real]
    for ku in range(1, order + 1):
        values += [coeffs[ku, 0].real, coeffs[ku, 0].imag]
    for kv in range(1, order + 1):
        for ku in range(-order, order + 1):
            c = coeffs[ku % n_u, kv]
            values += [c.real, c.imag]
    return np.array(values)


def material_vector(weave, params: dict, table: ParamTable, names, order: int = PATTERN_ORDER) -> np.ndarray:
    """The encoder input of one material: normalised parameters then the pattern descriptor."""
    return np.concatenate([normalised_parameters(params, table, names), pattern_descriptor(weave, order)])
