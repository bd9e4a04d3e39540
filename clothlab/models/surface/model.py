"""The fabric surface model (``kind: surface``) of Chen, Wang & Wang, "Real-time Neural Woven Fabric
Rendering" (SIGGRAPH 2024), sec. 3.1, eqs. 1-5, Table 1 - the model their network learns, after Jin et
al. 2022 (geometry, blended Lambertian) and SpongeCake (Wang et al. 2022: the fibre microflake layer).

Yarns are single-ply curved cylinders placed by the weave pattern (:mod:`clothlab.weave`: segments and
:func:`clothlab.weave.lookup.locate_segments`); the ply normal n_p and orientation t_p follow from the
eq. 11 (u, v) mapping of Irawan & Marschner 2012, twist psi, inclination umax, the gap ratio and the
height-field scaling beta (:mod:`.geometry`).  At a ply point, in the ply's own frame (eqs. 1-2):

    f_s = ks D(h) G(wi, wo) / (4 cos_i cos_o),   D(h) = 1 / (pi alpha q^2),  q = h^T S^-1 h,
    G = (1 - exp(-T rho (Lambda_i + Lambda_o))) / (Lambda_i + Lambda_o),  Lambda(w) = sigma(w) / cos(w),
    sigma(w) = sqrt(w^T S w),  S = R^T diag(1, 1, alpha^2) R (third axis t_p),  T rho = 2
    f_d = kd [w <wi . n_p> / (pi <wi . n_s>) + (1 - w) / pi]

Parameters (:mod:`clothlab.models.surface.parameters`; k = warp, weft; kd_k, ks_k are the linear
coefficients of the components below):

===========  ====  ============  ===========  ==============================================================
parameter    unit  range         default      meaning
===========  ====  ============  ===========  ==============================================================
k.psi        deg   [-80, 80]     weave's psi  twist: t_p is the yarn axis turned by psi about n_p
k.umax       deg   [0, 80]       weave's umax inclination: the yarn axis tilts in [-umax, umax] along a segment
k.alpha      1     [0.001, 1]    0.5          fibre roughness alpha (eq. 2; Table 2 samples U(0.1, 1))
k.beta       1     [0, 4]        1            height-field scaling of n_p and t_p (Table 2: U(0, 2))
gap          1     [0.01, 0.9]   0.2          gap ratio: the bare fraction of each yarn's width (sec. 5.1)
blend        1     [0, 1]        0.5          w of eq. 1: weight of the Lambertian about n_p
===========  ====  ============  ===========  ==============================================================

Components (1/sr, unit coefficients; eqs. 7-8): ``diffuse_warp``, ``diffuse_weft``, ``specular_warp``,
``specular_weft``; f = kd_warp C_warp + kd_weft C_weft + ks_warp S_warp + ks_weft S_weft, the coefficients
solved by NNLS per channel as for IM.  ``components`` (for BRDF tables) is the tile average: the texture
(:class:`clothlab.models.surface.texture.SurfaceTexture`, point evaluation at u, v) averaged over the
tile, i.e. eq. 3 with the box kernel over one tile; per yarn type k it is c_k (1 - g) times the mean over
the ply's (u, v) rectangle (midpoint rule, ``tile_nodes`` = (across, along), default (32, 16)), c_k the
cell share.  Reflection only: transmission (the gap's delta transmission, the BTDF of Zhu et al. 2023) is
out of scope; pairs with wi_z <= 0 or wo_z <= 0 give 0.

Decisions (where the paper leaves the choice open; each is tested in tests/test_surface.py):

1. Which cosine enters Lambda and eq. 1's f_s: the ply normal's (the SpongeCake slab lies along the ply
   surface): cos = <w . n_p>.  The form G / (cos_i cos_o) = (1 - exp(-2 x)) / (sigma_i cos_o + sigma_o
   cos_i), x = Lambda_i + Lambda_o, is evaluated directly: finite at grazing and at alpha's bounds.
2. Visibility V of eqs. 3-5: not traced (a height field without inter-yarn shadowing); replaced by the Smith
   (uncorrelated) estimate of the tile, V(w) ~ G1(w) = w_z / A~(w) with A~ the tile's unshadowed projected
   area (:func:`.geometry.projected_area`).  Then eq. 5's visible projected area is A_P(wo) = <wo . n_s>,
   exactly the macro area, and the point value (BRDF w.r.t. n_s, i.e. eq. 3 divided by cos_i) is
       T(p) = f_ply(p) <wi . n_p> <wo . n_p> / (<n_s . n_p> A~(wi) A~(wo))
   reciprocal by construction, and of albedo <= 1 for unit coefficients: the ply layer is single scattering
   (albedo <= ks) and A~(w) >= w_z.
3. The diffuse of eq. 1 made reciprocal the same way: the w part is the Lambertian 1/pi about n_p carried
   through decision 2 (it equals eq. 1's w <wi . n_p> / (pi <wi . n_s>) for a flat ply and beta = 0), the
   (1 - w) part is the Lambertian about n_s, kd / pi, at every ply point.
4. The gap is bare: no reflecting surface there (the light it passes is the delta transmission the paper
   mentions; out of scope).  It counts as flat in A~.
5. The tile average uses the cell shares c_k and each segment's w x l rectangle (true for every shipped
   weave and :mod:`clothlab.weave.patterns`), so it is the texture's tile average (tested to 1e-9 at the
   quadrature nodes and against a dense texture grid).
6. ks, kd are albedos (Table 1): the components are not normalised further (``normalised`` is accepted
   for the interface and changes nothing).
"""

from __future__ import annotations

import numpy as np

from clothlab.errors import ConfigError
from clothlab.frames import to_yarn_frame
from clothlab.models.base import Model, as_directions
from clothlab.models.surface.geometry import ply_frame, projected_area
from clothlab.models.surface.parameters import SURFACE_PARAMS, weave_parameters
from clothlab.weave.model import YARN_KINDS, Weave

DEFAULT_TILE_NODES = (32, 16)  # midpoint nodes across (v) and along (u) the ply


def ply_nodes(p: dict, kind: str, nodes: tuple[int, int]) -> np.ndarray:
    """(Q, 6) ply frames (n_p, t_p) at the midpoint nodes of the ply's (u, v) rectangle of yarn type ``kind``."""
    across, along = nodes
    half = 0.5 * np.pi * (1.0 - p["gap"])
    umax = np.deg2rad(p[f"{kind}.umax"])
    v = half * (2.0 * (np.arange(across) + 0.5) / across - 1.0)
    u = umax * (2.0 * (np.arange(along) + 0.5) / along - 1.0)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    n_p, t_p = ply_frame(uu.ravel(), vv.ravel(), np.deg2rad(p[f"{kind}.psi"]), p[f"{kind}.beta"])
    return np.ascontiguousarray(np.concatenate([n_p, t_p], axis=1))


AREA_PARAMETERS = ("gap",) + tuple(f"{kind}.{name}" for kind in YARN_KINDS for name in ("umax", "beta"))
"""The parameters the tile's projected area A~ depends on (:func:`.geometry.projected_area`)."""


def _runs(w: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
    """(first row of each run, run of each row) of the runs of equal consecutive rows of ``w`` (N, 3); (None,
    None) when no two consecutive rows are equal."""
    from clothlab.models.surface import kernels

    run = np.empty(len(w), dtype=np.int64)
    count = kernels.direction_runs(np.ascontiguousarray(w, dtype=np.float64), run)
    if count == len(w):
        return None, None
    return np.flatnonzero(np.diff(run, prepend=-1)), run


MAX_TILE_NODES = 1024
"""Most midpoint nodes per axis of ``tile_nodes``."""
MAX_TILE_POINTS = 1 << 18
"""Most nodes of the tile average per ply, across x along (262,144: a frame of 12 MiB; default 512)."""


def _tile_nodes(value) -> tuple[int, int]:
    """``tile_nodes`` as (across, along): each 1 to :data:`MAX_TILE_NODES`, their product at most
    :data:`MAX_TILE_POINTS`; ConfigError at ``model.options.tile_nodes`` otherwise."""
    if value is None:
        return DEFAULT_TILE_NODES
    if isinstance(value, int | np.integer) and not isinstance(value, bool):
        pair = (value, value)
    else:
        pair = tuple(value) if isinstance(value, list | tuple) else ()
    if len(pair) != 2 or not all(isinstance(n, int | np.integer) and not isinstance(n, bool) and n >= 1 for n in pair):
        raise ConfigError(f"tile_nodes must be a positive integer or a pair [across, along] of them, got {value!r}",
                          field="model.options.tile_nodes")
    if max(pair) > MAX_TILE_NODES or pair[0] * pair[1] > MAX_TILE_POINTS:
        raise ConfigError(f"tile_nodes {value!r}: at most {MAX_TILE_NODES} per axis and {MAX_TILE_POINTS} in all "
                          "(across x along)", field="model.options.tile_nodes")
    return int(pair[0]), int(pair[1])


class SurfaceModel(Model):
    """The fabric surface model of Chen, Wang & Wang 2024 (module docstring).

    Option ``tile_nodes``: midpoint nodes of the tile average, one integer or [across, along] (default
    [32, 16], at most :data:`MAX_TILE_NODES` per axis and :data:`MAX_TILE_POINTS` in all; the texture
    evaluates points and needs none)."""

    kind = "surface"
    params = SURFACE_PARAMS
    has_texture = True
    parameter_concepts = {
        "yarn inclination (IM sec. 5.2; Kang eqs. 3-4 c_y)": ("warp.umax", "weft.umax"),
        "fibre twist (IM sec. 5.2; Kang s_f)": ("warp.psi", "weft.psi"),
        "fibre scattering lobe (IM eq. 7; SGGX roughness and height scale; Kang eq. 2 exponents)":
            ("warp.alpha", "weft.alpha", "warp.beta", "weft.beta"),
        "yarn gap (SGGX sec. 5.1)": ("gap",),
        "diffuse blend (SGGX eq. 1)": ("blend",),
    }
    #: by role: the per-yarn SGGX roughness alpha and height scale beta shape the highlight as IM's do
    im_counterparts = {"alpha": ("warp.alpha", "weft.alpha"), "beta": ("warp.beta", "weft.beta")}
    texture_filters = False  # a renderer blends the texture with the tile average (im-lod, surface-lod)
    component_names = ("diffuse_warp", "diffuse_weft", "specular_warp", "specular_weft")
    coefficient_meaning = (
        "kd_<kind>: diffuse albedo of that yarn type (eq. 1, blended Lambertian); ks_<kind>: specular albedo of "
        "that yarn type (eq. 1-2, the fibre microflake layer, single scattering: albedo <= ks); components are "
        "tile averages, so each carries its yarn type's visible area")
    default_free = ("warp.umax", "weft.umax", "warp.alpha", "weft.alpha", "warp.beta", "weft.beta")
    quarter_turn_swaps = False  # the yarns' placement in the weave shapes the tile average (measured)

    def __init__(self, weave: Weave, *, tile_nodes=None):
        self.weave = weave
        self.tile_nodes = _tile_nodes(tile_nodes)
        self.options = {} if tile_nodes is None else {"tile_nodes": list(self.tile_nodes)}
        self.shares = {kind: weave.cell_share(kind) for kind in YARN_KINDS}
        self._area_memo: dict[int, tuple] = {}  # slot (0 wi, 1 wo) -> (parameters, directions, A~)

    @classmethod
    def from_config(cls, weave, quadrature=None, **options) -> SurfaceModel:
        return cls(weave, **options)

    @classmethod
    def check_option(cls, name: str, value) -> None:
        """ConfigError at ``model.options.<name>`` for a value the model cannot take (config validation names
        the yaml line): ``tile_nodes`` as :func:`_tile_nodes` takes it."""
        if name == "tile_nodes":
            _tile_nodes(value)

    def _default_parameters(self) -> dict[str, float]:
        return weave_parameters(self.weave)

    def settings(self) -> dict:
        return {"options": {"tile_nodes": list(self.tile_nodes)}}

    def _fitted_weave(self, params: dict):
        p = self.resolve(params)
        weave = self.weave
        for kind in YARN_KINDS:
            weave = weave.with_geometry(kind, psi=p[f"{kind}.psi"], umax=p[f"{kind}.umax"])
        return weave

    def texture(self, *, seed: int = 0):
        """The point model (:class:`clothlab.models.surface.texture.SurfaceTexture`); it has no noise, so
        ``seed`` selects nothing."""
        from clothlab.models.surface.texture import SurfaceTexture

        return SurfaceTexture(self)

    def projected_areas(self, wi: np.ndarray, wo: np.ndarray, p: dict) -> tuple[np.ndarray, np.ndarray]:
        """A~(wi), A~(wo) (N,) of the tile (decision 2), computed once per run of equal consecutive directions
        (the texture points of one footprint share theirs, as do those under a directional light).  The last
        set of each is kept with the parameters it depends on, so R and the texture probe of one surrogate
        query (the same directions) compute it once; :meth:`forget_directions` drops it."""
        return tuple(self._areas(slot, w, p) for slot, w in enumerate((wi, wo)))

    def _areas(self, slot: int, w: np.ndarray, p: dict) -> np.ndarray:
        starts, runs = _runs(w)
        unique = w if starts is None else w[starts]
        key = tuple(p[name] for name in AREA_PARAMETERS)
        if not all(np.ndim(k) == 0 for k in key):  # per-row parameters: nothing kept
            return projected_area(w, self.shares, p)
        kept = self._area_memo.get(slot)
        if kept is not None and kept[0] == key and kept[1].shape == unique.shape and np.array_equal(kept[1], unique):
            area = kept[2]
        else:
            area = projected_area(unique, self.shares, p)
            self._area_memo[slot] = (key, unique.copy(), area.copy())
        return area if runs is None else area[runs]

    def forget_directions(self) -> None:
        """Drop the projected areas kept of the last directions (:meth:`projected_areas`)."""
        self._area_memo = {}

    def _components(self, wi, wo, params: dict | None = None, *, need=None, normalised: bool = True,
                    warn: bool = True) -> dict[str, np.ndarray]:
        """Tile-averaged components (1/sr, each (N,)) at (N, 3) fabric-frame directions (module docstring);
        ``need`` limits those computed; ``normalised`` and ``warn`` change nothing (decision 6)."""
        from clothlab.models.surface import kernels

        p = self.resolve(params)
        wi, wo = as_directions(wi, wo)
        need = self.component_names if need is None else tuple(need)
        out = {name: np.zeros(len(wi)) for name in self.component_names if name in need}
        kinds = [k for k in YARN_KINDS if self.shares[k] > 0.0 and ({f"diffuse_{k}", f"specular_{k}"} & set(need))]
        if not kinds:
            return out
        area_i, area_o = self.projected_areas(wi, wo, p)
        for kind in kinds:
            frame = ply_nodes(p, kind, self.tile_nodes)
            spec, diff = kernels.tile_means(frame, np.ascontiguousarray(to_yarn_frame(wi, kind)),
                                            np.ascontiguousarray(to_yarn_frame(wo, kind)), area_i, area_o,
                                            float(p[f"{kind}.alpha"]), float(p["blend"]))
            scale = self.shares[kind] * (1.0 - p["gap"])
            for name, value in ((f"specular_{kind}", spec), (f"diffuse_{kind}", diff)):
                if name in out:
                    out[name] = scale * value
        return out
