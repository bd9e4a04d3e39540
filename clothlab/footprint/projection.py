"""The projected-area normalisation of the footprint-aggregated BSDF (Chen, Wang & Wang 2024, eqs. 3-5).

Eq. 3 aggregates a texture's point BSDF f_p over a footprint P with kernel k_P:

    f_P(wi, wo) = 1 / A_P(wo) int_P f_p <wi . n_p> V(x_p, wi) A(p, wo) k_P(p) dp
    A(p, wo)    = <wo . n_p> / <n_s . n_p> V(x_p, wo)                                         (eq. 4)
    A_P(wo)     = int_P A(p, wo) k_P(p) dp                                                    (eq. 5)

with n_p the micro (ply) normal at p, n_s = z the macro normal and <.> clamped at zero.  f_P carries the
cosine <wi . n_p>; clothlab's components are BRDFs (1/sr), so the aggregate returned is the macro BRDF
f_P / <wi . n_s>:

    F(wi, wo) = int_P f_p w_i a_o k_P dp / int_P a_o k_P dp,
    w_i = <wi . n_p> / <wi . n_s>,   a_o = <wo . n_p> / <n_s . n_p>.

Visibility V is 1: the texture models clothlab has (IM, Kang, the surface model) have no inter-yarn
shadowing.  A texture model that declares micro normals (a method ``micro_normals(u, v, params) -> (..., 3)``,
fabric-frame unit vectors) gets these weights.  A texture model without one reports values already in
macro-surface terms (n_p = n_s: w_i = 1 and a_o = wo_z cancels), so F is the plain kernel average of its
components; that is the case for the IM texture (Irawan & Marschner 2012, eq. 13, whose tile average is the
reflectance model) and for Kang's point shader.
"""

from __future__ import annotations

import numpy as np


def has_micro_normals(texture) -> bool:
    """True when ``texture`` declares micro normals (the eq. 4-5 weights apply)."""
    return callable(getattr(texture, "micro_normals", None))


def weighted_values(texture, params, u, v, wi, wo, *, need=None, noise: bool = False,
                    warn: bool = False) -> tuple[dict[str, np.ndarray], np.ndarray | None]:
    """The integrands of F at texture points u, v (n,) for directions wi, wo (n, 3) (one row per point; (1, 3)
    shared by all points for a texture with ``shared_directions``).

    Returns ({component: f_p w_i a_o}, a_o) for a texture with micro normals, ({component: f_p}, None)
    otherwise; every array (n,).  The texture's own footprint filtering is off (``footprint=None``).
    """
    comps = texture.components(u, v, wi, wo, params, need=need, noise=noise, warn=warn)
    comps = {name: np.asarray(value, dtype=np.float64).reshape(-1) for name, value in comps.items()}
    if not has_micro_normals(texture):
        return comps, None
    n_p = np.asarray(texture.micro_normals(u, v, params), dtype=np.float64).reshape(-1, 3)
    cos_s = n_p[:, 2]
    area = np.where(cos_s > 0.0, np.maximum(np.sum(wo * n_p, axis=1), 0.0) / np.where(cos_s > 0.0, cos_s, 1.0),
                    0.0)  # eq. 4 with V = 1
    wi_z = wi[:, 2]
    incident = np.where(wi_z > 0.0,
                        np.maximum(np.sum(wi * n_p, axis=1), 0.0) / np.where(wi_z > 0.0, wi_z, 1.0), 0.0)
    factor = incident * area
    return {name: value * factor for name, value in comps.items()}, area
