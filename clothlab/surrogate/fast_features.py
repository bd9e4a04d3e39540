"""The decoder's inputs in one compiled pass (issue 23, build item 3: cheap queries).

The same values as :func:`clothlab.surrogate.encodings.spatial_features`, :func:`~clothlab.surrogate.encodings.
yarn_features` and :func:`~clothlab.surrogate.encodings.direction_features` (computed in float64, stored in
float32: the decoder's dtype), written straight into two float32 arrays, without the ~20 temporary (N, k)
float64 arrays of the numpy path.  The yarn lookup (Irawan & Marschner 2012, sec. 7.2;
:func:`clothlab.weave.lookup.locate_segments`) reads a per-cell table of segment indices made once per weave
(:func:`yarn_tables`).  Measured on this machine: 0.42-0.5 -> 0.22-0.27 CPU-us per query (docs/neural.md,
"What changed in session 12").
"""

from __future__ import annotations

import math

import numba
import numpy as np

from clothlab.surrogate.encodings import SIZE_MAX, SIZE_S0

INV_E = math.exp(-1.0)


def njit(**options):
    """``numba.njit`` that compiles uncached where no cache directory is writable (numba raises RuntimeError
    "no locator available" then), as :func:`clothlab.models.jit.njit` does for the model kernels (this
    package sits below ``models`` in the import layers)."""
    def wrap(fn):
        try:
            return numba.njit(**options)(fn)
        except RuntimeError as exc:
            if "no locator available" not in str(exc):
                raise
            return numba.njit(**{**options, "cache": False})(fn)
    return wrap


@njit(cache=True, inline="always")
def _blob(out, n, start, t, bins, periodic):
    """exp(-x_j^2 / 2), x_j = (t - c_j) bins (wrapped when periodic): by the recurrence e_{j+1} = e_j g_j,
    g_{j+1} = g_j / e (x drops by 1 per bin), restarted wherever the wrap shifts x, so two or three exps
    per blob instead of one per bin."""
    e = g = 0.0
    shift = 2  # no run yet
    for j in range(bins):
        d = t - (j + 0.5) / bins
        k = 0
        if periodic:
            k = -round(d)
        if k != shift:
            x = (d + k) * bins
            e, g, shift = math.exp(-0.5 * x * x), math.exp(x - 0.5), k
        out[n, start + j] = e
        e *= g
        g *= INV_E


@njit(cache=True)
def _features(centre, size, wi, wo, pb, sb, yb, half_vector, cell_seg, seg_u, seg_v, seg_weft, seg_half,
              width, height, spatial, angular):
    size_norm = math.log1p(SIZE_MAX / SIZE_S0)
    for n in range(centre.shape[0]):
        u, v = centre[n, 0], centre[n, 1]
        _blob(spatial, n, 0, u - math.floor(u), pb, True)
        _blob(spatial, n, pb, v - math.floor(v), pb, True)
        s = min(max(size[n], 0.0), SIZE_MAX)
        _blob(spatial, n, 2 * pb, math.log1p(s / SIZE_S0) / size_norm, sb, False)
        if yb > 0:
            big_u, big_v = u * width, v * height
            col = int(math.floor(big_u)) % width
            row = height - 1 - int(math.floor(big_v)) % height
            seg = cell_seg[row, col]
            du = big_u - seg_u[seg]
            du = du - width * math.floor(du / width + 0.5)
            dv = big_v - seg_v[seg]
            dv = dv - height * math.floor(dv / height + 0.5)
            weft = seg_weft[seg]
            x, y = (-dv, du) if weft else (du, dv)
            o = 2 * pb + sb
            spatial[n, o] = 1.0 if weft else 0.0
            _blob(spatial, n, o + 1, min(max(0.5 * (x / seg_half[seg, 0] + 1.0), 0.0), 1.0), yb, False)
            _blob(spatial, n, o + 1 + yb, min(max(0.5 * (y / seg_half[seg, 1] + 1.0), 0.0), 1.0), yb, False)
        for k in range(3):
            angular[n, k] = wi[n, k]
        angular[n, 3], angular[n, 4] = wo[n, 0], wo[n, 1]
        if half_vector:
            hx, hy, hz = wi[n, 0] + wo[n, 0], wi[n, 1] + wo[n, 1], wi[n, 2] + wo[n, 2]
            norm = max(math.sqrt(hx * hx + hy * hy + hz * hz), 1e-12)
            angular[n, 5], angular[n, 6], angular[n, 7] = hx / norm, hy / norm, hz / norm


def yarn_tables(weave, extent: dict):
    """(cell -> segment index (H, W), segment centres u, v (cells), is-weft, half extents (S, 2) cells) of
    ``weave`` for :func:`features`; ``extent[kind] = (w / 2, l / 2)`` (cells) as :func:`yarn_features`."""
    from clothlab.weave.lookup import locate_segments

    w, h = weave.tile_width, weave.tile_height
    col, row = np.meshgrid(np.arange(w), np.arange(h))  # row from the top of the tile
    seg, _, _ = locate_segments(weave, (col + 0.5) / w, (h - 1 - row + 0.5) / h)
    segments = weave.segments
    return (np.ascontiguousarray(seg, dtype=np.int64),
            np.array([s.center_u for s in segments], dtype=np.float64) * w,
            np.array([s.center_v for s in segments], dtype=np.float64) * h,
            np.array([s.kind == "weft" for s in segments]),
            np.array([extent[s.kind] for s in segments], dtype=np.float64).reshape(-1, 2))


def features(centre, size, wi, wo, position_bins: int, size_bins: int, yarn_bins: int, half_vector: bool,
             tables=None, dtype=np.float32) -> tuple[np.ndarray, np.ndarray]:
    """(spatial (N, 2 pb + sb [+ 1 + 2 yb]), angular (N, 5 or 8)) features in ``dtype``; ``tables``:
    :func:`yarn_tables` when ``yarn_bins`` > 0."""
    centre = np.ascontiguousarray(np.atleast_2d(centre), dtype=np.float64)
    n = centre.shape[0]
    size = np.ascontiguousarray(np.broadcast_to(np.asarray(size, dtype=np.float64).reshape(-1), (n,)))
    wi = np.ascontiguousarray(np.broadcast_to(np.atleast_2d(np.asarray(wi, dtype=np.float64)), (n, 3)))
    wo = np.ascontiguousarray(np.broadcast_to(np.atleast_2d(np.asarray(wo, dtype=np.float64)), (n, 3)))
    yb = int(yarn_bins)
    spatial = np.empty((n, 2 * position_bins + size_bins + (1 + 2 * yb if yb else 0)), dtype=dtype)
    angular = np.empty((n, 8 if half_vector else 5), dtype=dtype)
    if yb:
        cell_seg, seg_u, seg_v, seg_weft, seg_half = tables
    else:
        cell_seg, seg_u, seg_v = np.zeros((1, 1), np.int64), np.zeros(1), np.zeros(1)
        seg_weft, seg_half = np.zeros(1, dtype=np.bool_), np.ones((1, 2))
    _features(centre, size, wi, wo, int(position_bins), int(size_bins), yb, bool(half_vector), cell_seg, seg_u,
              seg_v, seg_weft, seg_half, 1 if not yb else cell_seg.shape[1], 1 if not yb else cell_seg.shape[0],
              spatial, angular)
    return spatial, angular
