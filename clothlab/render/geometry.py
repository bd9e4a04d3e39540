"""Cloth patch geometry: ray intersection, shading frame, texture coordinates and pixel footprints.

Every surface has surface coordinates (s, t) in mm (s along its first tangent e_s, t along e_t, both 0 at
the patch centre) and a right-handed tangent frame e_s x e_t = n.  The weave lies in it rotated by the
warp angle a (counter-clockwise about n from e_t):

    warp  y_f = cos a e_t - sin a e_s,   weft  x_f = cos a e_s + sin a e_t,   normal z_f = n
    u = (s cos a + t sin a) / tile_u,    v = (-s sin a + t cos a) / tile_v      (texture coordinates, tiles)

so (x_f, y_f, z_f) is clothlab's fabric frame (z normal, y warp, x weft; clothlab.frames).

Footprint (weave tiles): the ray differentials of a one-pixel step in x and in y (pbrt's approach)
intersect the tangent plane at the hit point; their (du, dv) give the pixel's texture-space extent, and the
footprint is the larger of the two lengths (the isotropic choice of GPU mip selection, which the Kang LoD
also uses).  A differential ray parallel to the tangent plane gives an infinite footprint.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from clothlab.render.scene import Patch


@dataclass
class Hits:
    """Ray hits (M rays): ``hit`` mask; for the hit rays (others undefined): distance, world position,
    fabric frame (x_f weft, y_f warp, n normal; world unit vectors), texture coordinates u, v (tiles)."""

    hit: np.ndarray
    distance: np.ndarray
    position: np.ndarray
    weft: np.ndarray
    warp: np.ndarray
    normal: np.ndarray
    u: np.ndarray
    v: np.ndarray

    def to_fabric(self, w: np.ndarray) -> np.ndarray:
        """World directions (M, 3) in the fabric frame of each hit (x weft, y warp, z normal)."""
        return np.stack([np.einsum("ij,ij->i", w, self.weft), np.einsum("ij,ij->i", w, self.warp),
                         np.einsum("ij,ij->i", w, self.normal)], axis=1)

    def differentials(self, origin, d_x: np.ndarray, d_y: np.ndarray, tile_mm) -> np.ndarray:
        """(2, M, 2): the (du, dv) steps (tiles) of the differential rays d_x, d_y (M, 3) (one pixel step in x
        and in y from the same origin) intersected with each hit's tangent plane; inf where a differential ray
        is parallel to the plane or meets it behind the origin."""
        origin = np.asarray(origin, dtype=np.float64)
        steps = []
        for d in (d_x, d_y):
            along = np.einsum("ij,ij->i", d, self.normal)
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.einsum("ij,ij->i", self.position - origin, self.normal) / along
            step = origin + t[:, None] * d - self.position
            duv = np.column_stack([np.einsum("ij,ij->i", step, self.weft) / tile_mm[0],
                                   np.einsum("ij,ij->i", step, self.warp) / tile_mm[1]])
            ok = (np.abs(along) > 1e-12) & (t > 0.0) & np.isfinite(duv).all(axis=1)
            steps.append(np.where(ok[:, None], duv, np.inf))
        return np.stack(steps)

    def footprint(self, origin, d_x: np.ndarray, d_y: np.ndarray, tile_mm) -> np.ndarray:
        """Pixel footprint (M,) in weave tiles: :func:`footprint_of` the :meth:`differentials`."""
        return footprint_of(self.differentials(origin, d_x, d_y, tile_mm))


def footprint_of(steps: np.ndarray) -> np.ndarray:
    """The pixel footprint (tiles) of its (du, dv) steps (2, ..., 2): the longer of the two."""
    return np.hypot(steps[..., 0], steps[..., 1]).max(axis=0)


class Surface(ABC):
    """Base of the patch shapes: turns (s, t, frame) into fabric frame and texture coordinates."""

    def __init__(self, patch: Patch):
        self.patch = patch
        self.center = np.asarray(patch.center, dtype=np.float64)
        self.half = 0.5 * np.asarray(patch.size_mm, dtype=np.float64)
        a = np.deg2rad(patch.warp_angle_deg)
        self.cos_a, self.sin_a = np.cos(a), np.sin(a)
        self.tile_mm = np.asarray(patch.tile_mm, dtype=np.float64)

    def _hits(self, hit, distance, position, s, t, e_s, e_t, normal) -> Hits:
        c, sn = self.cos_a, self.sin_a
        return Hits(hit=hit, distance=distance, position=position,
                    weft=c * e_s + sn * e_t, warp=c * e_t - sn * e_s, normal=normal,
                    u=(s * c + t * sn) / self.tile_mm[0], v=(-s * sn + t * c) / self.tile_mm[1])

    @abstractmethod
    def intersect(self, origin, directions) -> Hits:
        """Hits of rays from ``origin`` (3,) along unit ``directions`` (M, 3)."""


class FlatPatch(Surface):
    """A rectangle in the plane z = center.z, normal +z; s along world x, t along world y."""

    def intersect(self, origin, directions) -> Hits:
        """Hits of rays from ``origin`` (3,) along unit ``directions`` (M, 3)."""
        o = np.asarray(origin, dtype=np.float64)
        d = np.asarray(directions, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            dist = (self.center[2] - o[2]) / d[:, 2]
        dist = np.where(np.isfinite(dist) & (dist > 0.0), dist, np.inf)
        position = o + np.where(np.isfinite(dist), dist, 0.0)[:, None] * d
        s, t = position[:, 0] - self.center[0], position[:, 1] - self.center[1]
        hit = np.isfinite(dist) & (np.abs(s) <= self.half[0]) & (np.abs(t) <= self.half[1])
        m = len(d)
        e_s = np.broadcast_to([1.0, 0.0, 0.0], (m, 3))
        e_t = np.broadcast_to([0.0, 1.0, 0.0], (m, 3))
        normal = np.broadcast_to([0.0, 0.0, 1.0], (m, 3))
        return self._hits(hit, dist, position, s, t, e_s, e_t, normal)


class CylinderPatch(Surface):
    """Part of a cylinder of radius r whose axis runs along world y through ``center``: the patch spans
    arc length s in [-size_s/2, size_s/2] around the top (+z) line and t in [-size_t/2, size_t/2] along the
    axis.  At polar angle theta = s / r:  n = (sin theta, 0, cos theta), e_s = (cos theta, 0, -sin theta),
    e_t = (0, 1, 0).  The nearer intersection inside the patch is used (the inside is back-facing)."""

    def intersect(self, origin, directions) -> Hits:
        o = np.asarray(origin, dtype=np.float64)
        d = np.asarray(directions, dtype=np.float64)
        r = self.patch.radius_mm
        q = o - self.center
        a = d[:, 0] ** 2 + d[:, 2] ** 2
        b = 2.0 * (q[0] * d[:, 0] + q[2] * d[:, 2])
        c = q[0] ** 2 + q[2] ** 2 - r * r
        disc = b * b - 4.0 * a * c
        root = np.sqrt(np.maximum(disc, 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            # numerically stable roots of a t^2 + b t + c
            k = -0.5 * (b + np.copysign(root, b))
            roots = np.sort(np.stack([k / a, c / k], axis=1), axis=1)
        ok = (disc >= 0.0) & (a > 0.0)
        best = np.full(len(d), np.inf)
        for j in (1, 0):  # the nearer valid root wins
            t_ray = roots[:, j]
            p = o + np.where(np.isfinite(t_ray), t_ray, 0.0)[:, None] * d
            theta = np.arctan2(p[:, 0] - self.center[0], p[:, 2] - self.center[2])
            inside = (ok & np.isfinite(t_ray) & (t_ray > 1e-9) & (np.abs(r * theta) <= self.half[0])
                      & (np.abs(p[:, 1] - self.center[1]) <= self.half[1]))
            best = np.where(inside, t_ray, best)
        hit = np.isfinite(best)
        position = o + np.where(hit, best, 0.0)[:, None] * d
        theta = np.arctan2(position[:, 0] - self.center[0], position[:, 2] - self.center[2])
        sin, cos, zero = np.sin(theta), np.cos(theta), np.zeros(len(d))
        normal = np.stack([sin, zero, cos], axis=1)
        e_s = np.stack([cos, zero, -sin], axis=1)
        e_t = np.broadcast_to([0.0, 1.0, 0.0], (len(d), 3))
        return self._hits(hit, best, position, r * theta, position[:, 1] - self.center[1], e_s, e_t, normal)


SHAPES = {"flat": FlatPatch, "cylinder": CylinderPatch}


def make_surface(patch: Patch) -> Surface:
    return SHAPES[patch.shape](patch)
