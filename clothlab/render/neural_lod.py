"""neural-lod's per-pixel estimator (issue 23 item 4): each pixel's filtered value (a box footprint of the
pixel's side f tiles at the pixel's centre, with the centre's directions,
:func:`clothlab.render.shade.pixel_boxes`; Chen, Wang & Wang 2024, eq. 3) from the cheapest estimator that
meets the network's error target, by the crossovers measured for its weave and stored in its sidecar
(:mod:`clothlab.surrogate.estimator_choice`):

* ``mc`` k: k stratified points of the scene's texture model over the pixel's box (noise as the scene's);
* ``surrogate``: one query of the weave's shipped network (its own configured R as the residual base:
  the reflectance model recorded in its sidecar, :func:`clothlab.models.neural.model.reference_model`);
* ``reflectance``: that configured reflectance model alone.

A network whose sidecar has no ``estimator_choice`` (the weights shipped before session 13, or a weave
without shipped weights) keeps the documented default of :func:`clothlab.render.shade.neural_lod_values`:
the network over 0.12-0.5 tile with dithered transitions, im-lod elsewhere.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from clothlab.models.components import combine

MC_SEED = 4049  # the stratified points of mc pixels (fixed: an image is reproducible)
MIN_SIZE, MAX_SIZE = 0.01, 5.0  # tiles: the footprint range of the networks' data (Table 2)


def estimator_choice(weave) -> dict | None:
    """The ``estimator_choice`` of the shipped network of ``weave`` (None without weights or without the
    field)."""
    from clothlab.models.neural.model import SHIPPED

    path = SHIPPED / f"{weave.name}.json"
    if not path.exists():
        return None
    return _choice(str(path), path.stat().st_mtime_ns)


@lru_cache(maxsize=16)
def _choice(path: str, mtime: int) -> dict | None:
    from clothlab.surrogate.serialise import read_sidecar

    return read_sidecar(Path(path)).get("estimator_choice")


def pixel_values(fabric, network, choice: dict, centre, size, wi, wo, counter, steps=None) -> np.ndarray:
    """f_r (P, C) of P pixels (centre (P, 2), footprint side ``size`` (P,) tiles, directions (P, 3)), each
    from its bin's estimator of ``choice``; ``network`` is the weave's kind-neural model; the evaluations are
    counted under ``texture``, ``neural`` and ``reflectance``.  ``steps`` (P, 2, 2): each pixel's (du, dv)
    tile steps of one pixel in x and in y (:func:`clothlab.render.shade.pixel_boxes`): its ``mc`` points are
    then spread over the pixel's own footprint (:func:`footprint_average`), elsewhere (steps None or not
    finite) over the square box of side ``size`` that the network and the crossovers assume."""
    from clothlab.surrogate.estimator_choice import estimator_at
    from clothlab.surrogate.labels import TextureMonteCarloLabels

    index, _ = estimator_at(choice, size)
    keys = [(b["estimator"], int(b.get("samples") or 0)) for b in choice["bins"]]  # per bin (estimator, k)
    used = np.unique(index)
    out = np.zeros((len(size), len(fabric.channels)))
    names = fabric.texture.component_names
    known = np.zeros(len(size), dtype=bool) if steps is None else np.isfinite(steps).all(axis=(1, 2))
    for kind, k in sorted({keys[i] for i in used}):
        sel = np.flatnonzero(np.isin(index, [i for i in used if keys[i] == (kind, k)]))
        # a footprint beyond the data's range (grazing differentials: up to inf) is answered at its largest
        c, s, a, b = centre[sel], np.clip(size[sel], MIN_SIZE, MAX_SIZE), wi[sel], wo[sel]
        if kind == "mc":
            comps, own = {}, known[sel]
            if own.any():
                comps = counter.run("texture", k * own.sum(), footprint_average, fabric, c[own], steps[sel][own],
                                    a[own], b[own], k)
            if not own.all():
                box = TextureMonteCarloLabels(fabric.texture, fabric.params, samples=k, seed=MC_SEED + k,
                                              noise=fabric.spec.noise)
                values = counter.run("texture", k * (~own).sum(), box, a[~own], b[~own], c[~own], s[~own])
                comps = {n: _merge(own, comps.get(n), values[:, i]) for i, n in enumerate(names)}
        elif kind == "surrogate":
            comps = counter.run(network.kind, sel.size, network.query, c, s, a, b, fabric.params)
        else:
            comps = counter.run("reflectance", sel.size, network.exact_model().components, a, b, fabric.params,
                                need=fabric.need, warn=False)
        out[sel] = combine({n: comps[n] for n in fabric.need}, fabric.coefficients)
    return out


def _merge(own, first, second) -> np.ndarray:
    """Values of the rows where ``own`` (from ``first``) and of the others (from ``second``) in row order."""
    out = np.zeros(own.size)
    if first is not None:
        out[own] = first
    out[~own] = second
    return out


def footprint_average(fabric, centre, steps, wi, wo, k: int) -> dict:
    """The texture components averaged over each pixel's own footprint: k stratified points of the unit
    pixel (:func:`clothlab.render.camera.pixel_jitter`, seeded by k) mapped to centre + (x - 1/2) step_x +
    (y - 1/2) step_y (the first-order image of the pixel on the surface, eq. 3's footprint integral over the
    pixel rather than over a square box), at the pixel centre's directions.  Returns {component: (P,)}."""
    from clothlab.render.camera import pixel_jitter

    n = len(centre)
    jitter = pixel_jitter((n,), k, np.random.default_rng(MC_SEED + k)) - 0.5  # (2, n, k)
    points = (centre[:, None, :] + jitter[0][..., None] * steps[:, None, 0, :]
              + jitter[1][..., None] * steps[:, None, 1, :])
    rows = np.repeat(np.arange(n), k)
    comps = fabric.texture.components(points[..., 0].reshape(-1), points[..., 1].reshape(-1), wi[rows], wo[rows],
                                      fabric.params, need=fabric.need, noise=fabric.spec.noise, warn=False)
    return {name: value.reshape(n, k).mean(axis=1) for name, value in comps.items()}
