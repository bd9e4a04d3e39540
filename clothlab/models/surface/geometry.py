"""Ply geometry of the fabric surface model: normal n_p and orientation t_p of a single-ply curved-cylinder
yarn (Chen, Wang & Wang 2024, sec. 3.1, after Jin et al. 2022), and the tile's projected area.

Yarn frame (clothlab.frames.to_yarn_frame): x across the yarn, y along it, z the fabric normal n_s.
A point at local coordinates (x, y) of a segment w cells wide and l long maps to the cylinder angles of
Irawan & Marschner 2012, eq. 11:

    u = 2 umax y / l    (inclination of the yarn axis, in [-umax, umax])
    v = pi x / w        (angle around the yarn, in [-pi/2, pi/2])

and the gap ratio g leaves the outer g of the width bare: the ply covers |v| < (1 - g) pi / 2.  On the
cylinder (IM 2012, sec. 5.2):

    n = (sin v, sin u cos v, cos u cos v)       surface normal
    T = (0, cos u, -sin u)                      yarn axis (spine tangent)
    t = cos psi T + sin psi (n x T)             ply orientation: T turned by the twist psi about n

Height-field scaling beta (sec. 3.1) scales the surface's heights: n_p ~ (beta n_x, beta n_y, n_z) and
t_p ~ (t_x, t_y, beta t_z), then t_p is re-orthogonalised against n_p (Gram-Schmidt) and both normalised.

Projected area of the tile seen from w (eq. 5 without visibility), per unit tile area:

    A~(w) = sum_k c_k [(1 - g) mean_(u,v) <w . n_p> / <n_s . n_p> + g w_z] + (1 - sum_k c_k) w_z

(c_k: the cell share of yarn type k; bare cells and the gap count as flat).  With n_p as above,
<w . n_p> / n_p,z = max(0, w_z + beta (w_x tan v / cos u + w_y tan u)), whose integral over v is closed
form; the mean over u uses the midpoint rule.  The unclamped mean is w_z (the heights are periodic), so
A~(w) >= w_z, with equality for beta = 0.
"""

from __future__ import annotations

import numpy as np

from clothlab.frames import to_yarn_frame
from clothlab.weave.model import YARN_KINDS

#: midpoint nodes along the yarn for the projected area A~ (its v integral is exact)
AREA_NODES = 32


def cylinder_angles(x, y, w: float, l: float, umax: float):
    """(u, v) in radians of local segment coordinates x (across), y (along), cells; eq. 11 of IM 2012."""
    return 2.0 * umax * np.asarray(y) / l, np.pi * np.asarray(x) / w


def ply_frame(u, v, psi: float, beta: float) -> tuple[np.ndarray, np.ndarray]:
    """(n_p, t_p), each (..., 3), at cylinder angles u, v (radians) for twist psi (radians) and height-field
    scaling beta (module docstring; all four broadcast together); yarn frame.  Compiled, point by point
    (:func:`clothlab.models.surface.kernels.ply_frame_at`, which the texture kernel also calls)."""
    from clothlab.models.surface import kernels

    u, v, psi, beta = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (u, v, psi, beta)))
    frames = kernels.ply_frames(*(np.ascontiguousarray(a.reshape(-1)) for a in (u, v, psi, beta)))
    return frames[:, :3].reshape(u.shape + (3,)), frames[:, 3:].reshape(u.shape + (3,))


def yarn_area(w: np.ndarray, umax, beta, gap: float, nodes: int = AREA_NODES) -> np.ndarray:
    """mean over the ply (u, v) of <w . n_p> / n_p,z for yarn-frame directions w (N, 3): (N,); umax
    (radians) and beta scalars or (N,) (compiled: :func:`clothlab.models.surface.kernels.yarn_area`)."""
    from clothlab.models.surface import kernels

    n = len(w)
    half = 0.5 * np.pi * (1.0 - gap)
    return kernels.yarn_area(np.ascontiguousarray(w, dtype=np.float64),
                             np.ascontiguousarray(np.broadcast_to(np.asarray(umax, dtype=np.float64), (n,))),
                             np.ascontiguousarray(np.broadcast_to(np.asarray(beta, dtype=np.float64), (n,))),
                             half, int(nodes))


def projected_area(w: np.ndarray, shares: dict, params: dict) -> np.ndarray:
    """A~(w) (N,) of the tile for fabric-frame directions w (N, 3) (module docstring); 0 where w_z <= 0.
    ``shares``: cell share per yarn type; ``params``: the model's, umax and beta may be (N,) arrays."""
    gap = params["gap"]
    wz = np.maximum(w[:, 2], 0.0)
    area = (1.0 - sum(shares.values())) * wz
    for kind in YARN_KINDS:
        share = shares[kind]
        if np.all(share == 0.0):
            continue
        ply = yarn_area(to_yarn_frame(w, kind), np.deg2rad(params[f"{kind}.umax"]), params[f"{kind}.beta"], gap)
        area = area + share * ((1.0 - gap) * ply + gap * wz)
    return np.where(w[:, 2] > 0.0, area, 0.0)
