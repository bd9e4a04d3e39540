"""A clothlab fabric as the Mitsuba plugin evaluates it: models, parameters, coefficients and the shading policy
of ``clothlab render`` (:mod:`clothlab.render.shade`), in numpy only (no Mitsuba import here).

Policy (the renderer's, by what the model can do; :class:`clothlab.models.base.Model` capabilities):

- ``lod`` = ``auto`` and a texture model that does not filter itself (irawan, surface): the im-lod rule of
  :mod:`clothlab.render.shade` - texture model where the pixel footprint f <= f0 tiles, reflectance model where
  f >= f1, the C^1 smoothstep blend (:func:`clothlab.render.shade.lod_weight`) between.  The blend is
  evaluated in full at every sample (both models): the renderer's thinning of texture samples in blend pixels
  (:func:`~clothlab.render.shade.blend_texture_samples`) is a cost saving with the same expected value.
- a texture model that takes the footprint (kang, neural): that model with the footprint at every sample
  (kang-lod without Algorithm 1).
- no texture model (lambert, oren-nayar, the composites): the reflectance model.
- ``lod`` = ``texture`` / ``reflectance`` force one model (im-texture / im-reflectance).

Directions are clothlab's fabric frame (z normal, y warp, x weft; docs/design.md principle 1) with
``wi`` towards the light and ``wo`` towards the viewer, as every clothlab model takes them.  A parameter
``orientation`` (the weave turned about the normal, :mod:`clothlab.models.base`) is taken out of the parameters
and applied here to both models: the directions are turned into the weave's frame
(:func:`clothlab.frames.to_weave_frame`), and texture points (u, v) are the weave's own tile coordinates (the
plugin turns its uv frame by the orientation), so the texture model - which refuses an orientation itself -
and the reflectance model see the same weave.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from clothlab.errors import ConfigError

LOD_MODES = ("auto", "texture", "reflectance")


@dataclass
class ClothMaterial:
    """An evaluable fabric: ``reflectance`` (the tile-averaged model), ``texture`` (its texture model or None),
    resolved ``params``, ``coefficients`` {name: (C,)}, ``channels``, ``need`` (the components to compute),
    LoD thresholds ``f0``, ``f1`` (tiles), ``lod`` mode, texture ``noise``; ``source`` says where it came from."""

    reflectance: object
    texture: object | None
    params: dict
    coefficients: dict
    channels: tuple
    need: tuple
    f0: float = 0.1
    f1: float = 0.5
    lod: str = "auto"
    noise: bool = True
    source: str = ""
    orientation: float = 0.0
    _sampler: object = field(default=None, repr=False)

    @property
    def kind(self) -> str:
        return self.reflectance.kind

    @property
    def policy(self) -> str:
        """Which rule shades a sample: ``im-lod``, ``footprint-texture``, ``reflectance`` or ``texture``."""
        if self.lod == "reflectance" or self.texture is None:
            return "reflectance"
        if self.lod == "texture":
            return "texture"
        return "footprint-texture" if self.reflectance.texture_filters else "im-lod"

    # ------------------------------------------------------------------------------------------ evaluation

    def _combine(self, comps, n):
        from clothlab.models.components import combine

        comps = {k: v for k, v in comps.items() if k in self.need}
        if not comps:
            return np.zeros((n, len(self.channels)))
        return combine(comps, self.coefficients)

    def reflectance_values(self, wi, wo) -> np.ndarray:
        """f_r (N, C) of the tile-averaged model at weave-frame wi (to the light), wo (to the viewer)."""
        if not self.need or len(wi) == 0:
            return np.zeros((len(wi), len(self.channels)))
        comps = self.reflectance.components(wi, wo, self.params, need=self.need, warn=False)
        return self._combine(comps, len(wi))

    def texture_values(self, u, v, wi, wo, footprint=None) -> np.ndarray:
        """f_r (N, C) of the texture model at texture points (u, v) (tiles)."""
        if not self.need or len(wi) == 0:
            return np.zeros((len(wi), len(self.channels)))
        if self.reflectance.texture_filters:
            from clothlab.render.shade import MAX_FOOTPRINT

            fp = None if footprint is None else np.minimum(np.asarray(footprint, dtype=np.float64), MAX_FOOTPRINT)
            comps = self.texture.components(u, v, wi, wo, self.params, footprint=fp)
        else:
            comps = self.texture.components(u, v, wi, wo, self.params, need=self.need, noise=self.noise, warn=False)
        return self._combine(comps, len(wi))

    def values(self, wi, wo, u=None, v=None, footprint=None, *, lod_override=None) -> np.ndarray:
        """f_r (N, C) >= 0 by the policy (module docstring); 0 where wi_z <= 0 or wo_z <= 0 (reflection only).
        ``u``, ``v`` texture coordinates (tiles), ``footprint`` the pixel footprint (tiles; None: 0)."""
        wi = np.atleast_2d(np.asarray(wi, dtype=np.float64))
        wo = np.atleast_2d(np.asarray(wo, dtype=np.float64))
        if self.orientation != 0.0:
            from clothlab.frames import to_weave_frame

            wi, wo = to_weave_frame(wi, self.orientation), to_weave_frame(wo, self.orientation)
        n = len(wi)
        out = np.zeros((n, len(self.channels)))
        front = np.flatnonzero((wi[:, 2] > 0.0) & (wo[:, 2] > 0.0))
        if front.size == 0:
            return out
        policy = lod_override or self.policy
        if policy == "reflectance":
            out[front] = self.reflectance_values(wi[front], wo[front])
            return out
        u = np.zeros(n) if u is None else np.broadcast_to(np.asarray(u, dtype=np.float64), (n,))
        v = np.zeros(n) if v is None else np.broadcast_to(np.asarray(v, dtype=np.float64), (n,))
        fp = np.zeros(n) if footprint is None else np.broadcast_to(np.asarray(footprint, dtype=np.float64), (n,))
        if policy == "footprint-texture":
            out[front] = self.texture_values(u[front], v[front], wi[front], wo[front], fp[front])
            return out
        if policy == "texture":
            out[front] = self.texture_values(u[front], v[front], wi[front], wo[front])
            return out
        from clothlab.render.shade import lod_weight

        b = lod_weight(fp[front], self.f0, self.f1)
        far = front[b > 0.0]
        if far.size:
            out[far] = b[b > 0.0, None] * self.reflectance_values(wi[far], wo[far])
        near = front[b < 1.0]
        if near.size:
            out[near] += (1.0 - b[b < 1.0])[:, None] * self.texture_values(u[near], v[near], wi[near], wo[near])
        return out

    def sampler(self):
        """The importance sampler of this material (:class:`clothlab.mitsuba.sampling.LobeSampler`), built once."""
        if self._sampler is None:
            from clothlab.mitsuba.sampling import LobeSampler

            self._sampler = LobeSampler(lambda wi, wo: self.values(wi, wo, lod_override="reflectance").mean(axis=1))
        return self._sampler


# ---------------------------------------------------------------------------------------------- building


def _coefficients_for(model, coefficients: dict, channels) -> dict:
    """``coefficients`` {name: (C,)} mapped onto the coefficient names of ``model``'s components: a name the model
    uses is kept; ``kd_warp`` / ``kd_weft`` fall back to ``kd`` (as
    :func:`clothlab.models.components.per_yarn_coefficients` does), ``kd`` to ``kd_warp``."""
    from clothlab.models.components import coefficient_name

    out = {}
    for component in model.component_names:
        name = coefficient_name(component)
        value = coefficients.get(name)
        if value is None and name in ("kd_warp", "kd_weft"):
            value = coefficients.get("kd")
        if value is None and name == "kd":
            value = coefficients.get("kd_warp")
        if value is not None:
            out[name] = np.broadcast_to(np.atleast_1d(np.asarray(value, dtype=np.float64)), (len(channels),)).copy()
    return out


def _needed(model, coefficients, weave, names) -> tuple:
    from clothlab.render.shade import _needed as needed

    return tuple(name for name in names if needed(name, coefficients, weave))


def material_from_model(model, params, coefficients, channels, *, lod: str = "auto", f0: float = 0.1,
                        f1: float = 0.5, seed: int = 0, noise: bool = True, source: str = "") -> ClothMaterial:
    """A :class:`ClothMaterial` of a built model with its (unresolved) parameters and coefficients."""
    if lod not in LOD_MODES:
        raise ConfigError(f"expected lod one of {', '.join(LOD_MODES)}, got {lod!r}", field="lod")
    if not (0.0 < f0 < f1):
        raise ConfigError(f"expected 0 < f0 < f1, got f0 = {f0:g}, f1 = {f1:g}", field="f1")
    channels = tuple(channels)
    coefficients = _coefficients_for(model, coefficients, channels)
    from clothlab.models.base import split_orientation

    resolved = model.resolve(params)  # validates (ParameterError names the parameter)
    resolved, orientation = split_orientation(resolved)
    texture = None
    if model.has_texture and lod != "reflectance":
        texture = model.texture(seed=seed)
        if not model.texture_filters:
            texture.resolve(resolved)  # validates before rendering (orientation was taken out above)
    need = _needed(model, coefficients, model.weave, model.component_names)
    return ClothMaterial(model, texture, resolved, coefficients, channels, need, f0=f0, f1=f1, lod=lod,
                         noise=noise, source=source, orientation=orientation)


def load_material(*, fit=None, preset=None, kind=None, lod: str = "auto", f0: float = 0.1, f1: float = 0.5,
                  seed: int = 0, noise: bool = True, base_dir=None) -> ClothMaterial:
    """The material of a fit directory (``fit``: any registered kind, :func:`clothlab.fit.store.load_fitted`)
    or of a weave preset (``preset``: ``cotton-denim`` or ``preset:cotton-denim``, a ``pattern:`` or a .wv
    path) as the registry's model ``kind`` (default: the registry's default kind) at its default parameters,
    with the scene defaults of ``clothlab render`` as coefficients
    (:data:`clothlab.render.scene.DEFAULT_COEFFICIENTS`)."""
    base = Path.cwd() if base_dir is None else Path(base_dir)
    if (fit is None) == (preset is None):
        raise ConfigError("give exactly one of fit (a fit directory) and preset (a weave preset)", field="fit")
    if fit is not None:
        from clothlab.fit.store import load_fitted

        path = Path(fit).expanduser()
        path = path if path.is_absolute() else base / path
        if not path.is_dir():
            raise ConfigError(f"fit directory '{path}' not found", path=path, field="fit")
        model, params, coefficients, channels = load_fitted(path)
        if kind is not None and kind != model.kind:
            raise ConfigError(f"the fit in {path} is of kind {model.kind!r}, not {kind!r}", path=path, field="kind")
        return material_from_model(model, params, coefficients, channels, lod=lod, f0=f0, f1=f1, seed=seed,
                                   noise=noise, source=str(path))
    from clothlab.config.build import model_from_weave
    from clothlab.models.registry import DEFAULT_KIND
    from clothlab.render.scene import DEFAULT_CHANNELS, DEFAULT_COEFFICIENTS
    from clothlab.weave.presets import PRESET_PREFIX

    spec = str(preset).strip()
    if ":" not in spec and not spec.endswith(".wv"):
        spec = PRESET_PREFIX + spec
    model = model_from_weave(spec, base, kind=kind or DEFAULT_KIND)
    return material_from_model(model, {}, DEFAULT_COEFFICIENTS, DEFAULT_CHANNELS, lod=lod, f0=f0, f1=f1, seed=seed,
                               noise=noise, source=spec)


def material_from_scene(scene, shader: str = "im-lod") -> ClothMaterial:
    """The material ``clothlab render --shader shader`` shades ``scene``'s fabric with (same models, parameters,
    coefficients, LoD thresholds and seed; :class:`clothlab.render.shade.FabricModels`): im-* the fabric (its
    fit or its weave as the default kind), kang-* ``fabric.kang``, surface-* the surface model: the shader's
    kind and policy as the registry declares them.  neural-lod (a per-pixel network query) has no per-sample
    form: ConfigError."""
    from clothlab.render.shade import FabricModels, kind_models, shader_kind

    kind, policy = shader_kind(shader)
    fabric = FabricModels.build(scene.fabric)
    common = dict(f0=scene.lod.f0, f1=scene.lod.f1, seed=scene.fabric.seed, noise=scene.fabric.noise,
                  source=str(scene.source or ""))
    if policy in ("lod", "texture", "reflectance"):
        models = kind_models(fabric, kind)
        return material_from_model(models.reflectance, models.params, models.coefficients, models.channels,
                                   lod="auto" if policy == "lod" else policy, **common)
    if policy in ("filtered-lod", "filtered-texture"):
        texture, params, coefficients = fabric.kang(kind)
        material = material_from_model(texture.model, params, coefficients, fabric.channels, lod="auto", **common)
        if policy == "filtered-texture":  # footprint None: full yarn detail (alpha = 0 of Kang's eq. 5)
            material.lod = "texture"
        return material
    raise ConfigError(f"shader {shader!r} queries a network once per pixel and has no Mitsuba form; use im-lod, "
                      "kang-lod or surface-lod", field="shader")
