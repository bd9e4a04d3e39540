"""The neural surrogate as a model (``kind: neural``; Chen, Wang & Wang 2024, sec. 4.3).

A per-fabric surrogate (:mod:`clothlab.neural`, trained by ``clothlab train-surrogate``) answers footprint
queries of the Irawan-Marschner texture model.  As a model:

* :meth:`NeuralModel.components` is the far view: the footprint of :data:`FAR_SIZE` tiles (the largest of
  Table 2's range, where the footprint average is the tile average, i.e. the reflectance model).
* :meth:`NeuralModel.texture` is a filtering texture model (``texture_filters``): the query centre is the
  texture point (u, v) and the footprint size is ``footprint`` (tiles; :data:`MIN_FOOTPRINT` when None).

A residual network (``--residual``; :mod:`clothlab.neural.surrogate`) adds its outputs to the transformed
reflectance model T(R(wi, wo)) of the sidecar's ``kind`` at the queried parameters (the trained ones, or
``params`` for another material): :func:`load_neural` attaches it, and each query evaluates it.

Options: ``weights`` (the ``.npz`` written by ``clothlab train-surrogate``; default: the shipped weights of
the weave's preset, :data:`SHIPPED`, where there are some).  Parameters are those
of the target model (the Irawan-Marschner table); a parameter set other than the trained one goes through
the encoder (a fast approximation, exact only near the trained materials).  Components as the target's:
``diffuse``, ``specular_warp``, ``specular_weft`` (1/sr), coefficients linear as always.

==========  =================================================================================
option      meaning
==========  =================================================================================
weights     path of the surrogate ``.npz`` (its ``.json`` sidecar beside it); default shipped
==========  =================================================================================
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from clothlab.errors import ConfigError
from clothlab.models.base import ORIENTATION, Model, as_directions
from clothlab.models.irawan.integrals import COMPONENTS
from clothlab.models.irawan.parameters import IRAWAN_PARAMS, weave_parameters
from clothlab.neural.encodings import normalised_parameters, pattern_descriptor
from clothlab.neural.serialise import load_surrogate

SHIPPED = Path(__file__).parent / "data"
"""Shipped per-fabric weights, ``<preset>.npz`` + ``.json`` (docs/neural.md says how they were trained)."""
FAR_SIZE = 4.5  # tiles
MIN_FOOTPRINT = 0.01  # tiles


def reference_model(sidecar: dict, weave=None):
    """The reflectance model a residual surrogate corrects: the sidecar's ``kind`` on ``weave`` (default:
    the weave recorded in the sidecar, ``encoding["weave_wv"]``)."""
    from clothlab.models.registry import build_model

    enc = sidecar.get("encoding", {})
    if weave is None:
        from clothlab.weave.wvformat import parse_wv_text

        weave = parse_wv_text(enc["weave_wv"], source="surrogate sidecar")
    return build_model(enc.get("kind", "irawan"), weave)


def load_neural(path, weave=None):
    """:func:`clothlab.neural.serialise.load_surrogate` with, for a residual network, the reflectance model
    of each trained material attached (``references``); returns (surrogate, sidecar)."""
    from clothlab.neural.labels import ModelLabels

    surrogate, sidecar = load_surrogate(Path(path))
    if surrogate.residual or surrogate.residual_input:
        enc = surrogate.encoding
        model = reference_model(sidecar, weave)
        surrogate.references = [ModelLabels(model, {k: float(v) for k, v in q.items()})
                                for q in enc.get("materials_params", [enc.get("params", {})])]
    return surrogate, sidecar


class NeuralModel(Model):
    """A trained surrogate of the IM texture model's footprint averages, for one weave."""

    kind = "neural"
    params = IRAWAN_PARAMS
    component_names = COMPONENTS
    coefficient_meaning = "kd: diffuse albedo; ks_<kind>: mean specular albedo of that segment type (as irawan)"
    default_free = ("alpha", "beta")
    has_texture = True
    texture_filters = True

    def __init__(self, weave, *, weights: str | None = None):
        super().__init__(weave, weights=weights)
        if not weights:
            weights = SHIPPED / f"{weave.name}.npz"
            if not weights.exists():
                shipped = ", ".join(sorted(p.stem for p in SHIPPED.glob("*.npz"))) or "none"
                raise ConfigError(f"no shipped surrogate for weave {weave.name!r} (shipped: {shipped}); give "
                                  "model.options.weights: a .npz written by clothlab train-surrogate",
                                  field="model.options.weights")
        self.surrogate, self.sidecar = load_neural(weights, weave)
        if tuple(self.surrogate.component_names) != COMPONENTS:
            raise ConfigError(f"{weights}: components {self.surrogate.component_names}, expected {COMPONENTS} "
                              "(an Irawan-Marschner target)", field="model.options.weights")
        self._encoding = self.surrogate.encoding
        self._trained = {k: float(v) for k, v in self._encoding.get("params", {}).items()}
        # the trained materials' parameters by row (a multi-material network lists them all)
        self._materials = [{k: float(v) for k, v in q.items()}
                           for q in self._encoding.get("materials_params", [self._trained])]
        self._reference = None
        self._pattern = pattern_descriptor(weave, self._encoding.get("pattern_order", 2))  # the encoder's pattern part

    def default_parameters(self) -> dict[str, float]:
        return {**weave_parameters(self.weave), **self._trained}

    def _material(self, params: dict | None):
        """The trained material's row (0) for its own parameters, else the encoder input of ``params``."""
        p = self.resolve(params)
        for row, trained in enumerate(self._materials):
            if all(abs(p[k] - v) <= 1e-12 * max(1.0, abs(v)) for k, v in trained.items()):
                return row
        return self.material_vector(p)

    def _material_names(self) -> list[str]:
        """The parameters the encoder sees: all declared ones but ``orientation`` (a rotation of the
        directions, applied before the network)."""
        return [name for name in self.params.names() if name != ORIENTATION]

    def material_vector(self, params: dict | None = None) -> np.ndarray:
        """The encoder input m of ``params`` (normalised parameters, then the pattern descriptor)."""
        names = self._encoding.get("parameters", self._material_names())
        return np.concatenate([normalised_parameters(self.resolve(params), self.params, names), self._pattern])

    def fit_material(self, wi, wo, values, free=None, params: dict | None = None, *, refine: bool = False,
                     **options):
        """Fast approximate fit of the ``free`` parameters (default ``default_free``) through the encoder
        (:func:`clothlab.neural.material_fit.fit_material`) to far-view values (N,) at directions (N, 3),
        starting from ``params``; returns (fitted parameters, the :class:`MaterialFit`).  ``refine``: then
        refine with the exact model the network learnt (the sidecar's ``kind``;
        :func:`~clothlab.neural.material_fit.refine_material`), whose coefficients and RMS replace the fast
        fit's."""
        from clothlab.models.registry import build_model
        from clothlab.neural.material_fit import fit_material, refine_material, unit_to_parameter

        if self.surrogate.residual or self.surrogate.residual_input:
            raise ConfigError("the fast material fit needs a network without --residual (the reflectance model's "
                              "parameters are not inputs of the encoder); fit kind irawan instead",
                              field="model.options.weights")
        names = list(self._encoding.get("parameters", self._material_names()))
        free = list(free or self.default_free)
        result = fit_material(self.surrogate, wi, wo, values, self.material_vector(params),
                              {k: names.index(k) for k in free}, size=FAR_SIZE, **options)
        fitted = {**self.resolve(params), **{k: unit_to_parameter(self.params[k], t) for k, t in result.unit.items()}}
        result.params = {k: fitted[k] for k in free}
        if refine:
            exact = build_model(self._encoding.get("kind", "irawan"), self.weave)
            fitted, result.coefficients, result.rms = refine_material(exact, wi, wo, values, fitted, free)
            result.params = {k: fitted[k] for k in free}
        return fitted, result

    def query(self, centre, size, wi, wo, params: dict | None = None, *, reference=None) -> dict[str, np.ndarray]:
        """Components of box footprints of side ``size`` tiles at ``centre`` (N, 2) tiles.  ``reference``:
        the reflectance model's components (N, C) at the queries, when the caller has them (a residual
        network's base R; computed here otherwise)."""
        material = self._material(params)
        if (reference is None and not isinstance(material, int)
                and (self.surrogate.residual or self.surrogate.residual_input)):
            reference = self.surrogate_reference(params)(wi, wo, centre, size)
        values = self.surrogate.query(centre, size, wi, wo, material=material, reference=reference)
        return {name: values[:, i] for i, name in enumerate(COMPONENTS)}

    def components(self, wi, wo, params: dict | None = None, *, need=None, normalised: bool = True,
                   warn: bool = True) -> dict[str, np.ndarray]:
        """The far view (footprint :data:`FAR_SIZE` tiles); ``normalised`` / ``warn`` as the interface."""
        wi, wo = as_directions(wi, wo)
        n = wi.shape[0]
        out = self.query(np.full((n, 2), 0.5), np.full(n, FAR_SIZE), wi, wo, params)
        return {k: v for k, v in out.items() if need is None or k in need}

    def surrogate_reference(self, params: dict | None):
        """The reflectance model at ``params`` as a label source (what a residual network corrects)."""
        from clothlab.neural.labels import ModelLabels

        if self._reference is None:
            self._reference = reference_model(self.sidecar, self.weave)
        return ModelLabels(self._reference, self.resolve(params))

    def texture(self, *, seed: int = 0):
        return NeuralTexture(self)


class NeuralTexture:
    """The surrogate at texture points: footprint centre (u, v), size ``footprint`` tiles (filters itself)."""

    kind = "neural-texture"
    params = IRAWAN_PARAMS
    component_names = COMPONENTS

    def __init__(self, model: NeuralModel):
        self.model, self.weave = model, model.weave

    def resolve(self, params: dict | None) -> dict[str, float]:
        return self.model.resolve(params)

    def components(self, u, v, wi, wo, params: dict | None = None, *, need=None, noise: bool = True,
                   normalised: bool = True, warn: bool = True, footprint=None, view_distance=None):
        """Arrays of the points' shape; ``footprint``: size in tiles (scalar or per point)."""
        u, v = np.broadcast_arrays(np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64))
        n = u.size
        wi, wo = (np.broadcast_to(np.atleast_2d(np.asarray(d, dtype=np.float64)), (n, 3)) for d in (wi, wo))
        size = np.broadcast_to(np.asarray(MIN_FOOTPRINT if footprint is None else footprint, dtype=np.float64),
                               u.shape).reshape(-1)
        out = self.model.query(np.column_stack([u.reshape(-1), v.reshape(-1)]), size, wi, wo, params)
        return {k: c.reshape(u.shape) for k, c in out.items() if need is None or k in need}
