"""The Kang fabric shader as a clothlab model ("Real-time level-of-detail fabric rendering", secs. 3-4,
extending Kang 2010): Ashikhmin-Shirley BRDF per yarn type with alternating anisotropy, yarn normal
perturbation with ambient occlusion, per-yarn noise, the eq. 5 LoD blend and Algorithm 1.

Parameters (:mod:`clothlab.models.kang.parameters`; "1" = dimensionless; ``weft.nx`` / ``weft.ny`` only with
the option ``alternating: false``, otherwise they are the warp's, sec. 3.3):

===============  ======  ==========  =======  ===========================================================
parameter        unit    range       default  meaning
===============  ======  ==========  =======  ===========================================================
warp.nx          1       [0, 10000]  1        microfacet exponent across the yarn (eq. 2, x)
warp.ny          1       [0, 10000]  30       microfacet exponent along the yarn (eq. 2, y)
weft.nx          1       [0, 10000]  1        weft exponent across the yarn (eq. 2, x; not alternating)
weft.ny          1       [0, 10000]  30       weft exponent along the yarn (eq. 2, y; not alternating)
n_strands        1/cell  [1, 1000]   6        fibre strands N_xi: fibre ridges per cell along the yarn
fibre_curvature  1       [0, 0.7]    0.3      c_f: amplitude of the along-yarn normal tilt (eqs. 3-4)
yarn_curvature   1       [0, 0.7]    0.5      c_y: across-yarn normal tilt at the yarn edge (eqs. 3-4)
fibre_slope      1       [-10, 10]   0.5      s_f: shear of the fibre ridges (eqs. 3-4)
fresnel_f0       1       [0, 1]      0.04     Schlick Fresnel reflectance at normal incidence (eq. 1)
noise            1       [0, 1]      0.1      per-yarn intensity noise amplitude (sec. 5.2), mean 1
===============  ======  ==========  =======  ===========================================================

Point components (1/sr, :meth:`KangModel.point_components`, for textures and renders), per yarn type k in
(warp, weft): ``diffuse_k`` = Lambert 1/pi on the points of type k, ``specular_k`` = eq. 1 with the eq. 2
distribution about the perturbed normal, times the ambient occlusion (sec. 4.2.2 applies the AO to the
anisotropic reflection only), both times the per-yarn noise; plus ``diffuse`` = diffuse_warp + diffuse_weft
(so a fit's single kd renders).  The per-yarn diffuse and specular colours (sec. 4.2.1; denim: blue weft,
white warp) are the linear coefficients (kd_warp, kd_weft, ks_warp, ks_weft; or kd, ks_warp, ks_weft).

Tile average (:meth:`KangModel.components`, for BRDF tables): ``diffuse`` (1/pi) and ``specular_k``.  The
per-yarn diffuse terms average to share_k / pi, constants proportional over all directions, so a table
cannot separate kd_warp from kd_weft and only one diffuse component is offered; its coefficient kd is the
cell-share-weighted mean of the per-yarn diffuse colours.  Within yarn type k the point BRDF depends on the
position only through the perturbation (delta_across, delta_along) of eqs. 3-4; over a yarn, sigma is
uniform in [-1, 1] and the sawtooth phase uniform in [0, 1), so delta_across is uniform in [-c_y, c_y] and
delta_along uniform in [-c_f, c_f] (exact when a yarn's visible part spans its width and a whole number of
fibre ridges).  The specular average is therefore share_k * E[ao * rho(n_p(delta))], with share_k the
pattern's cell share of k and E a quadrature over the perturbation rectangle: ``tile_rule='peak'``
(default) the compiled peak-centred rule of :mod:`clothlab.models.kang.kernels` (eq. 1's Fresnel and
denominator times the average of the eq. 2 lobe, a function of the half vector alone; at most
``tile_nodes`` per axis piece; ``components()`` keeps the direction set's parameter-free terms and evaluates
the lobe average once per group of equal |h|, :meth:`KangModel._at`), ``'legendre'`` the previous tensor
Gauss-Legendre rule (``tile_nodes`` per axis, None: :func:`nodes_for_axis`).  The per-yarn noise has
mean 1 over yarns and drops out.  Its accuracy is measured by the test suite against a fine grid over the tile.
"""

from __future__ import annotations

from functools import cache

import numpy as np

from clothlab.errors import ConfigError
from clothlab.frames import to_yarn_frame
from clothlab.models.base import Model, as_directions, front_facing, with_orientation
from clothlab.models.kang import lod, microfacet, yarn
from clothlab.models.kang.parameters import KANG_ALTERNATING_PARAMS, KANG_PARAMS, default_parameters, resolve_parameters
from clothlab.weave.lookup import locate_segments
from clothlab.weave.model import YARN_KINDS, Weave

WEAVE_LEVELS = ("prefiltered", "flat")
TILE_RULES = ("peak", "legendre")
#: most nodes per perturbation axis (per piece of a split axis) of the ``peak`` rule when ``tile_nodes`` is None
#: (docs/kang.md).
PEAK_NODES = 10
#: largest ``tile_nodes`` (per axis; the most :func:`nodes_for_axis` chooses itself): the legendre rule holds
#: tile_nodes^2 perturbed normals per direction pair, 256^2 x 3 floats = 1.5 MiB per pair
MAX_TILE_NODES = 256
#: largest ``prefilter_max_samples`` (Algorithm 1's samples per point; default 64)
MAX_PREFILTER_SAMPLES = 4096
#: largest ``seed`` (a 63-bit integer)
MAX_SEED = 2**63 - 1


class KangModel(Model):
    """Kang's procedural fabric shader behind the clothlab model interface.

    Options: ``alternating`` (default True, the paper's model): the weft lobe is the warp lobe rotated by
    90 deg (sec. 3.3), so only ``warp.nx`` / ``warp.ny`` are parameters; False declares independent
    ``weft.nx`` / ``weft.ny`` (a generalisation of Kang); ``tile_rule`` (``'peak'``, default, or
    ``'legendre'``: the rule of the tile average and the prefiltered weave level, module docstring);
    ``tile_nodes`` (peak: the most nodes per axis, None = :data:`PEAK_NODES`; legendre: Gauss-Legendre
    nodes per perturbation axis, None chooses per axis from the lobe width, see :func:`nodes_for_axis`);
    ``weave_level``: the far (alpha = 1) level of eq. 5,
    ``'prefiltered'`` (default: the yarn level averaged over the yarn, so the far view equals the tile
    average) or ``'flat'`` (the paper's literal choice: the unperturbed normal, no ambient occlusion);
    ``prefilter_min_samples`` / ``prefilter_max_samples`` / ``seed`` for Algorithm 1.
    """

    kind = "kang"
    params = KANG_PARAMS  # the class-level declarations (all options); an instance narrows them
    has_texture = True
    parameter_concepts = {
        "yarn inclination (IM sec. 5.2; Kang eqs. 3-4 c_y)": ("yarn_curvature",),
        "fibre twist (IM sec. 5.2; Kang s_f)": ("fibre_slope",),
        "fibre scattering lobe (IM eq. 7; SGGX roughness and height scale; Kang eq. 2 exponents)":
            ("warp.nx", "warp.ny", "weft.nx", "weft.ny"),
        "Kang fibre structure (eqs. 1-4)": ("fibre_curvature", "n_strands", "fresnel_f0", "noise"),
    }
    #: by role: the exponents n_x across / n_y along the yarn shape its highlight as IM's alpha / beta do
    im_counterparts = {"warp.umax": ("yarn_curvature",), "weft.umax": ("yarn_curvature",),
                       "warp.psi": ("fibre_slope",), "weft.psi": ("fibre_slope",), "alpha": ("warp.nx", "weft.nx"),
                       "beta": ("warp.ny", "weft.ny")}
    texture_filters = True  # the point shader takes the pixel footprint (eq. 5, Algorithm 1)
    #: tile-averaged components (components(), what a fit solves coefficients for)
    component_names = ("diffuse", "specular_warp", "specular_weft")
    #: point components (point_components(), for textures and renders)
    point_component_names = ("diffuse", "diffuse_warp", "diffuse_weft", "specular_warp", "specular_weft")
    coefficient_meaning = (
        "kd: diffuse albedo (Lambert), the cell-share-weighted mean of the per-yarn diffuse colours, which a "
        "BRDF table cannot separate; ks_<kind>: specular colour of that yarn type, multiplying its ambient-"
        "occluded eq. 1 lobe (Ashikhmin-Shirley, Schlick F with fresnel_f0) at its points - not an albedo: "
        "the yarn's specular albedo is ks_<kind> times the lobe's white-furnace albedo (<= 1)")

    def __init__(self, weave: Weave, *, alternating: bool = True, tile_rule: str = "peak",
                 tile_nodes: int | None = None, weave_level: str = "prefiltered", prefilter_min_samples: int = 5,
                 prefilter_max_samples: int = 64, seed: int = 0):
        for name, value in (("alternating", alternating), ("tile_rule", tile_rule), ("tile_nodes", tile_nodes),
                            ("weave_level", weave_level), ("prefilter_min_samples", prefilter_min_samples),
                            ("prefilter_max_samples", prefilter_max_samples), ("seed", seed)):
            self.check_option(name, value)
        self.check_options({"prefilter_min_samples": prefilter_min_samples,
                            "prefilter_max_samples": prefilter_max_samples})
        self.weave = weave
        self.alternating = bool(alternating)
        # an instance narrowing its declarations declares the orientation too (clothlab.models.base)
        self.params = with_orientation(KANG_ALTERNATING_PARAMS if self.alternating else KANG_PARAMS,
                                       self.orientation_period)
        self.tile_rule = tile_rule
        self.tile_nodes = None if tile_nodes is None else int(tile_nodes)
        self.weave_level = weave_level
        self.prefilter_min_samples = int(prefilter_min_samples)
        self.prefilter_max_samples = int(prefilter_max_samples)
        self.seed = seed
        self.shares = {kind: weave.cell_share(kind) for kind in YARN_KINDS}
        self._segment_is_weft = np.array([s.kind == "weft" for s in weave.segments])
        self._directions: dict | None = None  # the parameter-free quantities of the last directions; see _at

    @classmethod
    def check_option(cls, name: str, value) -> None:
        """ConfigError at ``model.options.<name>`` for a value the model cannot take (config validation names
        the yaml line): ``tile_nodes`` None or 1 to :data:`MAX_TILE_NODES`, sample counts 1 to
        :data:`MAX_PREFILTER_SAMPLES`, ``seed`` 0 to :data:`MAX_SEED`, the named choices."""
        field = f"model.options.{name}"

        def integer(lo, hi):
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or not lo <= value <= hi:
                raise ConfigError(f"{name} must be an integer from {lo} to {hi}, got {value!r}", field=field)

        if name == "alternating" and not isinstance(value, bool | np.bool_):
            raise ConfigError(f"alternating must be true or false, got {value!r}", field=field)
        if name == "tile_nodes" and value is not None:
            integer(1, MAX_TILE_NODES)
        if name in ("prefilter_min_samples", "prefilter_max_samples"):
            integer(1, MAX_PREFILTER_SAMPLES)
        if name == "seed":
            integer(0, MAX_SEED)
        if name == "tile_rule" and value not in TILE_RULES:
            raise ConfigError(f"tile_rule must be one of {TILE_RULES}, got {value!r}", field=field)
        if name == "weave_level" and value not in WEAVE_LEVELS:
            raise ConfigError(f"weave_level must be one of {WEAVE_LEVELS}, got {value!r}", field=field)

    @classmethod
    def check_options(cls, options: dict) -> None:
        """ConfigError for options that do not go together (each checked by :meth:`check_option`):
        ``prefilter_min_samples`` < ``prefilter_max_samples`` (the defaults 5 and 64 where not given)."""
        low, high = options.get("prefilter_min_samples", 5), options.get("prefilter_max_samples", 64)
        if not low < high:
            name = "prefilter_max_samples" if "prefilter_max_samples" in options else "prefilter_min_samples"
            raise ConfigError(f"need 1 <= prefilter_min_samples < prefilter_max_samples, got {low!r}, {high!r}",
                              field=f"model.options.{name}")

    # --- one yarn type, yarn frame -------------------------------------------------------------------

    def _exponents(self, kind, p):
        """(nx, ny) of yarn type ``kind`` in its yarn frame; the warp's for both types when alternating."""
        source = "warp" if self.alternating else kind
        return p[f"{source}.nx"], p[f"{source}.ny"]

    @staticmethod
    def _specular_about(wi_l, wo_l, normal, nx, ny, f0):
        """Eq. 1 with the eq. 2 lobe about ``normal`` (yarn frame; nx across, ny along the yarn)."""
        h = microfacet.half_vector(wi_l, wo_l)
        pdf = microfacet.half_vector_pdf(h, nx, ny, normal, yarn.tangent_of(normal))
        return microfacet.ashikhmin_shirley(wi_l, wo_l, pdf, f0)

    def _yarn_average(self, kind, wi_l, wo_l, p):
        """E[ao rho] (N,) over the perturbation rectangle of eqs. 3-4 (rule ``tile_rule``)."""
        if self.tile_rule == "peak":
            return self._peak_average(kind, wi_l, wo_l, p)
        return self._legendre_average(kind, wi_l, wo_l, p)

    def _peak_average(self, kind, wi_l, wo_l, p):
        """E[ao rho] = G(wi, wo) A(h): eq. 1's Fresnel and denominator (macro normal) times the compiled
        peak-centred average of the eq. 2 lobe over the perturbed normals (:mod:`.kernels`); no direction cache
        (the LoD render's weave level, a new point set every call)."""
        from clothlab.models.kang import kernels

        nx, ny = self._exponents(kind, p)
        most = PEAK_NODES if self.tile_nodes is None else self.tile_nodes
        x_gl, w_gl = _gauss_legendre_table(most)
        h = np.ascontiguousarray(microfacet.half_vector(wi_l, wo_l).reshape(-1, 3))
        g = microfacet.ashikhmin_shirley(wi_l, wo_l, 1.0, p["fresnel_f0"])  # eq. 1 with p(h) = 1
        a = kernels.peak_tile_average(h, float(nx), float(ny), float(p["yarn_curvature"]),
                                      float(p["fibre_curvature"]), x_gl, w_gl, most)
        return g * a.reshape(g.shape)

    def forget_directions(self) -> None:
        """Drop the memo of the last directions (:meth:`_at`)."""
        self._directions = None

    def _at(self, wi, wo) -> dict:
        """What the peak rule's tile average needs that does not depend on the parameters, for the last direction
        set (a fit evaluates the same directions every time): per yarn type the yarn-frame half vectors and
        eq. 1's Fresnel-free factors (1 - k.h)^5 and 1 / (4 (k.h) max(k1.n, k2.n)) (0 where not lit), and groups
        of equal half vectors (:func:`_half_vector_groups`, made when first needed).  Used only if the
        directions' *contents* equal the copies kept (not their identity), as ``IrawanModel._at``."""
        d = self._directions
        if d is not None and d["wi"].shape == wi.shape and np.array_equal(d["wi"], wi) and \
                np.array_equal(d["wo"], wo):
            return d
        from clothlab.models.kang import kernels

        d = {"wi": wi.copy(), "wo": wo.copy(), "h": {}, "m5": {}, "inv_denom": {}, "groups": {}}
        # one compiled pass (kernels.direction_terms): A depends on (|h_x|, |h_y|, h_z) only, the weft frame
        # swaps |h_x| and |h_y|, and eq. 1's factors do not change under that rotation
        h, m5, inv_denom = kernels.direction_terms(np.ascontiguousarray(wi, dtype=np.float64),
                                                   np.ascontiguousarray(wo, dtype=np.float64))
        d["h"] = h  # the warp's; the weft's has x and y swapped (made only inside the grouping, _half_vector_groups)
        d["m5"] = {"warp": m5, "weft": m5}
        d["inv_denom"] = {"warp": inv_denom, "weft": inv_denom}
        self._directions = d
        return d

    def _peak_averages(self, kinds, wi, wo, p) -> dict:
        """{kind: E[ao rho] (N,)} for yarn types ``kinds`` at fabric-frame directions (the cached path of
        :meth:`components`): A evaluated once per group of equal half vectors - shared by the two yarn types
        when their lobes are the same (alternating) - times G = F / (4 (k.h) max(k1.n, k2.n)) (eq. 1)."""
        from clothlab.models.kang import kernels

        d = self._at(wi, wo)
        most = PEAK_NODES if self.tile_nodes is None else self.tile_nodes
        x_gl, w_gl = _gauss_legendre_table(most)
        lobes = {kind: self._exponents(kind, p) for kind in kinds}
        sets = [tuple(kinds)] if len(set(lobes.values())) == 1 else [(kind,) for kind in kinds]
        f0 = p["fresnel_f0"]
        out = {}
        for group_kinds in sets:
            if group_kinds not in d["groups"]:
                d["groups"][group_kinds] = _half_vector_groups(d["h"], [k == "weft" for k in group_kinds])
            representatives, inverse = d["groups"][group_kinds]
            nx, ny = lobes[group_kinds[0]]
            a = kernels.peak_tile_average(representatives, float(nx), float(ny), float(p["yarn_curvature"]),
                                          float(p["fibre_curvature"]), x_gl, w_gl, most)[inverse]
            n = len(wi)
            for j, kind in enumerate(group_kinds):
                g = (f0 + (1.0 - f0) * d["m5"][kind]) * d["inv_denom"][kind]  # eq. 1 with p(h) = 1 (Schlick F)
                out[kind] = g * a[j * n:(j + 1) * n]
        return out

    def _legendre_average(self, kind, wi_l, wo_l, p):
        """E[ao rho] (N,) with a tensor Gauss-Legendre rule over the whole rectangle (the previous rule)."""
        nx, ny = self._exponents(kind, p)
        if self.tile_nodes is not None:
            q_across = q_along = self.tile_nodes
        else:
            q_across = nodes_for_axis(p["yarn_curvature"], nx)
            q_along = nodes_for_axis(p["fibre_curvature"], ny)
        x_across, w_across = _gauss_legendre(q_across)
        x_along, w_along = _gauss_legendre(q_along)
        d_across, d_along = np.meshgrid(p["yarn_curvature"] * x_across, p["fibre_curvature"] * x_along,
                                        indexing="ij")
        normal = yarn.perturbed_normal(d_across.ravel(), d_along.ravel())  # (Q, 3)
        ao = yarn.ambient_occlusion(normal)
        rho = self._specular_about(wi_l[:, None, :], wo_l[:, None, :], normal[None], nx, ny, p["fresnel_f0"])
        return rho @ (np.outer(w_across, w_along).ravel() * ao)

    def _weave_level(self, kind, wi_l, wo_l, p):
        """The alpha = 1 level of eq. 5: the specular of yarn type ``kind``."""
        if self.weave_level == "prefiltered":
            return self._yarn_average(kind, wi_l, wo_l, p)
        flat = np.broadcast_to(np.array([0.0, 0.0, 1.0]), wi_l.shape)
        return self._specular_about(wi_l, wo_l, flat, *self._exponents(kind, p), p["fresnel_f0"])

    # --- the interface ---------------------------------------------------------------------------------

    def texture(self, *, seed: int = 0):
        """The point shader as a texture model (:class:`clothlab.models.kang.texture.KangTexture`); the
        per-yarn noise is a hash of the yarn, so ``seed`` (the interface's) selects nothing here: Algorithm 1's
        jitter uses the model option ``seed``."""
        from clothlab.models.kang.texture import KangTexture

        return KangTexture(self)

    def _default_parameters(self) -> dict[str, float]:
        return default_parameters(self.params)

    def _resolve(self, params: dict | None) -> dict[str, float]:
        """Defaults overridden by ``params``, validated against ``self.params`` (the fit-facing interface;
        when alternating, ``weft.nx`` / ``weft.ny`` raise a ParameterError saying they are tied)."""
        return resolve_parameters(params, self.params)

    def _components(self, wi, wo, params: dict | None = None, *, need=None, normalised: bool = True,
                    warn: bool = True) -> dict[str, np.ndarray]:
        """Tile-averaged components (1/sr) at (N, 3) fabric-frame directions; zero below the horizon.

        ``diffuse`` (Lambert 1/pi) and ``specular_warp`` / ``specular_weft`` (module docstring).  ``need``
        limits the components computed; ``normalised`` and ``warn`` exist for interface parity with the IM
        model (Kang's components are already in albedo units and raise no geometry warnings)."""
        p = self.resolve(params)
        wi, wo = as_directions(wi, wo)
        visible = front_facing(wi, wo)
        need = self.component_names if need is None else tuple(need)
        out = {name: np.zeros(len(wi)) for name in self.component_names if name in need}
        if "diffuse" in need:
            out["diffuse"] = np.where(visible, 1.0 / np.pi, 0.0)
        kinds = [kind for kind in YARN_KINDS if self.shares[kind] > 0.0 and f"specular_{kind}" in need]
        # (a yarn type with no visible area is skipped: nothing runs that the fit does not need)
        if self.tile_rule == "peak" and kinds:
            for kind, value in self._peak_averages(kinds, wi, wo, p).items():
                out[f"specular_{kind}"] = self.shares[kind] * value
            return out
        for kind in kinds:
            out[f"specular_{kind}"] = self.shares[kind] * self._yarn_average(kind, to_yarn_frame(wi, kind),
                                                                              to_yarn_frame(wo, kind), p)
        return out

    def point_components(self, u, v, wi, wo, params: dict, footprint=None, *,
                         view_distance=None) -> dict[str, np.ndarray]:
        """Components (1/sr) at texture points (u, v) (tile units) for (N, 3) direction pairs.

        Keys :attr:`point_component_names`: per-yarn ``diffuse_warp`` / ``diffuse_weft`` (for per-yarn
        colours kd_warp, kd_weft) and their sum ``diffuse`` (for a fit's single kd): give coefficients for
        one or the other, not both (a renderer combining all keys would count the diffuse twice).
        ``footprint`` (scalar or (N,), tile units): the pixel's texture-space extent, giving the eq. 5
        blend (None: full yarn detail, alpha = 0).  ``view_distance`` (scalar or (N,)): when given
        (with a footprint), Algorithm 1 averages jittered evaluations over the footprint, stopping when
        the running mean changes by less than 1 / view_distance.
        """
        p = self.resolve(params)
        wi, wo = as_directions(wi, wo)
        u, v = (np.broadcast_to(np.asarray(c, dtype=np.float64), (len(wi),)).copy() for c in (u, v))
        if footprint is not None:
            footprint = np.broadcast_to(np.asarray(footprint, dtype=np.float64), (len(wi),))
            if not np.all(np.isfinite(footprint) & (footprint >= 0.0)):
                raise ConfigError("footprint must be finite and >= 0 (tile units)", field="footprint")
        if view_distance is None:
            return self._point(u, v, wi, wo, p, footprint)
        if footprint is None:
            raise ConfigError("Algorithm 1 (view_distance) needs a footprint", field="footprint")
        view_distance = np.broadcast_to(np.asarray(view_distance, dtype=np.float64), (len(wi),))
        if not np.all(np.isfinite(view_distance) & (view_distance > 0.0)):
            raise ConfigError("view_distance must be finite and > 0", field="view_distance")

        names = self.point_component_names[1:]  # the four independent ones (diffuse is their sum)

        def evaluate(index, uu, vv):
            comps = self._point(uu, vv, wi[index], wo[index], p, footprint[index])
            return np.stack([comps[name] for name in names], axis=-1)

        mean, _ = lod.adaptive_prefilter(evaluate, u, v, footprint, view_distance,
                                         rng=np.random.default_rng(self.seed),
                                         min_samples=self.prefilter_min_samples,
                                         max_samples=self.prefilter_max_samples)
        out = {name: mean[:, k] for k, name in enumerate(names)}
        return {"diffuse": out["diffuse_warp"] + out["diffuse_weft"], **out}

    def _point(self, u, v, wi, wo, p, footprint):
        """Point evaluation with the eq. 5 blend (no prefilter)."""
        segment, x_across, y_along = locate_segments(self.weave, u, v)
        visible = (wi[:, 2] > 0.0) & (wo[:, 2] > 0.0)
        if footprint is None:
            alpha = np.zeros(len(wi))
        else:
            cells = footprint * max(self.weave.tile_width, self.weave.tile_height)
            alpha = lod.lod_alpha(cells, p["n_strands"])
        noise = yarn.yarn_noise(np.floor(u), np.floor(v), segment, p["noise"])
        out = {name: np.zeros(len(wi)) for name in self.point_component_names}
        for kind in YARN_KINDS:
            m = self._segment_is_weft[segment] == (kind == "weft")
            if not np.any(m):
                continue
            wi_l, wo_l = to_yarn_frame(wi[m], kind), to_yarn_frame(wo[m], kind)
            sigma, phase = yarn.yarn_offsets(x_across[m], y_along[m], self.weave.geometry(kind).w,
                                             p["n_strands"], p["fibre_slope"])
            normal = yarn.perturbed_normal(*yarn.perturbation(sigma, phase, p["fibre_curvature"],
                                                              p["yarn_curvature"]))
            ao = yarn.ambient_occlusion(normal)  # scales the anisotropic reflection only (sec. 4.2.2)
            specular = ao * self._specular_about(wi_l, wo_l, normal, *self._exponents(kind, p), p["fresnel_f0"])
            far = alpha[m] > 0.0
            if np.any(far):
                specular[far] = lod.blend(specular[far], self._weave_level(kind, wi_l[far], wo_l[far], p),
                                          alpha[m][far])  # eq. 5
            out[f"specular_{kind}"][m] = noise[m] * specular
            out[f"diffuse_{kind}"][m] = np.where(visible[m], noise[m] / np.pi, 0.0)  # no AO (sec. 4.2.2)
        out["diffuse"] = out["diffuse_warp"] + out["diffuse_weft"]
        return out


def nodes_for_axis(curvature: float, exponent: float) -> int:
    """Gauss-Legendre nodes for one perturbation axis: ~1.5 per lobe width over the range 2 c, 8 to 256.

    The lobe of eq. 2 has an angular width ~ 1/sqrt(exponent); the perturbation moves it over 2 c.
    """
    if curvature == 0.0:
        return 1
    return int(np.clip(np.ceil(8.0 + 3.0 * curvature * np.sqrt(exponent)), 8, 256))


#: half vectors whose components agree to this (absolute, |h| = 1) share one tile-average evaluation
GROUP_TOLERANCE = 1e-12


def _half_vector_groups(h: np.ndarray, weft: list[bool]) -> tuple[np.ndarray, np.ndarray]:
    """(representatives (M, 3), inverse (B N,)) for the half vectors of B yarn types, each the warp's h (N, 3)
    or (``weft[b]``) the weft's, h with x and y swapped, one block after the other (compiled in one pass,
    :func:`.kernels.half_vector_groups`): rows whose components round to the
    same multiple of :data:`GROUP_TOLERANCE` form a group, evaluated once at its first row (a symmetric
    gonioreflectometer sampling repeats |h| up to rounding: the paper's 1,575 pairs x 2 yarn types give 770
    groups).  A member's value is the rule's value at a half vector within 1e-12 of its own: the same to rounding,
    except where that offset moves a node count (a ceil), where it differs by the rule's own error (tested:
    > 99 % of the values to 1e-9 relative, all to 1e-4 floored at 1 % of the mean; the rule's error is ~4e-4)."""
    from clothlab.models.kang import kernels

    return kernels.half_vector_groups(h, np.array(weft, dtype=np.bool_), 1.0 / GROUP_TOLERANCE)


@cache
def _gauss_legendre_table(most: int) -> tuple[np.ndarray, np.ndarray]:
    """The peak rule's Gauss-Legendre rows 1 ... ``most`` (:func:`.kernels.gauss_legendre_table`)."""
    from clothlab.models.kang import kernels

    return kernels.gauss_legendre_table(most)


@cache
def _gauss_legendre(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes on [-1, 1] and weights summing to 1."""
    nodes, weights = np.polynomial.legendre.leggauss(n)
    return nodes, weights / 2.0

