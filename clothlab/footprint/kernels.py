"""Footprint kernels k_P of Chen, Wang & Wang 2024, eq. 3 (int_P k_P(p) dp = 1) and their stratified samples.

A footprint is a centre (u, v) and a size s, both in weave tiles (texture units: u along the weft, v along
the warp).  Kernels, as offsets from the centre in units of s:

=========  ==============================================================================================
kernel     meaning
=========  ==============================================================================================
box        uniform over the square [-s/2, s/2]^2 (the paper's patch P; exact for summed-area tables)
gaussian   isotropic normal, standard deviation s / sqrt(12) per axis (the box's second moment), untruncated
=========  ==============================================================================================

Stratified samples: the unit square is cut into n x n strata, n = ceil(sqrt(samples)); each query takes
``samples`` distinct strata (all of them when samples = n^2) and one uniform point in each.  Every point is
marginally uniform on the square, so the estimate is unbiased for any count; the Gaussian maps the
stratified uniforms through the inverse normal CDF per axis (stratification survives the monotone map).
"""

from __future__ import annotations

import math

import numpy as np

KERNELS = ("box", "gaussian")
GAUSSIAN_SIGMA = 1.0 / math.sqrt(12.0)  # per unit size: the variance of the box of the same size


def check_kernel(kernel: str) -> str:
    """``kernel`` if it is one of :data:`KERNELS`, else ValueError naming the choices."""
    if kernel not in KERNELS:
        raise ValueError(f"unknown footprint kernel {kernel!r}; choose one of {', '.join(KERNELS)}")
    return kernel


def stratified_unit(rng: np.random.Generator, queries: int, samples: int) -> np.ndarray:
    """(queries, samples, 2) points in [0, 1)^2, stratified as in the module docstring."""
    n = math.isqrt(samples - 1) + 1 if samples > 1 else 1  # ceil(sqrt(samples))
    strata = n * n
    if samples == strata:
        index = np.broadcast_to(np.arange(strata), (queries, strata))
    else:  # a random subset of the strata per query (still marginally uniform)
        index = np.argsort(rng.random((queries, strata)), axis=1)[:, :samples]
    jitter = rng.random((queries, samples, 2))
    return np.stack([(index % n + jitter[..., 0]) / n, (index // n + jitter[..., 1]) / n], axis=-1)


def unit_offsets(kernel: str, xi: np.ndarray) -> np.ndarray:
    """Offsets from the footprint centre in units of its size, for stratified uniforms ``xi`` (..., 2)."""
    if check_kernel(kernel) == "box":
        return xi - 0.5
    from scipy.special import ndtri

    # xi = 0 has probability zero but would give -inf; keep it inside the open interval
    return GAUSSIAN_SIGMA * ndtri(np.clip(xi, 1e-300, 1.0 - 2.0 ** -53))
