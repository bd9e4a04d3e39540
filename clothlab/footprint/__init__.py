"""Footprint-aggregated components of any texture model (Chen, Wang & Wang 2024, "Real-time Neural Woven
Fabric Rendering", sec. 3.1, eqs. 3-5): the average of a texture model's components over a pixel footprint.

A footprint is a centre (u, v) and a size s, in weave tiles; its kernel is a box of side s (the paper's
patch P) or a Gaussian of the same second moment (:mod:`.kernels`); the projected-area normalisation of
eqs. 4-5 applies to textures that declare micro normals (:mod:`.projection`).  The operation needs only the
texture interface of :mod:`clothlab.models.base` (``Model.texture()``; IM, Kang and any later kind).

=================  ===========================================================================================
estimator          meaning
=================  ===========================================================================================
``method="sat"``   periodic summed-area tables of one tile (:mod:`.sat`): exact for box footprints of any size
                   on the midpoint-sampled texture (>= R texels per tile side, whole texels per weave cell),
                   O(1) per query after ~R^2 evaluations per direction pair (``resolution`` = R, default 128)
``method="mc"``    stratified Monte Carlo (:mod:`.montecarlo`), ``samples`` per query, seeded: the paper's
                   ground truth (2,048 samples there), any kernel, noise allowed
=================  ===========================================================================================

Public API: :func:`footprint_components` (one footprint per direction pair) and :class:`FootprintTable`
(many footprints per direction pair: what training-data generation needs).
"""

from __future__ import annotations

import numpy as np

from clothlab.errors import InputError
from clothlab.footprint.kernels import KERNELS, check_kernel
from clothlab.footprint.montecarlo import estimate
from clothlab.footprint.projection import has_micro_normals
from clothlab.footprint.sat import DEFAULT_RESOLUTION, FootprintTable, table_shape

METHODS = ("sat", "mc")
_TABLE_TEXELS = 1 << 21  # texels of tables held at once by footprint_components (x components x 8 bytes)

__all__ = ["DEFAULT_RESOLUTION", "KERNELS", "METHODS", "FootprintTable", "footprint_components",
           "has_micro_normals", "mc_estimate"]


def _queries(wi, wo, centre, size):
    """wi, wo (N, 3), centre (N, 2), size (N,) float64 (broadcast from single values); InputError if bad."""
    wi = np.atleast_2d(np.asarray(wi, dtype=np.float64))
    wo = np.atleast_2d(np.asarray(wo, dtype=np.float64))
    centre = np.atleast_2d(np.asarray(centre, dtype=np.float64))
    size = np.atleast_1d(np.asarray(size, dtype=np.float64))
    if wi.shape[-1] != 3 or wo.shape[-1] != 3 or wi.ndim != 2 or wo.ndim != 2:
        raise InputError(f"wi, wo must be (N, 3) direction arrays, got {wi.shape} and {wo.shape}", field="wi")
    if centre.ndim != 2 or centre.shape[-1] != 2:
        raise InputError(f"footprint centres must be (N, 2) (u, v in tiles), got shape {centre.shape}",
                         field="centre")
    if size.ndim != 1:
        raise InputError(f"footprint sizes must be (N,) (tiles), got shape {size.shape}", field="size")
    n = max(len(wi), len(wo), len(centre), len(size))
    try:
        wi, wo = np.broadcast_to(wi, (n, 3)), np.broadcast_to(wo, (n, 3))
        centre, size = np.broadcast_to(centre, (n, 2)), np.broadcast_to(size, (n,))
    except ValueError:
        raise InputError(f"wi, wo, centre and size must have one row per query (or one row shared); got "
                         f"{len(wi)}, {len(wo)}, {len(centre)}, {len(size)} rows", field="size") from None
    if not np.all(np.isfinite(centre)):
        raise InputError("footprint centres must be finite (tiles)", field="centre")
    bad = ~(np.isfinite(size) & (size > 0.0))
    if np.any(bad):
        raise InputError(f"footprint size must be finite and > 0 (tiles); found {size[bad][0]!r}", field="size")
    return wi, wo, centre, size


def footprint_components(texture, params, wi, wo, centre, size, *, method: str = "sat", samples: int = 16,
                         seed: int = 0, kernel: str = "box", resolution: int = DEFAULT_RESOLUTION, need=None,
                         noise: bool = False, warn: bool = True) -> dict[str, np.ndarray]:
    """Footprint averages (1/sr) of each component of ``texture`` (a texture model, ``Model.texture()``) with
    ``params`` for queries k = (wi[k], wo[k], centre[k], size[k]): wi, wo (N, 3) fabric frame; centre (N, 2)
    (u, v in tiles, any reals); size (N,) in tiles (> 0).  Returns {component: (N,)}.

    ``method``: ``"sat"`` (summed-area tables, box kernel, ``resolution`` texels per tile side; identical
    direction pairs share one table) or ``"mc"`` (stratified Monte Carlo, ``samples`` per query, ``seed``).
    ``kernel``: ``"box"`` or ``"gaussian"`` (MC only).  ``noise``: the texture's noise realisation (MC only;
    it is not periodic over a tile).  ``need`` limits the components.
    """
    if method not in METHODS:
        raise InputError(f"unknown footprint method {method!r}; choose one of {', '.join(METHODS)}", field="method")
    try:
        check_kernel(kernel)
    except ValueError as exc:
        raise InputError(str(exc), field="kernel") from None
    wi, wo, centre, size = _queries(wi, wo, centre, size)
    if method == "mc":
        return estimate(texture, params, wi, wo, centre, size, samples=samples, seed=seed, kernel=kernel,
                        need=need, noise=noise, warn=warn)[0]
    if kernel != "box":
        raise InputError("summed-area tables are exact for box footprints only; use method 'mc' for kernel "
                         f"{kernel!r}", field="kernel")
    if noise:
        raise InputError("summed-area tables need a tile-periodic texture; noise is for method 'mc'", field="noise")
    pairs, inverse = np.unique(np.concatenate([wi, wo], axis=1), axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    order = np.argsort(inverse, kind="stable")
    bounds = np.searchsorted(inverse[order], np.arange(len(pairs) + 1))
    r_u, r_v = table_shape(texture, int(resolution))
    per_batch = max(1, _TABLE_TEXELS // ((r_u + 1) * (r_v + 1)))
    out: dict[str, np.ndarray] = {}
    for start in range(0, len(pairs), per_batch):
        stop = min(start + per_batch, len(pairs))
        table = FootprintTable.build(texture, params, pairs[start:stop, :3], pairs[start:stop, 3:], resolution,
                                     need=need, warn=warn and start == 0)
        rows = order[bounds[start]:bounds[stop]]
        for name, value in table.query(centre[rows], size[rows], pair=inverse[rows] - start).items():
            out.setdefault(name, np.zeros(len(wi)))[rows] = value
    return out


def mc_estimate(texture, params, wi, wo, centre, size, *, samples: int = 16, seed: int = 0, kernel: str = "box",
                need=None, noise: bool = False, warn: bool = True):
    """(means, standard errors) of the stratified Monte Carlo estimator, each {component: (N,)}, inputs as
    :func:`footprint_components` (:func:`clothlab.footprint.montecarlo.estimate`)."""
    try:
        check_kernel(kernel)
    except ValueError as exc:
        raise InputError(str(exc), field="kernel") from None
    wi, wo, centre, size = _queries(wi, wo, centre, size)
    return estimate(texture, params, wi, wo, centre, size, samples=samples, seed=seed, kernel=kernel, need=need,
                    noise=noise, warn=warn)
