"""Periodic summed-area tables: exact box-footprint averages of a tile-periodic texture in O(1) per query.

The texture of one direction pair is sampled at the Ru x Rv texel centres of one tile (u_i = (i + 1/2) / Ru,
v_j = (j + 1/2) / Rv) and read as piecewise constant over the texels (the midpoint rule per texel).  Ru and
Rv are the requested ``resolution`` R rounded up to whole texels per weave cell (:func:`table_shape`), so
yarn and segment boundaries are texel edges.  The summed-area table S (Rv + 1, Ru + 1), S[j, i] = sum of
the texels left of i and below j (Crow 1984), gives the integral I(x, y) of that piecewise-constant texture
over [0, x] x [0, y] (texel units) for any real x, y: bilinear interpolation of S is exact inside a texel
(the cross term is the texel's value), and periodicity adds whole tiles,

    I(x, y) = B(rx, ry) + nx B(Ru, ry) + ny B(rx, Rv) + nx ny B(Ru, Rv),   x = nx Ru + rx,  y = ny Rv + ry,

with B the bilinear interpolant of S and 0 <= rx < Ru, 0 <= ry < Rv.  A box footprint's average is the
four-corner difference of I over its area, for any size (many tiles included); one compiled pass over the
queries does it for every component (:mod:`.compiled`).  For the eq. 3-5 normalisation (:mod:`.projection`)
a table of a_o gives the denominator.

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

from clothlab.footprint.projection import weighted_values

DEFAULT_RESOLUTION = 128
_BUILD_POINTS = 1 << 18  # texture points per evaluation call while building (memory bound)
_QUERY_CHUNK = 1 << 18  # footprints per compiled call (bounds the temporary arrays)


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
    None (:mod:`clothlab.footprint.projection`); ``wi``, ``wo`` (P, 3): the direction pairs;
    ``single``: built for one pair given as (3,) vectors.
    """

    def __init__(self, tables: dict[str, np.ndarray], area: np.ndarray | None, wi: np.ndarray, wo: np.ndarray, *,
                 single: bool = False):
        self.tables = tables
        self.wi, self.wo = wi, wo
        self.single = single
        first = next(iter(tables.values())) if tables else area
        self.shape = (first.shape[-1] - 1, first.shape[-2] - 1)  # (Ru, Rv) texels per tile
        self.pairs = first.shape[0]
        # every table side by side, (P, (Rv + 1) (Ru + 1), components [+ a_o]): a query gathers each stencil
        # entry once for all components; ``tables`` and ``area`` are views into it
        columns = list(tables.values()) + ([] if area is None else [area])
        self._stack = np.ascontiguousarray(np.stack([t.reshape(self.pairs, -1) for t in columns], axis=-1))
        full = (self.pairs, self.shape[1] + 1, self.shape[0] + 1)
        self.tables = {name: self._stack[..., k].reshape(full) for k, name in enumerate(tables)}
        self.area = None if area is None else self._stack[..., -1].reshape(full)

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
        chunks = self._chunks(centre, size, pair)
        if chunks is not None:
            parts = [self.query(c, s, pair=q) for c, s, q in chunks]
            return {name: np.concatenate([p[name] for p in parts], axis=-1) for name in parts[0]}
        box, area, shape = self._boxes(centre, size, pair)
        values = box()  # (..., components [+ a_o])
        names = list(self.tables)
        if self.area is None:
            ratio = values / area[:, None]
        else:
            denominator = values[..., -1:]
            ratio = np.divide(values[..., :-1], denominator, out=np.zeros_like(values[..., :-1]),
                              where=denominator > 0.0)
        return {name: shape(ratio[..., k]) for k, name in enumerate(names)}

    def projected_area(self, centre, size, *, pair=None) -> np.ndarray:
        """A_P(wo) of eq. 5 over the footprints (shapes as :meth:`query`): the box average of
        a_o = <wo . n_p> / <n_s . n_p>, or wo_z for a texture without micro normals (n_p = n_s)."""
        chunks = self._chunks(centre, size, pair)
        if chunks is not None:
            return np.concatenate([self.projected_area(c, s, pair=q) for c, s, q in chunks], axis=-1)
        box, area, shape = self._boxes(centre, size, pair)
        if self.area is not None:
            return shape(box()[..., -1] / area)
        wo_z = self.wo[:, 2]
        return shape(np.broadcast_to(wo_z[:, None], (self.pairs, len(area))) if pair is None
                     else wo_z[np.broadcast_to(pair, area.shape)])

    @staticmethod
    def _chunks(centre, size, pair):
        """Argument triples of at most :data:`_QUERY_CHUNK` footprints each, or None for a small call."""
        centre, size = np.asarray(centre, dtype=np.float64), np.asarray(size, dtype=np.float64)
        n = max(len(centre) if centre.ndim == 2 else 1, size.size)
        if n <= _QUERY_CHUNK:
            return None
        centre = np.broadcast_to(np.atleast_2d(centre), (n, 2))
        size = np.broadcast_to(size.reshape(-1) if size.ndim else size, (n,))
        pair = None if pair is None else np.broadcast_to(np.asarray(pair), (n,))
        return [(centre[k:k + _QUERY_CHUNK], size[k:k + _QUERY_CHUNK],
                 None if pair is None else pair[k:k + _QUERY_CHUNK]) for k in range(0, n, _QUERY_CHUNK)]

    def _boxes(self, centre, size, pair):
        """(box integrals of every table, (N, C) or (P, N, C); footprint areas (N,) in texels; output shaping)
        for the queries."""
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
        from clothlab.footprint.compiled import box_sums

        def box():  # the four-corner difference of I for every table column at once (compiled)
            stack = self._stack.reshape(-1, self._stack.shape[-1])
            if pair is not None:
                return box_sums(stack, np.ascontiguousarray(pair, dtype=np.int64), *self.shape, x0, x1, y0, y1)
            every = np.repeat(np.arange(self.pairs, dtype=np.int64), n)
            sums = box_sums(stack, every, *self.shape, *(np.tile(z, self.pairs) for z in (x0, x1, y0, y1)))
            return sums.reshape(self.pairs, n, -1)

        def shape(value):
            if self.single and pair is None:
                value = value[0]
            return value[..., 0] if scalar else value

        return box, 4.0 * half_u * half_v, shape
