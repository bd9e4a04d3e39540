"""The shading policy of :func:`clothlab.render.render`: which model runs at which sample.

A kind offers its shaders in the registry (:data:`clothlab.models.registry.SHADERS`: shader -> (kind,
policy)); :func:`shade` asks it for the shader's kind and runs the policy (:data:`POLICIES`) on the scene's
fabric as that kind (:func:`kind_models`; another kind than the scene's is mapped from its IM coefficients by
:func:`clothlab.models.registry.from_irawan`).  Policies: ``texture``, ``reflectance``, ``lod`` (the blend by
the footprint), ``filtered-texture`` / ``filtered-lod`` (a texture model that filters itself, without / with
the footprint), ``network-lod`` (:func:`neural_lod_values`).

Shaders (f_r in 1/sr per channel, for the fabric-frame directions of each sample):

- ``im-texture``     the Irawan-Marschner texture model (sec. 7.2) at every sample.
- ``im-reflectance`` the IM reflectance model (sec. 7.1), evaluated once per pixel (at its first surface
                     sample; f_r is smooth in the directions across a pixel) and used for all its samples.
- ``im-lod``         per sample, from the pixel footprint f (weave tiles, :mod:`.geometry`):
                         texture model             where f <= f0   (the pixel resolves yarns),
                         reflectance model         where f >= f1   (the pixel covers many tiles),
                         (1 - b) texture + b refl  between, b = smoothstep(log(f / f0) / log(f1 / f0)),
                     a C^1 blend in log footprint: continuous in the distance, with no jump at f0 or f1.
                     This is the paper's "seamless switching" (sec. 3.2, 7): the tile average of the texture
                     model equals the reflectance model, so the far limit of a supersampled texture and
                     the reflectance model agree (checked by the test suite).  Where b = 1 the texture model
                     is never called (counted); the reflectance part is evaluated once per pixel (at its
                     first sample with b > 0).  Blend pixels do not run the texture model at all their
                     samples: with m samples and texture weight W = sum (1 - b) the texture runs at
                     n = ceil(W) of them, spread over the strata, each weighted W / n
                     (:func:`blend_texture_samples`), so the texture work of a pixel falls with (1 - b)
                     and the cost per image falls monotonically with distance once no pixel is left in
                     the pure texture range (render_benchmark).  With one sample per pixel this is the
                     plain blend.
- ``kang-texture``   Kang's point shader with full yarn detail (footprint None, alpha = 0 of eq. 5).
- ``surface-lod``    the fabric surface model (Chen, Wang & Wang 2024, sec. 3.1; ``kind: surface``) with the
                     same LoD blend as ``im-lod``: its texture model (point evaluation) where the pixel
                     resolves yarns, its tile average (eq. 3 over one tile) beyond, the smoothstep between.
                     The model is the scene's fit when ``fabric.fit`` is of kind surface, else kind surface
                     with its defaults for the scene's weave and kd_warp = kd_weft = kd, ks_* as given.
- ``surface-texture`` the surface model's texture model at every sample.
- ``kang-lod``       Kang's point shader with the pixel footprint: the eq. 5 mip blend, and Algorithm 1
                     (adaptive prefiltering) when fabric.kang.prefilter is set, with view distance
                     = camera distance / fabric.kang.view_distance_mm.

- ``neural-lod``     im-lod, except where the pixel covers part of a tile: there the neural footprint
                     surrogate (Chen, Wang & Wang 2024, sec. 4.3; ``kind: neural``, the weave's shipped
                     weights) shades the pixel, queried once per pixel for a box footprint of side f (tiles) at
                     the pixel's centre with the centre's directions (:func:`pixel_boxes`): the query *is* the
                     pixel's filtered value (eq. 3), so it needs no supersampling, and more samples per pixel
                     do not move it (the jitter only enters through the per-sample irradiance and cosine);
                     the reflectance model at
                     the same directions is the base of a residual network.  The network's share w =
                     :func:`network_weight` (f) rises over :data:`NEURAL_RISE` and falls over
                     :data:`NEURAL_FALL`; where 0 < w < 1 a pixel is the network's when its dither threshold
                     (:func:`dither`, a low-discrepancy sequence over the pixel index) is below w, else
                     im-lod's: a stochastic transition (the expected image is the blend) that runs one of the
                     two per pixel, not both.  The scene's IM parameters and coefficients are used; a
                     parameter set other than the trained one goes through the network's encoder.  The networks
                     learn the noise-free texture: with ``fabric.noise`` on, network pixels lack the
                     per-segment intensity noise (as im-lod's reflectance part does).

Skipping (nothing runs that the scene does not need): a component whose coefficient is zero in every
channel, or whose yarn type covers no cell of the weave, is not computed (``need=``).

Choice of f0 = 0.1 and f1 = 0.5 tile (scene.lod).  Measured on the receding plane of render_benchmark
(cotton denim, 1 x 2 mm tile, camera at 45 deg elevation, distances 5..640 mm): relative L1 error per pixel
against the texture model at 256 stratified samples, binned by footprint (tiles):

    footprint    0.01-0.06  0.06-0.1  0.1-0.2  0.2-0.3  0.3-0.5  0.5-1   1-2    2-8
    texture 4spp   0.03      0.045     0.086    0.13     0.16     0.18   0.20   0.20
    reflectance    0.28-0.34 0.26      0.22     0.17     0.11     0.07   0.04   0.03

The curves cross near 0.25 tile; the blend spans 0.1..0.5 around it (the geometric mean 0.22).  Below
0.1 the texture model is within 5 % of the reference, above 0.5 the reflectance model within 7 % (3 % from
two tiles on, the reference's own sampling noise), and neither is better than ~15 % in between.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from clothlab.errors import ConfigError
from clothlab.models.components import combine
from clothlab.models.registry import SHADERS as SHADER_KINDS
from clothlab.models.registry import shader as shader_kind
from clothlab.render.scene import Fabric, Lod
from clothlab.weave.model import YARN_KINDS

#: the shader names (``clothlab render --shader``), as the registry declares them with their kinds
SHADERS = tuple(SHADER_KINDS)
#: finite stand-in for an infinite footprint (grazing differentials) handed to the Kang shader
MAX_FOOTPRINT = 1e6


def lod_weight(footprint, f0: float, f1: float) -> np.ndarray:
    """Reflectance weight b in [0, 1] of a footprint (tiles): 0 for f <= f0, 1 for f >= f1, smoothstep of
    log(f / f0) / log(f1 / f0) between (continuous, with continuous slope, at both ends)."""
    f = np.asarray(footprint, dtype=np.float64)
    with np.errstate(divide="ignore"):
        t = np.clip(np.log(np.maximum(f, 0.0) / f0) / np.log(f1 / f0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


@dataclass
class PixelCentres:
    """The surface point seen through each pixel's centre, indexed by pixel (H W,): texture coordinates
    (tiles), fabric-frame directions (H W, 3), footprint (tiles), the (du, dv) tile steps of a one-pixel step
    in x and in y (H W, 2, 2: the pixel's footprint is, to first order, the parallelogram they span about the
    centre; inf where unknown); ``valid``: the centre's ray hits the front of the patch (elsewhere the other
    arrays are undefined)."""

    u: np.ndarray
    v: np.ndarray
    wi: np.ndarray
    wo: np.ndarray
    footprint: np.ndarray
    steps: np.ndarray
    valid: np.ndarray


@dataclass
class Samples:
    """Surface samples to shade: texture coordinates (tiles), fabric-frame directions (M, 3), pixel footprint
    (tiles), pixel index, distance from the camera (mm); ``centre``: the pixels' centres, for the shaders that
    shade a pixel's footprint as one box (:func:`pixel_boxes`; None when the shader does not need them)."""

    u: np.ndarray
    v: np.ndarray
    wi: np.ndarray
    wo: np.ndarray
    footprint: np.ndarray
    pixel: np.ndarray
    distance: np.ndarray
    centre: PixelCentres | None = None

    def take(self, index) -> Samples:
        return Samples(*(np.take(getattr(self, k), index, axis=0)
                         for k in ("u", "v", "wi", "wo", "footprint", "pixel", "distance")), centre=self.centre)


@dataclass
class FabricModels:
    """The fabric of a scene as evaluable models: weave, reflectance and texture models (IM unless the fit is
    of another kind with a texture model) with parameters and coefficients (C,) per component name, channels;
    the Kang shader, the fabric as another kind's models and the network are built on first use."""

    spec: Fabric
    weave: object
    reflectance: object
    texture: object
    params: dict
    coefficients: dict
    channels: tuple
    need: tuple
    _kang: tuple | None = field(default=None, repr=False)
    _as_kind: dict = field(default_factory=dict, repr=False)  # kind -> FabricModels (:func:`kind_models`)
    _neural: object = field(default=None, repr=False)  # the network (:func:`neural_model`)

    @classmethod
    def build(cls, spec: Fabric) -> FabricModels:
        """The models of ``spec``: the fit's (``fabric.fit``: a model with a texture model), else the
        registry's default kind for the weave with ``fabric.params``."""
        from clothlab.config.build import model_from_weave

        if spec.fit is not None:
            from clothlab.fit.store import load_fitted

            model, params, coefficients, channels = load_fitted(spec.fit)
            if not model.has_texture or model.texture_filters:
                raise ConfigError(f"the fit in {spec.fit} is of kind {model.kind!r}, "
                                  + ("whose texture model filters itself (it goes under fabric.kang.fit)"
                                     if model.has_texture else "which has no texture model")
                                  + "; fabric.fit needs a model whose texture model the im-* shaders blend with its "
                                  "reflectance", field="fabric.fit")
        else:
            model = model_from_weave(spec.weave, spec.base_dir)  # the registry's default kind
            params, coefficients, channels = spec.params, spec.coefficients, spec.channels
        weave = model.weave
        params = model.resolve(params)  # validates (ParameterError names the parameter)
        coefficients = _broadcast(coefficients, len(channels), "fabric.coefficients")
        texture = model.texture(seed=spec.seed)
        need = tuple(name for name in texture.component_names if _needed(name, coefficients, weave))
        return cls(spec, weave, model, texture, params, coefficients, tuple(channels), need)

    def forget_directions(self) -> None:
        """Drop the direction memos of the scene's reflectance models (the scene's own, those of the scene as
        another kind, the network's), so that a timed render starts cold
        (:meth:`clothlab.models.base.Model.forget_directions`)."""
        self.reflectance.forget_directions()
        for models in self._as_kind.values():
            if models is not self:
                models.reflectance.forget_directions()
        if self._neural is not None:
            self._neural.forget_directions()

    def kang(self, kind: str | None = None):
        """(texture model, params, coefficients) of the scene's self-filtering shader (``fabric.kang``): the
        fit's (``fabric.kang.fit``: a model whose texture model takes the pixel footprint), else the scene's
        fabric as ``kind`` (default: the kind of the registry's ``kang-lod`` shader), which that section
        configures (:func:`clothlab.models.registry.from_irawan`; ``fabric.kang.coefficients`` replace the
        mapped ones)."""
        if self._kang is None:
            from clothlab.models.registry import from_irawan

            kind = shader_kind("kang-lod")[0] if kind is None else kind
            k = self.spec.kang
            if k.fit is not None:
                from clothlab.fit.store import load_fitted

                model, params, coefficients, channels = load_fitted(k.fit)
                if not model.texture_filters:
                    raise ConfigError(f"the fit in {k.fit} is of kind {model.kind!r}, whose model has no texture "
                                      "model taking a pixel footprint; fabric.kang.fit needs one (kind kang)",
                                      field="fabric.kang.fit")
                if tuple(channels) != self.channels:
                    raise ConfigError(f"the Kang fit's channels {list(channels)} differ from the fabric's "
                                      f"{list(self.channels)}", field="fabric.kang.fit")
            else:
                model, params, coefficients = from_irawan(kind, self.weave, self.coefficients, k.params)
                coefficients = k.coefficients or coefficients
            params = model.resolve(params)
            self._kang = (model.texture(), params,
                          _broadcast(coefficients, len(self.channels), "fabric.kang.coefficients"))
        return self._kang


def kind_models(fabric: FabricModels, kind: str) -> FabricModels:
    """The scene's fabric as the models of ``kind`` (the models a shader of that kind shades; module
    docstring), built once per kind: the scene's own when it is of that kind or ``kind`` is the registry's
    default kind (``fabric.fit`` may be of any kind whose texture the shaders blend), else the kind built for
    the scene's weave from its IM coefficients at the kind's default parameters
    (:func:`clothlab.models.registry.from_irawan`)."""
    from clothlab.models.registry import DEFAULT_KIND, from_irawan

    cache = fabric._as_kind
    if kind not in cache:
        if kind in (DEFAULT_KIND, fabric.reflectance.kind):
            cache[kind] = fabric
        else:
            model, params, coefficients = from_irawan(kind, fabric.weave, fabric.coefficients)
            coefficients = _broadcast(coefficients, len(fabric.channels), "fabric.coefficients")
            texture = model.texture(seed=fabric.spec.seed)
            need = tuple(name for name in texture.component_names if _needed(name, coefficients, fabric.weave))
            cache[kind] = FabricModels(fabric.spec, fabric.weave, model, texture, params, coefficients,
                                       fabric.channels, need)
    return cache[kind]


def _broadcast(coefficients: dict, n: int, where: str) -> dict:
    out = {}
    for name, coef in coefficients.items():
        coef = np.atleast_1d(np.asarray(coef, dtype=np.float64))
        if coef.shape not in ((1,), (n,)):
            raise ConfigError(f"coefficient {name} has {coef.size} values for {n} channels", field=f"{where}.{name}")
        out[name] = np.broadcast_to(coef, (n,)).copy()
    return out


def _needed(component: str, coefficients: dict, weave) -> bool:
    """A component is computed only if its coefficient is non-zero somewhere and its yarn type is present."""
    from clothlab.models.components import coefficient_name

    coef = coefficients.get(coefficient_name(component), coefficients.get(component))
    if coef is None or not np.any(coef != 0.0):
        return False
    kind = component.rsplit("_", 1)[-1]
    return kind not in YARN_KINDS or weave.cell_share(kind) > 0.0


# ---------------------------------------------------------------------------------------------- shaders


class Counter(dict):
    """Model evaluations per model (points passed in) and the time spent in each (``<model>_seconds`` wall
    clock, ``<model>_cpu_seconds`` this process's CPU time)."""

    def run(self, name, n, fn, *args, **kwargs):
        import time

        start, cpu = time.perf_counter(), time.process_time()
        out = fn(*args, **kwargs)
        self[f"{name}_points"] = self.get(f"{name}_points", 0) + int(n)
        self[f"{name}_seconds"] = self.get(f"{name}_seconds", 0.0) + time.perf_counter() - start
        self[f"{name}_cpu_seconds"] = self.get(f"{name}_cpu_seconds", 0.0) + time.process_time() - cpu
        return out


def _zeros(fabric, m):
    return np.zeros((m, len(fabric.channels)))


def texture_values(fabric: FabricModels, s: Samples, counter: Counter) -> np.ndarray:
    """IM texture model f_r (M, C) at every sample."""
    if not fabric.need or len(s.u) == 0:
        return _zeros(fabric, len(s.u))
    comps = counter.run("texture", len(s.u), fabric.texture.components, s.u, s.v, s.wi, s.wo, fabric.params,
                        need=fabric.need, noise=fabric.spec.noise, warn=False)
    return combine(comps, fabric.coefficients)


def pixel_groups(pixel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Samples grouped by pixel: (order, starts, group) with ``order`` the permutation that sorts the samples
    by pixel (stable; the identity when they already are, as :func:`clothlab.render.render` emits them),
    ``starts`` the first sorted position of each pixel's run and ``group`` (M,) the run of each sorted sample."""
    pixel = np.asarray(pixel)
    if pixel.size > 1 and np.any(pixel[1:] < pixel[:-1]):
        order = np.argsort(pixel, kind="stable")
        pixel = pixel[order]
    else:
        order = np.arange(pixel.size)
    new_run = np.empty(pixel.size, dtype=bool)
    new_run[:1] = True
    np.not_equal(pixel[1:], pixel[:-1], out=new_run[1:])
    starts = np.flatnonzero(new_run)
    group = np.repeat(np.arange(starts.size), np.diff(np.append(starts, pixel.size)))
    return order, starts, group


def pixel_runs(pixel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(first, back): the index of each pixel's first sample (in :func:`pixel_groups` order) and, per sample,
    the position of its pixel in ``first`` - per-pixel values ``v`` (P,) spread to the samples are ``v[back]``."""
    order, starts, group = pixel_groups(pixel)
    back = np.empty(len(order), dtype=np.intp)
    back[order] = group
    return order[starts], back


def pixel_boxes(s: Samples):
    """Each pixel's footprint (Chen, Wang & Wang 2024, eq. 3) for the shaders that shade it as one query:
    (first, back, centre (P, 2) tiles, side (P,) tiles, wi (P, 3), wo (P, 3), steps (P, 2, 2)) with
    ``first``, ``back`` of :func:`pixel_runs`.  The footprint is the pixel's centre - its surface point
    (u, v), footprint and directions (``s.centre``) - so that it does not move with the jitter of the pixel's
    samples; ``steps``: the (du, dv) of a one-pixel step in x and in y there (:class:`PixelCentres`).  A
    pixel whose centre misses the front of the patch (a partly covered pixel), or samples without
    ``centre``, take the mean (u, v) of the pixel's samples, its first sample's footprint and directions,
    and steps inf (unknown)."""
    first, back = pixel_runs(s.pixel)
    count = np.bincount(back)
    centre = np.column_stack([np.bincount(back, s.u) / count, np.bincount(back, s.v) / count])
    size, wi, wo = s.footprint[first], s.wi[first], s.wo[first]
    steps = np.full((first.size, 2, 2), np.inf)
    if s.centre is not None:
        c, p = s.centre, s.pixel[first]
        ok = c.valid[p]
        q = p[ok]
        centre[ok] = np.column_stack([c.u[q], c.v[q]])
        size[ok], wi[ok], wo[ok], steps[ok] = c.footprint[q], c.wi[q], c.wo[q], c.steps[q]
    return first, back, centre, size, wi, wo, steps


def reflectance_values(fabric: FabricModels, s: Samples, counter: Counter, *, per_pixel: bool = True) -> np.ndarray:
    """IM reflectance model f_r (M, C); with ``per_pixel`` evaluated at the first sample of each pixel."""
    if not fabric.need or len(s.u) == 0:
        return _zeros(fabric, len(s.u))
    if per_pixel:
        first, back = pixel_runs(s.pixel)
        wi, wo = s.wi[first], s.wo[first]
    else:
        back, wi, wo = slice(None), s.wi, s.wo
    comps = counter.run("reflectance", len(wi), fabric.reflectance.components, wi, wo, fabric.params,
                        need=fabric.need, warn=False)
    return combine(comps, fabric.coefficients)[back]


def blend_texture_samples(pixel: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which samples of the texture range (b < 1) run the texture model, and their texture weight.

    Per pixel with m samples of b < 1 the full blend needs W = sum (1 - b) of texture weight.  The texture
    runs at n = ceil(W) of the m samples (at least 1; all m where b = 0, so the pure texture range is
    unchanged), spread evenly over the pixel's strata (rotated by the pixel index), each weighted W / n:
    the same total texture weight with about (1 - b) of the texture work.  Returns (sample indices,
    weights)."""
    candidates = np.flatnonzero(b < 1.0)
    if candidates.size == 0:
        return candidates, np.zeros(0)
    order, starts, group = pixel_groups(pixel[candidates])
    sorted_idx = candidates[order]
    m = np.diff(np.append(starts, sorted_idx.size))
    weight_sum = np.bincount(group, 1.0 - b[sorted_idx], minlength=starts.size)
    n = np.clip(np.ceil(weight_sum - 1e-9), 1, m)
    # rank of each sample in its pixel, rotated by the pixel index; keep rank r iff floor((r + 1) n / m) >
    # floor(r n / m): exactly n of the m ranks, evenly spread (ratios of integers <= m: the 1e-9 is exact)
    rotation = pixel[sorted_idx[starts]] % m
    rank = np.arange(sorted_idx.size) - starts[group] + rotation[group]
    rank -= np.where(rank >= m[group], m[group], 0)
    q = (n / m)[group]
    keep = np.floor((rank + 1) * q + 1e-9) > np.floor(rank * q + 1e-9)
    return sorted_idx[keep], (weight_sum / n)[group[keep]]


def im_lod_values(fabric: FabricModels, s: Samples, counter: Counter, lod: Lod) -> np.ndarray:
    """The IM level of detail (module docstring): texture, blend or reflectance by the pixel footprint."""
    b = lod_weight(s.footprint, lod.f0, lod.f1)
    if not np.any(b > 0.0):  # the whole view resolves yarns
        return texture_values(fabric, s, counter)
    if np.all(b >= 1.0):  # the whole view covers many tiles
        return reflectance_values(fabric, s, counter)
    out = _zeros(fabric, len(b))
    some = np.flatnonzero(b > 0.0)  # blend and far samples: the reflectance once per pixel
    out[some] = b[some, None] * reflectance_values(fabric, s.take(some), counter)
    index, weight = blend_texture_samples(s.pixel, b)
    if index.size:
        out[index] += weight[:, None] * texture_values(fabric, s.take(index), counter)
    return out


#: footprints (tiles) over which neural-lod's network takes over from im-lod (rising) and hands back to it
#: (falling; im-lod is the reflectance model alone from its f1 = 0.5 on).  Measured on the receding plane
#: (noise-free cotton denim, 64 x 48 px, distances 5-120 mm; relative L1 per pixel against im-texture at 256
#: samples, binned by the pixel footprint; docs/neural.md "neural-lod"): the network beats the 4-sample
#: texture from ~0.12 tile on (0.055 against 0.060 at 0.12-0.15, 0.061 against 0.090 at 0.2-0.3) and the
#: reflectance model up to ~0.7 tile (0.040 against 0.050 at 0.4-0.5, 0.030 against 0.036 at 0.5-0.7); a
#: network query (~1.3 us) costs about four texture samples, so it takes over where im-lod's own blend is
#: weakest and hands back where im-lod is one cheap reflectance evaluation per pixel.
NEURAL_RISE = (0.12, 0.16)
NEURAL_FALL = (0.4, 0.5)


def network_weight(footprint) -> np.ndarray:
    """Share of neural-lod's network at pixel footprints (tiles): 0 -> 1 over :data:`NEURAL_RISE`, 1 -> 0
    over :data:`NEURAL_FALL` (smoothsteps in log footprint, :func:`lod_weight`)."""
    return lod_weight(footprint, *NEURAL_RISE) * (1.0 - lod_weight(footprint, *NEURAL_FALL))


def dither(pixel: np.ndarray) -> np.ndarray:
    """Per pixel index a threshold in [0, 1): the additive recurrence frac((p + 0.5) / golden ratio) (the R1
    low-discrepancy sequence), so that in a band where the weight is w about a share w of neighbouring pixels
    falls below it, evenly spread."""
    return np.mod((np.asarray(pixel, dtype=np.float64) + 0.5) * 0.6180339887498949, 1.0)


def network_samples(s: Samples) -> np.ndarray:
    """Which samples neural-lod shades with the network (bool, M): all samples of the pixels whose dither
    threshold lies below the network weight of the pixel's footprint (its box's, :func:`pixel_boxes`)."""
    first, back, _, size, _, _, _ = pixel_boxes(s)
    return (dither(s.pixel[first]) < network_weight(size))[back]


def neural_model(fabric: FabricModels, kind: str | None = None):
    """The scene's weave as the network kind ``kind`` (default: the kind of the registry's ``neural-lod``
    shader; its shipped weights), built once; ConfigError if the fabric's components are not the network's (it
    learns the IM texture)."""
    cached = fabric._neural
    if cached is None:
        from clothlab.config.build import model_from_weave

        cached = model_from_weave(fabric.weave, kind=shader_kind("neural-lod")[0] if kind is None else kind)
        if tuple(cached.component_names) != tuple(fabric.texture.component_names):
            raise ConfigError(f"neural-lod learns the Irawan-Marschner components {list(cached.component_names)}; "
                              f"the scene's fabric has {list(fabric.texture.component_names)}", field="fabric.fit")
        fabric._neural = cached
    return cached


def network_pixel_values(fabric: FabricModels, s: Samples, counter: Counter) -> np.ndarray:
    """The network's f_r (M, C), one query per pixel shared by its samples: the pixel's box footprint
    (:func:`pixel_boxes`: at the pixel's centre, with its directions), and the reflectance model's
    components there as the base of a residual network (computed once per pixel)."""
    if not fabric.need or len(s.u) == 0:
        return _zeros(fabric, len(s.u))
    model = neural_model(fabric)
    first, back, centre, size, wi, wo, _ = pixel_boxes(s)
    comps = counter.run("reflectance", first.size, fabric.reflectance.components, wi, wo, fabric.params,
                        need=fabric.need, warn=False)
    reference = np.column_stack([comps[k] if k in comps else np.zeros(first.size)
                                 for k in fabric.reflectance.component_names])
    net = counter.run(model.kind, first.size, model.query, centre, size, wi, wo, fabric.params,
                      reference=reference)
    return combine({k: net[k] for k in fabric.need}, fabric.coefficients)[back]


def neural_lod_values(fabric: FabricModels, s: Samples, counter: Counter, lod: Lod) -> np.ndarray:
    """neural-lod: per pixel the cheapest estimator of its footprint average that meets the error, by the
    crossovers measured for the weave's network (:mod:`clothlab.render.neural_lod`); for a network without
    them (its sidecar has no ``estimator_choice``) the documented default (module docstring): the network
    or im-lod, chosen by the footprint."""
    from clothlab.render.neural_lod import estimator_choice, pixel_values

    choice = estimator_choice(fabric.weave)
    if choice is not None:
        if not fabric.need or len(s.u) == 0:
            return _zeros(fabric, len(s.u))
        _, back, centre, size, wi, wo, steps = pixel_boxes(s)
        return pixel_values(fabric, neural_model(fabric), choice, centre, size, wi, wo, counter, steps)[back]
    chosen = network_samples(s) if np.any(network_weight(s.footprint) > 0.0) else None  # per pixel only if needed
    if chosen is None or not chosen.any():
        return im_lod_values(fabric, s, counter, lod)
    if chosen.all():
        return network_pixel_values(fabric, s, counter)
    out = _zeros(fabric, len(s.u))
    network, rest = np.flatnonzero(chosen), np.flatnonzero(~chosen)
    out[network] = network_pixel_values(fabric, s.take(network), counter)
    out[rest] = im_lod_values(fabric, s.take(rest), counter, lod)
    return out


def kang_values(fabric: FabricModels, s: Samples, counter: Counter, *, lod: bool, kind: str | None = None
                ) -> np.ndarray:
    """The self-filtering point shader of ``kind`` (Kang's: :meth:`FabricModels.kang`) f_r (M, C), counted
    under its kind; ``lod``: with the pixel footprint (eq. 5, optionally Algorithm 1)."""
    kind = shader_kind("kang-lod")[0] if kind is None else kind
    texture, params, coefficients = fabric.kang(kind)
    if len(s.u) == 0:
        return _zeros(fabric, 0)
    footprint = np.minimum(s.footprint, MAX_FOOTPRINT) if lod else None
    view = None
    if lod and fabric.spec.kang.prefilter:
        view = s.distance / fabric.spec.kang.view_distance_mm
    comps = counter.run(kind, len(s.u), texture.components, s.u, s.v, s.wi, s.wo, params,
                        footprint=footprint, view_distance=view)
    return combine(comps, coefficients)


#: Shading policies by name (what :data:`clothlab.models.registry.SHADERS` names for each shader): policy ->
#: f(fabric, kind, samples, counter, lod) -> f_r (M, C) of the scene's fabric as ``kind`` (module docstring).
POLICIES = {
    "lod": lambda fabric, kind, s, counter, lod: im_lod_values(kind_models(fabric, kind), s, counter, lod),
    "texture": lambda fabric, kind, s, counter, lod: texture_values(kind_models(fabric, kind), s, counter),
    "reflectance": lambda fabric, kind, s, counter, lod: reflectance_values(kind_models(fabric, kind), s, counter),
    "filtered-lod": lambda fabric, kind, s, counter, lod: kang_values(fabric, s, counter, lod=True, kind=kind),
    "filtered-texture": lambda fabric, kind, s, counter, lod: kang_values(fabric, s, counter, lod=False, kind=kind),
    "network-lod": lambda fabric, kind, s, counter, lod: neural_lod_values(fabric, s, counter, lod),
}
#: policies whose every covered pixel runs a texture model (the others: the reflectance model alone, or a
#: per-pixel choice by the footprint, :data:`FOOTPRINT_POLICIES`)
TEXTURE_POLICIES = ("texture", "filtered-lod", "filtered-texture")
#: policies that choose per sample by the pixel footprint between the texture and the reflectance model
FOOTPRINT_POLICIES = ("lod", "network-lod")
#: policies that shade a pixel's footprint as one box at the pixel's centre (:func:`pixel_boxes`): the renderer
#: traces the pixel centres for them (``Samples.centre``) when the samples are not the centres
CENTRE_POLICIES = ("network-lod",)
#: the reflectance and texture counters of the scene's fabric, then those of the kinds whose shaders count
#: their own model (a self-filtering texture, a network): the ``<name>_evaluations`` of a render's stats
COUNTERS = ("texture", "reflectance", *dict.fromkeys(
    kind for kind, policy in SHADER_KINDS.values() if policy in ("filtered-lod", "filtered-texture", "network-lod")))
#: the counters of models evaluated per sample (the timed models of :func:`clothlab.render.render.compare_lod`)
SAMPLE_COUNTERS = ("texture", "reflectance", *dict.fromkeys(
    kind for kind, policy in SHADER_KINDS.values() if policy in ("filtered-lod", "filtered-texture")))


def reference_shader(shader: str) -> str:
    """The antialiasing reference of ``shader`` (supersampled by :func:`clothlab.render.render.compare_lod`):
    the texture-level shader of its kind (policy ``texture`` or ``filtered-texture``), or, for a kind with none
    (a network learns the scene fabric's texture), the default kind's."""
    from clothlab.models.registry import DEFAULT_KIND

    kind = shader_kind(shader)[0]
    for want in (kind, DEFAULT_KIND):
        for name, (k, policy) in SHADER_KINDS.items():
            if k == want and policy in ("texture", "filtered-texture"):
                return name
    raise ConfigError(f"shader {shader!r} has no texture-level reference shader", field="shader")


def shade(shader: str, fabric: FabricModels, samples: Samples, lod: Lod, counter: Counter) -> np.ndarray:
    """f_r (M, C) of ``shader`` at the samples: its kind's models shaded by its policy (the registry's
    :data:`~clothlab.models.registry.SHADERS`, :data:`POLICIES`)."""
    kind, policy = shader_kind(shader)
    return POLICIES[policy](fabric, kind, samples, counter, lod)
