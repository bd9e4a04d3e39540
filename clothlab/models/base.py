"""The model interface every clothlab model implements (DESIGN.md principles 2-5).

A model is a pure function of fabric-frame directions and parameters: no file I/O, no plotting, no global
state.  It returns named *components* (diffuse and specular parts per yarn type, 1/sr, each (N,)); the linear
coefficients (kd, ks per channel and yarn type) are applied outside (:func:`clothlab.models.components.combine`)
so a fit solves them by non-negative least squares.

Everything the fitter, the report, the texture fit and the renderer need to know about a model is asked of
this interface; only :mod:`clothlab.models.registry` knows which kinds exist.  A new model is one package
that subclasses :class:`Model` plus one registry line.

==================  ==========================================================================================
member              meaning
==================  ==========================================================================================
``kind``            the registry name (``model.kind`` in fabric.yaml)
``params``          the parameter declarations (:class:`clothlab.params.ParamTable`) of this instance
``component_names`` the components :meth:`components` returns, in design-matrix order
``default_free``    the parameters a fit frees when fabric.yaml names none
``from_config``     build from a weave, the configured quadrature and ``model.options``
``components``      the components at directions wi, wo (N, 3)
``settings``        what a fit directory records about this model (quadrature or options)
``fitted_weave``    the weave with fitted parameters applied (for the ``.wv`` export)
``geometry_warnings`` notes on parameter sets outside the model's valid geometry (empty by default)
==================  ==========================================================================================
"""

from __future__ import annotations

import abc
from typing import ClassVar

import numpy as np

from clothlab.models.components import combine
from clothlab.params import ParamTable


class Model(abc.ABC):
    """Base class of clothlab's reflectance models (see the module docstring for the members)."""

    kind: ClassVar[str]
    component_names: ClassVar[tuple[str, ...]]
    coefficient_meaning: ClassVar[str] = "coefficients multiply the components linearly"
    default_free: ClassVar[tuple[str, ...]] = ()
    #: True for models with a texture (spatially varying) evaluation, ``point_components``
    has_texture: ClassVar[bool] = False
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
