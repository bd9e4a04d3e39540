"""Scene description for :mod:`clothlab.render`: a cloth patch, a pinhole camera, one light, the fabric.

A scene is read from YAML (:func:`load_scene`) or built from a dict (:func:`scene_from_dict`); every
mistake raises :class:`~clothlab.errors.ConfigError` naming the file and the field (``camera.fov_deg``).
Lengths are in millimetres, angles in degrees, world z is "up".

```yaml
patch:
  shape: flat                 # flat (in the plane z = center.z) | cylinder (axis along world y)
  size_mm: [400, 400]         # extent along the patch's s (world x / around the cylinder) and t (world y)
  radius_mm: 20               # cylinder only
  center: [0, 0, 0]           # flat: patch centre; cylinder: a point of the axis
  tile_mm: [1.0, 2.0]         # weave tile size along the weft (u) and the warp (v); a number = square
  warp_angle_deg: 0           # warp direction, counter-clockwise from the patch's t axis (world y)
camera:
  position: [0, -60, 60]
  look_at: [0, 0, 0]
  up: [0, 0, 1]
  fov_deg: 30                 # vertical field of view
  resolution: [160, 120]      # width, height in pixels
light:
  type: directional           # directional | point
  direction: [0.3, -0.2, 1]   # towards the light (directional)
  position: [0, 0, 100]       # point light, mm
  intensity: 1.0              # directional: irradiance E at normal incidence; point: I, E = I / d^2 (d in m)
fabric:
  weave: preset:cotton-denim  # or a .wv file (relative to the scene file)
  params: {}                  # Irawan-Marschner parameters overriding the weave's
  coefficients: {kd: [0.2, 0.26, 0.42], ks_warp: [0.12, 0.12, 0.12], ks_weft: [0.02, 0.03, 0.07]}
  channels: [R, G, B]
  fit: null                   # a fit directory (kind irawan): its weave, parameters, coefficients, channels
  seed: 0                     # texture noise realisation
  noise: true                 # the IM texture noise of sec. 7.2.1 (false: the noise-free texture that the
                              # neural surrogate learns; im-texture / im-lod / neural-lod compare on it)
  kang:                       # the Kang shader in the same scene (optional)
    fit: null                 # a fit directory of kind kang, or:
    params: {}                # Kang parameters (defaults otherwise)
    coefficients: null        # default: kd_warp = kd_weft = kd, ks_* as the IM coefficients
    prefilter: false          # Algorithm 1 (adaptive prefiltering) in kang-lod
    view_distance_mm: 100     # Algorithm 1 tolerance 1 / (distance / view_distance_mm)
lod:
  f0: 0.1                     # footprint (tiles) below which only the texture model runs
  f1: 0.5                     # footprint (tiles) above which only the reflectance model runs
render:
  spp: 1
  seed: 0
  exposure: 0.0               # PNG exposure in stops
```
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from clothlab.errors import ConfigError

SHAPES = ("flat", "cylinder")
MAX_MAGNITUDE = 1e9
"""Largest magnitude of a scene number or vector component (mm for lengths: 1000 km), so products of
positions and directions cannot overflow."""
MAX_COEFFICIENT = 1e6
"""Largest kd / ks coefficient accepted in a scene (they scale a BRDF in 1/sr)."""
RENDER_BYTES_PER_SAMPLE = 8 * 48
"""Working memory of one camera sample while shading, besides 4 float64 per channel (about 48 float64 values:
positions, normals, directions, texture coordinates, components); measured: 512 x 384 pixels at 1 and 4
samples differ by about 440 bytes per sample with RGB."""
MAX_RENDER_BYTES = 4 << 30
"""Largest estimated working memory of a render (4 GiB); :func:`check_render_memory`."""
LIGHT_TYPES = ("directional", "point")
#: LoD thresholds (pixel footprint in weave tiles), chosen from the receding-plane error measurements
#: (render_benchmark; docstring of :mod:`clothlab.render.shade`).
DEFAULT_F0 = 0.1
DEFAULT_F1 = 0.5
DEFAULT_COEFFICIENTS = {"kd": (0.2, 0.26, 0.42), "ks_warp": (0.12, 0.12, 0.12), "ks_weft": (0.02, 0.03, 0.07)}
DEFAULT_CHANNELS = ("R", "G", "B")


@dataclass(frozen=True)
class Patch:
    """The cloth surface: shape, size (mm), weave tile size (mm, along weft u and warp v), warp angle."""

    shape: str = "flat"
    size_mm: tuple[float, float] = (100.0, 100.0)
    center: tuple[float, float, float] = (0.0, 0.0, 0.0)
    tile_mm: tuple[float, float] = (1.0, 1.0)
    warp_angle_deg: float = 0.0
    radius_mm: float = 0.0


@dataclass(frozen=True)
class Camera:
    """Pinhole camera: position and look-at (mm), up vector, vertical field of view (deg), (width, height)."""

    position: tuple[float, float, float]
    look_at: tuple[float, float, float] = (0.0, 0.0, 0.0)
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)
    fov_deg: float = 30.0
    resolution: tuple[int, int] = (64, 48)

    @property
    def distance(self) -> float:
        return float(np.linalg.norm(np.subtract(self.position, self.look_at)))

    def at_distance(self, distance_mm: float) -> Camera:
        """The same view direction, moved to ``distance_mm`` from the look-at point."""
        offset = np.subtract(self.position, self.look_at)
        position = np.asarray(self.look_at) + offset * (float(distance_mm) / np.linalg.norm(offset))
        return replace(self, position=tuple(float(c) for c in position))


@dataclass(frozen=True)
class Light:
    """A directional light (direction towards the light, irradiance ``intensity`` at normal incidence) or a
    point light (position in mm, intensity I in W/sr; irradiance I / d^2 with d in metres)."""

    type: str = "directional"
    direction: tuple[float, float, float] = (0.0, 0.0, 1.0)
    position: tuple[float, float, float] = (0.0, 0.0, 100.0)
    intensity: float = 1.0


@dataclass(frozen=True)
class KangSpec:
    """The Kang shader of the scene: parameters, coefficients (None: derived from the IM ones), Algorithm 1."""

    params: dict = field(default_factory=dict)
    coefficients: dict | None = None
    prefilter: bool = False
    view_distance_mm: float = 100.0
    fit: Path | None = None


@dataclass(frozen=True)
class Fabric:
    """The fabric: weave spec (preset:<name> or a .wv path), IM parameters and coefficients, or a fit dir."""

    weave: str = "preset:cotton-denim"
    params: dict = field(default_factory=dict)
    coefficients: dict = field(default_factory=lambda: {k: np.array(v) for k, v in DEFAULT_COEFFICIENTS.items()})
    channels: tuple[str, ...] = DEFAULT_CHANNELS
    fit: Path | None = None
    seed: int = 0
    noise: bool = True
    kang: KangSpec = field(default_factory=KangSpec)
    base_dir: Path = field(default_factory=Path.cwd)


@dataclass(frozen=True)
class Lod:
    """Footprint thresholds (weave tiles) of the IM level of detail: texture below f0, reflectance above f1."""

    f0: float = DEFAULT_F0
    f1: float = DEFAULT_F1


@dataclass(frozen=True)
class Scene:
    patch: Patch
    camera: Camera
    light: Light
    fabric: Fabric = field(default_factory=Fabric)
    lod: Lod = field(default_factory=Lod)
    spp: int = 1
    seed: int = 0
    exposure: float = 0.0
    source: str | None = None


# ---------------------------------------------------------------------------------------------- parsing


class _Reader:
    """Field access with errors that name the file and the dotted field."""

    def __init__(self, source):
        self.source = source

    def error(self, field_name, message):
        return ConfigError(message, path=self.source, field=field_name)

    def section(self, data, name, required=True):
        value = data.get(name) if isinstance(data, dict) else None
        if value is None:
            if required:
                raise self.error(name, "missing section")
            return {}
        if not isinstance(value, dict):
            raise self.error(name, f"expected a mapping, got {value!r}")
        return value

    def known(self, data, prefix, allowed):
        for key in data:
            if key not in allowed:
                raise self.error(f"{prefix}.{key}", f"unknown field; expected one of {', '.join(allowed)}")

    def number(self, data, prefix, name, default=None, *, minimum=None, exclusive=False, maximum=None):
        value = data.get(name, default)
        where = f"{prefix}.{name}"
        if value is None:
            raise self.error(where, "missing value")
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise self.error(where, f"expected a finite number, got {value!r}")
        if abs(value) > MAX_MAGNITUDE:
            raise self.error(where, f"expected a number within +-{MAX_MAGNITUDE:g}, got {value!r}")
        if minimum is not None and (value <= minimum if exclusive else value < minimum):
            raise self.error(where, f"expected a number {'>' if exclusive else '>='} {minimum}, got {value!r}")
        if maximum is not None and value > maximum:
            raise self.error(where, f"expected a number <= {maximum}, got {value!r}")
        return float(value)

    def vector(self, data, prefix, name, n, default=None, *, positive=False, nonzero=False):
        value = data.get(name, default)
        where = f"{prefix}.{name}"
        if value is None:
            raise self.error(where, f"missing value; expected a list of {n} numbers")
        if isinstance(value, int | float) and not isinstance(value, bool) and n == 2 and positive:
            value = [value, value]
        if (not isinstance(value, list | tuple) or len(value) != n
                or not all(isinstance(c, int | float) and not isinstance(c, bool) and math.isfinite(c)
                           for c in value)):
            raise self.error(where, f"expected a list of {n} finite numbers, got {value!r}")
        if not all(abs(c) <= MAX_MAGNITUDE for c in value):
            raise self.error(where, f"expected numbers within +-{MAX_MAGNITUDE:g} (mm), got {value!r}")
        if positive and not all(c > 0 for c in value):
            raise self.error(where, f"expected positive numbers, got {value!r}")
        if nonzero and not any(c != 0 for c in value):
            raise self.error(where, f"expected a non-zero vector, got {value!r}")
        return tuple(float(c) for c in value)

    def integer(self, data, prefix, name, default, *, minimum=1):
        value = data.get(name, default)
        if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
            raise self.error(f"{prefix}.{name}", f"expected an integer >= {minimum}, got {value!r}")
        return int(value)

    def choice(self, data, prefix, name, default, choices):
        value = data.get(name, default)
        if value not in choices:
            raise self.error(f"{prefix}.{name}", f"expected one of {', '.join(choices)}, got {value!r}")
        return value


def _coefficients(reader, value, where, channels=None):
    if not isinstance(value, dict) or not value:
        raise reader.error(where, f"expected a mapping of coefficient name -> list of channel values, got {value!r}")
    out = {}
    for name, coef in value.items():
        arr = np.atleast_1d(np.asarray(coef, dtype=object))
        if arr.ndim != 1 or not all(isinstance(c, int | float) and not isinstance(c, bool) for c in arr):
            raise reader.error(f"{where}.{name}", f"expected a number or a list of numbers, got {coef!r}")
        for i, c in enumerate(arr.tolist()):
            if not (math.isfinite(c) and 0.0 <= c <= MAX_COEFFICIENT):
                spot = f"{where}.{name}" + (f"[{i}]" if isinstance(coef, list) else "")
                raise reader.error(spot, f"expected a coefficient in [0, {MAX_COEFFICIENT:g}] (a negative one "
                                   f"gives negative radiance), got {c!r}")
        out[str(name)] = arr.astype(np.float64)
    sizes = {len(c) for c in out.values()}
    if len(sizes - {1}) > 1 or (channels is not None and sizes - {1, len(channels)}):
        raise reader.error(where, f"coefficients have inconsistent channel counts {sorted(sizes)}"
                           + (f"; channels are {list(channels)}" if channels is not None else ""))
    return out


def _path(base_dir, value, reader, where):
    if not isinstance(value, str) or not value.strip():
        raise reader.error(where, f"expected a path, got {value!r}")
    path = Path(value).expanduser()
    path = path if path.is_absolute() else Path(base_dir) / path
    if not path.is_dir():
        raise reader.error(where, f"fit directory '{path}' not found")
    return path


def render_bytes(resolution, spp: int, channels: int = 3) -> int:
    """Estimated working memory (bytes) of rendering ``resolution`` = (width, height) at ``spp`` samples."""
    width, height = resolution
    return int(width) * int(height) * int(spp) * (RENDER_BYTES_PER_SAMPLE + 8 * 4 * int(channels))


def check_render_memory(resolution, spp: int, channels: int = 3, *, source=None) -> None:
    """ConfigError naming ``camera.resolution`` and ``render.spp`` when :func:`render_bytes` exceeds
    :data:`MAX_RENDER_BYTES`."""
    need = render_bytes(resolution, spp, channels)
    if need > MAX_RENDER_BYTES:
        raise ConfigError(
            f"rendering {resolution[0]}x{resolution[1]} pixels at {spp} samples per pixel needs about "
            f"{need / 2**30:.1f} GiB (at most {MAX_RENDER_BYTES / 2**30:.0f} GiB); lower camera.resolution or "
            "render.spp (--spp)", path=source, field="camera.resolution")


def _check_params(r: _Reader, params: dict, where: str) -> dict:
    """fabric.params: Irawan-Marschner parameter names and their declared physical ranges."""
    from clothlab.errors import ParameterError
    from clothlab.weave.parameters import IRAWAN_PARAMS

    for name, value in params.items():
        if name not in IRAWAN_PARAMS:
            raise r.error(f"{where}.{name}", f"unknown parameter; expected one of {', '.join(IRAWAN_PARAMS.names())}")
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise r.error(f"{where}.{name}", f"expected a finite number, got {value!r}")
        try:
            IRAWAN_PARAMS[name].check(float(value), f"{where}.{name}")
        except ParameterError as err:
            raise r.error(f"{where}.{name}", err.detail) from None
    return params


def scene_from_dict(data: dict, *, source=None, base_dir=None) -> Scene:
    """A :class:`Scene` from a parsed YAML mapping; ConfigError naming the field for any mistake."""
    r = _Reader(source)
    base_dir = Path(base_dir) if base_dir is not None else (Path(source).parent if source else Path.cwd())
    if not isinstance(data, dict):
        raise ConfigError(f"a scene file must be a mapping with sections patch, camera, light, fabric; got "
                          f"{type(data).__name__}", path=source)
    r.known(data, "scene", ("patch", "camera", "light", "fabric", "lod", "render"))
    d = r.section(data, "patch")
    r.known(d, "patch", ("shape", "size_mm", "center", "tile_mm", "warp_angle_deg", "radius_mm"))
    shape = r.choice(d, "patch", "shape", "flat", SHAPES)
    patch = Patch(
        shape=shape,
        size_mm=r.vector(d, "patch", "size_mm", 2, positive=True),
        center=r.vector(d, "patch", "center", 3, (0.0, 0.0, 0.0)),
        tile_mm=r.vector(d, "patch", "tile_mm", 2, positive=True),
        warp_angle_deg=r.number(d, "patch", "warp_angle_deg", 0.0),
        radius_mm=r.number(d, "patch", "radius_mm", None if shape == "cylinder" else 0.0, minimum=0.0,
                           exclusive=shape == "cylinder"),
    )
    if shape == "cylinder" and patch.size_mm[0] > 2.0 * math.pi * patch.radius_mm:
        raise r.error("patch.size_mm", f"the arc length {patch.size_mm[0]:g} mm exceeds the cylinder's "
                      f"circumference {2 * math.pi * patch.radius_mm:.4g} mm")

    d = r.section(data, "camera")
    r.known(d, "camera", ("position", "look_at", "up", "fov_deg", "resolution"))
    resolution = d.get("resolution", (64, 48))
    if (not isinstance(resolution, list | tuple) or len(resolution) != 2
            or not all(isinstance(c, int) and not isinstance(c, bool) and 1 <= c <= 16384 for c in resolution)):
        raise r.error("camera.resolution", f"expected [width, height] in pixels (integers 1..16384), got "
                      f"{resolution!r}")
    camera = Camera(position=r.vector(d, "camera", "position", 3),
                    look_at=r.vector(d, "camera", "look_at", 3, (0.0, 0.0, 0.0)),
                    up=r.vector(d, "camera", "up", 3, (0.0, 0.0, 1.0), nonzero=True),
                    fov_deg=r.number(d, "camera", "fov_deg", 30.0, minimum=0.0, exclusive=True, maximum=179.0),
                    resolution=(int(resolution[0]), int(resolution[1])))
    forward = np.subtract(camera.look_at, camera.position)
    if np.linalg.norm(forward) == 0.0:
        raise r.error("camera.look_at", "the camera looks at its own position")
    if np.linalg.norm(np.cross(forward, camera.up)) <= 1e-9 * np.linalg.norm(forward) * np.linalg.norm(camera.up):
        raise r.error("camera.up", f"up {list(camera.up)} is parallel to the view direction")

    d = r.section(data, "light")
    r.known(d, "light", ("type", "direction", "position", "intensity"))
    kind = r.choice(d, "light", "type", "directional", LIGHT_TYPES)
    light = Light(type=kind,
                  direction=r.vector(d, "light", "direction", 3, None if kind == "directional" else (0, 0, 1),
                                     nonzero=True),
                  position=r.vector(d, "light", "position", 3, None if kind == "point" else (0, 0, 100)),
                  intensity=r.number(d, "light", "intensity", 1.0, minimum=0.0))

    fabric = _fabric(r, r.section(data, "fabric", required=False), base_dir)

    d = r.section(data, "lod", required=False)
    r.known(d, "lod", ("f0", "f1"))
    lod = Lod(f0=r.number(d, "lod", "f0", DEFAULT_F0, minimum=0.0, exclusive=True),
              f1=r.number(d, "lod", "f1", DEFAULT_F1, minimum=0.0, exclusive=True))
    if lod.f1 <= lod.f0:
        raise r.error("lod.f1", f"expected f1 > f0 = {lod.f0:g}, got {lod.f1:g}")

    d = r.section(data, "render", required=False)
    r.known(d, "render", ("spp", "seed", "exposure"))
    spp = r.integer(d, "render", "spp", 1)
    check_render_memory(camera.resolution, spp, len(fabric.channels), source=source)
    return Scene(patch=patch, camera=camera, light=light, fabric=fabric, lod=lod,
                 spp=spp, seed=r.integer(d, "render", "seed", 0, minimum=0),
                 exposure=r.number(d, "render", "exposure", 0.0), source=None if source is None else str(source))


def _fabric(r: _Reader, d: dict, base_dir) -> Fabric:
    r.known(d, "fabric", ("weave", "params", "coefficients", "channels", "fit", "seed", "noise", "kang"))
    weave = d.get("weave", "preset:cotton-denim")
    if not isinstance(weave, str) or not weave.strip():
        raise r.error("fabric.weave", f"expected 'preset:<name>' or a .wv path, got {weave!r}")
    params = d.get("params") or {}
    if not isinstance(params, dict):
        raise r.error("fabric.params", f"expected a mapping of parameter -> value, got {params!r}")
    _check_params(r, params, "fabric.params")
    channels = d.get("channels", DEFAULT_CHANNELS)
    if (not isinstance(channels, list | tuple) or not channels
            or not all(isinstance(c, str) for c in channels)):
        raise r.error("fabric.channels", f"expected a list of channel names, got {channels!r}")
    coefficients = (_coefficients(r, d["coefficients"], "fabric.coefficients", channels)
                    if d.get("coefficients") is not None else Fabric().coefficients)
    fit = _path(base_dir, d["fit"], r, "fabric.fit") if d.get("fit") is not None else None
    k = r.section(d, "kang", required=False)
    r.known(k, "fabric.kang", ("fit", "params", "coefficients", "prefilter", "view_distance_mm"))
    kang_params = k.get("params") or {}
    if not isinstance(kang_params, dict):
        raise r.error("fabric.kang.params", f"expected a mapping of parameter -> value, got {kang_params!r}")
    noise = d.get("noise", True)
    if not isinstance(noise, bool):
        raise r.error("fabric.noise", f"expected true or false, got {noise!r}")
    prefilter = k.get("prefilter", False)
    if not isinstance(prefilter, bool):
        raise r.error("fabric.kang.prefilter", f"expected true or false, got {prefilter!r}")
    kang = KangSpec(
        params=dict(kang_params),
        coefficients=(_coefficients(r, k["coefficients"], "fabric.kang.coefficients", channels)
                      if k.get("coefficients") is not None else None),
        prefilter=prefilter,
        view_distance_mm=r.number(k, "fabric.kang", "view_distance_mm", 100.0, minimum=0.0, exclusive=True),
        fit=_path(base_dir, k["fit"], r, "fabric.kang.fit") if k.get("fit") is not None else None,
    )
    return Fabric(weave=weave.strip(), params=dict(params), coefficients=coefficients, channels=tuple(channels),
                  fit=fit, seed=r.integer(d, "fabric", "seed", 0, minimum=0), noise=noise, kang=kang,
                  base_dir=Path(base_dir))


def load_scene(path) -> Scene:
    """Read a scene YAML file (see the module docstring); ConfigError / InputError name file and field."""
    from clothlab.untrusted import load_yaml_file

    path = Path(path)
    data = load_yaml_file(path, error=ConfigError, what="scene file")
    return scene_from_dict(data, source=path, base_dir=path.parent)
