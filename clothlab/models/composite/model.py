"""Composite models: the specular components of one model with the diffuse component(s) of another, e.g.
``kind: irawan+oren-nayar`` (the Irawan-Marschner yarn highlights over an Oren & Nayar 1994 rough-diffuse base
instead of the IM model's Lambertian, issue 14 item 3).

A composite of a *specular* model S and a *diffuse* model D is the sum

    f_r = sum_{k: specular parts of S} c_k S_k(wi, wo; theta_S) + sum_{k: parts of D} c_k D_k(wi, wo; theta_D)

Its components are S's components except the diffuse ones (names starting ``diffuse``) followed by all of
D's; its parameters are the union of both tables (names must not clash; ``orientation`` is the composite's
own, applied once to both parts, :mod:`clothlab.models.base`), its default free parameters both parts'
defaults, ``model.options`` go to S (D, a baseline, takes none) and so does the quadrature.  The period in
orientation is the common one (:func:`clothlab.models.base.common_period`: an isotropic diffuse part leaves
S's).  The kinds are registered in :data:`clothlab.models.registry.COMPOSITE_KINDS`; the class of each is
made once by :func:`composite_class`.  Composites have no texture model.
"""

from __future__ import annotations

from functools import cache
from typing import ClassVar

from clothlab.errors import ConfigError
from clothlab.models.base import ORIENTATION, Model, SetsTogetherModel, common_period, with_orientation
from clothlab.params import ParamTable


def _own(table) -> list:
    """The declarations of a part's table without the (shared) orientation."""
    return [s for s in table if s.name != ORIENTATION]


def union_table(specular_table, diffuse_table, kind: str) -> ParamTable:
    """The union of two parts' declarations (orientation excluded); ConfigError when a name is in both."""
    specs = _own(specular_table)
    names = {s.name for s in specs}
    for spec in _own(diffuse_table):
        if spec.name in names:
            raise ConfigError(f"composite kind {kind!r}: parameter {spec.name!r} is declared by both parts",
                              field="model.kind")
        specs.append(spec)
    return ParamTable(specs)


class CompositeModel(SetsTogetherModel):
    """S's specular components + D's diffuse ones (module docstring); subclasses made by :func:`composite_class`
    fix ``specular_class`` and ``diffuse_class``."""

    specular_class: ClassVar[type]
    diffuse_class: ClassVar[type]
    has_texture = False

    def __init__(self, weave, specular: Model, diffuse: Model):
        self.weave = weave
        self.specular, self.diffuse = specular, diffuse
        self.options = dict(getattr(specular, "options", {}))
        self.params = with_orientation(union_table(specular.params, diffuse.params, self.kind),
                                       self.orientation_period)  # the composite's own orientation
        self._specular_names = frozenset(s.name for s in _own(specular.params))
        self._diffuse_names = frozenset(s.name for s in _own(diffuse.params))
        self._specular_components = tuple(n for n in specular.component_names if not n.startswith("diffuse"))
        self.component_names = self._specular_components + tuple(diffuse.component_names)

    @classmethod
    def _declared_parameters(cls, options: dict | None = None) -> ParamTable:
        return union_table(cls.specular_class.declared_parameters(options), cls.diffuse_class.declared_parameters(),
                           cls.kind)

    @classmethod
    def from_config(cls, weave, quadrature=None, **options) -> CompositeModel:
        return cls(weave, cls.specular_class.from_config(weave, quadrature, **options),
                   cls.diffuse_class.from_config(weave, None))

    def _split(self, p: dict) -> tuple[dict, dict]:
        return ({k: v for k, v in p.items() if k in self._specular_names},
                {k: v for k, v in p.items() if k in self._diffuse_names})

    def _default_parameters(self) -> dict[str, float]:
        return {**self.specular.default_parameters(), **self.diffuse.default_parameters()}

    def _components_many(self, wi, wo, params_list, *, need=None, normalised: bool = True, warn: bool = True):
        """:meth:`components` for J parameter sets (each part evaluates its sets in one call)."""
        need = self.component_names if need is None else tuple(need)
        parts = [self._split(self.resolve(p)) for p in params_list]
        out = {}
        wanted = [n for n in self._specular_components if n in need]
        if wanted:
            out.update(self.specular.components_many(wi, wo, [s for s, _ in parts], need=wanted,
                                                     normalised=normalised, warn=warn))
        wanted = [n for n in self.diffuse.component_names if n in need]
        if wanted:
            out.update(self.diffuse.components_many(wi, wo, [d for _, d in parts], need=wanted,
                                                    normalised=normalised, warn=warn))
        return {name: out[name] for name in self.component_names if name in out}

    def _geometry_warnings(self, params: dict) -> list[str]:
        specular, diffuse = self._split(self.resolve(params))
        return self.specular.geometry_warnings(specular) + self.diffuse.geometry_warnings(diffuse)

    def _fitted_weave(self, params: dict):
        return self.specular.fitted_weave(self._split(self.resolve(params))[0])

    def settings(self) -> dict:
        return {"specular": {"kind": self.specular.kind, **self.specular.settings()},
                "diffuse": {"kind": self.diffuse.kind, **self.diffuse.settings()}}

    @classmethod
    def describe_settings(cls, settings: dict) -> str:
        spec, diff = settings.get("specular") or {}, settings.get("diffuse") or {}
        return (f"specular {cls.specular_class.kind} ({cls.specular_class.describe_settings(spec)}), diffuse "
                f"{cls.diffuse_class.kind} ({cls.diffuse_class.describe_settings(diff)})")

    def with_quadrature(self, rule: str | None = None, nodes: int | None = None) -> CompositeModel:
        specular = self.specular.with_quadrature(rule, nodes)
        return self if specular is self.specular else type(self)(self.weave, specular, self.diffuse)


@cache
def composite_class(kind: str, specular_class: type, diffuse_class: type) -> type:
    """The composite model class ``kind`` of these two registered model classes (made once)."""
    components = tuple(n for n in specular_class.component_names if not n.startswith("diffuse")) + \
        tuple(diffuse_class.component_names)
    return type(f"Composite[{kind}]", (CompositeModel,), {
        "__module__": __name__,
        "__doc__": f"{specular_class.kind} specular components + {diffuse_class.kind} diffuse ({__name__}).",
        "kind": kind,
        "specular_class": specular_class,
        "diffuse_class": diffuse_class,
        "params": union_table(specular_class.params, diffuse_class.params, kind),
        "component_names": components,
        "default_free": tuple(specular_class.default_free) + tuple(diffuse_class.default_free),
        "coefficient_meaning": f"{specular_class.coefficient_meaning}; diffuse part ({diffuse_class.kind}): "
                               f"{diffuse_class.coefficient_meaning}",
        "orientation_period": common_period([specular_class.orientation_period, diffuse_class.orientation_period]),
        "quarter_turn_swaps": specular_class.quarter_turn_swaps,
    })
