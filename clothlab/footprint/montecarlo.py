"""Stratified Monte Carlo footprint averages: the ground-truth estimator of Chen, Wang & Wang 2024 (sec. 5.1
labels each query with 2,048 samples of eq. 3).

Each query draws ``samples`` stratified points from its kernel (:mod:`.kernels`), evaluates the texture
there (one vectorised call per chunk of queries) and averages; with the eq. 4-5 normalisation
(:mod:`.projection`) the estimate is the ratio sum(f w_i a_o) / sum(a_o).  Seeded: the same seed, queries and
sample count give the same numbers.

Standard error: s / sqrt(samples) from the sample variance s^2 (for a ratio, the delta-method form
sqrt(sum (y - F a)^2 / (S (S - 1))) / mean(a)).  That is the error of independent uniform samples; the
stratified estimate's own variance is at most that (stratification with proportional allocation never
increases it), so the figure is an upper bound, the safe side for a comparison within k standard errors.
"""

from __future__ import annotations

import numpy as np

from clothlab.footprint.kernels import stratified_unit, unit_offsets
from clothlab.footprint.projection import weighted_values

_CHUNK_POINTS = 1 << 17  # texture points per evaluation call (memory bound)
_MIN_SHARED_POINTS = 1024  # points per call below which grouping by direction pair does not pay


def _evaluate(texture, params, u, v, wi, wo, samples: int, **kw):
    """weighted_values for k queries x ``samples`` points (u, v flat, query-major; wi, wo (k, 3)).

    A texture with ``shared_directions`` is called once per distinct direction pair of the chunk with (1, 3)
    directions when that gives calls of :data:`_MIN_SHARED_POINTS` points or more on average (IM: ~4x
    faster per point); otherwise once with the directions repeated per sample.  The sample points are
    drawn before, in query order, so the grouping never changes the numbers.
    """
    k = len(wi)
    if getattr(texture, "shared_directions", False):
        pairs, inverse = np.unique(np.concatenate([wi, wo], axis=1), axis=0, return_inverse=True)
        if len(pairs) * _MIN_SHARED_POINTS <= k * samples:
            inverse = inverse.reshape(-1)
            values: dict[str, np.ndarray] = {}
            area = None
            for g, pair in enumerate(pairs):
                rows = np.flatnonzero(inverse == g)
                points = (rows[:, None] * samples + np.arange(samples)).ravel()
                part, part_area = weighted_values(texture, params, u[points], v[points], pair[None, :3],
                                                  pair[None, 3:], **kw)
                kw["warn"] = False
                for name, value in part.items():
                    values.setdefault(name, np.zeros(k * samples))[points] = value
                if part_area is not None:
                    area = np.zeros(k * samples) if area is None else area
                    area[points] = part_area
            return values, area
    return weighted_values(texture, params, u, v, np.repeat(wi, samples, axis=0), np.repeat(wo, samples, axis=0),
                           **kw)


def estimate(texture, params, wi, wo, centre, size, *, samples: int = 16, seed: int = 0, kernel: str = "box",
             need=None, noise: bool = False, warn: bool = True) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """(means, standard errors) per component, each (N,), of the footprint averages of ``texture`` for
    queries k = (wi[k], wo[k], centre[k], size[k]): wi, wo (N, 3) fabric frame, centre (N, 2) and size (N,)
    in tiles.  ``noise`` is passed to the texture (MC, unlike the tables, accepts a non-periodic texture)."""
    samples = int(samples)
    if samples < 1:
        raise ValueError(f"samples must be a positive integer, got {samples}")
    rng = np.random.default_rng(seed)
    n = len(wi)
    per_call = max(1, _CHUNK_POINTS // samples)
    means: dict[str, list[np.ndarray]] = {}
    errors: dict[str, list[np.ndarray]] = {}
    for start in range(0, n, per_call):
        stop = min(start + per_call, n)
        k = stop - start
        offsets = unit_offsets(kernel, stratified_unit(rng, k, samples)) * size[start:stop, None, None]
        u = (centre[start:stop, 0, None] + offsets[..., 0]).ravel()
        v = (centre[start:stop, 1, None] + offsets[..., 1]).ravel()
        values, area = _evaluate(texture, params, u, v, wi[start:stop], wo[start:stop], samples, need=need,
                                 noise=noise, warn=warn and start == 0)
        a = None if area is None else area.reshape(k, samples)
        a_mean = None if a is None else a.mean(axis=1)
        for name, value in values.items():
            y = value.reshape(k, samples)
            if a is None:
                mean = y.mean(axis=1)
                residual = y - mean[:, None]
                scale = np.ones(k)
            else:
                mean = np.divide(y.mean(axis=1), a_mean, out=np.zeros(k), where=a_mean > 0.0)
                residual = y - mean[:, None] * a
                scale = np.where(a_mean > 0.0, a_mean, np.inf)
            if samples > 1:
                error = np.sqrt(np.sum(residual ** 2, axis=1) / (samples * (samples - 1))) / scale
            else:
                error = np.full(k, np.nan)
            means.setdefault(name, []).append(mean)
            errors.setdefault(name, []).append(error)
    return ({name: np.concatenate(parts) for name, parts in means.items()},
            {name: np.concatenate(parts) for name, parts in errors.items()})
