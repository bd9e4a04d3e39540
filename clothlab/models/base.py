"""The model interface every clothlab model implements.

A model is a pure function of fabric-frame directions and parameters: no file I/O, no plotting, no global
state.  It returns named *components* (diffuse and specular parts per yarn type, 1/sr, each (N,)); the linear
coefficients (kd, ks per channel and yarn type) are applied outside (:func:`clothlab.models.components.combine`)
so a fit solves them by non-negative least squares.

Everything the fitter, the report, the texture fit and the renderer need to know about a model is asked of
this interface; only :mod:`clothlab.models.registry` knows which kinds exist.  A new model is one package
that subclasses :class:`Model` plus one registry line.

=======================  =====================================================================================
member                   meaning
=======================  =====================================================================================
``kind``                 the registry name (``model.kind`` in fabric.yaml)
``params``               the parameter declarations (:class:`clothlab.params.ParamTable`) of this instance
``declared_parameters``  the declarations for given ``model.options`` (class method; config validation)
``component_names``      the components :meth:`components` returns, in design-matrix order
``coefficient_meaning``  what the linear coefficients (kd, ks_...) of the components mean, for fit.json
``default_free``         the parameters a fit frees when fabric.yaml names none
``from_config``          build from a weave, the configured quadrature and ``model.options`` (class method)
``default_parameters``   every declared parameter's value for this weave (a fit's start)
``resolve``              the defaults overridden by given values, validated against the declarations
``components``           the components (1/sr, each (N,)) at fabric-frame directions wi, wo (N, 3)
``components_many``      the components for J parameter sets at once, each (J, N) (a loop by default)
``evaluate``             f_r (N, C): the components times their coefficients
``settings``             what a fit directory records about this model (quadrature or options)
``option_files``         the files its file options (``path_options``) name; a fit directory keeps copies
``describe_settings``    those recorded settings in a few words, for reports (class method)
``fitted_weave``         the weave with fitted parameters applied (for the ``.wv`` export)
``geometry_warnings``    notes on parameter sets outside the model's valid geometry (empty by default)
``with_quadrature``      a copy integrating with another rule / node count (itself if it integrates nothing)
``forget_directions``    drop the memo of the last directions evaluated (benchmarks time cold; no-op by default)
``forget_results``       drop memoised results at those directions, keeping them (a new parameter point's cost)
``has_texture``          True when :meth:`texture` gives a texture model (capability)
``texture``              the texture model: components at texture points (u, v) whose tile average is
                         :meth:`components`; ConfigError for models without one
``texture_filters``      True when the texture model takes a pixel footprint and filters itself (capability)
``orientation_period``   the period (deg) of the model under a rotation of the weave about the normal
                         (:data:`ISOTROPIC` = 0: any rotation); the bounds of ``orientation`` span one period
``quarter_turn_swaps``   True when a quarter turn maps the warp components onto the weft ones (capability)
``fit_period``           the period of ``orientation`` at given parameters, up to relabelling warp <-> weft
``path_options``         the ``model.options`` that name files (resolved against the yaml's directory)
``check_option``         a model's own check of one option's value (class method; ConfigError; no-op default)
``check_options``        a check of options that must agree with each other (class method; no-op default)
``options_class``        the class whose keyword arguments ``model.options`` are (a composite: its specular
                         part; class method)
``declared_free``        the parameters a fit frees when fabric.yaml names none, for given options (class
                         method; ``default_free`` by default)
``specular_class``       a composite's specular and diffuse model classes (None for a single model)
``diffuse_class``
``footprint_queries``    True when the model answers footprint averages itself (``clothlab eval``'s footprint
                         column; kind neural: its network), rather than by averaging its texture (capability)
``refine``               True when a fit polishes its optimum with the exact model it approximates (neural)
``quadrature``           the rule the model integrates with (None for a model that integrates nothing)
``parameter_concepts``   what its parameters mean across model families: concept -> its parameters (the
                         selection maps fabric.yaml's fit.free through it; empty: no counterparts)
``im_counterparts``      name-level counterparts of the IM model's fit.free names (by role), tried first
``tile_average_quadrature``  (rule, nodes) of a converged tile average (the surrogate's labels and R), or None
=======================  =====================================================================================

Orientation (one implementation for every model, here).  Every model accepts the parameter ``orientation``
(deg): the weave rotated counter-clockwise about the surface normal, seen from above, so that its warp lies at
azimuth 90 + orientation deg of the table's fabric frame (docs/design.md principle 1).  The value at a
direction pair is the unrotated model's at the directions turned back into the weave's frame,

    f_r(wi, wo; orientation) = f_r(R(-orientation) wi, R(-orientation) wo; 0)     (R: rotation about z)

(:func:`clothlab.frames.to_weave_frame`).  The public methods that take parameters are template methods
(:data:`TEMPLATE_METHODS`): :meth:`Model.components` takes ``orientation`` out of the parameters, turns the
directions into the weave's frame and calls the subclass's hook ``_components`` with the rest;
``components_many`` does so per orientation of a batch; ``resolve`` / ``default_parameters``,
``fitted_weave``, ``geometry_warnings`` and ``declared_parameters`` likewise call ``_resolve``,
``_default_parameters``, ... .  A subclass writes only the hooks, in the weave's frame, and never sees
``orientation``; one that defines a template method itself is refused at class creation (TypeError), and
its parameter table gains the declaration then (an instance that narrows its table declares it with
:func:`with_orientation`).  Absent or 0, nothing is rotated: results are bitwise those of the model alone.
:meth:`resolve` lists ``orientation`` only when it is given, and :meth:`default_parameters` never (so
existing fits and simulated tables are unchanged); a configuration that frees it gets the start value 0
(:mod:`clothlab.config.validate`).  Texture models (u, v; base :class:`Texture`, the same template form)
do not rotate the tile: their ``components`` and ``resolve`` refuse an orientation other than 0
(:func:`texture_parameters`) before their hooks run.

Symmetry (:attr:`orientation_period`).  The tile-averaged models of woven cloth are invariant under a turn by
180 deg (the yarn integrals of a segment are even in the segment's arc parameter u and a helix keeps its
handedness under a half turn: Irawan & Marschner 2012, eqs. 4-10; Kang's perturbation rectangle is symmetric),
so their period is 180 deg and ``orientation`` is bounded to [-90, 90] by default.  A quarter turn maps the
warp components onto the weft ones (the weft frame is the warp frame turned by 90 deg, sec. 5.2): when warp and
weft carry the same parameters (or tied ones, as Kang's alternating lobes), a quarter turn changes only which
linear coefficient is called ks_warp and which ks_weft, so a fit determines the orientation modulo 90 deg only
(:meth:`fit_period`).  Isotropic models (Lambert, Oren-Nayar) do not depend on it at all (:data:`ISOTROPIC`).
The test suite checks these symmetries numerically for every registered kind.

A texture model (what :meth:`Model.texture` returns, a :class:`Texture`) has ``weave``, ``params``,
``component_names``, ``resolve(params)`` and ``components(u, v, wi, wo, params, *, need=None, noise=True,
normalised=True, warn=True, footprint=None, view_distance=None)`` returning arrays of the points' shape;
models with ``texture_filters`` use ``footprint`` (tiles) and ``view_distance``, the others ignore them.
Optional members, read by the footprint aggregation (:mod:`clothlab.footprint`, docs/footprint.md):
``shared_directions = True`` when ``components`` takes (1, 3) directions shared by every point (faster), and
``micro_normals(u, v, params)`` for a texture whose values are point BSDFs about micro normals (eqs. 4-5
weights then apply).

Helpers for implementations: :func:`as_directions` (the (N, 3) float64 arrays every model takes) and
:func:`front_facing` (the pairs a reflection model lights).
"""

from __future__ import annotations

import abc
import copy
import functools
import math
from pathlib import Path
from typing import ClassVar

import numpy as np

from clothlab.errors import ConfigError
from clothlab.frames import to_weave_frame
from clothlab.models.components import combine
from clothlab.params import ParamSpec, ParamTable

#: The name of the rotation of the weave about the normal, a parameter of every model (module docstring).
ORIENTATION = "orientation"
#: The public template methods of :class:`Model`: they apply ``orientation`` and call the hook of the same name
#: with a leading underscore (``components`` -> ``_components``), which a subclass writes in the weave's frame.
TEMPLATE_METHODS = ("components", "components_many", "resolve", "default_parameters", "fitted_weave",
                    "geometry_warnings", "declared_parameters")
#: The public template methods of :class:`Texture` (they refuse an ``orientation`` other than 0).
TEXTURE_TEMPLATE_METHODS = ("components", "resolve")


def _refuse_template_overrides(cls, names) -> None:
    """TypeError when class ``cls`` defines one of the template methods ``names`` itself: it writes the hook
    (``_<name>``) instead, so that the orientation cannot be bypassed."""
    own = sorted(name for name in names if name in cls.__dict__)
    if own:
        raise TypeError(f"{cls.__qualname__} defines {', '.join(own)}: a subclass of {cls.__mro__[1].__name__} "
                        f"writes the hook{'s' if len(own) > 1 else ''} {', '.join('_' + n for n in own)} instead "
                        "(the public method applies the orientation; clothlab.models.base)")
#: :attr:`Model.orientation_period` of a model that does not depend on the orientation at all.
ISOTROPIC = 0.0
#: The period of the tile-averaged woven-cloth models (a half turn maps a weave onto itself).
HALF_TURN = 180.0


def orientation_spec(period: float) -> ParamSpec:
    """The declaration of ``orientation`` for a model of period ``period`` deg (:data:`ISOTROPIC`: a full
    turn): default 0, fit bounds one period centred on 0, any value in [-360, 360] accepted."""
    span = float(period) if period and period > 0 else 360.0
    return ParamSpec(ORIENTATION, "deg", (-360.0, 360.0), (-0.5 * span, 0.5 * span), 0.0, "linear",
                     "rotation of the weave about the surface normal, counter-clockwise from above: the warp at "
                     f"azimuth 90 + orientation deg of the table (periodic, {span:g} deg)", period=span)


def with_orientation(table, period: float):
    """``table`` (a ParamTable or subclass, kept) with the ``orientation`` declaration added (once)."""
    if table is None or not isinstance(table, ParamTable) or ORIENTATION in table.specs:
        return table
    out = copy.copy(table)
    out.specs = {**table.specs, ORIENTATION: orientation_spec(period)}
    return out


def common_period(periods) -> float:
    """The period of a sum of models of these periods: the least common multiple of the non-isotropic ones
    (in units of 1e-6 deg), :data:`ISOTROPIC` if all are."""
    ticks = [round(p * 1e6) for p in periods if p and p > 0]
    if not ticks:
        return ISOTROPIC
    return functools.reduce(lambda a, b: a * b // math.gcd(a, b), ticks) / 1e6


def split_orientation(params):
    """(``params`` without ``orientation``, the orientation in deg; 0 when absent)."""
    if not params or ORIENTATION not in params:
        return params, 0.0
    return {k: v for k, v in params.items() if k != ORIENTATION}, float(params[ORIENTATION])


def texture_parameters(params, kind: str):
    """``params`` for a texture model, which evaluates the weave in its own tile frame: ``orientation`` taken
    out, and refused (ConfigError) unless 0 - rotate the scene's (u, v) frame instead."""
    rest, angle = split_orientation(params)
    if angle != 0.0:
        raise ConfigError(f"the texture model of kind {kind!r} takes no orientation (got {angle:g} deg): it "
                          "evaluates the weave in its tile frame; rotate the scene's (u, v) frame instead",
                          field=ORIENTATION)
    return rest


def as_directions(wi, wo) -> tuple[np.ndarray, np.ndarray]:
    """wi, wo as (N, 3) float64 arrays (a single (3,) direction becomes (1, 3)); ValueError on other shapes."""
    wi = np.atleast_2d(np.asarray(wi, dtype=np.float64))
    wo = np.atleast_2d(np.asarray(wo, dtype=np.float64))
    if wi.shape != wo.shape or wi.ndim != 2 or wi.shape[-1] != 3:
        raise ValueError(f"wi, wo must both be (N, 3) arrays, got {wi.shape} and {wo.shape}")
    return wi, wo


def front_facing(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """(N,) True where both directions lie above the surface (wi_z > 0 and wo_z > 0): reflection only."""
    return (wi[:, 2] > 0.0) & (wo[:, 2] > 0.0)


class Model(abc.ABC):
    """Base class of clothlab's reflectance models (see the module docstring for the members)."""

    kind: ClassVar[str]
    component_names: ClassVar[tuple[str, ...]]
    coefficient_meaning: ClassVar[str] = "coefficients multiply the components linearly"
    default_free: ClassVar[tuple[str, ...]] = ()
    #: True when :meth:`texture` gives a texture (spatially varying) model
    has_texture: ClassVar[bool] = False
    #: True when the texture model takes a pixel footprint and filters itself (a renderer need not blend)
    texture_filters: ClassVar[bool] = False
    #: period (deg) under a rotation of the weave about the normal; ISOTROPIC (0) for no dependence at all
    orientation_period: ClassVar[float] = HALF_TURN
    #: True when the weft components are the warp components turned by 90 deg up to a constant factor (the
    #: same yarn model for both types, the weave entering only through cell shares): :meth:`fit_period`
    quarter_turn_swaps: ClassVar[bool] = True
    #: the ``model.options`` that name files: resolved against fabric.yaml's directory, copied into fit dirs
    path_options: ClassVar[tuple[str, ...]] = ()
    #: a composite's specular and diffuse model classes; None for a single model
    specular_class: ClassVar[type | None] = None
    diffuse_class: ClassVar[type | None] = None
    #: True when the model answers footprint averages itself (kind neural), not by averaging its texture
    footprint_queries: ClassVar[bool] = False
    #: what its parameters mean across model families (the selection's per-kind mapping of fabric.yaml's
    #: fit.free, issue 28 item 1): concept -> this model's parameters of it; a concept it lacks has no counterpart
    parameter_concepts: ClassVar[dict[str, tuple[str, ...]]] = {}
    #: name-level counterparts of the IM model's fit.free names here, tried before the concepts (by role)
    im_counterparts: ClassVar[dict[str, tuple[str, ...]]] = {}
    #: True when a fit polishes its optimum with the exact model this one approximates (kind neural)
    refine: bool = False
    #: the quadrature rule the model integrates with; None for a model that integrates nothing
    quadrature = None
    #: (rule, nodes) whose tile average converges to the texture's own (the surrogate's labels and R, issue 23
    #: item 5); None: the model as built already converges or integrates nothing
    tile_average_quadrature: ClassVar[tuple[str, int] | None] = None
    params: ParamTable

    def __init_subclass__(cls, **kwargs):
        """Declarations only (module docstring): the subclass's own parameter table gains the ``orientation``
        entry, and a subclass that defines a template method (:data:`TEMPLATE_METHODS`) instead of its hook
        is refused (TypeError).  No method is wrapped."""
        super().__init_subclass__(**kwargs)
        _refuse_template_overrides(cls, TEMPLATE_METHODS)
        if "params" in cls.__dict__:
            cls.params = with_orientation(cls.__dict__["params"], cls.orientation_period)

    @classmethod
    def options_class(cls) -> type:
        """The class whose keyword-only constructor arguments ``model.options`` are: a composite passes its
        options to its specular part, any other model takes them itself."""
        return cls.specular_class if cls.specular_class is not None else cls

    @classmethod
    def check_option(cls, name: str, value) -> None:
        """A model's own check of one ``model.options`` value (ConfigError naming the problem); none here."""
        return None

    @classmethod
    def check_options(cls, options: dict) -> None:
        """A check of ``model.options`` that must agree with each other (ConfigError); none here."""
        return None

    @classmethod
    def declared_free(cls, options: dict | None = None) -> tuple:
        """The parameters a fit frees when fabric.yaml names none, for these ``model.options``:
        :attr:`default_free` unless the model reads them from its options (kind neural: its network)."""
        return tuple(cls.default_free)

    def fit_period(self, params: dict | None = None) -> float:
        """The period (deg) of ``orientation`` as a fit sees it at ``params``: :attr:`orientation_period`,
        halved when every warp parameter equals its weft counterpart (or has none: tied), because a quarter turn
        then only exchanges ks_warp and ks_weft (module docstring); :data:`ISOTROPIC` stays 0."""
        period = self.orientation_period
        if not period:
            return ISOTROPIC
        p = self.resolve(params)
        warp = {k[len("warp."):]: v for k, v in p.items() if k.startswith("warp.")}
        weft = {k[len("weft."):]: v for k, v in p.items() if k.startswith("weft.")}
        if "specular_warp" in self.component_names and "specular_weft" in self.component_names and \
                all(name not in weft or weft[name] == value for name, value in warp.items()) and \
                set(weft) <= set(warp) and self.quarter_turn_swaps:
            return period / 2.0
        return period


    def __init__(self, weave, **options):
        self.weave = weave
        self.options = dict(options)

    @classmethod
    def declared_parameters(cls, options: dict | None = None) -> ParamTable:
        """The parameter declarations for these ``model.options`` (used by config validation): the hook's
        (:meth:`_declared_parameters`) with ``orientation`` added."""
        return with_orientation(cls._declared_parameters(options), cls.orientation_period)

    @classmethod
    def _declared_parameters(cls, options: dict | None = None) -> ParamTable:
        """Hook of :meth:`declared_parameters`: the class's table by default."""
        return cls.params

    @classmethod
    def from_config(cls, weave, quadrature=None, **options) -> Model:
        """An instance for ``weave``; ``quadrature`` is (rule, nodes) for models that integrate, else ignored."""
        model = cls(weave, **options)
        model.options = dict(options)
        return model

    def default_parameters(self) -> dict[str, float]:
        """Every declared parameter's value for this weave (the starting point of a fit): the hook's
        (:meth:`_default_parameters`), never ``orientation`` (module docstring)."""
        out = self._default_parameters()
        out.pop(ORIENTATION, None)  # a hook listing every declaration of the table puts its default in
        return out

    @abc.abstractmethod
    def _default_parameters(self) -> dict[str, float]:
        """Hook of :meth:`default_parameters`: every parameter's value for this weave."""

    def resolve(self, params: dict | None) -> dict[str, float]:
        """The default parameters overridden by ``params``, validated against the declarations: the hook's
        (:meth:`_resolve`, given ``params`` without ``orientation``), with ``orientation`` only when given."""
        rest, angle = split_orientation(params)
        out = self._resolve(rest)
        out.pop(ORIENTATION, None)
        if rest is not params:  # orientation given
            out[ORIENTATION] = self.params[ORIENTATION].check(angle, ORIENTATION)
        return out

    def _resolve(self, params: dict | None) -> dict[str, float]:
        """Hook of :meth:`resolve` (no ``orientation`` in ``params``): the defaults overridden by ``params``,
        validated against the declarations."""
        full = self.default_parameters()
        if params:
            full.update(self.params.validate(params))
        return full

    def components(self, wi, wo, params: dict | None = None, *, need=None, normalised: bool = True,
                   warn: bool = True) -> dict[str, np.ndarray]:
        """Components (1/sr, each (N,)) at fabric-frame directions wi, wo (N, 3); ``need`` limits which.  The
        directions are turned into the weave's frame by ``orientation`` (module docstring) and the hook
        :meth:`_components` evaluates them with the other parameters; absent or 0, nothing is rotated."""
        rest, angle = split_orientation(params)
        if angle != 0.0:
            self.params[ORIENTATION].check(angle)
            wi, wo = as_directions(wi, wo)
            wi, wo = to_weave_frame(wi, angle), to_weave_frame(wo, angle)
        return self._components(wi, wo, rest, need=need, normalised=normalised, warn=warn)

    @abc.abstractmethod
    def _components(self, wi, wo, params: dict | None = None, *, need=None, normalised: bool = True,
                    warn: bool = True) -> dict[str, np.ndarray]:
        """Hook of :meth:`components`: the components at weave-frame directions, ``params`` without
        ``orientation``."""

    def components_many(self, wi, wo, params_list, *, need=None, normalised: bool = True,
                        warn: bool = True) -> dict[str, np.ndarray]:
        """:meth:`components` for J parameter sets, each component (J, N): the sets of one orientation are
        evaluated together by the hook :meth:`_components_many` at the directions turned into that
        orientation's weave frame; the rows come back in the given order."""
        split = [split_orientation(p) for p in params_list]
        angles = [a for _, a in split]
        kw = dict(need=need, normalised=normalised, warn=warn)
        if all(a == 0.0 for a in angles):
            return self._components_many(wi, wo, [p for p, _ in split], **kw)
        wi, wo = as_directions(wi, wo)
        out: dict = {}
        for angle in dict.fromkeys(angles):
            rows = [j for j, a in enumerate(angles) if a == angle]
            if angle != 0.0:
                self.params[ORIENTATION].check(angle)
            part = self._components_many(to_weave_frame(wi, angle), to_weave_frame(wo, angle),
                                         [split[j][0] for j in rows], **kw)
            for name, value in part.items():
                if name not in out:
                    out[name] = np.zeros((len(angles),) + value.shape[1:], dtype=value.dtype)
                out[name][rows] = value
        return out

    def _components_many(self, wi, wo, params_list, *, need=None, normalised: bool = True,
                         warn: bool = True) -> dict[str, np.ndarray]:
        """Hook of :meth:`components_many` (weave-frame directions, no ``orientation``): one :meth:`_components`
        per set by default; models override it when they can share work between the sets (the posterior
        evaluates a whole ensemble half at once)."""
        rows = [self._components(wi, wo, p, need=need, normalised=normalised, warn=warn) for p in params_list]
        return {name: np.stack([r[name] for r in rows]) for name in rows[0]} if rows else {}

    def evaluate(self, wi, wo, coefficients: dict, params: dict | None = None) -> np.ndarray:
        """f_r (N, C) = sum_k coefficients[k] * component_k."""
        return combine(self.components(wi, wo, params), coefficients)

    def geometry_warnings(self, params: dict) -> list[str]:
        """Notes on ``params`` that lie outside the geometry the model is valid for: the hook's
        (:meth:`_geometry_warnings`) for ``params`` without ``orientation`` (it does not change the weave)."""
        return self._geometry_warnings(split_orientation(params)[0])

    def _geometry_warnings(self, params: dict) -> list[str]:
        """Hook of :meth:`geometry_warnings` (no ``orientation`` in ``params``): none by default."""
        return []

    def fitted_weave(self, params: dict):
        """The weave with ``params`` applied, for the ``.wv`` export of a fit: the hook's
        (:meth:`_fitted_weave`) for ``params`` without ``orientation`` (the .wv format has none)."""
        return self._fitted_weave(split_orientation(params)[0])

    def _fitted_weave(self, params: dict):
        """Hook of :meth:`fitted_weave` (no ``orientation`` in ``params``): the weave itself by default."""
        return self.weave

    def settings(self) -> dict:
        """What a fit directory records about this model besides kind and weave."""
        return {"options": dict(getattr(self, "options", {}))}

    def option_files(self) -> dict[str, list[Path]]:
        """{file option: the files it names} of the options in ``path_options`` that are set; by default the
        option's own file.  A fit directory keeps copies of them."""
        options = dict(getattr(self, "options", {}) or {})
        return {name: [Path(options[name])] for name in getattr(self, "path_options", ()) if options.get(name)}

    @classmethod
    def describe_settings(cls, settings: dict) -> str:
        """The recorded :meth:`settings` (a fit.json ``model`` entry) in a few words: the options as
        ``name=value``, or ``defaults``."""
        options = settings.get("options") or {}
        return ", ".join(f"{k}={v}" for k, v in options.items()) or "defaults"

    def with_quadrature(self, rule: str | None = None, nodes: int | None = None) -> Model:
        """This model integrating with another quadrature (None keeps the current rule / node count); a
        model that integrates nothing returns itself."""
        return self

    def forget_results(self) -> None:
        """Drop what the model remembers of results at the current directions (memoised integrals), keeping
        the direction set: the next evaluation costs what a new parameter point costs.  Nothing here."""
        return None

    def forget_directions(self) -> None:
        """Drop what the model keeps of the last directions it evaluated (models that memoise the
        parameter-free work of a direction set for fits override this); benchmarks call it so that each
        timed evaluation starts cold.  Nothing to drop here."""
        return None

    def texture(self, *, seed: int = 0):
        """The texture model of this model's weave and settings (module docstring); ``seed`` selects its
        noise realisation.  ConfigError for a model without one (:attr:`has_texture` False)."""
        raise ConfigError(f"model kind {self.kind!r} has no texture model (no evaluation at texture points u, v)",
                          field="model.kind")


class SetsTogetherModel(Model):
    """A model that evaluates parameter sets together (the composites: each part evaluates all sets in one
    call): it implements :meth:`Model._components_many`, and one set is that hook's first row."""

    def _components(self, wi, wo, params: dict | None = None, *, need=None, normalised: bool = True,
                    warn: bool = True) -> dict[str, np.ndarray]:
        many = self._components_many(wi, wo, [params], need=need, normalised=normalised, warn=warn)
        return {name: value[0] for name, value in many.items()}


class Texture(abc.ABC):
    """Base class of the texture models (module docstring): :meth:`components` and :meth:`resolve` are
    template methods that refuse an ``orientation`` other than 0 (:func:`texture_parameters`: a texture
    evaluates the weave in its tile frame) and call the hooks :meth:`_components` / :meth:`_resolve` with the
    other parameters.  A subclass declares ``weave``, ``params`` (its model's, ``orientation`` included) and
    ``component_names``, and writes the hooks."""

    #: the kind of the model whose texture this is (named by the refusal)
    model_kind: ClassVar[str]
    component_names: tuple[str, ...]
    params: ParamTable

    def __init_subclass__(cls, **kwargs):
        """A subclass writes the hooks, not the template methods (:data:`TEXTURE_TEMPLATE_METHODS`; TypeError)."""
        super().__init_subclass__(**kwargs)
        _refuse_template_overrides(cls, TEXTURE_TEMPLATE_METHODS)

    def components(self, u, v, wi, wo, params: dict | None = None, **kw) -> dict[str, np.ndarray]:
        """Components (1/sr) at texture points u, v (tiles) for fabric-frame directions wi, wo (keywords:
        module docstring); ConfigError at ``orientation`` for an orientation other than 0."""
        return self._components(u, v, wi, wo, texture_parameters(params, self.model_kind), **kw)

    @abc.abstractmethod
    def _components(self, u, v, wi, wo, params: dict | None = None, **kw) -> dict[str, np.ndarray]:
        """Hook of :meth:`components` (no ``orientation`` in ``params``)."""

    def resolve(self, params: dict | None) -> dict[str, float]:
        """The resolved parameters (the hook :meth:`_resolve`); an ``orientation`` other than 0 is refused."""
        return self._resolve(texture_parameters(params, self.model_kind))

    @abc.abstractmethod
    def _resolve(self, params: dict | None) -> dict[str, float]:
        """Hook of :meth:`resolve` (no ``orientation`` in ``params``)."""


class ModelTexture(Texture):
    """The texture (point) evaluation of a model as a texture model: weave, parameter declarations, defaults and
    validation come from the model; subclasses write the hook ``_components(u, v, wi, wo, params, ...)``."""

    #: the model attribute naming the point components
    component_attribute: ClassVar[str] = "component_names"

    def __init__(self, model: Model):
        self.model = model
        self.weave = model.weave
        self.params = model.params
        self.component_names = getattr(model, self.component_attribute)

    def default_parameters(self) -> dict[str, float]:
        return self.model.default_parameters()

    @property
    def model_kind(self) -> str:
        return self.model.kind

    def _resolve(self, params: dict | None) -> dict[str, float]:
        """The model's resolved parameters."""
        return self.model.resolve(params)
