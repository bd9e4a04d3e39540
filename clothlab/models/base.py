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
``describe_settings``    those recorded settings in a few words, for reports (class method)
``fitted_weave``         the weave with fitted parameters applied (for the ``.wv`` export)
``geometry_warnings``    notes on parameter sets outside the model's valid geometry (empty by default)
``with_quadrature``      a copy integrating with another rule / node count (itself if it integrates nothing)
``has_texture``          True when :meth:`texture` gives a texture model (capability)
``texture``              the texture model: components at texture points (u, v) whose tile average is
                         :meth:`components`; ConfigError for models without one
``texture_filters``      True when the texture model takes a pixel footprint and filters itself (capability)
=======================  =====================================================================================

A texture model (what :meth:`Model.texture` returns) has ``weave``, ``component_names``, ``resolve(params)``
and ``components(u, v, wi, wo, params, *, need=None, noise=True, normalised=True, warn=True, footprint=None,
view_distance=None)`` returning arrays of the points' shape; models with ``texture_filters`` use
``footprint`` (tiles) and ``view_distance``, the others ignore them.  Optional members, read by the
footprint aggregation (:mod:`clothlab.models.footprint`, docs/footprint.md): ``shared_directions = True``
when ``components`` takes (1, 3) directions shared by every point (faster), and ``micro_normals(u, v,
params)`` for a texture whose values are point BSDFs about micro normals (eqs. 4-5 weights then apply).

Helpers for implementations: :func:`as_directions` (the (N, 3) float64 arrays every model takes) and
:func:`front_facing` (the pairs a reflection model lights).
"""

from __future__ import annotations

import abc
from typing import ClassVar

import numpy as np

from clothlab.errors import ConfigError
from clothlab.models.components import combine
from clothlab.params import ParamTable


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
    params: ParamTable

    def __init__(self, weave, **options):
        self.weave = weave
        self.options = dict(options)

    @classmethod
    def declared_parameters(cls, options: dict | None = None) -> ParamTable:
        """The parameter declarations for these ``model.options`` (used by config validation)."""
        return cls.params

    @classmethod
    def from_config(cls, weave, quadrature=None, **options) -> Model:
        """An instance for ``weave``; ``quadrature`` is (rule, nodes) for models that integrate, else ignored."""
        model = cls(weave, **options)
        model.options = dict(options)
        return model

    @abc.abstractmethod
    def default_parameters(self) -> dict[str, float]:
        """Every declared parameter's value for this weave (the starting point of a fit)."""

    def resolve(self, params: dict | None) -> dict[str, float]:
        """The default parameters overridden by ``params``, validated against the declarations."""
        full = self.default_parameters()
        if params:
            full.update(self.params.validate(params))
        return full

    @abc.abstractmethod
    def components(self, wi, wo, params: dict | None = None, *, need=None, normalised: bool = True,
                   warn: bool = True) -> dict[str, np.ndarray]:
        """Components (1/sr, each (N,)) at fabric-frame directions wi, wo (N, 3); ``need`` limits which."""

    def components_many(self, wi, wo, params_list, *, need=None, normalised: bool = True,
                        warn: bool = True) -> dict[str, np.ndarray]:
        """:meth:`components` for J parameter sets, each component (J, N); models override it when they can
        share work between the sets (the posterior evaluates a whole ensemble half at once)."""
        rows = [self.components(wi, wo, p, need=need, normalised=normalised, warn=warn) for p in params_list]
        return {name: np.stack([r[name] for r in rows]) for name in rows[0]} if rows else {}

    def evaluate(self, wi, wo, coefficients: dict, params: dict | None = None) -> np.ndarray:
        """f_r (N, C) = sum_k coefficients[k] * component_k."""
        return combine(self.components(wi, wo, params), coefficients)

    def geometry_warnings(self, params: dict) -> list[str]:
        """Notes on ``params`` that lie outside the geometry the model is valid for (none by default)."""
        return []

    def fitted_weave(self, params: dict):
        """The weave with ``params`` applied, for the ``.wv`` export of a fit (the weave itself by default)."""
        return self.weave

    def settings(self) -> dict:
        """What a fit directory records about this model besides kind and weave."""
        return {"options": dict(getattr(self, "options", {}))}

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

    def texture(self, *, seed: int = 0):
        """The texture model of this model's weave and settings (module docstring); ``seed`` selects its
        noise realisation.  ConfigError for a model without one (:attr:`has_texture` False)."""
        raise ConfigError(f"model kind {self.kind!r} has no texture model (no evaluation at texture points u, v)",
                          field="model.kind")


class ModelTexture:
    """The texture (point) evaluation of a model as a texture model: weave, parameter declarations, defaults and
    validation come from the model; subclasses add ``components(u, v, wi, wo, params, ...)``."""

    #: the model attribute naming the point components
    component_attribute: ClassVar[str] = "component_names"

    def __init__(self, model: Model):
        self.model = model
        self.weave = model.weave
        self.params = model.params
        self.component_names = getattr(model, self.component_attribute)

    def default_parameters(self) -> dict[str, float]:
        return self.model.default_parameters()

    def resolve(self, params: dict | None) -> dict[str, float]:
        return self.model.resolve(params)
