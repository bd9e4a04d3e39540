"""Level of detail for the Kang shader: the two-level mip blend (paper sec. 4.1, eq. 5) and the adaptive
prefilter (sec. 4.2.3, Algorithm 1).

Mip level.  The finest level (0) is the yarn geometry, whose smallest feature is one fibre ridge, 1/N_xi
cell long.  For a footprint of ``f`` cells (the larger side of the pixel's texture-space footprint, as the
GPU's derivative-based mip selection), the level is log2(f N_xi), i.e. 0 when one ridge fills the pixel and
1 when two do; it is clamped to [0, 1] and used as the blend weight alpha (sec. 4.1).  alpha is continuous in
the footprint (a clamped logarithm), so the blend has no jump at either level boundary.

Eq. 5 blends the two distributions: p(h) = (1 - alpha) p_yarn(h) + alpha p_weave(h) (alpha = 0: close-up,
perturbed normals; alpha = 1: the weave level).
"""

from __future__ import annotations

import numpy as np


def mip_level(footprint_cells, texels_per_cell):
    """log2(footprint in cells x texels per cell), unclamped (-inf for a zero footprint)."""
    f = np.asarray(footprint_cells, dtype=np.float64) * texels_per_cell
    with np.errstate(divide="ignore"):
        return np.log2(f)


def lod_alpha(footprint_cells, texels_per_cell):
    """The blend weight of eq. 5: the mip level clamped to [0, 1] (sec. 4.1)."""
    return np.clip(mip_level(footprint_cells, texels_per_cell), 0.0, 1.0)


def blend(yarn_level, weave_level, alpha):
    """Eq. 5: (1 - alpha) * yarn_level + alpha * weave_level (distributions or anything linear in them)."""
    return (1.0 - alpha) * yarn_level + alpha * weave_level


def adaptive_prefilter(evaluate, u, v, footprint, view_distance, *, rng, min_samples: int = 5,
                       max_samples: int = 64):
    """Algorithm 1: average jittered evaluations over the pixel footprint until the estimate settles.

    ``evaluate(index, u, v) -> (n, K)``: values of points ``index`` (into the N points) at texture
    coordinates ``u``, ``v`` (tile units; the jittered positions).  ``footprint`` (N,) or scalar pixel
    extent in tile units; ``view_distance`` (N,) or scalar, same length unit as the stopping rule's
    colour scale.  Each point starts with its centre sample (count = 1) and adds samples at
    u + (footprint / 2) xi_1, v + (footprint / 2) xi_2, with xi uniform in [-1, 1) (the printed algorithm
    jitters one-sided, [0, 1): that shifts the mean by a quarter pixel; centred is the unbiased version).
    Stopping rule: once more than ``min_samples`` samples are taken, a point stops when the change of its
    running mean, |mean_n - mean_{n-1}| (Euclidean over K), is below 1 / view_distance.  (The printed test
    compares lastColor - color of the running *sum*, i.e. the size of the new sample, which never settles
    for a bright fabric; the running mean is what the text describes.)  ``max_samples`` bounds the loop,
    which the printed ``while true`` does not.  Returns (mean (N, K), sample count (N,)).
    """
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    half = 0.5 * np.broadcast_to(np.asarray(footprint, dtype=np.float64), u.shape)
    tolerance = 1.0 / np.broadcast_to(np.asarray(view_distance, dtype=np.float64), u.shape)
    total = np.array(evaluate(np.arange(u.size), u, v), dtype=np.float64)
    count = np.ones(u.shape, dtype=np.int64)
    active = np.ones(u.shape, dtype=bool)
    while np.any(active) and count.max() < max_samples:
        idx = np.flatnonzero(active)
        jitter = rng.uniform(-1.0, 1.0, size=(2, idx.size))
        sample = evaluate(idx, u[idx] + half[idx] * jitter[0], v[idx] + half[idx] * jitter[1])
        last_mean = total[idx] / count[idx, None]
        total[idx] += sample
        count[idx] += 1
        change = np.linalg.norm(total[idx] / count[idx, None] - last_mean, axis=-1)
        settled = (count[idx] > min_samples) & (change < tolerance[idx])
        active[idx[settled]] = False
    return total / count[:, None], count
