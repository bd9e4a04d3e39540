"""Periodic summed-area tables: exact box-footprint averages of a tile-periodic texture in O(1) per query.

The texture of one direction pair is sampled at the Ru x Rv texel centres of one tile (u_i = (i + 1/2) / Ru,
v_j = (j + 1/2) / Rv) and read as piecewise constant over the texels (the midpoint rule per texel).  Ru and
Rv are the requested ``resolution`` R rounded up to whole texels per weave cell (:func:`table_shape`), so
yarn and segment boundaries are texel edges.  The summed-area table S (Rv + 1, Ru + 1), S[j, i] = sum of the
texels left of i and below j (Crow 1984), gives the
integral I(x, y) of that piecewise-constant texture over [0, x] x [0, y] (texel units) for any real x, y:
bilinear interpolation of S is exact inside a texel (the cross term is the texel's value), and periodicity
adds whole tiles,

    I(x, y) = B(rx, ry) + nx B(Ru, ry) + ny B(rx, Rv) + nx ny B(Ru, Rv),   x = nx Ru + rx,  y = ny Rv + ry,

with B the bilinear interpolant of S and 0 <= rx < Ru, 0 <= ry < Rv.  A box footprint's average is the four-corner
difference of I over its area, for any size (many tiles included), with no loop per query.  For the eq. 3-5
normalisation (:mod:`.projection`) a second table of a_o gives the denominator.

Exactness and discretisation error.  The query is exact (to rounding, ~1e-13 relative) for the
piecewise-constant texture; whole-tile footprints give the table's mean exactly.  Against the continuous
texture the error comes from texels cut by a discontinuity (the IM highlight band edges of eq. 12, Kang's
fibre ridges; the yarn boundaries are texel edges): the midpoint rule moves each axis-aligned edge to a texel
boundary, by at most half a texel, so a footprint of s tiles (s R texels a side) crossing an edge of jump df
has an error up to ~ df / (2 s R) per edge, and a band of width b texels has its tile-average weight off by
up to 1 / (2 b) per edge.  R = 128 (the default) makes a texel ~1/128 tile; docs/footprint.md and the
``footprint`` bench section give the measured error by footprint size.  Cost: Ru Rv texture evaluations
per direction pair to build, then O(1) per query.
"""

from __future__ import annotations

import numpy as np

from clothlab.models.footprint.projection import weighted_values

DEFAULT_RESOLUTION = 128
_BUILD_POINTS = 1 << 18  # texture points per evaluation call while building (memory bound)


def _bilinear(table: np.ndarray, pair, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """B(x, y), 0 <= x <= Ru, 0 <= y <= Rv (texel units) of tables (P, Rv + 1, Ru + 1): (N,) for pair (N,),
    else (P, N)."""
    i0 = np.minimum(np.floor(x), table.shape[-1] - 2).astype(np.intp)
    j0 = np.minimum(np.floor(y), table.shape[-2] - 2).astype(np.intp)
    a, b = x - i0, y - j0
    if pair is None:
        s00, s10 = table[:, j0, i0], table[:, j0, i0 + 1]
        s01, s11 = table[:, j0 + 1, i0], table[:, j0 + 1, i0 + 1]
    else:
        s00, s10 = table[pair, j0, i0], table[pair, j0, i0 + 1]
        s01, s11 = table[pair, j0 + 1, i0], table[pair, j0 + 1, i0 + 1]
    return (1.0 - b) * ((1.0 - a) * s00 + a * s10) + b * ((1.0 - a) * s01 + a * s11)


def _integral(table: np.ndarray, pair, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """I(x, y) of the periodic piecewise-constant texture (module docstring), x, y any reals (texel units)."""
    r_u, r_v = table.shape[-1] - 1, table.shape[-2] - 1
    nx, ny = np.floor(x / r_u), np.floor(y / r_v)
    rx, ry = np.clip(x - nx * r_u, 0.0, r_u), np.clip(y - ny * r_v, 0.0, r_v)
    full_u, full_v = np.full_like(rx, float(r_u)), np.full_like(ry, float(r_v))
    return (_bilinear(table, pair, rx, ry) + nx * _bilinear(table, pair, full_u, ry)
            + ny * _bilinear(table, pair, rx, full_v) + nx * ny * _bilinear(table, pair, full_u, full_v))


def summed_area(values: np.ndarray) -> np.ndarray:
    """S (..., Rv + 1, Ru + 1) of texel values (..., Rv, Ru) (rows v, columns u), S[..., 0, :] = S[..., :, 0] = 0."""
    shape = values.shape[:-2] + (values.shape[-2] + 1, values.shape[-1] + 1)
    table = np.zeros(shape)
    table[..., 1:, 1:] = np.cumsum(np.cumsum(values, axis=-2), axis=-1)
    return table


def table_shape(texture, resolution: int) -> tuple[int, int]:
    """(Ru, Rv): texels per tile along u and v, each at least ``resolution`` and a whole number of texels per
    weave cell (W x H cells: Ru = W ceil(R / W), Rv = H ceil(R / H)), so that yarn and segment boundaries fall
    on texel edges; (R, R) for a texture without a weave."""
    weave = getattr(texture, "weave", None)
    if weave is None:
        return resolution, resolution
    w, h = int(weave.tile_width), int(weave.tile_height)
    return w * -(-resolution // w), h * -(-resolution // h)


def texel_centres(r_u: int, r_v: int) -> tuple[np.ndarray, np.ndarray]:
    """u, v (Rv * Ru,) of the texel centres of one tile, row-major (v rows, u columns)."""
    v, u = np.meshgrid((np.arange(r_v) + 0.5) / r_v, (np.arange(r_u) + 0.5) / r_u, indexing="ij")
    return u.ravel(), v.ravel()


class FootprintTable:
    """Summed-area tables of a texture over one tile, one per direction pair and component.

    Build with :meth:`build`; :meth:`query` returns box-footprint averages (1/sr) for many footprints.
    ``tables``: {component: (P, Rv + 1, Ru + 1)}; ``area``: the a_o table for the eq. 4-5 normalisation, or
    None (:mod:`clothlab.models.footprint.projection`); ``wi``, ``wo`` (P, 3): the direction pairs;
    ``single``: built for one pair given as (3,) vectors.
    """

    def __init__(self, tables: dict[str, np.ndarray], area: np.ndarray | None, wi: np.ndarray, wo: np.ndarray, *,
                 single: bool = False):
        self.tables = tables
        self.wi, self.wo = wi, wo
        self.area = area
        self.single = single
        first = next(iter(tables.values())) if tables else area
        self.shape = (first.shape[-1] - 1, first.shape[-2] - 1)  # (Ru, Rv) texels per tile
        self.pairs = first.shape[0]

    @classmethod
    def build(cls, texture, params, wi, wo, resolution: int = DEFAULT_RESOLUTION, *, need=None,
              noise: bool = False, warn: bool = True) -> FootprintTable:
        """Tables of ``texture`` (the texture interface of :mod:`clothlab.models.base`) with ``params`` for
        direction pairs wi, wo ((3,) for one pair or (P, 3), fabric frame) at at least ``resolution`` texels
        per tile side (:func:`table_shape`).  ``need`` limits the components; ``noise`` must stay False (a
        texture's noise is not periodic over one tile, which the table assumes)."""
        if noise:
            raise ValueError("summed-area tables need a tile-periodic texture: noise=True is for method='mc'")
        resolution = int(resolution)
        if resolution < 1:
            raise ValueError(f"resolution must be a positive number of texels per tile side, got {resolution}")
        single = np.ndim(wi) == 1
        wi = np.atleast_2d(np.asarray(wi, dtype=np.float64))
        wo = np.atleast_2d(np.asarray(wo, dtype=np.float64))
        if wi.shape != wo.shape or wi.shape[1] != 3:
            raise ValueError(f"wi, wo must be (3,) or (P, 3) arrays of the same shape, got {wi.shape}, {wo.shape}")
        r_u, r_v = table_shape(texture, resolution)
        u, v = texel_centres(r_u, r_v)
        texels = r_u * r_v
        # one call per pair with (1, 3) directions where the texture takes them (IM: ~4x faster per point),
        # else several pairs per call with the directions repeated per texel
        shared = bool(getattr(texture, "shared_directions", False))
        per_call = 1 if shared else max(1, _BUILD_POINTS // texels)
        tables: dict[str, list[np.ndarray]] = {}
        areas: list[np.ndarray] = []
        for start in range(0, len(wi), per_call):
            stop = min(start + per_call, len(wi))
            k = stop - start
            if shared:
                uu, vv, di, do = u, v, wi[start:stop], wo[start:stop]
            else:
                uu, vv = np.tile(u, k), np.tile(v, k)
                di, do = np.repeat(wi[start:stop], texels, axis=0), np.repeat(wo[start:stop], texels, axis=0)
            values, area = weighted_values(texture, params, uu, vv, di, do, need=need, noise=False,
                                           warn=warn and start == 0)
            for name, value in values.items():
                tables.setdefault(name, []).append(summed_area(value.reshape(k, r_v, r_u)))
            if area is not None:
                areas.append(summed_area(area.reshape(k, r_v, r_u)))
        return cls({name: np.concatenate(parts) for name, parts in tables.items()},
                   np.concatenate(areas) if areas else None, wi, wo, single=single)

    def tile_average(self) -> dict[str, np.ndarray]:
        """The table's whole-tile averages per component, (P,) (or scalars for a single pair)."""
        return self.query(np.zeros(2), 1.0)

    def query(self, centre, size, *, pair=None) -> dict[str, np.ndarray]:
        """Box-footprint averages: ``centre`` (N, 2) or (2,) in tiles (any reals), ``size`` (N,) or scalar,
        tiles, > 0.  Without ``pair``: every built pair, (P, N) ((N,) for a single pair; scalars for a
        single footprint too); with ``pair`` (N,) int: footprint k uses pair[k], (N,)."""
        box, area, shape = self._boxes(centre, size, pair)
        denominator = area if self.area is None else box(self.area)
        out = {}
        for name, table in self.tables.items():
            numerator = box(table)
            if self.area is None:
                value = numerator / denominator
            else:
                value = np.divide(numerator, denominator, out=np.zeros_like(numerator), where=denominator > 0.0)
            out[name] = shape(value)
        return out

    def projected_area(self, centre, size, *, pair=None) -> np.ndarray:
        """A_P(wo) of eq. 5 over the footprints (shapes as :meth:`query`): the box average of
        a_o = <wo . n_p> / <n_s . n_p>, or wo_z for a texture without micro normals (n_p = n_s)."""
        box, area, shape = self._boxes(centre, size, pair)
        if self.area is not None:
            return shape(box(self.area) / area)
        wo_z = self.wo[:, 2]
        return shape(np.broadcast_to(wo_z[:, None], (self.pairs, len(area))) if pair is None
                     else wo_z[np.broadcast_to(pair, area.shape)])

    def _boxes(self, centre, size, pair):
        """(box integral of a table, footprint areas (N,) in texels, output shaping) for the queries."""
        centre = np.asarray(centre, dtype=np.float64)
        scalar = centre.ndim == 1 and np.ndim(size) == 0
        centre = np.atleast_2d(centre)
        size = np.atleast_1d(np.asarray(size, dtype=np.float64))
        n = max(len(centre), len(size))
        centre, size = np.broadcast_to(centre, (n, 2)), np.broadcast_to(size, (n,))
        if not (np.all(np.isfinite(centre)) and np.all(np.isfinite(size)) and np.all(size > 0.0)):
            raise ValueError("footprint centres must be finite and sizes finite and > 0 (tiles)")
        if pair is not None:
            pair = np.broadcast_to(np.asarray(pair, dtype=np.intp), (n,))
            if np.any((pair < 0) | (pair >= self.pairs)):
                raise ValueError(f"pair indices must lie in [0, {self.pairs})")
        r = np.array(self.shape, dtype=np.float64)
        c = np.mod(centre, 1.0) * r  # periodic: stay near the first tile (small integrals, little rounding)
        half_u, half_v = 0.5 * size * r[0], 0.5 * size * r[1]
        x0, x1, y0, y1 = c[:, 0] - half_u, c[:, 0] + half_u, c[:, 1] - half_v, c[:, 1] + half_v

        def box(table):
            return (_integral(table, pair, x1, y1) - _integral(table, pair, x0, y1)
                    - _integral(table, pair, x1, y0) + _integral(table, pair, x0, y0))

        def shape(value):
            if self.single and pair is None:
                value = value[0]
            return value[..., 0] if scalar else value

        return box, 4.0 * half_u * half_v, shape
