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


def pixel_values(fabric, network, choice: dict, centre, size, wi, wo, counter) -> np.ndarray:
    """f_r (P, C) of P pixels (centre (P, 2), footprint side ``size`` (P,) tiles, directions (P, 3)), each
    from its bin's estimator of ``choice``; ``network`` is the weave's kind-neural model; the evaluations are
    counted under ``texture``, ``neural`` and ``reflectance``."""
    from clothlab.surrogate.estimator_choice import estimator_at
    from clothlab.surrogate.labels import TextureMonteCarloLabels

    index, samples = estimator_at(choice, size)
    kinds = np.array([b["estimator"] for b in choice["bins"]])[index]
    out = np.zeros((len(size), len(fabric.channels)))
    names = fabric.texture.component_names
    for kind, k in sorted({(str(e), int(n)) for e, n in zip(kinds, samples, strict=True)}):
        sel = np.flatnonzero((kinds == kind) & (samples == k))
        # a footprint beyond the data's range (grazing differentials: up to inf) is answered at its largest
        c, s, a, b = centre[sel], np.clip(size[sel], MIN_SIZE, MAX_SIZE), wi[sel], wo[sel]
        if kind == "mc":
            mc = TextureMonteCarloLabels(fabric.texture, fabric.params, samples=k, seed=MC_SEED + k,
                                         noise=fabric.spec.noise)
            values = counter.run("texture", k * sel.size, mc, a, b, c, s)
            comps = {n: values[:, i] for i, n in enumerate(names)}
        elif kind == "surrogate":
            comps = counter.run(network.kind, sel.size, network.query, c, s, a, b, fabric.params)
        else:
            comps = counter.run("reflectance", sel.size, network.exact_model().components, a, b, fabric.params,
                                need=fabric.need, warn=False)
        out[sel] = combine({n: comps[n] for n in fabric.need}, fabric.coefficients)
    return out
