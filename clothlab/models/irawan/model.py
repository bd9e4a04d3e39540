"""The Irawan-Marschner reflectance model of woven cloth (Irawan & Marschner 2012, sec. 7.1 and 7.3).

Parameters (paper Table I; :data:`clothlab.models.irawan.parameters.IRAWAN_PARAMS`; "1" = dimensionless,
``cell`` = weave-tile cells; the default is the declared one, a weave brings its own values, which are the
model's defaults and a fit's start):

==========  ====  ===========  =======  ==============================================================
parameter   unit  range        default  meaning
==========  ====  ===========  =======  ==============================================================
alpha       1     [0, 100]     0.05     uniform scattering of the phase function f_c, eq. 7
beta        1     (0, 100000]  4        forward scattering of the phase function f_c, eq. 7
delta       1     [0, 1)       0.3      filament smoothing: the faded fraction of the arc, eq. 9
hwidth      1     (0, 1]       0.5      highlight band width / segment size, eq. 12 (texture model only)
warp.psi    deg   (-90, 90)    0        fibre twist angle, sec. 5.2 (0: filament yarn)
warp.umax   deg   [1e-09, 90)  30       maximum inclination angle, sec. 5.2
warp.kappa  1     (-1, 1000]   0        spine curvature, sec. 5.4
warp.w      cell  (0, 1000]    1        segment rectangle width, sec. 5.3
warp.l      cell  (0, 1000]    1        segment rectangle length, sec. 5.3
weft.psi    deg   (-90, 90)    0        as warp.psi, for the weft segments
weft.umax   deg   [1e-09, 90)  30       as warp.umax, for the weft segments
weft.kappa  1     (-1, 1000]   0        as warp.kappa, for the weft segments
weft.w      cell  (0, 1000]    1        as warp.w, for the weft segments
weft.l      cell  (0, 1000]    1        as warp.l, for the weft segments
==========  ====  ===========  =======  ==============================================================

    f_r(wi, wo) = kd / pi + sum_j ks_j S_j(wi, wo),     S_j = f_c(wi, wo) I_j(wi, wo) / a_j

for the segment types j = warp, weft.  I_j is the yarn integral of eq. 10 (:mod:`.yarn`), f_c the phase
function of eq. 7 (:mod:`.phase`).  Components, not totals: the model returns
``diffuse`` (= 1/pi, a Lambertian of unit albedo), ``specular_warp`` and ``specular_weft``; the per-channel
coefficients kd, ks_warp, ks_weft are linear and solved outside.

Normalisation (decided here; the paper absorbs all constants into k_s): a_j is the mean hemispherical
albedo of f_c I_j,  a_j = (1/pi) int int f_c I_j cos(theta_i) cos(theta_o) dwi dwo,  computed
deterministically with a fixed scrambled Sobol point set in the cosine-weighted (mu^2, phi) coordinates of
both directions (:func:`specular_albedo`).  With it, kd and ks_j are albedos: ks_j is the mean specular
albedo that segment type j adds to the fabric (its area share is part of it, so the published renderer's
warpArea/weftArea balancing is absorbed into ks_j).  ``normalised=False`` gives the raw f_c I_j, used inside
fits (the scale only rescales ks) and converted once at the end.

Decisions on what the paper leaves open:
- staple path for |psi| >= PSI_FILAMENT_THRESHOLD (1e-3 rad = 0.057 deg), filament path below; the staple
  integral tends to the filament one as psi -> 0, and the test suite measures the jump at the threshold.
- eq. 3: the +arccos(D) root only (the one with n.h >= 0), visible when |v| < pi/2.
- phase lobe evaluated at -wi.wo; Seeliger's law without the 1/(4 pi) constant (absorbed by a_j).
- filament smoothing (eq. 9): R(u) on the full arc (option ``filament_arc: full``, the paper's text: sec. 5.4
  defines R(u) on |u| <= umax and eq. 9 only fades A); the cubic smoothstep fades the last delta*umax.
  ``filament_arc: shortened`` is the form of the Mitsuba 0.5/0.6 ``irawan`` plugin the exported ``.wv`` is
  rendered in: r_hat, L and t_max of sec. 5.4 on (1 - delta) umax, |u| clamped to it
  (:data:`.integrals.FILAMENT_ARCS`).  The option is recorded in fit.json (``model.options``) and in the
  ``.wv`` export; a fit made with ``full`` on a smoothed filament yarn gets a note that the renderer shows the
  other form, and a ``.wv`` recorded with one arc loaded into a model with the other gives a GeometryWarning.
- a segment with w sin(umax) >= l (sec. 5.3) gets L = 0 (R = 0) and a GeometryWarning naming it.
"""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np

from clothlab.errors import ClothlabError, GeometryWarning
from clothlab.models.base import Model
from clothlab.models.irawan.integrals import (  # noqa: F401  (re-exported: the model's public names)
    ALBEDO_SAMPLES,
    ALBEDO_SEED,
    COMPONENTS,
    FILAMENT_ARCS,
    GEOMETRY_KEYS,
    PSI_FILAMENT_THRESHOLD,
    Quadrature,
    YarnTerms,
    _albedo_directions,
    _specular_albedo_cached,
    arc_matters,
    check_filament_arc,
    filament_rule,
    geometry_warnings,
    specular_albedo,
    uses_filament_moments,
    yarn_geometry_key,
    yarn_integral_fabric,
    yarn_integrals,
    yarn_specular,
    yarn_terms,
)
from clothlab.models.irawan.parameters import IRAWAN_PARAMS, apply_parameters, weave_parameters
from clothlab.models.irawan.phase import von_mises
from clothlab.weave.model import YARN_KINDS, Weave

_NO_RULE = (np.zeros((1, 1)), np.zeros((1, 1)), False)
"""The nodes, weights and on_arc of :func:`.kernels.direction_set` when it makes no filament moments."""


class IrawanModel(Model):
    """Irawan-Marschner reflectance model of one weave (the pure model: no I/O, no state but the weave)."""

    kind = "irawan"
    params = IRAWAN_PARAMS
    component_names = COMPONENTS
    coefficient_meaning = "kd: diffuse albedo; ks_<kind>: mean specular albedo of that segment type"
    default_free = ("warp.umax", "weft.umax", "warp.kappa", "weft.kappa", "alpha", "beta")
    has_texture = True
    #: trapezoid 41: 0.22-0.26 % relative RMS from a 65,536-point texture tile average (trapezoid 11:
    #: 0.9-1.2 %), 0.33 CPU-us per pair cold (docs/neural.md, "The tile average")
    tile_average_quadrature = ("trapezoid", 41)
    parameter_concepts = {
        "yarn inclination (IM sec. 5.2; Kang eqs. 3-4 c_y)": ("warp.umax", "weft.umax"),
        "fibre twist (IM sec. 5.2; Kang s_f)": ("warp.psi", "weft.psi"),
        "fibre scattering lobe (IM eq. 7; SGGX roughness and height scale; Kang eq. 2 exponents)": ("alpha", "beta"),
        "spine curvature (IM sec. 5.4)": ("warp.kappa", "weft.kappa"),
        "filament smoothing (IM eq. 9)": ("delta",),
        "highlight band width (IM eq. 12)": ("hwidth",),
        "segment rectangle (IM sec. 5.3)": ("warp.w", "warp.l", "weft.w", "weft.l"),
    }

    @classmethod
    def from_config(cls, weave: Weave, quadrature=None, **options) -> IrawanModel:
        """Option ``filament_arc``: ``full`` (default, the paper's text) or ``shortened`` (the renderer's); the
        registry checks the options (:func:`clothlab.models.registry.build_model`)."""
        q = quadrature if quadrature is None or isinstance(quadrature, Quadrature) else Quadrature(*quadrature)
        return cls(weave, q, **options)

    @classmethod
    def check_option(cls, name: str, value) -> None:
        """ConfigError for a ``model.options`` value the model cannot take (config validation names the line)."""
        if name == "filament_arc":
            check_filament_arc(value)

    def _geometry_warnings(self, params: dict) -> list[str]:
        """The segment-fitting notes of sec. 5.3 and, for a fit with ``filament_arc: full`` on a smoothed
        filament yarn, that the exported ``.wv`` is rendered with the other arc."""
        p = self.resolve(params)
        notes = geometry_warnings(p, self.weave.name, self.filament_arc)
        kinds = [kind for kind in YARN_KINDS if arc_matters(p, kind)]
        if self.filament_arc == "full" and kinds:
            notes.append(f"{self.weave.name} {'/'.join(kinds)}: fitted with filament_arc: full (the paper's text, "
                         f"R(u) on the whole arc); the exported weave.wv is rendered by the Mitsuba 0.5/0.6 irawan "
                         f"plugin on the shortened arc (1 - delta) umax (delta = {p['delta']:g}), which changes the "
                         "highlight's shape; fit with model.options.filament_arc: shortened for renderer parity")
        return notes

    def _fitted_weave(self, params: dict) -> Weave:
        """The weave with ``params`` applied, recording this model's ``filament_arc`` for the ``.wv`` export."""
        return replace(apply_parameters(self.weave, self.resolve(params)), filament_arc=self.filament_arc)

    def settings(self) -> dict:
        return {"quadrature": self.quadrature.record(), "options": {"filament_arc": self.filament_arc}}

    @classmethod
    def describe_settings(cls, settings: dict) -> str:
        """The quadrature as ``rule nodes`` (e.g. ``trapezoid 11``), then ``filament_arc=shortened`` if so."""
        quadrature = settings.get("quadrature") or {}
        text = " ".join(str(quadrature[k]) for k in ("rule", "nodes") if k in quadrature) or "defaults"
        arc = (settings.get("options") or {}).get("filament_arc", "full")
        return text if arc == "full" else f"{text}, filament_arc={arc}"

    def with_quadrature(self, rule: str | None = None, nodes: int | None = None) -> IrawanModel:
        if rule is None and nodes is None:
            return self
        return IrawanModel(self.weave, Quadrature(rule or self.quadrature.rule,
                                                  int(nodes) if nodes is not None else self.quadrature.nodes),
                           filament_arc=self.filament_arc)

    def texture(self, *, seed: int = 0):
        """The texture model of sec. 7.2 (:class:`clothlab.models.irawan.texture.IrawanTexture`) with this
        model's quadrature and filament arc (so its tile average is :meth:`components`)."""
        from clothlab.models.irawan.texture import IrawanTexture

        return IrawanTexture(self.weave, self.quadrature, seed=seed, filament_arc=self.filament_arc)

    def __init__(self, weave: Weave, quadrature: Quadrature | None = None, *, filament_arc: str = "full"):
        self.weave = weave
        self.quadrature = quadrature or Quadrature()
        self.filament_arc = check_filament_arc(filament_arc)
        recorded = getattr(weave, "filament_arc", None)
        if recorded not in (None, self.filament_arc):
            kinds = [kind for kind in YARN_KINDS if arc_matters(weave_parameters(weave), kind)]
            if kinds:
                warnings.warn(f"{weave.source or weave.name}: the weave was fitted with filament_arc: {recorded} but "
                              f"this model evaluates filament_arc: {self.filament_arc}; the {'/'.join(kinds)} "
                              "highlight's shape differs (set model.options.filament_arc to match)",
                              GeometryWarning, stacklevel=2)
        self._memo: dict = {}  # (kind, geometry key) -> I_j at the directions of self._at; see _integrals
        self._directions: dict | None = None  # the parameter-free quantities of the last directions; see _at

    def forget_results(self) -> None:
        """Drop the memoised yarn integrals I_j at the current directions (:meth:`_integrals`)."""
        self._memo.clear()

    def forget_directions(self) -> None:
        """Drop the memo of the last directions (:meth:`_at`)."""
        self._directions = None
        self._memo.clear()

    def _at(self, wi, wo, resolved=(), need=COMPONENTS) -> dict:
        """What does not depend on the parameters at (wi, wo): -wi.wo (eq. 7), the front-facing mask and, per
        segment type, :class:`.integrals.YarnTerms` (made when first needed); kept for the last direction set.
        It is used only if the directions' *contents* equal the copies it keeps (not their identity), so
        directions changed in place, or new arrays at a reused address, never return stale values (nor a
        stale memo).  A new set's filament moments are made in the same compiled call for the segment types
        in ``need`` that the first of ``resolved`` (the call's parameter sets) takes on the filament path
        (:func:`.integrals.uses_filament_moments`); the others' when first needed."""
        import clothlab.models.irawan.kernels as kernels  # (numba: imported with the first evaluation)

        d = self._directions
        if d is not None and kernels.same_pairs(d["wi"], d["wo"], wi, wo):  # one compiled pass
            return d
        self._memo.clear()
        first = resolved[0] if resolved else None  # (a batch's sets share their paths, as a rule)
        warp = first is not None and "specular_warp" in need and uses_filament_moments(first, "warp",
                                                                                        self.quadrature)
        weft = first is not None and "specular_weft" in need and uses_filament_moments(first, "weft",
                                                                                        self.quadrature)
        rule = filament_rule(self.quadrature) if warp or weft else None
        if rule is None:
            warp = weft = False
        cos_x, front, kept, ok, moments = kernels.direction_set(wi, wo, *(rule or _NO_RULE), warp, weft)
        filament = {}
        if warp:
            filament["warp"] = (ok[0], moments[0])
        if weft:
            filament["weft"] = (ok[1], moments[1])
        self._directions = {"wi": kept[0], "wo": kept[1], "cos_x": cos_x, "front": front, "terms": {},
                            "filament": filament}
        return self._directions

    def _yarn_terms(self, wi, wo, kind, at: dict | None = None) -> YarnTerms:
        """The parameter-free part of I_j at (wi, wo) (:meth:`_at`; ``at``: its result for these directions,
        if already looked up in this call)."""
        at = self._at(wi, wo) if at is None else at
        terms = at["terms"]
        if kind not in terms:  # from the kept copies: the terms' lazy parts are computed later
            terms[kind] = yarn_terms(at["wi"], at["wo"], kind, self.quadrature, at["filament"].get(kind))
        return terms[kind]

    def _integrals(self, wi, wo, resolved: list[dict], kind, at: dict | None = None) -> np.ndarray:
        """I_j (J, N) for J resolved parameter sets.  One set's I_j is remembered (the last few geometries at
        these directions), so a fit varying only alpha / beta computes it once; batches are not memoised."""
        terms = self._yarn_terms(wi, wo, kind, at)
        if len(resolved) != 1:
            return yarn_integrals(terms, np.array([yarn_geometry_key(p, kind) for p in resolved]), self.quadrature,
                                  self.filament_arc)
        key = (kind, yarn_geometry_key(resolved[0], kind))
        hit = self._memo.get(key)
        if hit is None:
            hit = yarn_integrals(terms, np.array([key[1]]), self.quadrature, self.filament_arc)[0]
            if len(self._memo) >= 8:
                self._memo.pop(next(iter(self._memo)))
            self._memo[key] = hit
        return hit[None, :]

    def _default_parameters(self) -> dict[str, float]:
        if getattr(self, "_defaults", None) is None or self._defaults[0] is not self.weave:
            self._defaults = (self.weave, weave_parameters(self.weave))
        return dict(self._defaults[1])

    def _resolve_many(self, params_list) -> list[dict]:
        """:meth:`resolve` of each dict; when all name the same parameters, each parameter's range is checked
        once on the smallest and largest value (the ranges are intervals), else dict by dict."""
        keys = list(params_list[0] or {}) if params_list else []
        try:
            if len(params_list) < 2 or any(list(p or {}) != keys for p in params_list):
                raise ValueError
            values = np.array([[p[k] for k in keys] for p in params_list], dtype=np.float64)
            for name, column in zip(keys, values.T, strict=True):
                self.params[name].check(column.min())
                self.params[name].check(column.max())
        except (ValueError, TypeError, ClothlabError):
            return [self.resolve(p) for p in params_list]
        defaults = self.default_parameters()
        return [{**defaults, **dict(zip(keys, row, strict=True))} for row in values.tolist()]

    def with_parameters(self, params: dict) -> Weave:
        return apply_parameters(self.weave, self.resolve(params))

    def _components(self, wi, wo, params: dict | None = None, *, need=None, normalised: bool = True,
                    warn: bool = True) -> dict[str, np.ndarray]:
        """BRDF components (1/sr) at fabric-frame directions wi, wo (N, 3).

        ``need``: the component names wanted (others are not computed).
        Back-facing pairs (wi_z <= 0 or wo_z <= 0) give 0 (reflection only).
        """
        many = self.components_many(wi, wo, [params], need=need, normalised=normalised, warn=warn)
        return {name: value[0] for name, value in many.items()}

    def _components_many(self, wi, wo, params_list, *, need=None, normalised: bool = True,
                         warn: bool = True) -> dict[str, np.ndarray]:
        """:meth:`components` for J parameter sets at once: each component (J, N).

        The parameter-free parts (yarn frames, the filament moments, -wi.wo) are computed once for all sets,
        the staple sums of all sets in one compiled call (:func:`.integrals.yarn_integrals`)."""
        resolved = self._resolve_many(params_list)
        wi = np.atleast_2d(np.ascontiguousarray(wi, dtype=np.float64))
        wo = np.atleast_2d(np.ascontiguousarray(wo, dtype=np.float64))
        need = COMPONENTS if need is None else tuple(need)
        if warn:
            for p in resolved:
                for message in geometry_warnings(p, self.weave.name, self.filament_arc):
                    warnings.warn(message, GeometryWarning, stacklevel=3)
        out = {}
        at = self._at(wi, wo, resolved, need)
        if "diffuse" in need:
            out["diffuse"] = np.repeat(np.where(at["front"], 1.0 / np.pi, 0.0)[None, :], len(resolved), axis=0)
        phase = None
        for kind in YARN_KINDS:
            name = f"specular_{kind}"
            if name not in need:
                continue
            if phase is None:  # eq. 7, as phase_function computes it, for every set
                alpha = np.array([p["alpha"] for p in resolved])[:, None]
                beta = np.array([p["beta"] for p in resolved])[:, None]
                phase = alpha + von_mises(at["cos_x"][None, :], beta)
            value = phase * self._integrals(wi, wo, resolved, kind, at)  # the directions compared once
            if normalised:
                for j, p in enumerate(resolved):
                    albedo = specular_albedo(p, kind, self.quadrature, filament_arc=self.filament_arc)
                    if albedo > 0.0:
                        value[j] = value[j] / albedo
                    else:  # e.g. a filament with umax -> 0: the highlight has no extent; say so, never a silent 0
                        value[j] = 0.0
                        if warn:
                            warnings.warn(f"{self.weave.name} {kind}: the specular albedo is 0 (umax = "
                                          f"{p[f'{kind}.umax']:g} deg, psi = {p[f'{kind}.psi']:g} deg), so the "
                                          f"normalised specular_{kind} is 0 everywhere", GeometryWarning,
                                          stacklevel=3)
            out[name] = value
        return out
