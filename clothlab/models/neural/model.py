"""The neural surrogate as a model (``kind: neural``; Chen, Wang & Wang 2024, sec. 4.3).

A surrogate (:mod:`clothlab.surrogate`, trained by ``clothlab train-surrogate``) answers footprint queries of
the texture model of its *target kind*, the sidecar's ``encoding.kind`` (:data:`TARGET_KINDS`: ``irawan``,
or ``surface``, the Chen et al. model).  As a model:

* parameters, components and the linear coefficients' meaning are the target kind's (IM: ``diffuse``,
  ``specular_warp``, ``specular_weft``; surface: ``diffuse_warp``, ``diffuse_weft``, ``specular_warp``,
  ``specular_weft``; 1/sr), set per instance from the sidecar (:meth:`NeuralModel.declared_parameters`
  gives config validation the same table from ``model.options.weights``);
* :meth:`NeuralModel.components` is the far view: the footprint of :data:`FAR_SIZE` tiles (the largest of
  Table 2's range, where the footprint average is the tile average, i.e. the reflectance model);
* :meth:`NeuralModel.texture` is a filtering texture model (``texture_filters``): the query centre is the
  texture point (u, v) and the footprint size is ``footprint`` (tiles; :data:`MIN_FOOTPRINT` when None).

A trained material is answered from its stored latent; any other parameter set goes through the encoder
(a fast approximation, exact only near the trained materials; meaningful for a ``--vary`` network over
the varied parameters, which a fit frees by default).  A residual network (``--residual``;
:mod:`clothlab.surrogate.surrogate`) adds its outputs to the transformed reflectance model T(R(wi, wo)) of the
target kind at the queried parameters: :func:`load_neural` attaches R of the trained materials, and a query
at other parameters evaluates it (:meth:`NeuralModel.exact_model`).

==========  =================================================================================
option      meaning
==========  =================================================================================
weights     path of the surrogate ``.npz`` (its ``.json`` sidecar beside it; relative to fabric.yaml);
            default: the shipped weights of the weave's preset (:data:`SHIPPED`), IM networks
refine      ``clothlab fit``: after the fit through the encoder, refine the free parameters with the exact
            target model (:mod:`clothlab.fit.refine`); default false
==========  =================================================================================
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from clothlab.errors import ConfigError, InputError
from clothlab.frames import to_weave_frame
from clothlab.models.base import ORIENTATION, Model, ModelTexture, as_directions, split_orientation
from clothlab.models.irawan.integrals import COMPONENTS
from clothlab.models.irawan.model import IrawanModel
from clothlab.models.irawan.parameters import IRAWAN_PARAMS
from clothlab.surrogate.encodings import normalised_parameters, pattern_descriptor
from clothlab.surrogate.serialise import load_surrogate

SHIPPED = Path(__file__).parent / "data"
"""Shipped per-fabric weights, ``<preset>.npz`` + ``.json`` (docs/neural.md says how they were trained)."""
FAR_SIZE = 4.5  # tiles
TARGET_KINDS = ("irawan", "surface")
DEFAULT_TARGET_KIND = TARGET_KINDS[0]
"""A sidecar's ``encoding.kind`` when it has none (the shipped per-preset networks learn the IM texture)."""
"""Target kinds of a network that ``kind: neural`` takes (the sidecar's ``encoding.kind``)."""
MIN_FOOTPRINT = 0.01  # tiles


def reference_model(sidecar: dict, weave=None, name: str | None = None):
    """The reflectance model a residual surrogate corrects: the sidecar's ``kind`` with its
    ``encoding.reference_quadrature`` (the kind's default for older files) on ``weave`` (default:
    the weave recorded in the sidecar, ``encoding["weave_wv"]``, or with ``name`` the weave of that name in
    ``encoding["weaves_wv"]``, networks over several weaves)."""
    from clothlab.models.registry import build_model

    enc = sidecar.get("encoding", {})
    if weave is None:
        from clothlab.weave.wvformat import parse_wv_text

        text = enc["weave_wv"] if name is None else enc["weaves_wv"][name]
        weave = parse_wv_text(text, source="surrogate sidecar")
    q = enc.get("reference_quadrature")  # the network's configured R (clothlab.surrogate.materials); else defaults
    return build_model(enc.get("kind", DEFAULT_TARGET_KIND), weave, None if q is None else (q["rule"], q["nodes"]))


def load_neural(path, weave=None):
    """:func:`clothlab.surrogate.serialise.load_surrogate` with, for a residual network, the reflectance model
    of each trained material attached (``references``), each on its own weave (``encoding["materials_weave"]``
    of a network over several weaves, unless ``weave`` is given); returns (surrogate, sidecar)."""
    from clothlab.surrogate.labels import ModelLabels, TextureProbe

    surrogate, sidecar = load_surrogate(Path(path))
    if surrogate.residual or surrogate.residual_input or surrogate.probe_points:
        enc = surrogate.encoding
        sets = enc.get("materials_params", [enc.get("params", {})])
        owners = (enc.get("materials_weave") if weave is None else None) or [None] * len(sets)
        models = {name: reference_model(sidecar, weave, name) for name in set(owners)}
        sets = [{k: float(v) for k, v in q.items()} for q in sets]
        if surrogate.residual or surrogate.residual_input:
            surrogate.references = [ModelLabels(models[name], q) for name, q in zip(owners, sets, strict=True)]
        if surrogate.probe_points:
            textures = {name: model.texture() for name, model in models.items()}
            surrogate.probes = [TextureProbe(textures[name], q, surrogate.probe_points)
                                for name, q in zip(owners, sets, strict=True)]
    return surrogate, sidecar


class NeuralModel(Model):
    """A trained surrogate of the footprint averages of the texture model of its sidecar's ``kind`` (irawan
    or surface), for one weave: parameters, components and reflectance model R are those of that kind."""

    kind = "neural"
    #: class-level declarations: those of the shipped per-preset networks (Irawan-Marschner); an instance
    #: (and :meth:`declared_parameters` given ``weights``) takes its network's target kind's
    params = IRAWAN_PARAMS
    component_names = COMPONENTS
    coefficient_meaning = "as the network's target kind (irawan: kd diffuse albedo, ks_<kind> mean specular albedo)"
    default_free = ("alpha", "beta")
    has_texture = True
    texture_filters = True
    parameter_concepts = IrawanModel.parameter_concepts  # the class-level target kind's
    #: the texture's ``footprint`` is a box footprint's side (tiles) and its value the box average (eq. 3):
    #: ``clothlab eval`` with a footprint column asks the network instead of averaging its texture
    footprint_queries = True
    #: options naming files: resolved against fabric.yaml's directory by config validation
    path_options = ("weights",)

    def __init__(self, weave, *, weights: str | None = None, refine: bool = False):
        super().__init__(weave, weights=weights, refine=refine)
        if not isinstance(refine, bool):
            raise ConfigError(f"refine must be true or false, got {refine!r}", field="model.options.refine")
        self.refine = refine
        if not weights:
            weights = SHIPPED / f"{weave.name}.npz"
            if not weights.exists():
                shipped = ", ".join(sorted(p.stem for p in SHIPPED.glob("*.npz"))) or "none"
                raise ConfigError(f"no shipped surrogate for weave {weave.name!r} (shipped: {shipped}); give "
                                  "model.options.weights: a .npz written by clothlab train-surrogate",
                                  field="model.options.weights")
        target = target_class(read_sidecar(weights, as_config=False))  # ConfigError naming the file first
        try:
            self.surrogate, self.sidecar = load_neural(weights, weave)
        except InputError as exc:  # the file named, and its member or field in the message
            raise as_option_error(exc) from None
        if tuple(self.surrogate.component_names) != tuple(target.component_names):
            raise ConfigError(f"components: {list(self.surrogate.component_names)}, expected "
                              f"{list(target.component_names)} of its target kind {target.kind!r}",
                              path=Path(weights).with_suffix(".json"), field="model.options.weights")
        self.target = target.kind
        self.params = target.declared_parameters()
        self.component_names = tuple(target.component_names)
        self.coefficient_meaning = target.coefficient_meaning
        self.quarter_turn_swaps = target.quarter_turn_swaps
        self.default_free = trained_free(self.sidecar)
        self._encoding = self.surrogate.encoding
        self._trained = {k: float(v) for k, v in self._encoding.get("params", {}).items()}
        # the trained materials' parameters by row (a multi-material network lists them all)
        self._materials = [{k: float(v) for k, v in q.items()}
                           for q in self._encoding.get("materials_params", [self._trained])]
        self._reference = None
        self._probe_texture = None
        self._pattern = pattern_descriptor(weave, self._encoding.get("pattern_order", 2))  # the encoder's pattern part

    @classmethod
    def check_option(cls, name: str, value) -> None:
        """ConfigError at ``model.options.<name>``: ``weights`` a path (string) or null, ``refine`` true or false
        (config validation names the yaml line; a fit directory's recorded options go through it too)."""
        if name == "weights" and value is not None and not isinstance(value, str | Path):
            raise ConfigError(f"weights must be the path of a .npz, got {type(value).__name__} {value!r:.40}",
                              field="model.options.weights")
        if name == "refine" and not isinstance(value, bool):
            raise ConfigError(f"refine must be true or false, got {value!r:.40}", field="model.options.refine")

    @classmethod
    def _declared_parameters(cls, options: dict | None = None):
        """The declarations of the target kind of ``options["weights"]`` (its sidecar's ``encoding.kind``);
        without weights those of the shipped per-preset networks (Irawan-Marschner)."""
        weights = (options or {}).get("weights")
        return target_class(read_sidecar(weights)).declared_parameters() if weights else cls.params

    @classmethod
    def declared_free(cls, options: dict | None = None) -> tuple:
        """The parameters a fit frees by default for ``options``: those the network was trained over."""
        weights = (options or {}).get("weights")
        return trained_free(read_sidecar(weights)) if weights else cls.default_free

    @classmethod
    def describe_settings(cls, settings: dict) -> str:
        """The recorded options in a few words: the weights by file name (the path is in fit.json)."""
        options = dict(settings.get("options") or {})
        if options.get("weights"):
            options["weights"] = Path(str(options["weights"])).name
        return ", ".join(f"{k}={v}" for k, v in options.items()) or "defaults (shipped weights)"

    def exact_model(self):
        """The model the network learnt (the sidecar's kind on this weave; :func:`reference_model`): R of a
        residual network, the refinement of a fit (``refine``)."""
        if self._reference is None:
            self._reference = reference_model(self.sidecar, self.weave)
        return self._reference

    def _default_parameters(self) -> dict[str, float]:
        return {**self.exact_model().default_parameters(), **self._trained}

    def forget_directions(self) -> None:
        """Forget the direction memos of the exact model and of the residual references."""
        for model in [self._reference, *(r.model for r in self.surrogate.references or ())]:
            if model is not None:
                model.forget_directions()

    def _material(self, params: dict | None):
        """The trained material's row for its own parameters on its own weave (``materials_weave`` of a
        network over several weaves, else the sidecar's ``weave``), else the encoder input of ``params``."""
        p = self.resolve(params)
        owners = self._encoding.get("materials_weave") or [self._encoding.get("weave")] * len(self._materials)
        for row, trained in enumerate(self._materials):
            if owners[row] not in (None, self.weave.name):
                continue
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

    def material_objective(self, wi, wo, values, free=None, params: dict | None = None):
        """The fast fit's objective (:class:`clothlab.surrogate.material_fit.MaterialObjective`) of the ``free``
        parameters (default ``default_free``) through the encoder, far view, from ``params``; a network over
        the reflectance model (g = T(R) + net, or T(R) as an input; docs/neural.md) evaluates R of
        :meth:`exact_model` at each trial, a probing one the texture probe (:meth:`surrogate_probe`)."""
        from clothlab.surrogate.material_fit import MaterialObjective, unit_to_parameter

        names = list(self._encoding.get("parameters", self._material_names()))
        free = list(free or self.default_free)
        for k in free:
            if k not in names:
                raise ConfigError(f"{k!r} is not an encoder input of this network (inputs: {', '.join(names)})",
                                  field="fit.free")
        start = self.resolve(params)

        def trial(unit):
            return {**start, **{k: unit_to_parameter(self.params[k], t) for k, t in zip(free, unit, strict=True)}}

        reference = probe = None
        if self.surrogate.residual or self.surrogate.residual_input:
            exact = self.exact_model()

            def reference(unit):
                c = exact.components(wi, wo, trial(unit), warn=False)
                return np.column_stack([np.asarray(c[n], dtype=np.float64).reshape(-1) for n in self.component_names])
        if self.surrogate.probe_points:
            n = np.atleast_2d(wi).shape[0]
            centre, size = np.full((n, 2), 0.5), np.full(n, FAR_SIZE)

            def probe(unit):
                return self.surrogate_probe(trial(unit))(wi, wo, centre, size)
        return MaterialObjective(self.surrogate, wi, wo, values, self.material_vector(start),
                                 {k: names.index(k) for k in free}, size=FAR_SIZE, reference=reference, probe=probe)

    def fit_material(self, wi, wo, values, free=None, params: dict | None = None, *, refine: bool = False,
                     **options):
        """Fast approximate fit of the ``free`` parameters (default ``default_free``) through the encoder
        (:meth:`material_objective`, :func:`clothlab.surrogate.material_fit.fit_material`; ``options``: its
        steps, lr, starts) to far-view values (N,) at directions (N, 3), starting from ``params``; returns
        (fitted parameters, the :class:`MaterialFit`).  ``refine``: then refine with the exact model the
        network learnt (:meth:`exact_model`; :func:`~clothlab.surrogate.material_fit.refine_material`), whose
        parameters, coefficients and RMS replace the fast fit's (kept in ``fast``)."""
        from clothlab.surrogate.material_fit import fit_material, refine_material, unit_to_parameter

        objective = self.material_objective(wi, wo, values, free, params)
        result = fit_material(objective, **options)
        fitted = {**self.resolve(params), **{k: unit_to_parameter(self.params[k], t) for k, t in result.unit.items()}}
        result.params = {k: fitted[k] for k in objective.names}
        if refine:
            result.fast = {"params": dict(result.params), "coefficients": dict(result.coefficients),
                           "rms": result.rms}
            fitted, result.coefficients, result.rms = refine_material(self.exact_model(), wi, wo, values, fitted,
                                                                      objective.names)
            result.params = {k: fitted[k] for k in objective.names}
        return fitted, result

    def query(self, centre, size, wi, wo, params: dict | None = None, *, reference=None) -> dict[str, np.ndarray]:
        """Components of box footprints of side ``size`` tiles at ``centre`` (N, 2) tiles.  ``reference``:
        the reflectance model's components (N, C) at the queries, when the caller has them (a residual
        network's base R; computed here otherwise).  ``orientation`` in ``params`` rotates the directions into
        the weave's frame as :meth:`components` does (module docstring of :mod:`clothlab.models.base`); centre
        and size stay in the tile's frame."""
        params, angle = split_orientation(params)
        if angle != 0.0:
            self.params[ORIENTATION].check(angle)
            wi, wo = as_directions(wi, wo)
            wi, wo = to_weave_frame(wi, angle), to_weave_frame(wo, angle)
        material = self._material(params)
        if (reference is None and not isinstance(material, int)
                and (self.surrogate.residual or self.surrogate.residual_input)):
            reference = self.surrogate_reference(params)(wi, wo, centre, size)
        probe = None
        if self.surrogate.probe_points and not isinstance(material, int):
            probe = self.surrogate_probe(params)(wi, wo, centre, size)
        values = self.surrogate.query(centre, size, wi, wo, material=material, reference=reference, probe=probe)
        return {name: values[:, i] for i, name in enumerate(self.component_names)}

    def _components(self, wi, wo, params: dict | None = None, *, need=None, normalised: bool = True,
                    warn: bool = True) -> dict[str, np.ndarray]:
        """The far view (footprint :data:`FAR_SIZE` tiles); ``normalised`` / ``warn`` as the interface."""
        wi, wo = as_directions(wi, wo)
        n = wi.shape[0]
        out = self.query(np.full((n, 2), 0.5), np.full(n, FAR_SIZE), wi, wo, params)
        return {k: v for k, v in out.items() if need is None or k in need}

    def surrogate_reference(self, params: dict | None):
        """The reflectance model at ``params`` as a label source (what a residual network corrects)."""
        from clothlab.surrogate.labels import ModelLabels

        return ModelLabels(self.exact_model(), self.resolve(params))

    def option_files(self) -> dict[str, list[Path]]:
        """The weights' ``.npz`` and its ``.json`` sidecar (architecture, encodings)."""
        return {name: [path, path.with_suffix(".json")] for name, (path,) in super().option_files().items()}

    def surrogate_probe(self, params: dict | None):
        """The texture probe at ``params`` (:class:`clothlab.surrogate.labels.TextureProbe` of the exact model's
        texture), the input of a probing network (``encoding["probe_points"]``) at a material it did not store."""
        from clothlab.surrogate.labels import TextureProbe

        if self._probe_texture is None:
            self._probe_texture = self.exact_model().texture()
        return TextureProbe(self._probe_texture, self.resolve(params), self.surrogate.probe_points)

    def texture(self, *, seed: int = 0):
        return NeuralTexture(self)


def read_sidecar(weights, *, as_config: bool = True) -> dict:
    """The checked ``.json`` sidecar of surrogate weights ``weights`` (.npz or .json;
    :func:`clothlab.surrogate.serialise.read_sidecar`'s schema, then the target kind and the parameter names
    against that kind's declarations).  A ConfigError at ``model.options.weights`` when a file is missing;
    a bad sidecar is a ConfigError there too, naming the sidecar (``path``) and its dotted field (first in
    the message); with ``as_config`` (config validation, which names the yaml line of the option) both are
    in the message."""
    from clothlab.surrogate.serialise import read_sidecar as read_checked

    path = Path(weights)
    for p in (path.with_suffix(".npz"), path.with_suffix(".json")):
        if not p.is_file():
            raise ConfigError(f"surrogate file not found: {p} (a .npz and its .json sidecar written by clothlab "
                              "train-surrogate)", field="model.options.weights")
    try:
        sidecar = read_checked(path)
        check_sidecar_names(sidecar, path.with_suffix(".json"))
    except InputError as exc:
        if as_config:  # config validation puts this at the option's yaml line: the sidecar named in the message
            raise ConfigError(f"{exc}", field="model.options.weights") from None
        raise as_option_error(exc) from None
    return sidecar


def as_option_error(exc: InputError) -> ConfigError:
    """A ConfigError at ``model.options.weights`` naming the weights' file (``path``) and, first in the
    message, the sidecar field or the ``.npz`` member at fault."""
    return ConfigError(f"{exc.field}: {exc.detail}" if exc.field else exc.detail, path=exc.path, line=exc.line,
                       field="model.options.weights")


def check_sidecar_names(sidecar: dict, path) -> None:
    """InputError naming ``path`` and the field: the sidecar's target kind must be one of
    :data:`TARGET_KINDS` and its parameter names (``encoding.parameters``, ``params``, ``materials_params``)
    parameters of that kind, with values inside their physical ranges."""
    from clothlab.errors import ParameterError

    enc = sidecar.get("encoding") or {}
    kind = enc.get("kind", DEFAULT_TARGET_KIND)
    if kind not in TARGET_KINDS:
        raise InputError(f"surrogate target kind {kind!r}: kind neural takes networks of {', '.join(TARGET_KINDS)}",
                         path=path, field="encoding.kind")
    from clothlab.surrogate.serialise import pattern_length

    table = target_class(sidecar).declared_parameters()
    for i, name in enumerate(enc.get("parameters", ())):
        if name not in table or name == ORIENTATION:
            raise InputError(f"{name!r} is not an encoder parameter of kind {kind!r}", path=path,
                             field=f"encoding.parameters[{i}]")
    if "parameters" not in enc:  # an older file: the encoder reads every declared parameter but orientation
        n = len([name for name in table.names() if name != ORIENTATION]) + pattern_length(enc.get("pattern_order", 2))
        if n != sidecar["architecture"]["n_material"]:
            raise InputError(f"n_material = {sidecar['architecture']['n_material']}, but the parameters of kind "
                             f"{kind!r} and the pattern descriptor make {n} (and encoding.parameters is not given)",
                             path=path, field="architecture.n_material")
    sets = [("encoding.params", enc.get("params") or {})]
    sets += [(f"encoding.materials_params[{i}]", q) for i, q in enumerate(enc.get("materials_params") or ())]
    for where, values in sets:
        for name, value in values.items():
            if name not in table:
                raise InputError(f"{name!r} is not a parameter of kind {kind!r}", path=path, field=f"{where}.{name}")
            try:
                table[name].check(value)
            except ParameterError as exc:
                raise InputError(exc.detail, path=path, field=f"{where}.{name}") from None


def target_class(sidecar: dict):
    """The model class the network learnt (the sidecar's ``encoding.kind``, irawan for older files)."""
    from clothlab.models.registry import model_class

    kind = (sidecar.get("encoding") or {}).get("kind", DEFAULT_TARGET_KIND)
    if kind not in TARGET_KINDS:
        raise ConfigError(f"surrogate target kind {kind!r}: kind neural takes networks of {', '.join(TARGET_KINDS)}",
                          field="model.options.weights")
    return model_class(kind)


def trained_free(sidecar: dict) -> tuple:
    """The parameters a fit frees by default: those that differ between the network's materials (a
    ``--vary`` grid), else ``alpha`` / ``beta`` where the target declares them (IM) and the target's own
    otherwise."""
    materials = (sidecar.get("encoding") or {}).get("materials_params") or []
    varied = tuple(k for k in (materials[0] if materials else {})
                   if len({float(q[k]) for q in materials if k in q}) > 1)
    if varied:
        return varied
    target = target_class(sidecar)
    declared = set(target.declared_parameters().names())
    return NeuralModel.default_free if declared.issuperset(NeuralModel.default_free) else tuple(target.default_free)


class NeuralTexture(ModelTexture):
    """The surrogate at texture points: footprint centre (u, v), size ``footprint`` tiles (filters itself).
    A :class:`clothlab.models.base.ModelTexture`: declarations, defaults, component names and the refusal of
    an ``orientation`` other than 0 (the texture evaluates the weave in its tile frame) are the other texture
    models'; :meth:`NeuralModel.query` takes an orientation."""

    kind = "neural-texture"

    def _components(self, u, v, wi, wo, params: dict | None = None, *, need=None, noise: bool = True,
                    normalised: bool = True, warn: bool = True, footprint=None, view_distance=None):
        """Arrays of the points' shape; ``footprint``: size in tiles (scalar or per point)."""
        from clothlab.models.base import texture_parameters

        params = texture_parameters(params, self.model.kind)
        u, v = np.broadcast_arrays(np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64))
        n = u.size
        wi, wo = (np.broadcast_to(np.atleast_2d(np.asarray(d, dtype=np.float64)), (n, 3)) for d in (wi, wo))
        size = np.broadcast_to(np.asarray(MIN_FOOTPRINT if footprint is None else footprint, dtype=np.float64),
                               u.shape).reshape(-1)
        out = self.model.query(np.column_stack([u.reshape(-1), v.reshape(-1)]), size, wi, wo, params)
        return {k: c.reshape(u.shape) for k, c in out.items() if need is None or k in need}
