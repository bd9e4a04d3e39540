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
"""

from __future__ import annotations

import numpy as np

from clothlab.errors import ParameterError
from clothlab.frames import to_yarn_frame
from clothlab.models.base import ModelTexture
from clothlab.models.components import combine
from clothlab.models.surface.geometry import cylinder_angles, ply_frame
from clothlab.weave.lookup import locate_segments
from clothlab.weave.model import YARN_KINDS


class SurfaceTexture(ModelTexture):
    """The texture model of a :class:`~clothlab.models.surface.model.SurfaceModel` (no noise, no filtering)."""

    kind = "surface-texture"
    #: ``components`` takes (1, 3) directions shared by every point (the footprint aggregation's fast path);
    #: there is deliberately no ``micro_normals``: the values already carry eqs. 3-5's weights (module docstring)
    shared_directions = True

    def __init__(self, model):
        super().__init__(model)
        self._is_weft = np.array([s.kind == "weft" for s in self.weave.segments])

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
        seg, x, y = locate_segments(self.weave, u, v)
        shape, n_pts = x.shape, x.size
        wi = np.atleast_2d(np.asarray(wi, dtype=np.float64))
        wo = np.atleast_2d(np.asarray(wo, dtype=np.float64))
        for d in (wi, wo):
            if d.ndim != 2 or d.shape[1] != 3 or d.shape[0] not in (1, n_pts):
                raise ParameterError(f"directions must be (3,), (1, 3) or (N, 3) with N = {n_pts} texture points; "
                                     f"got wi {wi.shape}, wo {wo.shape}")
        area_i, area_o = self.model.projected_areas(wi, wo, p)  # per distinct direction, then broadcast
        wi, wo = np.broadcast_to(wi, (n_pts, 3)), np.broadcast_to(wo, (n_pts, 3))
        area_i, area_o = np.broadcast_to(area_i, (n_pts,)), np.broadcast_to(area_o, (n_pts,))
        seg, x, y = seg.reshape(-1), x.reshape(-1), y.reshape(-1)
        out = {name: np.zeros(n_pts) for name in self.component_names if name in need}
        for kind in YARN_KINDS:
            names = [name for name in (f"specular_{kind}", f"diffuse_{kind}") if name in out]
            if not names:
                continue
            g = self.weave.geometry(kind)
            rows = np.flatnonzero((self._is_weft[seg] == (kind == "weft"))
                                  & (np.abs(x) < 0.5 * (1.0 - p["gap"]) * g.w))
            if rows.size == 0:
                continue
            cu, cv = cylinder_angles(x[rows], y[rows], g.w, g.l, np.deg2rad(p[f"{kind}.umax"]))
            n_p, t_p = ply_frame(cu, cv, np.deg2rad(p[f"{kind}.psi"]), p[f"{kind}.beta"])
            spec, diff = kernels.point_values(
                np.ascontiguousarray(np.concatenate([n_p, t_p], axis=1)),
                np.ascontiguousarray(to_yarn_frame(wi[rows], kind)),
                np.ascontiguousarray(to_yarn_frame(wo[rows], kind)),
                np.ascontiguousarray(area_i[rows]), np.ascontiguousarray(area_o[rows]),
                np.full(rows.size, float(p[f"{kind}.alpha"])), float(p["blend"]))
            for name, value in ((f"specular_{kind}", spec), (f"diffuse_{kind}", diff)):
                if name in out:
                    out[name][rows] = value
        return {name: value.reshape(shape) for name, value in out.items()}

    def evaluate(self, u, v, wi, wo, coefficients: dict, params: dict | None = None, *,
                 noise: bool = True) -> np.ndarray:
        """f_r (N, C) = sum_k coefficients[k] * component_k at texture points (flattened)."""
        comps = self.components(u, v, wi, wo, params)
        return combine({k: c.reshape(-1) for k, c in comps.items()}, coefficients)
