"""Point evaluation of the fabric surface model at texture points (u, v) (Chen, Wang & Wang 2024, sec. 3.1).

A texture point falls on a segment (:func:`clothlab.weave.lookup.locate_segments`: local x across, y along
the yarn, cells); eq. 11 of Irawan & Marschner 2012 gives its cylinder angles (u, v), and
:func:`clothlab.models.surface.geometry.ply_frame` its n_p, t_p.  Points with |x| >= (1 - g) w / 2 are in
the gap and give 0.  The value is the point BRDF T(p) of :mod:`clothlab.models.surface.model` (decision 2):
it already carries eq. 4's projected-area factor and the tile's Smith visibility, so eq. 3 over any
footprint (box kernel) is the plain mean of T over the footprint, and its mean over one tile is
:meth:`SurfaceModel.components`.  A point of a warp segment has zero weft components and vice versa.
So a footprint aggregation must not weight these values by micro normals again: the texture declares
``shared_directions`` but no ``micro_normals`` (the texture interface's optional members).

All of it runs in one compiled pass (:func:`clothlab.models.surface.kernels.texture_points`), and the tile's
projected areas, the only costly direction-dependent part, are computed once per run of equal consecutive
direction pairs (:meth:`SurfaceModel.projected_areas`): the points of a footprint (a texture probe, MC
samples) passed with their query's directions repeated share them (issue 23 item 3).
"""

from __future__ import annotations

import numpy as np

from clothlab.errors import ParameterError
from clothlab.models.base import ModelTexture
from clothlab.models.components import combine
from clothlab.weave.lookup import locate_segments
from clothlab.weave.model import YARN_KINDS

#: the kernel's output columns (:func:`clothlab.models.surface.kernels.texture_points`)
COLUMNS = ("diffuse_warp", "diffuse_weft", "specular_warp", "specular_weft")


class SurfaceTexture(ModelTexture):
    """The texture model of a :class:`~clothlab.models.surface.model.SurfaceModel` (no noise, no filtering)."""

    kind = "surface-texture"
    #: ``components`` takes (1, 3) directions shared by every point (the footprint aggregation's fast path);
    #: there is deliberately no ``micro_normals``: the values already carry eqs. 3-5's weights (module docstring)
    shared_directions = True

    def __init__(self, model):
        super().__init__(model)
        self._tables = self._lookup_tables()

    def _lookup_tables(self):
        """(segment index per cell (H, W), rows from the top; segment centres u, v (cells); is-weft) for the
        kernel's segment lookup, from :func:`clothlab.weave.lookup.locate_segments` at the cell centres."""
        weave = self.weave
        w, h = weave.tile_width, weave.tile_height
        col, row = np.meshgrid(np.arange(w), np.arange(h))
        seg, _, _ = locate_segments(weave, (col + 0.5) / w, (h - 1 - row + 0.5) / h)
        return (np.ascontiguousarray(seg, dtype=np.int64),
                np.array([s.center_u for s in weave.segments], dtype=np.float64) * w,
                np.array([s.center_v for s in weave.segments], dtype=np.float64) * h,
                np.array([s.kind == "weft" for s in weave.segments]))

    def _yarn_table(self, p: dict) -> np.ndarray:
        """(2, 8) per yarn type: the kernel's ``yarn`` table (w, l, umax rad, cos psi, sin psi, beta, alpha, the
        ply's half width (1 - g) w / 2)."""
        rows = []
        for kind in YARN_KINDS:
            g = self.weave.geometry(kind)
            psi = np.deg2rad(p[f"{kind}.psi"])
            rows.append([g.w, g.l, np.deg2rad(p[f"{kind}.umax"]), np.cos(psi), np.sin(psi), p[f"{kind}.beta"],
                         p[f"{kind}.alpha"], 0.5 * (1.0 - p["gap"]) * g.w])
        return np.array(rows, dtype=np.float64)

    def _components(self, u, v, wi, wo, params: dict | None = None, *, need=None, noise: bool = True,
                    normalised: bool = True, warn: bool = True, footprint=None,
                    view_distance=None) -> dict[str, np.ndarray]:
        """Components (1/sr) at texture points u, v (tiles, broadcast together) for fabric-frame directions
        wi, wo: (N, 3) one row per point, or (3,) / (1, 3) shared by all.  Arrays of the points' shape.
        ``noise``, ``normalised``, ``warn``, ``footprint`` and ``view_distance`` belong to the texture
        interface (:mod:`clothlab.models.base`) and change nothing: the model has no noise and does not filter
        itself."""
        from clothlab.models.surface import kernels

        p = self.resolve(params)
        need = self.component_names if need is None else tuple(need)
        u, v = np.broadcast_arrays(np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64))
        if not (np.all(np.isfinite(u)) and np.all(np.isfinite(v))):
            raise ValueError("texture coordinates u, v must be finite")
        shape, n_pts = u.shape, u.size
        wi = np.atleast_2d(np.asarray(wi, dtype=np.float64))
        wo = np.atleast_2d(np.asarray(wo, dtype=np.float64))
        for d in (wi, wo):
            if d.ndim != 2 or d.shape[1] != 3 or d.shape[0] not in (1, n_pts):
                raise ParameterError(f"directions must be (3,), (1, 3) or (N, 3) with N = {n_pts} texture points; "
                                     f"got wi {wi.shape}, wo {wo.shape}")
        if wi.shape[0] != wo.shape[0]:
            wi, wo = np.broadcast_to(wi, (n_pts, 3)), np.broadcast_to(wo, (n_pts, 3))
        area_i, area_o = self.model.projected_areas(wi, wo, p)  # once per run of equal directions
        which = np.arange(n_pts) if wi.shape[0] == n_pts else np.zeros(n_pts, dtype=np.int64)
        out = np.empty((n_pts, len(COLUMNS)))
        kernels.texture_points(np.ascontiguousarray(u.reshape(-1)), np.ascontiguousarray(v.reshape(-1)), which,
                               np.ascontiguousarray(wi), np.ascontiguousarray(wo),
                               np.ascontiguousarray(area_i, dtype=np.float64),
                               np.ascontiguousarray(area_o, dtype=np.float64), *self._tables, self._yarn_table(p),
                               float(p["blend"]), out)
        return {name: out[:, i].reshape(shape) for i, name in enumerate(COLUMNS) if name in need}

    def evaluate(self, u, v, wi, wo, coefficients: dict, params: dict | None = None, *,
                 noise: bool = True) -> np.ndarray:
        """f_r (N, C) = sum_k coefficients[k] * component_k at texture points (flattened)."""
        comps = self.components(u, v, wi, wo, params)
        return combine({k: c.reshape(-1) for k, c in comps.items()}, coefficients)
