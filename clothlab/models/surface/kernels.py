"""Compiled (numba) kernels of the fabric surface model's shading (Chen, Wang & Wang 2024, eqs. 1-2).

One scalar function per equation, ``inline="always"``, used by both loops: :func:`tile_means` (the tile
average over a ply quadrature, for BRDF tables) and :func:`point_values` (texture points).  Vectors are
in the yarn frame; S = I - (1 - alpha^2) t t^T is the fibre microflake matrix of eq. 2 (S = R^T diag(1, 1,
alpha^2) R with the ply orientation t_p as R's third row), so only t_p enters.

Imported lazily (numba costs ~0.5 s to import); compiled code is cached on disk.  Serial, as the IM kernels.
"""

from __future__ import annotations

import math

import numpy as np

from clothlab.models.jit import njit

T_RHO = 2.0  # sec. 3.1: "T rho is always assigned a value of 2 for fabrics"


@njit(cache=True, inline="always")
def projected_sigma(wt, alpha):
    """sigma(w) = sqrt(w^T S w) = sqrt(1 - (1 - alpha^2) (w . t)^2) (eq. 2), wt = w . t_p."""
    return math.sqrt(max(1.0 - (1.0 - alpha * alpha) * wt * wt, 0.0))


@njit(cache=True, inline="always")
def microflake_d(ht, alpha):
    """D(h) = 1 / (pi alpha q^2), q = h^T S^-1 h = 1 + (h . t)^2 (1 / alpha^2 - 1) for unit h (eq. 2)."""
    q = 1.0 + ht * ht * (1.0 / (alpha * alpha) - 1.0)
    return 1.0 / (math.pi * alpha * q * q)


@njit(cache=True, inline="always")
def attenuation_over_cosines(ci, co, sigma_i, sigma_o):
    """G / (cos_i cos_o) of eq. 2 with Lambda(w) = sigma(w) / cos(w), cosines to the ply normal:
    (1 - exp(-T rho (Lambda_i + Lambda_o))) / (sigma_i cos_o + sigma_o cos_i) - finite as a cosine -> 0."""
    den = sigma_i * co + sigma_o * ci
    product = ci * co
    if product <= 0.0:  # underflow at grazing: Lambda_i + Lambda_o = inf, 1 - exp(-inf) = 1
        return 1.0 / den
    return -math.expm1(-T_RHO * den / product) / den  # den / (ci co) = Lambda_i + Lambda_o


@njit(cache=True, inline="always")
def shade(nx, ny, nz, tx, ty, tz, ix, iy, iz, ox, oy, oz, area_i, area_o, alpha, blend):
    """(specular, diffuse) point values (1/sr, unit ks and kd) of one ply point for one direction pair
    (model docstring): eq. 1-2 in the ply frame, times the eq. 3-4 projected-area factor and the Smith
    visibility of the tile, divided by the fabric cosines."""
    diffuse = (1.0 - blend) / math.pi  # eq. 1: the Lambertian about n_s
    ci = ix * nx + iy * ny + iz * nz
    co = ox * nx + oy * ny + oz * nz
    if ci <= 0.0 or co <= 0.0 or area_i <= 0.0 or area_o <= 0.0:
        return 0.0, diffuse
    weight = (ci / area_i) * (co / area_o) / nz  # <wi.n_p> <wo.n_p> / <n_s.n_p> / (A~_i A~_o)
    diffuse += blend * weight / math.pi  # eq. 1: the Lambertian about n_p
    hx, hy, hz = ix + ox, iy + oy, iz + oz
    norm = math.sqrt(hx * hx + hy * hy + hz * hz)
    if norm <= 0.0:
        return 0.0, diffuse
    ht = (hx * tx + hy * ty + hz * tz) / norm
    sigma_i = projected_sigma(ix * tx + iy * ty + iz * tz, alpha)
    sigma_o = projected_sigma(ox * tx + oy * ty + oz * tz, alpha)
    specular = 0.25 * microflake_d(ht, alpha) * attenuation_over_cosines(ci, co, sigma_i, sigma_o) * weight
    return specular, diffuse


@njit(cache=True)
def tile_means(frame, wi, wo, area_i, area_o, alpha, blend):
    """Mean (specular, diffuse) over the ply nodes: frame (Q, 6) = (n_p, t_p) per node, wi, wo (N, 3)
    yarn frame, area_i, area_o (N,) the tile's A~; pairs with wi_z or wo_z <= 0 give 0."""
    n, q = wi.shape[0], frame.shape[0]
    spec = np.zeros(n)
    diff = np.zeros(n)
    for k in range(n):
        if wi[k, 2] <= 0.0 or wo[k, 2] <= 0.0:
            continue
        s_sum = 0.0
        d_sum = 0.0
        for j in range(q):
            s, d = shade(frame[j, 0], frame[j, 1], frame[j, 2], frame[j, 3], frame[j, 4], frame[j, 5],
                         wi[k, 0], wi[k, 1], wi[k, 2], wo[k, 0], wo[k, 1], wo[k, 2],
                         area_i[k], area_o[k], alpha, blend)
            s_sum += s
            d_sum += d
        spec[k] = s_sum / q
        diff[k] = d_sum / q
    return spec, diff


@njit(cache=True)
def point_values(frame, wi, wo, area_i, area_o, alpha, blend):
    """(specular, diffuse) (N,) at N ply points: frame (N, 6), wi, wo (N, 3) yarn frame, area_i, area_o,
    alpha (N,); pairs with wi_z or wo_z <= 0 give 0."""
    n = wi.shape[0]
    spec = np.zeros(n)
    diff = np.zeros(n)
    for k in range(n):
        if wi[k, 2] <= 0.0 or wo[k, 2] <= 0.0:
            continue
        spec[k], diff[k] = shade(frame[k, 0], frame[k, 1], frame[k, 2], frame[k, 3], frame[k, 4], frame[k, 5],
                                 wi[k, 0], wi[k, 1], wi[k, 2], wo[k, 0], wo[k, 1], wo[k, 2],
                                 area_i[k], area_o[k], alpha[k], blend)
    return spec, diff


@njit(cache=True)
def yarn_area(w, umax, beta, half, nodes):
    """mean over u in [-umax, umax] (midpoint, ``nodes``) and v in [-half, half] (exact) of
    max(0, w_z + beta (w_x tan v / cos u + w_y tan u)) for yarn-frame directions w (N, 3), umax and beta
    (N,): (N,) (:mod:`clothlab.models.surface.geometry`, the ply's projected area)."""
    n = w.shape[0]
    out = np.zeros(n)
    log_cos_half = math.log(math.cos(half))
    tan_u = np.zeros(nodes)
    sec_u = np.zeros(nodes)
    last = np.nan
    for k in range(n):
        if umax[k] != last:  # the nodes' tan u and 1 / cos u, recomputed only when umax changes
            last = umax[k]
            for j in range(nodes):
                u = last * (2.0 * (j + 0.5) / nodes - 1.0)
                tan_u[j] = math.tan(u)
                sec_u[j] = 1.0 / math.cos(u)
        total = 0.0
        for j in range(nodes):
            c = w[k, 2] + beta[k] * w[k, 1] * tan_u[j]
            d = abs(beta[k] * w[k, 0] * sec_u[j])  # the sign of d mirrors v: the range is symmetric
            if d <= 1e-300:
                total += 2.0 * half * max(c, 0.0)
                continue
            lo = min(max(math.atan(-c / d), -half), half)  # c + d tan v > 0 for v > lo
            total += max(c * (half - lo) - d * (log_cos_half - math.log(math.cos(lo))), 0.0)
        out[k] = total / (nodes * 2.0 * half)
    return out
