"""The Irawan-Marschner yarn integrals over a fabric and their normalisation (Irawan & Marschner 2012,
sec. 6, eq. 2 and Algorithms 1-2): the quadrature choice, the per-yarn-type specular I_j times the phase
function, its albedo a_j (a fixed Sobol estimate, so the normalised component has unit albedo) and the
geometry checks of sec. 5.3.  Used by the reflectance model (:mod:`.model`) and the texture model
(:mod:`.texture`)."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from clothlab.errors import ConfigError, GeometryWarning
from clothlab.frames import to_yarn_frame
from clothlab.models.irawan.phase import phase_function
from clothlab.models.irawan.quadrature import Quadrature, cosine_mapped_unit_rule, interval_rule, unit_rule
from clothlab.models.irawan.yarn import staple_path, yarn_integral
from clothlab.weave.model import YARN_KINDS

PSI_FILAMENT_THRESHOLD = 1e-3  # radians
ALBEDO_SAMPLES = 2**16
ALBEDO_SEED = 20120101
COMPONENTS = ("diffuse", "specular_warp", "specular_weft")
PIECE_HEADROOM = math.radians(10.0)  # the lit pieces of the support rule are cut on umax + this (YarnTerms)
FILAMENT_ARCS = ("full", "shortened")
"""``model.options.filament_arc``: the arc a smoothed filament spine's R(u) is evaluated on (sec. 5.4, eq. 9).
``full`` (default) is the paper's text: R(u) of sec. 5.4 on the whole segment |u| <= umax, eq. 9 fading A over
the last delta umax.  ``shortened`` is the Mitsuba 0.5/0.6 ``irawan`` plugin's form, which users render
the exported ``.wv`` in: r_hat, L and t_max of sec. 5.4 on (1 - delta) umax and |u| clamped to it
(:func:`clothlab.models.irawan.kernels.spine_arc`).  The two agree for staple yarns and for delta = 0."""


def check_filament_arc(value) -> str:
    """``value`` if it is one of :data:`FILAMENT_ARCS`, else ConfigError at ``model.options.filament_arc``."""
    if value not in FILAMENT_ARCS:
        raise ConfigError(f"filament_arc must be one of {', '.join(FILAMENT_ARCS)}, got {value!r}",
                          field="model.options.filament_arc")
    return value


def arc_matters(params: dict, kind: str) -> bool:
    """Whether ``filament_arc`` changes segment type ``kind``: a filament yarn (sec. 6.2) with smoothing."""
    return abs(math.radians(params[f"{kind}.psi"])) < PSI_FILAMENT_THRESHOLD and params["delta"] > 0.0


def geometry_warnings(params: dict, fabric: str = "", filament_arc: str = "full") -> list[str]:
    """Messages for segment types whose rectangle cannot hold the segment (sec. 5.3: w sin umax < l); with
    ``filament_arc`` ``shortened`` a smoothed filament spine is checked on its arc (1 - delta) umax."""
    out = []
    for kind in YARN_KINDS:
        w, l, umax = params[f"{kind}.w"], params[f"{kind}.l"], params[f"{kind}.umax"]
        if filament_arc == "shortened" and arc_matters(params, kind):
            umax = (1.0 - params["delta"]) * umax  # the arc the renderer fits the spine to
        if w * np.sin(np.deg2rad(umax)) >= l:
            out.append(
                f"{fabric + ' ' if fabric else ''}{kind}: w sin(umax) = {w:g} * sin({umax:g} deg) = "
                f"{w * np.sin(np.deg2rad(umax)):.4g} >= l = {l:g} violates the segment-fitting constraint of "
                f"sec. 5.3; the spine radius is clamped to its limit R = 0"
            )
    return out


GEOMETRY_KEYS = ("psi", "umax", "kappa", "w", "l")


def yarn_geometry_key(params: dict, kind: str) -> tuple:
    """The parameters the yarn integral I_j depends on (not alpha, beta: f_c factors out of eq. 10)."""
    return tuple(params[f"{kind}.{k}"] for k in GEOMETRY_KEYS) + (params["delta"],)


def yarn_integral_fabric(wi, wo, params: dict, kind: str, quadrature: Quadrature,
                         filament_arc: str = "full") -> np.ndarray:
    """I_j (eq. 10 without f_c) for segment type ``kind`` at fabric-frame directions (N, 3); ``filament_arc``
    one of :data:`FILAMENT_ARCS`."""
    lw, lo = to_yarn_frame(wi, kind), to_yarn_frame(wo, kind)
    return yarn_integral(
        lw, lo,
        psi=np.deg2rad(params[f"{kind}.psi"]), umax=np.deg2rad(params[f"{kind}.umax"]),
        kappa=params[f"{kind}.kappa"], w=params[f"{kind}.w"], l=params[f"{kind}.l"],
        delta=params["delta"], rule=quadrature.rule, n=int(quadrature.nodes),
        psi_threshold=PSI_FILAMENT_THRESHOLD, shortened=check_filament_arc(filament_arc) == "shortened",
    )


def yarn_specular(wi, wo, params: dict, kind: str, quadrature: Quadrature, filament_arc: str = "full") -> np.ndarray:
    """Raw f_c I_j for segment type ``kind`` at fabric-frame directions (N, 3); params in declared units."""
    integral = yarn_integral_fabric(wi, wo, params, kind, quadrature, filament_arc)
    return phase_function(wi, wo, params["alpha"], params["beta"]) * integral


@lru_cache(maxsize=1)
def _albedo_directions(samples: int) -> tuple[np.ndarray, np.ndarray]:
    from scipy.stats import qmc

    xi = qmc.Sobol(d=4, scramble=True, rng=np.random.default_rng(ALBEDO_SEED)).random(samples)

    def cosine_hemisphere(a, b):
        r = np.sqrt(a)
        phi = 2.0 * np.pi * b
        return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(1.0 - a, 0.0))], axis=1)

    return cosine_hemisphere(xi[:, 0], xi[:, 1]), cosine_hemisphere(xi[:, 2], xi[:, 3])


def specular_albedo(params: dict, kind: str, quadrature: Quadrature, samples: int = ALBEDO_SAMPLES,
                    filament_arc: str = "full") -> float:
    """a_j = (1/pi) int int f_c I_j cos cos dwi dwo (deterministic Sobol estimate; see module docstring)."""
    arc = check_filament_arc(filament_arc) if params["delta"] > 0.0 else "full"  # delta = 0: the same R(u)
    key = (kind, quadrature, samples, arc) + tuple(
        params[k] for k in ("alpha", "beta", "delta", f"{kind}.psi", f"{kind}.umax", f"{kind}.kappa",
                            f"{kind}.w", f"{kind}.l"))
    return _specular_albedo_cached(key, samples)


@lru_cache(maxsize=256)
def _specular_albedo_cached(key, samples):
    kind, quadrature = key[0], key[1]
    names = ("alpha", "beta", "delta", f"{kind}.psi", f"{kind}.umax", f"{kind}.kappa", f"{kind}.w", f"{kind}.l")
    params = dict(zip(names, key[4:], strict=True))
    wi, wo = _albedo_directions(samples)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        # the batched path of a fit's evaluations (yarn_integrals; equal to yarn_specular's per-direction
        # quadrature to rounding): a first run compiles no kernel for the normalisation alone
        integral = yarn_integrals(yarn_terms(wi, wo, kind, quadrature),
                                  np.array([yarn_geometry_key(params, kind)]), quadrature, key[3])[0]
        values = phase_function(wi, wo, params["alpha"], params["beta"]) * integral
    # E[f] under cosine-weighted sampling of both directions times pi^2, divided by pi.
    return float(np.pi * values.mean())


# ------------------------------------------------------------------ many parameter sets at once


@dataclass(frozen=True, eq=False)
class YarnTerms:
    """What of I_j depends on the directions alone, for one segment type, each part made when first needed: the
    yarn-frame directions (:attr:`wi`, :attr:`wo`; the staple paths), the filament path's moments of
    :func:`clothlab.models.irawan.kernels.filament_moments` (:attr:`filament`; None for the ``adaptive`` rule,
    whose node count depends on the values, made from the fabric-frame directions without yarn-frame copies)
    and, per twist, the staple integrand's lit pieces (:meth:`staple_pieces`).  So a new direction set costs
    only what its parameter sets use: a staple fit computes no filament moments, a filament fit no yarn frame.
    ``fabric_wi``, ``fabric_wo`` are the caller's own (N, 3) C-contiguous float64 copies: the lazy parts are
    computed from them later, so they must not change."""

    kind: str  # the segment type (warp / weft)
    fabric_wi: np.ndarray  # (N, 3) fabric frame
    fabric_wo: np.ndarray
    quadrature: Quadrature | None = None
    #: psi (radians) -> (domain, lo, hi): the staple integrand's lit pieces on [-domain, domain]
    #: (:func:`clothlab.models.irawan.yarn.staple_pieces`, for the support / adaptive rules; they depend on the
    #: directions and psi only), the last few psi
    staple: dict = field(default_factory=dict)
    _lazy: dict = field(default_factory=dict, repr=False)
    _frame: dict = field(default_factory=dict, repr=False)

    def _yarn_frame(self) -> tuple[np.ndarray, np.ndarray]:
        if not self._frame:
            for name, w in (("wi", self.fabric_wi), ("wo", self.fabric_wo)):
                self._frame[name] = np.ascontiguousarray(to_yarn_frame(w, self.kind), dtype=np.float64)
        return self._frame["wi"], self._frame["wo"]

    @property
    def wi(self) -> np.ndarray:
        """(N, 3) yarn-frame wi (computed on first use)."""
        return self._yarn_frame()[0]

    @property
    def wo(self) -> np.ndarray:
        """(N, 3) yarn-frame wo (computed on first use)."""
        return self._yarn_frame()[1]

    def __len__(self) -> int:
        return len(self.fabric_wi)

    @property
    def filament(self) -> tuple | None:
        """(ok (N,), moments (6, N): u, inv, s0, s1, cos u, sin u), computed on first use; None for
        ``adaptive``."""
        if "filament" not in self._lazy:
            self._lazy["filament"] = _filament_moments(self.fabric_wi, self.fabric_wo, self.kind, self.quadrature)
        return self._lazy["filament"]

    def staple_pieces(self, psi: float, umax: float) -> tuple[np.ndarray, np.ndarray]:
        """The lit pieces for twist ``psi`` valid up to ``umax`` (radians): computed once per psi on umax plus
        PIECE_HEADROOM (a fit moving umax up within it reuses them), again only for a larger umax."""
        from clothlab.models.irawan.yarn import staple_pieces

        hit = self.staple.get(psi)
        if hit is None or hit[0] < umax:
            if hit is None and len(self.staple) >= 8:
                self.staple.pop(next(iter(self.staple)))
            domain = min(umax + PIECE_HEADROOM, 0.5 * math.pi)
            hit = self.staple[psi] = (domain, *staple_pieces(self.wi, self.wo, psi, domain))
        return hit[1], hit[2]


_FILAMENT_NODES: dict = {}
"""Quadrature -> (nodes (1, K), weights (1, K), on_arc) of the filament moments (made once per rule)."""


def filament_rule(quadrature: Quadrature) -> tuple | None:
    """(nodes (1, K), weights (1, K), on_arc) of the filament moments under ``quadrature``
    (:func:`clothlab.models.irawan.kernels.filament_moments`); None for ``adaptive`` (no moments)."""
    hit = _FILAMENT_NODES.get(quadrature)
    if hit is None:
        rule, n = quadrature.rule, int(quadrature.nodes)
        if rule in ("trapezoid", "gauss"):
            nodes, weights = interval_rule(rule, n, -0.5 * np.pi, 0.5 * np.pi)
            hit = (nodes[None, :], weights[None, :], False)
        elif rule == "support":
            t, wt = unit_rule("gauss", n)
            hit = (t[None, :], wt[None, :], True)
        else:
            return None
        _FILAMENT_NODES[quadrature] = hit
    return hit


def _filament_moments(wi, wo, kind: str, quadrature: Quadrature | None) -> tuple | None:
    """The filament moments of fabric-frame directions for segment type ``kind`` under ``quadrature`` (None:
    the trapezoid-11 default)."""
    from clothlab.models.irawan import kernels

    rule = filament_rule(quadrature or Quadrature())
    if rule is None:
        return None
    if kind not in YARN_KINDS:
        raise ValueError(f"yarn kind must be 'warp' or 'weft', got {kind!r}")
    return kernels.filament_moments(wi, wo, *rule, kind == "weft")


def yarn_terms(wi, wo, kind: str, quadrature: Quadrature, filament: tuple | None = None) -> YarnTerms:
    """The parameter-free part of I_j at fabric-frame directions (N, 3), each part made when first used
    (:class:`YarnTerms`); ``wi``, ``wo`` are kept as they are if C-contiguous float64 (so pass copies the
    caller will not change), else copied.  ``filament``: the filament moments of these directions under
    ``quadrature`` if already made (:attr:`YarnTerms.filament`; e.g. by
    :func:`clothlab.models.irawan.kernels.direction_set`)."""
    return YarnTerms(kind, np.ascontiguousarray(wi, dtype=np.float64), np.ascontiguousarray(wo, dtype=np.float64),
                     quadrature, _lazy={} if filament is None else {"filament": filament})


def uses_filament_moments(params: dict, kind: str, quadrature: Quadrature) -> bool:
    """Whether :func:`yarn_integrals` takes segment type ``kind``'s I_j under resolved ``params`` from the
    filament moments: the filament path (:func:`clothlab.models.irawan.yarn.staple_path`) with a rule other
    than ``adaptive``."""
    rule, n = quadrature.rule, int(quadrature.nodes)
    return rule != "adaptive" and not staple_path(math.radians(params[f"{kind}.psi"]),
                                                  math.radians(params[f"{kind}.umax"]), rule, n,
                                                  PSI_FILAMENT_THRESHOLD)


_TO_RADIANS = np.array([[math.pi / 180.0], [math.pi / 180.0], [1.0], [1.0], [1.0], [1.0]])
"""Per row of the transposed geometry of :func:`yarn_integrals`: psi and umax from degrees (np.deg2rad's factor)."""


def yarn_integrals(terms: YarnTerms, geometry: np.ndarray, quadrature: Quadrature,
                   filament_arc: str = "full") -> np.ndarray:
    """I_j (eq. 10 without f_c) for J parameter sets at once: (J, N).

    ``geometry`` (J, 6) holds each set's psi, umax (deg), kappa, w, l and delta (:func:`yarn_geometry_key`
    order).  The path per set is :func:`clothlab.models.irawan.yarn.staple_path`'s; filament sets use the
    moments (equal to :func:`yarn_integral_fabric` to rounding), staple sets under a fixed rule one compiled
    call for all of them (bit-identical), the rest :func:`clothlab.models.irawan.yarn.yarn_integral` per set.
    ``filament_arc``: one of :data:`FILAMENT_ARCS`."""
    import clothlab.models.irawan.kernels as kernels  # (numba: imported with the first evaluation)

    geometry = np.asarray(geometry, dtype=np.float64)
    if geometry.ndim == 1:
        geometry = geometry[None, :]
    cols = np.multiply(geometry.T, _TO_RADIANS, order="C")  # rows: psi, umax (radians), kappa, w, l, delta
    psi, umax, kappa, w, l, delta = cols
    rule, n = quadrature.rule, int(quadrature.nodes)
    shortened = check_filament_arc(filament_arc) == "shortened"
    staple = [staple_path(p, u, rule, n, PSI_FILAMENT_THRESHOLD) for p, u in zip(psi.tolist(), umax.tolist(),
                                                                                   strict=True)]
    fixed = rule in ("trapezoid", "gauss")
    if not any(staple) and rule != "adaptive":
        return kernels.filament_from_moments(*terms.filament, umax, kappa, w, l, delta, shortened)
    if all(staple) and fixed:
        return kernels.staple_quadrature_sets(terms.wi, terms.wo, *unit_rule(rule, n), psi, umax, kappa, w, l)
    out = np.empty((len(geometry), len(terms)))
    for j, on_staple in enumerate(staple):  # mixed paths, or a rule without a batched form
        if not on_staple and rule != "adaptive":
            out[j] = kernels.filament_from_moments(*terms.filament, *cols[[1, 2, 3, 4, 5], j:j + 1], shortened)[0]
        elif on_staple and fixed:
            out[j] = kernels.staple_quadrature_sets(terms.wi, terms.wo, *unit_rule(rule, n),
                                                    *cols[:5, j:j + 1])[0]
        elif on_staple and rule == "support":  # the lit pieces of these directions, kept per psi
            lo, hi = terms.staple_pieces(float(psi[j]), float(umax[j]))
            out[j] = kernels.staple_support_sum(terms.wi, terms.wo, lo, hi, *cosine_mapped_unit_rule(n), psi[j],
                                                umax[j], kappa[j], w[j], l[j])
        else:
            staple_rule = on_staple and rule in ("support", "adaptive")
            pieces = terms.staple_pieces(float(psi[j]), float(umax[j])) if staple_rule else None
            out[j] = yarn_integral(terms.wi, terms.wo, psi=psi[j], umax=umax[j], kappa=kappa[j], w=w[j], l=l[j],
                                   delta=delta[j], rule=rule, n=n, psi_threshold=PSI_FILAMENT_THRESHOLD,
                                   shortened=shortened, pieces=pieces)
    return out
