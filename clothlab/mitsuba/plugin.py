"""The Mitsuba 3 BSDF plugin ``type: clothlab`` (:func:`register`); Mitsuba is imported only by these functions.

Plugin properties (all optional except one of ``fit`` / ``preset`` / ``material``):

===================  ==========================================================================================
``fit``              a fit directory (any kind of :data:`clothlab.models.registry.MODEL_KINDS`)
``preset``           a weave preset (``cotton-denim``), ``pattern:<name>`` or a .wv path, with ``kind``
``kind``             the model kind for ``preset`` (default: the registry's default)
``material``         the key of an in-memory material (:func:`add_material`; :mod:`clothlab.mitsuba.scene` uses it)
``lod``              ``auto`` (the renderer's rule by pixel footprint), ``texture`` or ``reflectance``
``f0``, ``f1``       LoD footprint thresholds in weave tiles (0.1, 0.5: ``clothlab render``'s)
``seed``, ``noise``  texture-noise realisation and switch (as ``fabric.seed`` / ``fabric.noise``)
``uv_size_mm``       "sx sy": the surface extent (mm) that uv in [0, 1] spans (default "1 1")
``tile_mm``          "tu tv": the weave tile along the weft and the warp (mm; default "1 1")
``warp_angle_deg``   the warp's angle counter-clockwise from the uv v axis about the normal (default 0)
``camera_*``         ``camera_origin``, ``camera_target``, ``camera_up`` ("x y z"), ``camera_fov`` (vertical,
                     deg), ``camera_height`` (pixels): the pinhole whose one-pixel ray differentials give the
                     footprint exactly as ``clothlab render`` does; without them Mitsuba's own uv partials
                     (``si.duv_dx``, ``si.duv_dy``, per sample), times ``footprint_scale`` (default 1)
===================  ==========================================================================================

Frame convention (docs/mitsuba.md, figure there).  Mitsuba's shading frame (s = dp/du, t = n x s, n) with the
weave rotated by ``warp_angle_deg`` = a about n: weft x_f = cos a s + sin a t, warp y_f = cos a t - sin a s,
z_f = n, exactly the flat patch of :mod:`clothlab.render.geometry`; texture coordinates (tiles)
u = (S cos b + T sin b) / tu, v = (-S sin b + T cos b) / tv with S = (uv.x - 0.5) sx, T = (uv.y - 0.5) sy and
b = a + the fit's ``orientation`` (the weave's own tile frame; the models see the directions turned by the
orientation, :mod:`clothlab.mitsuba.material`).
In radiance transport Mitsuba's ``si.wi`` (towards the camera) is clothlab's ``wo`` and the queried ``wo``
(towards the light) is clothlab's ``wi``; in importance transport the roles swap (the adjoint BSDF).
``eval`` returns f_r |cos theta| (Mitsuba's convention) and is zero unless both directions lie above n.

Batching: every method converts the whole wavefront (JIT variants, with symbolic loops and calls off, so that
Mitsuba hands the plugin evaluated arrays) to numpy and calls clothlab's models once.  Scalar variants call
the plugin per sample.
"""

from __future__ import annotations

import itertools
import math
import threading

import numpy as np

from clothlab.errors import ConfigError

#: BSDFFlags.NeedsDifferentials (not exported to Python by Mitsuba 3.9): Mitsuba then computes si.duv_dx / dy.
NEEDS_DIFFERENTIALS = 0x20000
PLUGIN_NAME = "clothlab"
_MATERIALS: dict[str, object] = {}
_CACHE: dict[tuple, object] = {}
_REGISTERED: set[str] = set()
_KEYS = itertools.count()


def add_material(material) -> str:
    """Keep an in-memory :class:`~clothlab.mitsuba.material.ClothMaterial` for the plugin; returns its key (the
    plugin's ``material`` property)."""
    key = f"material-{next(_KEYS)}"
    _MATERIALS[key] = material
    return key


def forget_material(key: str) -> None:
    _MATERIALS.pop(key, None)


def prepare_jit() -> None:
    """Turn Dr.Jit's symbolic loops and calls off: the plugin's methods then receive evaluated arrays they can
    hand to numpy (wavefront mode).  No-op in scalar variants."""
    import drjit as dr
    import mitsuba as mi

    if not mi.variant().startswith("scalar"):
        dr.set_flag(dr.JitFlag.SymbolicLoops, False)
        dr.set_flag(dr.JitFlag.SymbolicCalls, False)


def register() -> None:
    """Register ``type: clothlab`` for Mitsuba's current variant (once per variant); rgb and mono variants."""
    import mitsuba as mi

    variant = mi.variant()
    if variant is None:
        raise ConfigError("no Mitsuba variant is set; call mitsuba.set_variant('llvm_ad_rgb') (or scalar_rgb) first",
                          field="variant")
    if "spectral" in variant or "polarized" in variant:
        raise ConfigError(f"the clothlab plugin renders RGB and mono variants, not {variant!r}", field="variant")
    prepare_jit()
    if variant in _REGISTERED:
        return
    cls = bsdf_class()
    mi.register_bsdf(PLUGIN_NAME, lambda props: cls(props))
    _REGISTERED.add(variant)


def _vector(props, name, n, default):
    text = props.get(name, None) if name in props else None
    if text is None:
        return np.asarray(default, dtype=np.float64)
    from clothlab.untrusted import parse_number

    parts = str(text).replace(",", " ").split()
    if len(parts) != n:
        raise ConfigError(f"expected {n} numbers, got {text!r}", field=name)
    return np.asarray([parse_number(p, field=name) for p in parts], dtype=np.float64)


def _material_from_props(props):
    from clothlab.mitsuba.material import load_material

    def get(name, default=None):
        return props.get(name, default) if name in props else default

    if get("material") is not None:
        key = str(get("material"))
        if key not in _MATERIALS:
            raise ConfigError(f"no in-memory clothlab material {key!r}", field="material")
        return _MATERIALS[key]
    options = dict(fit=get("fit"), preset=get("preset"), kind=get("kind"), lod=str(get("lod", "auto")),
                   f0=float(get("f0", 0.1)), f1=float(get("f1", 0.5)), seed=int(get("seed", 0)),
                   noise=bool(get("noise", True)))
    key = tuple(sorted(options.items()))
    if key not in _CACHE:
        _CACHE[key] = load_material(**options)
    return _CACHE[key]


class SurfacePoints:
    """Surface points as numpy arrays (N rows): ``uv`` (N, 2), world position ``p``, world shading frame ``s``,
    ``t``, ``n`` (N, 3), uv partials ``duv_dx``, ``duv_dy`` (N, 2); fields not given are zeros."""

    def __init__(self, count, **fields):
        self.count = count
        for name, dim in (("uv", 2), ("p", 3), ("s", 3), ("t", 3), ("n", 3), ("duv_dx", 2), ("duv_dy", 2)):
            value = fields.get(name)
            setattr(self, name, np.zeros((count, dim)) if value is None else np.asarray(value, dtype=np.float64))

    @classmethod
    def of(cls, si, n, npv):
        """The points of a Mitsuba SurfaceInteraction (``npv``: the variant's array conversion)."""
        frame = si.sh_frame
        return cls(n, uv=npv(si.uv, n, 2), p=npv(si.p, n), s=npv(frame.s, n), t=npv(frame.t, n),
                   n=npv(frame.n, n), duv_dx=npv(si.duv_dx, n, 2), duv_dy=npv(si.duv_dy, n, 2))


def bsdf_class():
    """The plugin class for Mitsuba's current variant (a subclass of that variant's ``mi.BSDF``)."""
    import drjit as dr
    import mitsuba as mi

    jit = not mi.variant().startswith("scalar")
    mono = mi.is_monochromatic

    def np1(x, n=1):
        return np.broadcast_to(np.atleast_1d(np.asarray(x.numpy() if jit else x, dtype=np.float64)), (n,))

    def npv(x, n=1, dim=3):
        """A Dr.Jit vector (width n or 1) as an (n, dim) float64 array."""
        a = np.asarray(x.numpy() if jit else x, dtype=np.float64)
        a = a.reshape(dim, -1).T if jit else a.reshape(1, dim)
        return np.broadcast_to(a, (n, dim))

    def lanes(si, *arrays):
        """The wavefront width of a call (inputs of width 1 are broadcast)."""
        return max([dr.width(a) for a in arrays] + [dr.width(si.wi), dr.width(si.uv), dr.width(si.p), 1]) if jit else 1

    def to_vector(a):
        if jit:
            return mi.Vector3f(mi.Float(a[:, 0]), mi.Float(a[:, 1]), mi.Float(a[:, 2]))
        return mi.Vector3f(float(a[0, 0]), float(a[0, 1]), float(a[0, 2]))

    def to_float(a):
        return mi.Float(a) if jit else float(a[0])

    class ClothlabBSDF(mi.BSDF):
        """clothlab fabric (see :mod:`clothlab.mitsuba.plugin`)."""

        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            self.material = _material_from_props(props)
            channels = len(self.material.channels)
            if channels not in (1, 3):
                raise ConfigError(f"the fit has {channels} channels {list(self.material.channels)}; the plugin "
                                  "renders 3 (taken as R, G, B in the fit's order) or 1 (grey)", field="fit")
            self.uv_size = _vector(props, "uv_size_mm", 2, (1.0, 1.0))
            self.tile = _vector(props, "tile_mm", 2, (1.0, 1.0))
            if np.any(self.tile <= 0.0):
                raise ConfigError(f"expected positive tile_mm, got {self.tile.tolist()}", field="tile_mm")
            degrees = float(props.get("warp_angle_deg", 0.0)) if "warp_angle_deg" in props else 0.0
            angle = math.radians(degrees)
            self.cos_a, self.sin_a = math.cos(angle), math.sin(angle)
            # texture coordinates: the weave's own tile frame, turned further by the fit's orientation
            tile_angle = math.radians(degrees + self.material.orientation)
            self.cos_t, self.sin_t = math.cos(tile_angle), math.sin(tile_angle)
            self.footprint_scale = float(props.get("footprint_scale", 1.0)) if "footprint_scale" in props else 1.0
            self.camera = None
            if "camera_origin" in props:
                eye = _vector(props, "camera_origin", 3, (0, 0, 0))
                target = _vector(props, "camera_target", 3, (0, 0, 0))
                up = _vector(props, "camera_up", 3, (0, 0, 1))
                fov = float(props.get("camera_fov", 30.0)) if "camera_fov" in props else 30.0
                height = int(props.get("camera_height", 1)) if "camera_height" in props else 1
                forward = (target - eye) / np.linalg.norm(target - eye)
                right = np.cross(forward, up)
                right /= np.linalg.norm(right)
                down = np.cross(forward, right)
                self.camera = (eye, forward, right, down, 2.0 * math.tan(0.5 * math.radians(fov)) / height)
            # glossy unless every component is a diffuse one (the baselines: Lambert, Oren-Nayar)
            glossy = any(not name.startswith("diffuse") for name in self.material.reflectance.component_names)
            lobe = mi.BSDFFlags.GlossyReflection if glossy else mi.BSDFFlags.DiffuseReflection
            self.lobe = lobe
            flags = lobe | mi.BSDFFlags.FrontSide | mi.BSDFFlags.Anisotropic | mi.BSDFFlags.SpatiallyVarying
            self.m_flags = int(flags) | NEEDS_DIFFERENTIALS
            self.m_components = [self.m_flags]
            self.calls = 0  # model calls (for the batching measurements)
            self.lanes = 0
            # scalar variants call the plugin from Mitsuba's render threads; clothlab's models keep per-instance
            # memos and are not shared between threads (models.base), so calls into them are serialised
            self.lock = threading.RLock()

        # ------------------------------------------------------------------------------------ geometry

        def _to_fabric(self, w):
            c, s = self.cos_a, self.sin_a
            return np.stack([c * w[:, 0] + s * w[:, 1], -s * w[:, 0] + c * w[:, 1], w[:, 2]], axis=1)

        def _from_fabric(self, w):
            c, s = self.cos_a, self.sin_a
            return np.stack([c * w[:, 0] - s * w[:, 1], s * w[:, 0] + c * w[:, 1], w[:, 2]], axis=1)

        def _tiles(self, duv):
            """uv offsets (N, 2) -> texture-coordinate offsets (tiles) (N, 2)."""
            ds, dt = duv[:, 0] * self.uv_size[0], duv[:, 1] * self.uv_size[1]
            c, s = self.cos_t, self.sin_t
            return np.stack([(ds * c + dt * s) / self.tile[0], (-ds * s + dt * c) / self.tile[1]], axis=1)

        def _texture_point(self, points):
            tiles = self._tiles(points.uv - 0.5)
            return tiles[:, 0], tiles[:, 1]

        def _footprint(self, points):
            if self.material.policy in ("reflectance", "texture"):
                return None
            if self.camera is not None:
                eye, forward, right, down, scale = self.camera
                p, s_w, t_w, n_w = points.p, points.s, points.t, points.n
                c, sn = self.cos_t, self.sin_t
                weft, warp = c * s_w + sn * t_w, c * t_w - sn * s_w  # the weave's tile axes
                d = p - eye
                depth = d @ forward
                x, y = (d @ right) / depth, (d @ down) / depth
                extent = []
                for dx, dy in ((scale, 0.0), (0.0, scale)):
                    ray = forward[None, :] + (x + dx)[:, None] * right + (y + dy)[:, None] * down
                    along = np.einsum("ij,ij->i", ray, n_w)
                    with np.errstate(divide="ignore", invalid="ignore"):
                        t = np.einsum("ij,ij->i", p - eye, n_w) / along
                    step = eye + t[:, None] * ray - p
                    length = np.hypot(np.einsum("ij,ij->i", step, weft) / self.tile[0],
                                      np.einsum("ij,ij->i", step, warp) / self.tile[1])
                    extent.append(np.where((np.abs(along) > 1e-12) & (t > 0.0) & np.isfinite(length), length,
                                           np.inf))
                return np.maximum(extent[0], extent[1])
            fx, fy = self._tiles(points.duv_dx), self._tiles(points.duv_dy)
            return self.footprint_scale * np.maximum(np.hypot(fx[:, 0], fx[:, 1]), np.hypot(fy[:, 0], fy[:, 1]))

        # ------------------------------------------------------------------------------------ evaluation

        def _pair(self, ctx, si, wo_local, n):
            """(clothlab wi, wo, the given direction as the sampler's view) in the fabric frame."""
            given = self._to_fabric(npv(si.wi, n))
            other = self._to_fabric(npv(wo_local, n))
            if ctx.mode == mi.TransportMode.Importance:
                return given, other, given
            return other, given, given

        def _values(self, si, wi, wo):
            points = si if isinstance(si, SurfacePoints) else SurfacePoints.of(si, len(wi), npv)
            u, v = self._texture_point(points) if self.material.policy != "reflectance" else (None, None)
            footprint = self._footprint(points)
            with self.lock:
                self.calls += 1
                self.lanes += len(wi)
                return self.material.values(wi, wo, u, v, footprint)

        def _pdf(self, view, other):
            with self.lock:
                return self.material.sampler().pdf(view, other)

        def eval_arrays(self, points, view, light):
            """f_r |cos theta_light| (N, C) in radiance transport for local directions ``view`` (to the camera) and
            ``light`` (N, 3) at ``points`` (:class:`SurfacePoints`): the plugin's ``eval`` on numpy arrays, one
            model call (the scalar wavefront path of :mod:`clothlab.mitsuba.scene`)."""
            f = self._values(points, self._to_fabric(light), self._to_fabric(view))
            return f * np.abs(light[:, 2])[:, None]

        def _spectrum(self, rgb):
            if mono:
                grey = rgb.mean(axis=1)
                return mi.Color1f(to_float(grey)) if jit else mi.Color1f(float(grey[0]))
            if rgb.shape[1] == 1:
                rgb = np.repeat(rgb, 3, axis=1)
            if jit:
                return mi.Color3f(mi.Float(rgb[:, 0]), mi.Float(rgb[:, 1]), mi.Float(rgb[:, 2]))
            return mi.Color3f(float(rgb[0, 0]), float(rgb[0, 1]), float(rgb[0, 2]))

        def _enabled(self, ctx):
            return ctx.is_enabled(self.lobe, 0)

        def eval(self, ctx, si, wo, active=True):
            n = lanes(si, wo)
            if not self._enabled(ctx):
                return self._spectrum(np.zeros((n, 3)))
            wi_f, wo_f, _ = self._pair(ctx, si, wo, n)
            f = self._values(si, wi_f, wo_f) * np.abs(npv(wo, n)[:, 2])[:, None]
            return dr.select(active, self._spectrum(f), 0.0)

        def pdf(self, ctx, si, wo, active=True):
            n = lanes(si, wo)
            if not self._enabled(ctx):
                return to_float(np.zeros(n))
            _, _, view = self._pair(ctx, si, wo, n)
            other = self._to_fabric(npv(wo, n))
            return dr.select(active, to_float(self._pdf(view, other)), 0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            n = lanes(si, wo)
            if not self._enabled(ctx):
                return self._spectrum(np.zeros((n, 3))), to_float(np.zeros(n))
            wi_f, wo_f, view = self._pair(ctx, si, wo, n)
            other = self._to_fabric(npv(wo, n))
            f = self._values(si, wi_f, wo_f) * np.abs(npv(wo, n)[:, 2])[:, None]
            pdf = self._pdf(view, other)
            return dr.select(active, self._spectrum(f), 0.0), dr.select(active, to_float(pdf), 0.0)

        def sample(self, ctx, si, sample1, sample2, active=True):
            n = lanes(si, sample1, sample2)
            view = self._to_fabric(npv(si.wi, n))
            u1 = np1(sample1, n)
            u2 = npv(sample2, n, 2)
            if self._enabled(ctx):
                with self.lock:
                    w, pdf = self.material.sampler().sample(view, u1, u2)
            else:
                w, pdf = np.tile([0.0, 0.0, 1.0], (n, 1)), np.zeros(n)
            importance = ctx.mode == mi.TransportMode.Importance
            wi_f, wo_f = (view, w) if importance else (w, view)
            f = self._values(si, wi_f, wo_f) if self._enabled(ctx) else np.zeros((n, len(self.material.channels)))
            with np.errstate(divide="ignore", invalid="ignore"):
                weight = np.where((pdf > 0.0)[:, None], f * w[:, 2:3] / np.where(pdf > 0.0, pdf, 1.0)[:, None], 0.0)
            bs = dr.zeros(mi.BSDFSample3f, n) if jit else mi.BSDFSample3f()
            bs.wo = to_vector(self._from_fabric(w))
            bs.pdf = to_float(pdf)
            bs.eta = 1.0
            bs.sampled_type = mi.UInt32(+self.lobe)
            bs.sampled_component = mi.UInt32(0)
            ok = active & (bs.pdf > 0.0)
            return bs, dr.select(ok, self._spectrum(weight), 0.0)

        def traverse(self, callback):
            pass

        def parameters_changed(self, keys):
            pass

        def to_string(self):
            m = self.material
            return f"ClothlabBSDF[kind={m.kind}, policy={m.policy}, source={m.source}]"

    return ClothlabBSDF
