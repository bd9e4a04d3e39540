"""The Irawan-Marschner texture model (Irawan & Marschner 2012, sec. 7.2, eqs. 11-13, Algorithms 3-4, 7.2.1).

The reflectance integrand of eq. 10 "unrolled" onto each yarn segment.  For a texture point (u, v):

1. :func:`clothlab.weave.lookup.locate_segments` finds the segment and the local coordinates (x across,
   y along the yarn, cells from the segment centre); any real u, v (negative, many repeats) and segment
   centres outside the tile are handled there.
2. Eq. 11 maps the point onto the yarn surface: u_yarn = 2 umax y / l (staple), v_yarn = pi x / w (filament).
3. The ideal specular point follows from eq. 3 (staple: v(u), + root, visible if |v| < pi/2) or eq. 4
   (filament: u(v)); eq. 11 maps it back to x(v) = w v / pi or y(u) = l u / (2 umax), clamped to
   +-(w - Dx)/2 or +-(l - Dy)/2 (Algorithms 3-4), so the whole band lies inside the segment.
4. Band (eq. 12): chi = 1 where |x - x(v)| < Dx/2 (staple) or |y - y(u)| < Dy/2 (filament), with the
   band widths  Dx = hwidth * w,  Dy = hwidth * l  (hwidth: the weave files' hWidth, the lit fraction
   of the segment across resp. along the yarn).
5. Brightness (eq. 13), with G A in the bounded form of :mod:`.yarn`:
       staple    T = chi 2 w umax G_v f_c A / Dx = chi 2 umax G_v f_c A / hwidth
       filament  T = chi pi l G_u f_c A_s / Dy   = chi pi G_u f_c A_s / hwidth.
   Averaged over its w x l rectangle, T equals f_c I_j, the raw reflectance integral of eq. 10.

Normalisation (the same as :class:`IrawanModel`, so that switching models needs no adjustment, sec. 7):
the tile average of T_j is c_j f_c I_j, with c_j the fraction of the tile covered by segments of type j
(:meth:`Weave.cell_share`).  The components are therefore

    specular_j = T_j / (c_j a_j)   (normalised; a_j = specular_albedo, as the reflectance model)
    specular_j = T_j / c_j         (normalised=False; tile average = the model's raw f_c I_j)

and ``diffuse`` = 1/pi.  For all six presets the declared warpArea / weftArea (:meth:`Weave.area_share`,
which the published renderer divides by) equal the cell shares; where a weave file's areas disagree
with its pattern, the cell share is what makes the tile average equal the reflectance model, so it is used.
A point on a warp segment has specular_weft = 0 and vice versa.

Identity: the tile average of each specular
component over a dense grid equals the reflectance model's component (checked by the test suite).  It holds
when each segment's pattern cells form its w x l rectangle centred on the segment centre (true for all
presets).  Reciprocity: T depends on wi, wo only through h, |wi + wo|, ci cr / (ci + cr) and wi.wo, so
swapping wi and wo leaves every point's value unchanged (noise does not depend on directions).

Noise (sec. 7.2.1; :mod:`clothlab.models.irawan.texture_noise`), only when ``noise=True``:

- Intensity: if weave.fineness = k > 0, each segment *instance* (a physical segment, keyed by its
  absolute centre; :class:`TexturePoints`) is split into k x k rectangles (k across, k along; cell size
  w/k by l/k; the paper's "k by k rectangles in a yarn segment"; a non-integer k leaves a narrower last
  rectangle), and the specular components are multiplied by an exponential variate of mean 1 per
  rectangle (capped at 10, rescaled to mean exactly 1: :func:`clothlab.models.irawan.texture_noise.exponential_noise`).
- umax modulation: if period > 0 and any dumax != 0, every warp yarn (a column of the fabric, keyed by its
  centre in half cells) and weft yarn (a row) carries a 1-D Perlin function P in [-1, 1] of the position
  along it, in cells / period (``period``: Perlin lattice spacing in weave cells).  A segment with centre
  (U, V) (cells, absolute) uses P_warp = P(warp column through U, V / period) and P_weft = P(weft row
  through V, U / period) (for a warp segment the first is its own yarn, for a weft segment the second):
      warp segment: umax + dumax[0] P_warp + dumax[1] P_weft   (warp<-warp, warp<-weft)
      weft segment: umax + dumax[2] P_warp + dumax[3] P_weft   (weft<-warp, weft<-weft)
  in degrees, clamped to [UMAX_MIN, UMAX_MAX] (noise must not push umax <= 0, where the yarn has no highlight).
  The modulated umax enters eq. 11, R(u) and eq. 13; the albedo a_j stays that of the unmodulated yarn.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from clothlab.errors import GeometryWarning, ParameterError
from clothlab.frames import to_yarn_frame
from clothlab.models.base import HALF_TURN, Texture, with_orientation
from clothlab.models.components import combine
from clothlab.models.irawan.integrals import (
    COMPONENTS,
    PSI_FILAMENT_THRESHOLD,
    Quadrature,
    check_filament_arc,
    geometry_warnings,
    specular_albedo,
)
from clothlab.models.irawan.parameters import IRAWAN_PARAMS, weave_parameters
from clothlab.models.irawan.phase import phase_function
from clothlab.models.irawan.texture_noise import exponential_noise, perlin_1d
from clothlab.weave.lookup import locate_segments
from clothlab.weave.model import YARN_KINDS, Weave

UMAX_MIN = 0.1  # degrees: lower clamp of the noise-modulated umax
UMAX_MAX = 89.9  # degrees: upper clamp
_STREAM_INTENSITY, _STREAM_WARP, _STREAM_WEFT = 1, 2, 3  # hash streams (first key)


@dataclass(frozen=True)
class TexturePoints:
    """Where texture points fall (arrays of the points' shape): segment index into weave.segments, local
    x, y (cells from the segment centre), whether the segment is weft, and the segment *instance*: its
    absolute centre (U, V) in cells and the same rounded to half cells (int64 ``key_u``, ``key_v``).

    The instance key identifies a physical segment: a segment crossing the tile edge appears in the
    pattern under two ids whose centres differ by a whole tile (denim ids 1 and 2, charmeuse 2 and 3);
    both parts get the same key, so noise does not change at the tile edge."""

    segment: np.ndarray
    x: np.ndarray
    y: np.ndarray
    is_weft: np.ndarray
    centre_u: np.ndarray
    centre_v: np.ndarray
    key_u: np.ndarray
    key_v: np.ndarray


class IrawanTexture(Texture):
    """Irawan-Marschner texture model of one weave; ``quadrature`` only sets the albedo a_j (use the same
    one as the reflectance model it is combined with); ``seed`` selects the noise realisation;
    ``filament_arc`` the arc of a smoothed filament spine's R(u), as :class:`IrawanModel`'s option
    (:data:`clothlab.models.irawan.integrals.FILAMENT_ARCS`)."""

    kind = "irawan-texture"
    model_kind = "irawan"
    #: :class:`IrawanModel`'s declarations (``orientation`` included; the texture refuses one other than 0)
    params = with_orientation(IRAWAN_PARAMS, HALF_TURN)
    component_names = COMPONENTS
    #: components() takes (1, 3) directions shared by every point (faster than one row per point)
    shared_directions = True

    def __init__(self, weave: Weave, quadrature: Quadrature | None = None, *, seed: int = 0,
                 filament_arc: str = "full"):
        self.weave = weave
        self.quadrature = quadrature or Quadrature()
        self.seed = int(seed)
        self.filament_arc = check_filament_arc(filament_arc)
        self.cell_shares = {kind: weave.cell_share(kind) for kind in YARN_KINDS}
        w, h = weave.tile_width, weave.tile_height
        self._centre_u = np.array([s.center_u for s in weave.segments]) * w  # cells
        self._centre_v = np.array([s.center_v for s in weave.segments]) * h
        self._is_weft = np.array([s.kind == "weft" for s in weave.segments])
        # segment centres in half cells: instance keys, and yarn keys (a warp yarn is a column, key_u;
        # a weft yarn a row, key_v)
        self._key_u = np.rint(2.0 * self._centre_u).astype(np.int64)
        self._key_v = np.rint(2.0 * self._centre_v).astype(np.int64)

    def default_parameters(self) -> dict[str, float]:
        return weave_parameters(self.weave)

    def _resolve(self, params: dict | None) -> dict[str, float]:
        """Hook of :meth:`Texture.resolve` (which refuses an orientation other than 0: the weave's own frame):
        the weave's parameters overridden by ``params``, validated (as :meth:`IrawanModel.resolve`)."""
        full = self.default_parameters()
        if params:
            full.update(IRAWAN_PARAMS.validate(params))
        return full

    # ------------------------------------------------------------------ geometry and noise

    def locate(self, u, v) -> TexturePoints:
        """Segment, local (x, y) and segment-instance tile of texture points u, v (tile units, any reals)."""
        u, v = np.broadcast_arrays(np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64))
        seg, x, y = locate_segments(self.weave, u, v)
        weft = self._is_weft[seg]
        du = np.where(weft, y, x)  # cells from the segment centre, fabric axes
        dv = np.where(weft, -x, y)
        w, h = self.weave.tile_width, self.weave.tile_height
        tile_u = np.rint((u * w - du - self._centre_u[seg]) / w).astype(np.int64)
        tile_v = np.rint((v * h - dv - self._centre_v[seg]) / h).astype(np.int64)
        return TexturePoints(seg, x, y, weft,
                             self._centre_u[seg] + w * tile_u, self._centre_v[seg] + h * tile_v,
                             self._key_u[seg] + 2 * w * tile_u, self._key_v[seg] + 2 * h * tile_v)

    def intensity_noise(self, points: TexturePoints, params: dict) -> np.ndarray | None:
        """Exponential intensity factor (mean 1) per k x k cell of each segment instance; None if k = 0."""
        k = float(self.weave.fineness)
        if k <= 0.0:
            return None
        weft = points.is_weft
        w = np.where(weft, params["weft.w"], params["warp.w"])
        l = np.where(weft, params["weft.l"], params["warp.l"])
        last = int(np.ceil(k)) - 1
        i = np.clip(np.floor((points.x / w + 0.5) * k), 0, last).astype(np.int64)
        j = np.clip(np.floor((points.y / l + 0.5) * k), 0, last).astype(np.int64)
        return exponential_noise(_STREAM_INTENSITY, weft, points.key_u, points.key_v, i, j, seed=self.seed)

    def umax_offsets(self, points: TexturePoints) -> np.ndarray | None:
        """Perlin modulation of umax (degrees) per point's segment instance; None if there is none."""
        weave = self.weave
        dumax = np.asarray(weave.dumax, dtype=np.float64)
        if weave.period <= 0.0 or not np.any(dumax != 0.0):
            return None
        p_warp = perlin_1d(points.centre_v / weave.period, _STREAM_WARP, points.key_u, seed=self.seed)
        p_weft = perlin_1d(points.centre_u / weave.period, _STREAM_WEFT, points.key_v, seed=self.seed)
        weft = points.is_weft
        return (np.where(weft, dumax[2], dumax[0]) * p_warp + np.where(weft, dumax[3], dumax[1]) * p_weft)

    # ------------------------------------------------------------------ the model

    def _components(self, u, v, wi, wo, params: dict | None = None, *, need=None, noise: bool = True,
                    normalised: bool = True, warn: bool = True, footprint=None,
                    view_distance=None) -> dict[str, np.ndarray]:
        """Texture components (1/sr) at texture points u, v (tile units; arrays broadcast together) for
        fabric-frame directions wi, wo: (N, 3) with one row per point, or (3,) / (1, 3) shared by all.

        Returns arrays of the points' shape: ``diffuse`` (1/pi), ``specular_warp``, ``specular_weft``
        (see the module docstring).  Back-facing pairs (wi_z <= 0 or wo_z <= 0) give 0.  ``footprint`` and
        ``view_distance`` belong to the texture interface (:mod:`clothlab.models.base`) and are ignored:
        this model does not filter itself (a renderer blends it with the reflectance model).
        """
        p = self.resolve(params)
        need = COMPONENTS if need is None else tuple(need)
        if warn:
            for message in geometry_warnings(p, self.weave.name, self.filament_arc):
                warnings.warn(message, GeometryWarning, stacklevel=2)
        wi = np.atleast_2d(np.asarray(wi, dtype=np.float64))
        wo = np.atleast_2d(np.asarray(wo, dtype=np.float64))
        points = self.locate(u, v)
        shape = points.x.shape
        n_pts = points.x.size
        for d in (wi, wo):
            if d.ndim != 2 or d.shape[1] != 3 or d.shape[0] not in (1, n_pts):
                raise ParameterError(f"directions must be (3,), (1, 3) or (N, 3) with N = {n_pts} texture "
                                     f"points; got wi {wi.shape}, wo {wo.shape}")
        shared = wi.shape[0] == 1 and wo.shape[0] == 1
        if not shared:
            wi, wo = np.broadcast_to(wi, (n_pts, 3)), np.broadcast_to(wo, (n_pts, 3))
        front = (wi[:, 2] > 0.0) & (wo[:, 2] > 0.0)
        out = {}
        if "diffuse" in need:
            out["diffuse"] = np.broadcast_to(np.where(front, 1.0 / np.pi, 0.0), (n_pts,)).reshape(shape).copy()
        kinds = [kind for kind in YARN_KINDS if f"specular_{kind}" in need]
        if not kinds:
            return out
        phase = phase_function(wi, wo, p["alpha"], p["beta"])
        offsets = self.umax_offsets(points) if noise else None
        factor = self.intensity_noise(points, p) if noise else None
        flat = {name: getattr(points, name).reshape(-1) for name in ("x", "y", "is_weft")}
        for kind in kinds:
            value = np.zeros(n_pts)
            rows = np.flatnonzero(flat["is_weft"] == (kind == "weft"))
            share = self.cell_shares[kind]
            if rows.size and share > 0.0:
                umax_deg = np.full(rows.size, p[f"{kind}.umax"])
                if offsets is not None:
                    umax_deg = np.clip(umax_deg + offsets.reshape(-1)[rows], UMAX_MIN, UMAX_MAX)
                sel = slice(None) if shared else rows
                t = self._brightness(kind, p, flat["x"][rows], flat["y"][rows], np.deg2rad(umax_deg),
                                     to_yarn_frame(wi[sel], kind), to_yarn_frame(wo[sel], kind),
                                     self.filament_arc == "shortened")
                t *= phase[0] if shared else phase[rows]
                if factor is not None:
                    t *= factor.reshape(-1)[rows]
                scale = share
                if normalised:
                    scale *= specular_albedo(p, kind, self.quadrature, filament_arc=self.filament_arc)
                value[rows] = t / scale if scale > 0.0 else 0.0
            out[f"specular_{kind}"] = value.reshape(shape)
        return out

    @staticmethod
    def _brightness(kind, p, x, y, umax, wi, wo, shortened=False) -> np.ndarray:
        """T / f_c of eq. 13 at local (x, y) (cells) with per-point umax (radians); yarn-frame directions;
        ``shortened``: the filament R(u) on the arc (1 - delta) umax."""
        from clothlab.models.irawan import kernels

        psi = np.deg2rad(p[f"{kind}.psi"])
        kappa, w, l, hwidth = p[f"{kind}.kappa"], p[f"{kind}.w"], p[f"{kind}.l"], p["hwidth"]
        wi, wo = np.ascontiguousarray(wi), np.ascontiguousarray(wo)
        if abs(psi) >= PSI_FILAMENT_THRESHOLD:  # staple: Algorithm 3
            dx = hwidth * w
            u_yarn = 2.0 * umax * y / l  # eq. 11
            g, v_spec = kernels.staple_points(wi, wo, u_yarn, umax, float(psi), float(kappa), float(w), float(l))
            x_spec = np.clip(w * v_spec / np.pi, -0.5 * (w - dx), 0.5 * (w - dx))  # eq. 11, clamp
            chi = np.abs(x - x_spec) < 0.5 * dx  # eq. 12
            return np.where(chi, g * 2.0 * umax / hwidth, 0.0)  # eq. 13
        dy = hwidth * l  # filament: Algorithm 4
        v_yarn = np.pi * x / w  # eq. 11
        g, u_spec = kernels.filament_points(wi, wo, v_yarn, umax, float(kappa), float(w), float(l),
                                            float(p["delta"]), bool(shortened))
        y_spec = np.clip(l * u_spec / (2.0 * umax), -0.5 * (l - dy), 0.5 * (l - dy))
        chi = np.abs(y - y_spec) < 0.5 * dy
        return np.where(chi, g * np.pi / hwidth, 0.0)

    def evaluate(self, u, v, wi, wo, coefficients: dict, params: dict | None = None, *,
                 noise: bool = True) -> np.ndarray:
        """f_r (N, C) = sum_k coefficients[k] * component_k at texture points (flattened); coefficients as
        :meth:`IrawanModel.evaluate` ('kd', 'ks_warp', 'ks_weft' -> (C,) arrays)."""
        comps = self.components(u, v, wi, wo, params, noise=noise)
        return combine({k: c.reshape(-1) for k, c in comps.items()}, coefficients)
