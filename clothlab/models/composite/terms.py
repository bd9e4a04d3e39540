"""Physics options over any kind (issue 28 item 5): a model ``B`` with an added term or a grazing factor.

* ``<B>+sheen``: B's components plus the fibre sheen lobe (:mod:`clothlab.models.baselines.sheen`), an extra
  linear component ``sheen`` whose coefficient the NNLS solves like kd and ks, with its own parameter
  ``sheen.r``:   f_r = sum_k c_k B_k + c_sheen f_sheen(r).
* ``<B>+fresnel``: B's specular components (names not starting with ``diffuse``) each multiplied by the
  grazing factor F(wi . h) / F0 * G1(wi) G1(wo) of :mod:`clothlab.models.grazing` (Schlick 1994 eq. 24;
  Smith-GGX, Walter et al. 2007 eq. 34), parameters ``fresnel.eta`` (1.55) and ``smith.alpha`` (0: no
  shadowing), neither freed by default:   f_r = sum_{k specular} c_k F G B_k + sum_{k diffuse} c_k B_k.
* ``<B>+fresnel-smith``: the same with ``smith.alpha`` (the shadowing-masking roughness) freed;
  ``<B>+fresnel-eta``: with ``fresnel.eta`` (the strength of the grazing rise) freed.
* ``<B>+retro``: B's components plus the opposition (retro-reflection) surge of a fibre layer
  (:mod:`clothlab.models.baselines.retro`), an extra linear component ``retro`` = B(g) / pi with its width
  ``retro.h`` freed:   f_r = sum_k c_k B_k + c_retro B(g; h) / pi.
* ``<B>+tilt``: B seen on a sample whose normal is tilted from the table's z axis
  (:mod:`clothlab.models.baselines.tilt`, its eq. 1), parameters ``tilt.x``, ``tilt.y`` (deg) freed:
  f_r = (n . wi) / cos theta_i sum_k c_k B_k(T^-1 wi, T^-1 wo).  The tilt is applied in the weave's frame (after
  the orientation), so the model is no longer symmetric under a half turn: its orientation period is a full turn
  (and a warp/weft quarter turn is no symmetry); the tilt's table azimuth is atan2(tilt.y, tilt.x) +
  orientation.

The wrapper is B for everything else: its parameters are B's and the term's (no clash allowed), options and
quadrature go to B, the orientation is applied once (the sheen and the grazing factor are isotropic, so the
period is B's; the tilt's is a full turn), and
``specular_class`` / ``diffuse_class`` are B's (so the selection maps fit.free names by B's family).  Kinds
registered in :data:`clothlab.models.registry.TERM_KINDS`; each class made once by :func:`term_class`.
"""

from __future__ import annotations

from functools import cache
from typing import ClassVar

import numpy as np

from clothlab.models.base import Model, SetsTogetherModel, with_orientation
from clothlab.models.baselines.retro import RETRO_FREE, RETRO_PARAMS, retro_lobe
from clothlab.models.baselines.sheen import SHEEN_PARAMS, sheen_lobe
from clothlab.models.baselines.tilt import TILT_FREE, TILT_PARAMS, to_sample_frame
from clothlab.models.composite.model import union_table
from clothlab.models.grazing import FRESNEL_ETA_FREE, FRESNEL_FREE, FRESNEL_SMITH_FREE, GRAZING_PARAMS, grazing_factor

#: term name -> (its parameter declarations, its default free parameters, its added components)
TERMS = {
    "sheen": (SHEEN_PARAMS, ("sheen.r",), ("sheen",)),
    "fresnel": (GRAZING_PARAMS, FRESNEL_FREE, ()),
    "fresnel-smith": (GRAZING_PARAMS, FRESNEL_SMITH_FREE, ()),
    "fresnel-eta": (GRAZING_PARAMS, FRESNEL_ETA_FREE, ()),
    "tilt": (TILT_PARAMS, TILT_FREE, ()),
    "retro": (RETRO_PARAMS, RETRO_FREE, ("retro",)),
}
#: the terms that multiply the specular components by the grazing factor (the others add a component)
FACTOR_TERMS = ("fresnel", "fresnel-smith", "fresnel-eta")
#: the terms that change the directions B is evaluated at (the tilted sample frame) and scale every component
FRAME_TERMS = ("tilt",)
#: a full turn: the orientation period of B with a term that is fixed in the weave's frame but not symmetric
FULL_TURN = 360.0


#: the components the terms add (none of them specular: the grazing factor leaves them alone)
ADDED = frozenset(name for _, _, added in TERMS.values() for name in added)


def _specular(name: str) -> bool:
    return not name.startswith("diffuse") and name not in ADDED


class TermModel(SetsTogetherModel):
    """B with a term (module docstring); subclasses made by :func:`term_class` fix ``base_class`` and ``term``."""

    base_class: ClassVar[type]
    term: ClassVar[str]
    has_texture = False

    def __init__(self, weave, base: Model):
        self.weave = weave
        self.base = base
        self.options = dict(base.options)
        term_params = TERMS[self.term][0]
        self.params = with_orientation(union_table(base.params, term_params, self.kind),
                                       self.orientation_period)  # the wrapper's own orientation
        self._term_names = frozenset(s.name for s in term_params)
        self.component_names = tuple(base.component_names) + TERMS[self.term][2]

    @classmethod
    def _declared_parameters(cls, options: dict | None = None):
        return union_table(cls.base_class.declared_parameters(options), TERMS[cls.term][0], cls.kind)

    @classmethod
    def from_config(cls, weave, quadrature=None, **options) -> TermModel:
        return cls(weave, cls.base_class.from_config(weave, quadrature, **options))

    def _split(self, p: dict) -> tuple[dict, dict]:
        return ({k: v for k, v in p.items() if k not in self._term_names},
                {k: v for k, v in p.items() if k in self._term_names})

    def _default_parameters(self) -> dict[str, float]:
        return {**self.base.default_parameters(), **{s.name: float(s.default) for s in TERMS[self.term][0]}}

    def _components_many(self, wi, wo, params_list, *, need=None, normalised: bool = True, warn: bool = True):
        """:meth:`components` for J parameter sets (B evaluates its sets in one call), each (J, N)."""
        need = self.component_names if need is None else tuple(need)
        wi = np.atleast_2d(np.asarray(wi, dtype=np.float64))
        wo = np.atleast_2d(np.asarray(wo, dtype=np.float64))
        parts = [self._split(self.resolve(p)) for p in params_list]
        wanted = [n for n in self.base.component_names if n in need]
        out = {}
        if self.term in FRAME_TERMS:
            return self._tilted_many(wi, wo, parts, wanted, normalised=normalised, warn=warn)
        if wanted:
            out.update(self.base.components_many(wi, wo, [b for b, _ in parts], need=wanted, normalised=normalised,
                                                 warn=warn))
        if self.term == "sheen" and "sheen" in need:
            out["sheen"] = np.stack([sheen_lobe(wi, wo, t["sheen.r"]) for _, t in parts])
        elif self.term == "retro" and "retro" in need:
            out["retro"] = np.stack([retro_lobe(wi, wo, t["retro.h"]) for _, t in parts])
        elif self.term in FACTOR_TERMS and any(_specular(n) for n in out):
            factor = np.stack([grazing_factor(wi, wo, t["fresnel.eta"], t["smith.alpha"]) for _, t in parts])
            out = {n: v * factor if _specular(n) else v for n, v in out.items()}
        return {name: out[name] for name in self.component_names if name in out}

    def _tilted_many(self, wi, wo, parts, wanted, **kw) -> dict:
        """B's components in the tilted sample's frame times the irradiance factor (tilt module, eq. 1), one call
        of B per distinct tilt among the sets (the rows in the given order)."""
        tilts = [(t["tilt.x"], t["tilt.y"]) for _, t in parts]
        out: dict = {}
        for tilt in dict.fromkeys(tilts):
            rows = [j for j, t in enumerate(tilts) if t == tilt]
            wi_s, wo_s, factor = to_sample_frame(wi, wo, *tilt)
            part = self.base.components_many(wi_s, wo_s, [parts[j][0] for j in rows], need=wanted, **kw)
            for name, value in part.items():
                if name not in out:
                    out[name] = np.zeros((len(tilts),) + value.shape[1:], dtype=value.dtype)
                out[name][rows] = value * factor
        return {name: out[name] for name in self.component_names if name in out}

    def _geometry_warnings(self, params: dict) -> list[str]:
        return self.base.geometry_warnings(self._split(self.resolve(params))[0])

    def _fitted_weave(self, params: dict):
        return self.base.fitted_weave(self._split(self.resolve(params))[0])

    def settings(self) -> dict:
        return {"base": {"kind": self.base.kind, **self.base.settings()}, "term": self.term}

    @classmethod
    def describe_settings(cls, settings: dict) -> str:
        return f"{cls.base_class.kind} ({cls.base_class.describe_settings(settings.get('base') or {})}) + {cls.term}"

    def with_quadrature(self, rule: str | None = None, nodes: int | None = None) -> TermModel:
        base = self.base.with_quadrature(rule, nodes)
        return self if base is self.base else type(self)(self.weave, base)

    def forget_results(self) -> None:
        self.base.forget_results()

    def forget_directions(self) -> None:
        self.base.forget_directions()


@cache
def term_class(kind: str, base_class: type, term: str) -> type:
    """The class of kind ``kind``: the registered model class ``base_class`` with ``term`` (made once)."""
    params, free, added = TERMS[term]
    meaning = {"sheen": "; sheen: scale of the fibre sheen lobe (Estevez & Kulla 2017)",
               "fresnel": "; specular coefficients at normal incidence (the Fresnel factor is 1 there)",
               "fresnel-smith": "; specular coefficients at normal incidence (the grazing factor is 1 there)",
               "fresnel-eta": "; specular coefficients at normal incidence (the Fresnel factor is 1 there)",
               "tilt": "; of the tilted sample, in its own frame (tilt: the sample normal's tilt)",
               "retro": "; retro: scale of the opposition surge B(g) / pi (Hapke 1986)"}[term]
    frame = term in FRAME_TERMS
    return type(f"Term[{kind}]", (TermModel,), {
        "__module__": __name__,
        "__doc__": f"{base_class.kind} with the {term} term ({__name__}).",
        "kind": kind,
        "base_class": base_class,
        "term": term,
        "specular_class": base_class.specular_class or base_class,
        "diffuse_class": base_class.diffuse_class or base_class,
        "params": union_table(base_class.params, params, kind),
        "component_names": tuple(base_class.component_names) + added,
        "default_free": tuple(base_class.default_free) + tuple(f for f in free if f not in base_class.default_free),
        "coefficient_meaning": base_class.coefficient_meaning + meaning,
        "orientation_period": FULL_TURN if frame else base_class.orientation_period,
        "quarter_turn_swaps": False if frame else base_class.quarter_turn_swaps,
    })
