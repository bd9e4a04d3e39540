"""Label sources: what the training data learns, one callable (wi, wo, centre, size) -> (N, C) components.

A label source has ``component_names`` (the columns) and is called with fabric-frame directions wi, wo (N, 3),
footprint centres (N, 2) in tiles and footprint sizes (N,) in tiles (the side of a square box footprint).
Three implementations; each takes the model objects it uses (this package sits below the models):

* :class:`ModelLabels`: the reflectance model (``Model.components``), the large-footprint limit: position
  and size are ignored.  Cheap and exact where it applies; the tests use it.
* :class:`TextureMonteCarloLabels`: the box-footprint average of a texture model (``Model.texture()``) by
  stratified Monte-Carlo (``samples`` jittered points per query): Chen, Wang & Wang 2024, eq. 3 with a box
  kernel, estimated as sec. 5.1 does (there with 2,048 samples).
* :class:`FootprintLabels`: a footprint estimator with the signature of
  ``clothlab.models.footprint.footprint_components(texture, params, wi, wo, centre, size, *, method, samples,
  seed, ...)`` (summed-area tables where the box kernel allows them, MC elsewhere), handed in by the caller.
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

    def __init__(self, texture, params: dict | None = None, samples: int = 16, seed: int = 0, noise: bool = False):
        self.texture, self.params = texture, dict(params or {})
        self.samples, self.seed, self.noise = int(samples), int(seed), bool(noise)
        self.component_names = tuple(texture.component_names)

    def __call__(self, wi, wo, centre, size) -> np.ndarray:
        n, k = len(size), self.samples
        side = max(1, int(round(np.sqrt(k))))
        rng = np.random.default_rng([self.seed, n])
        cell = np.arange(k)
        jitter = rng.random((n, k, 2))
        offset = np.stack([(cell % side + jitter[..., 0]) / side, ((cell // side) % side + jitter[..., 1]) / side],
                          axis=-1) if side * side == k else jitter
        points = np.asarray(centre)[:, None, :] + (offset - 0.5) * np.asarray(size)[:, None, None]
        rows = np.repeat(np.arange(n), k)
        comps = self.texture.components(points[..., 0].reshape(-1), points[..., 1].reshape(-1), wi[rows], wo[rows],
                                        self.params, noise=self.noise, warn=False)
        return _stack(comps, self.component_names).reshape(n, k, -1).mean(axis=1)


class FootprintLabels:
    """Labels from a footprint estimator ``estimate(texture, params, wi, wo, centre, size, **options)`` that
    returns a dict of components (e.g. ``clothlab.models.footprint.footprint_components``)."""

    def __init__(self, estimate, texture, params: dict | None = None, **options):
        self.estimate, self.texture, self.params, self.options = estimate, texture, dict(params or {}), options
        self.component_names = tuple(texture.component_names)

    def __call__(self, wi, wo, centre, size) -> np.ndarray:
        comps = self.estimate(self.texture, self.params, wi, wo, centre, size, **self.options)
        return _stack(comps, self.component_names)
