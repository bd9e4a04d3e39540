"""Label sources: what the training data learns, one callable (wi, wo, centre, size) -> (N, C) components.

A label source has ``component_names`` (the columns) and is called with fabric-frame directions wi, wo (N, 3),
footprint centres (N, 2) in tiles and footprint sizes (N,) in tiles (the side of a square box footprint).
Three implementations; each takes the model objects it uses (this package sits below the models):

* :class:`ModelLabels`: the reflectance model (``Model.components``), the large-footprint limit: position
  and size are ignored.  Cheap and exact where it applies; the tests use it.
* :class:`TextureMonteCarloLabels`: the box-footprint average of a texture model (``Model.texture()``) by
  stratified Monte-Carlo (``samples`` jittered points per query): Chen, Wang & Wang 2024, eq. 3 with a box
  kernel, estimated as sec. 5.1 does (there with 2,048 samples).  Given the reflectance model (the exact
  tile average of the texture), a box of side s = n + f tiles (n whole) is split into an n x n sub-box of
  whole periods, whose average *is* the tile average, and the L-shaped rest (area s^2 - n^2), the only part
  sampled: the MC variance falls by ~((s^2 - n^2) / s^2)^2 and a footprint of whole tiles is exact.
* :class:`FootprintLabels`: a footprint estimator with the signature of
  ``clothlab.footprint.footprint_components(texture, params, wi, wo, centre, size, *, method, samples,
  seed, ...)`` (summed-area tables where the box kernel allows them, MC elsewhere), handed in by the caller.

:class:`TextureProbe` has the same call signature but is an *input* of the network, not a label: the
noise-free texture at the midpoints of an n x n grid over the footprint (the midpoint rule; n = 1 is the
footprint centre), which locates the yarn highlights the footprint covers (docs/neural.md, "Texture probe").
"""

from __future__ import annotations

from typing import Protocol

import numpy as np


class LabelSource(Protocol):
    component_names: tuple[str, ...]

    def __call__(self, wi: np.ndarray, wo: np.ndarray, centre: np.ndarray, size: np.ndarray) -> np.ndarray:
        """(N, C) components (1/sr) in ``component_names`` order."""


def _stack(components: dict, names) -> np.ndarray:
    return np.stack([np.asarray(components[n], dtype=np.float64).reshape(-1) for n in names], axis=1)


def _texture_at(texture, params: dict, points: np.ndarray, wi, wo, noise: bool, names) -> np.ndarray:
    """(n, k, C) texture components at ``points`` (n, k, 2) (tiles), query i's k points with its directions
    wi[i], wo[i] ((n, 3), or (1, 3) shared by all)."""
    n, k = points.shape[:2]
    wi, wo = np.atleast_2d(wi), np.atleast_2d(wo)
    rows = np.repeat(np.arange(n), k)
    comps = texture.components(points[..., 0].reshape(-1), points[..., 1].reshape(-1),
                               wi[rows] if wi.shape[0] == n else wi, wo[rows] if wo.shape[0] == n else wo,
                               params, noise=noise, warn=False)
    return _stack(comps, names).reshape(n, k, -1)


class ModelLabels:
    """The reflectance model's components (the footprint-independent, large-footprint limit)."""

    def __init__(self, model, params: dict | None = None):
        self.model, self.params = model, dict(params or {})
        self.component_names = tuple(model.component_names)

    def __call__(self, wi, wo, centre, size) -> np.ndarray:
        return _stack(self.model.components(wi, wo, self.params, warn=False), self.component_names)


class TextureMonteCarloLabels:
    """Stratified MC box-footprint average of a texture model (noise off by default: the surrogate learns
    the deterministic structure; the intensity noise has mean 1)."""

    def __init__(self, texture, params: dict | None = None, samples: int = 16, seed: int = 0, noise: bool = False,
                 tile_average=None):
        self.texture, self.params = texture, dict(params or {})
        self.samples, self.seed, self.noise = int(samples), int(seed), bool(noise)
        self.tile_average = tile_average  # a ModelLabels of the same parameters, or None (plain MC)
        if tile_average is not None and self.samples < 2:
            raise ValueError("the whole-tile split needs at least 2 samples per query")
        self.component_names = tuple(texture.component_names)

    def _stratified(self, rng, n: int) -> np.ndarray:
        """(n, k, 2) points in [0, 1)^2: jittered on a sqrt(k) grid when k is square, else uniform."""
        k = self.samples
        side = int(round(np.sqrt(k)))
        jitter = rng.random((n, k, 2))
        if side * side != k:
            return jitter
        cell = np.arange(k)
        return np.stack([(cell % side + jitter[..., 0]) / side, (cell // side + jitter[..., 1]) / side], axis=-1)

    def __call__(self, wi, wo, centre, size) -> np.ndarray:
        size = np.asarray(size, dtype=np.float64)
        n, k = len(size), self.samples
        rng = np.random.default_rng([self.seed, n])
        unit = self._stratified(rng, n)  # in random order: each share gets a random subset of the strata
        unit = unit[np.arange(n)[:, None], rng.permuted(np.tile(np.arange(k), (n, 1)), axis=1)]
        low = np.asarray(centre) - 0.5 * size[:, None]  # the box's lower corner
        whole = np.floor(size) if self.tile_average is not None else np.zeros(n)
        rest = size - whole
        # points of the L-shaped rest: a share of the samples in [n, s] x [0, s] (area f s), the others in
        # [0, n] x [n, s] (area n f), each share mapped from the unit square (the whole box when n = 0)
        first = rest * size / np.maximum(size * size - whole * whole, 1e-300)
        in_first = (np.arange(k) + 0.5) / k < first[:, None]
        t = unit
        x = np.where(in_first, whole[:, None] + rest[:, None] * t[..., 0], whole[:, None] * t[..., 0])
        y = np.where(in_first, size[:, None] * t[..., 1], whole[:, None] + rest[:, None] * t[..., 1])
        points = low[:, None, :] + np.stack([x, y], axis=-1)
        values = _texture_at(self.texture, self.params, points, wi, wo, self.noise, self.component_names)
        # each share's mean times its area (the stratum estimator), plus the exact whole-tile part
        n_first = in_first.sum(axis=1)
        mean_first = np.where(in_first[..., None], values, 0.0).sum(axis=1) / np.maximum(n_first, 1)[:, None]
        mean_second = np.where(in_first[..., None], 0.0, values).sum(axis=1) / np.maximum(k - n_first, 1)[:, None]
        area_first, area_second = rest * size, whole * rest
        integral = area_first[:, None] * mean_first + area_second[:, None] * mean_second
        whole_rows = np.flatnonzero(whole > 0.0)
        if self.tile_average is not None and whole_rows.size:  # R only where a whole tile is covered
            wi, wo = (d[whole_rows] if d.shape[0] == n else d for d in (np.atleast_2d(wi), np.atleast_2d(wo)))
            integral[whole_rows] += (whole[whole_rows] ** 2)[:, None] * self.tile_average(
                wi, wo, np.atleast_2d(centre)[whole_rows], size[whole_rows])
        return integral / (size * size)[:, None]


class FootprintLabels:
    """Labels from a footprint estimator ``estimate(texture, params, wi, wo, centre, size, **options)`` that
    returns a dict of components (e.g. ``clothlab.footprint.footprint_components``)."""

    def __init__(self, estimate, texture, params: dict | None = None, **options):
        self.estimate, self.texture, self.params, self.options = estimate, texture, dict(params or {}), options
        self.component_names = tuple(texture.component_names)

    def __call__(self, wi, wo, centre, size) -> np.ndarray:
        comps = self.estimate(self.texture, self.params, wi, wo, centre, size, **self.options)
        return _stack(comps, self.component_names)


class TextureProbe:
    """The noise-free texture components at the n x n midpoints of each box footprint, (N, n^2 C): point by
    point (row-major over (i, j), i along u), each point's C components in ``component_names`` order.  The
    points are (centre + ((i + 0.5) / n - 0.5) size, ...): n = 1 is the centre alone, n = 2 the centres of
    the four quarters.  An input of the surrogate (``encoding["probe_points"]``), not a label."""

    def __init__(self, texture, params: dict | None = None, points: int = 1):
        if int(points) < 1:
            raise ValueError(f"need at least 1 probe point per side, got {points}")
        self.texture, self.params, self.points = texture, dict(params or {}), int(points)
        self.component_names = tuple(texture.component_names)

    def offsets(self) -> np.ndarray:
        """(n^2, 2) point offsets in units of the footprint side."""
        t = (np.arange(self.points) + 0.5) / self.points - 0.5
        return np.stack(np.meshgrid(t, t, indexing="ij"), axis=-1).reshape(-1, 2)

    def __call__(self, wi, wo, centre, size) -> np.ndarray:
        centre = np.atleast_2d(np.asarray(centre, dtype=np.float64))
        size = np.atleast_1d(np.asarray(size, dtype=np.float64))
        points = centre[:, None, :] + size[:, None, None] * self.offsets()[None]
        return _texture_at(self.texture, self.params, points, wi, wo, False, self.component_names).reshape(
            centre.shape[0], -1)
