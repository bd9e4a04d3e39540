"""Compiled (numba) kernels of the fabric surface model's shading (Chen, Wang & Wang 2024, eqs. 1-2).

One scalar function per equation, ``inline="always"``, used by both loops: :func:`tile_means` (the tile
average over a ply quadrature, for BRDF tables) and :func:`texture_points` / :func:`point_values` (texture
points).  Vectors are in the yarn frame; S = I - (1 - alpha^2) t t^T is the fibre microflake matrix of eq. 2
(S = R^T diag(1, 1, alpha^2) R with the ply orientation t_p as R's third row), so only t_p enters.

:func:`shade` is branch-free (selects, and :func:`one_minus_exp_neg` in place of ``math.expm1``, which LLVM
cannot vectorise), and the loops are compiled with numpy's error model (a division by zero gives inf instead
of raising, which would branch), so the tile average's loop over its ply nodes runs in SIMD lanes (issue 23
item 3; figures in docs/neural.md).  Values change by rounding only (products may fuse, the node sum runs in
four partial sums): tests/test_surface.py checks them against the literal formulas.

Imported lazily (numba costs ~0.5 s to import); compiled code is cached on disk.  Serial, as the IM kernels.
"""

from __future__ import annotations

import math
from decimal import Decimal, localcontext

import numpy as np

from clothlab.models.jit import njit

T_RHO = 2.0  # sec. 3.1: "T rho is always assigned a value of 2 for fabrics"

#: LLVM flags of the shading kernels: fused multiply-add only.  No reassociation (it would regroup the
#: products of tiny cosines and large inverse areas at grazing, and 1 - e^-x into a cancelling form), so the
#: tile average stores its node values and sums them in a separate loop (:func:`tile_means`)
FASTMATH = {"contract"}


def _ln2_split() -> tuple[float, float]:
    """(hi, lo): ln 2 = hi + lo to ~1e-26, hi with 32 significant bits (so k hi is exact for k < 2^21)."""
    with localcontext() as ctx:
        ctx.prec = 40
        ln2 = Decimal(2).ln()
        hi = math.ldexp(math.floor(math.ldexp(float(ln2), 32)), -32)
        return hi, float(ln2 - Decimal(hi))


LN2_HI, LN2_LO = _ln2_split()
INV_LN2 = 1.0 / math.log(2.0)
#: 1 / j! for the Taylor polynomial of e^r - 1 (|r| <= ln 2 / 2: the 14th term is below 2^-60 of the 1st)
_F2, _F3, _F4, _F5, _F6, _F7, _F8, _F9, _F10, _F11, _F12, _F13, _F14 = (1.0 / math.factorial(j) for j in range(2, 15))


@njit(cache=True, inline="always", fastmath=FASTMATH, error_model="numpy")
def one_minus_exp_neg(x):
    """1 - exp(-x) for x >= 0 (inf included) to ~1 ulp, as ``-math.expm1(-x)`` but in plain arithmetic (so a
    loop over it vectorises): -x = -k ln 2 + r with |r| <= ln 2 / 2 (ln 2 split hi + lo, Cody-Waite), e^r - 1
    by its Taylor polynomial to r^14, then 1 - e^-x = (1 - 2^-k) - 2^-k (e^r - 1) (-(e^r - 1) for k = 0),
    without cancellation; 2^-k from the bits of k.  x > 60 gives 1 - 2^-87 = 1.0."""
    x = min(x, 60.0)
    kf = math.floor(x * INV_LN2 + 0.5)
    r = (kf * LN2_HI - x) + kf * LN2_LO
    p = ((((((_F14 * r + _F13) * r + _F12) * r + _F11) * r + _F10) * r + _F9) * r + _F8) * r + _F7
    p = (((((p * r + _F6) * r + _F5) * r + _F4) * r + _F3) * r + _F2)
    em1 = r + r * r * p
    k = int(kf)
    scale = 1.0
    scale *= 0.5 if k & 1 else 1.0
    scale *= 0.25 if k & 2 else 1.0
    scale *= 0.0625 if k & 4 else 1.0
    scale *= 0.00390625 if k & 8 else 1.0
    scale *= 2.0 ** -16 if k & 16 else 1.0
    scale *= 2.0 ** -32 if k & 32 else 1.0
    scale *= 2.0 ** -64 if k & 64 else 1.0
    # k = 0 (x < ln 2 / 2): 1 - e^-x = -(e^r - 1) exactly; otherwise 1 - 2^-k >= 1/2 and the subtraction
    # cannot cancel
    return -em1 if k == 0 else (1.0 - scale) - scale * em1


@njit(cache=True, inline="always", fastmath=FASTMATH, error_model="numpy")
def projected_sigma(wt, alpha):
    """sigma(w) = sqrt(w^T S w) = sqrt(1 - (1 - alpha^2) (w . t)^2) (eq. 2), wt = w . t_p."""
    return math.sqrt(max(1.0 - (1.0 - alpha * alpha) * wt * wt, 0.0))


@njit(cache=True, inline="always", fastmath=FASTMATH, error_model="numpy")
def microflake_d(ht, alpha):
    """D(h) = 1 / (pi alpha q^2), q = h^T S^-1 h = 1 + (h . t)^2 (1 / alpha^2 - 1) for unit h (eq. 2)."""
    q = 1.0 + ht * ht * (1.0 / (alpha * alpha) - 1.0)
    return 1.0 / (math.pi * alpha * q * q)


@njit(cache=True, inline="always", fastmath=FASTMATH, error_model="numpy")
def attenuation_over_cosines(ci, co, sigma_i, sigma_o):
    """G / (cos_i cos_o) of eq. 2 with Lambda(w) = sigma(w) / cos(w), cosines to the ply normal:
    (1 - exp(-T rho (Lambda_i + Lambda_o))) / (sigma_i cos_o + sigma_o cos_i) - finite as a cosine -> 0 (an
    underflowing cos_i cos_o gives Lambda = inf and 1 - exp(-inf) = 1)."""
    den = sigma_i * co + sigma_o * ci
    return one_minus_exp_neg(T_RHO * den / (ci * co)) / den  # den / (ci co) = Lambda_i + Lambda_o


@njit(cache=True, inline="always", fastmath=FASTMATH, error_model="numpy")
def shade(nx, ny, nz, tx, ty, tz, ix, iy, iz, ox, oy, oz, hx, hy, hz, inv_i, inv_o, alpha, blend):
    """(specular, diffuse) point values (1/sr, unit ks and kd) of one ply point (n_p, t_p) for one direction
    pair wi, wo with unit half vector h (model docstring): eq. 1-2 in the ply frame, times the eq. 3-4
    projected-area factor and the Smith visibility of the tile (``inv_i``, ``inv_o`` = 1 / A~(wi), 1 / A~(wo),
    0 where an area is 0), divided by the fabric cosines.  A ply point that wi or wo does not see gives (0,
    (1 - blend) / pi).  Branch-free: a loop over points or nodes vectorises."""
    ci = ix * nx + iy * ny + iz * nz
    co = ox * nx + oy * ny + oz * nz
    lit = (ci > 0.0) & (co > 0.0)
    weight = (ci * inv_i) * (co * inv_o) / nz if lit else 0.0  # <wi.n_p> <wo.n_p> / <n_s.n_p> / (A~_i A~_o)
    diffuse = (1.0 - blend) / math.pi + blend * weight / math.pi  # eq. 1: about n_s, and about n_p
    sigma_i = projected_sigma(ix * tx + iy * ty + iz * tz, alpha)
    sigma_o = projected_sigma(ox * tx + oy * ty + oz * tz, alpha)
    g = attenuation_over_cosines(ci, co, sigma_i, sigma_o) if lit else 0.0
    specular = 0.25 * microflake_d(hx * tx + hy * ty + hz * tz, alpha) * g * weight
    return specular, diffuse


@njit(cache=True, inline="always", fastmath=FASTMATH, error_model="numpy")
def pair_terms(ix, iy, iz, ox, oy, oz, area_i, area_o):
    """(h_x, h_y, h_z, 1 / A~_i, 1 / A~_o) of a direction pair with wi_z, wo_z > 0: the unit half vector and
    the inverse areas :func:`shade` takes (0 where an area is 0).  h is scaled by its largest entry before it
    is normalised, so a mirror pair at grazing (|wi + wo| ~ 1e-300, whose square underflows) keeps its h."""
    hx, hy, hz = ix + ox, iy + oy, iz + oz
    scale = max(abs(hx), abs(hy), abs(hz))  # > 0: h_z > 0
    hx, hy, hz = hx / scale, hy / scale, hz / scale
    norm = math.sqrt(hx * hx + hy * hy + hz * hz)
    inv_i = 1.0 / area_i if area_i > 0.0 else 0.0
    inv_o = 1.0 / area_o if area_o > 0.0 else 0.0
    return hx / norm, hy / norm, hz / norm, inv_i, inv_o


@njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def tile_means(frame, wi, wo, area_i, area_o, alpha, blend):
    """Mean (specular, diffuse) over the ply nodes: frame (Q, 6) = (n_p, t_p) per node, wi, wo (N, 3)
    yarn frame, area_i, area_o (N,) the tile's A~; pairs with wi_z or wo_z <= 0 give 0.  The frame is read
    coordinate by coordinate (6, Q) and the node values are stored, then summed (:func:`node_sum`), so the
    loop over nodes runs in SIMD lanes."""
    n, q = wi.shape[0], frame.shape[0]
    nodes = np.empty((6, q))
    for j in range(q):
        for c in range(6):
            nodes[c, j] = frame[j, c]
    nx, ny, nz, tx, ty, tz = nodes[0], nodes[1], nodes[2], nodes[3], nodes[4], nodes[5]
    s_node = np.empty(q)
    d_node = np.empty(q)
    spec = np.zeros(n)
    diff = np.zeros(n)
    for k in range(n):
        ix, iy, iz, ox, oy, oz = wi[k, 0], wi[k, 1], wi[k, 2], wo[k, 0], wo[k, 1], wo[k, 2]
        if iz <= 0.0 or oz <= 0.0:
            continue
        hx, hy, hz, inv_i, inv_o = pair_terms(ix, iy, iz, ox, oy, oz, area_i[k], area_o[k])
        for j in range(q):
            s_node[j], d_node[j] = shade(nx[j], ny[j], nz[j], tx[j], ty[j], tz[j], ix, iy, iz, ox, oy, oz, hx, hy,
                                         hz, inv_i, inv_o, alpha, blend)
        spec[k] = node_sum(s_node) / q
        diff[k] = node_sum(d_node) / q
    return spec, diff


@njit(cache=True, inline="always", fastmath=FASTMATH, error_model="numpy")
def node_sum(values):
    """sum of ``values`` (Q,) in four interleaved partial sums (independent chains; the same order every call)."""
    q = values.shape[0]
    a = b = c = d = 0.0
    for j in range(0, q - 3, 4):
        a += values[j]
        b += values[j + 1]
        c += values[j + 2]
        d += values[j + 3]
    for j in range(q - q % 4, q):
        a += values[j]
    return (a + b) + (c + d)


@njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def point_values(frame, wi, wo, area_i, area_o, alpha, blend):
    """(specular, diffuse) (N,) at N ply points: frame (N, 6), wi, wo (N, 3) yarn frame, area_i, area_o,
    alpha (N,); pairs with wi_z or wo_z <= 0 give 0."""
    n = wi.shape[0]
    spec = np.zeros(n)
    diff = np.zeros(n)
    for k in range(n):
        ix, iy, iz, ox, oy, oz = wi[k, 0], wi[k, 1], wi[k, 2], wo[k, 0], wo[k, 1], wo[k, 2]
        if iz <= 0.0 or oz <= 0.0:
            continue
        hx, hy, hz, inv_i, inv_o = pair_terms(ix, iy, iz, ox, oy, oz, area_i[k], area_o[k])
        spec[k], diff[k] = shade(frame[k, 0], frame[k, 1], frame[k, 2], frame[k, 3], frame[k, 4], frame[k, 5],
                                 ix, iy, iz, ox, oy, oz, hx, hy, hz, inv_i, inv_o, alpha[k], blend)
    return spec, diff


@njit(cache=True, inline="always", fastmath=FASTMATH, error_model="numpy")
def ply_frame_at(u, v, cos_psi, sin_psi, beta):
    """(n_p, t_p) as six floats (yarn frame) at cylinder angles u, v (radians) for twist psi (its cosine and
    sine) and height-field scaling beta (:mod:`clothlab.models.surface.geometry`: the cylinder's n and spine T,
    t = cos psi T + sin psi (n x T), scaled by beta, t_p re-orthogonalised against n_p, both normalised)."""
    su, cu, sv, cv = math.sin(u), math.cos(u), math.sin(v), math.cos(v)
    nx, ny, nz = sv, su * cv, cu * cv
    sx, sy, sz = 0.0, cu, -su  # the spine T
    ax, ay, az = ny * sz - nz * sy, nz * sx - nx * sz, nx * sy - ny * sx  # n x T
    tx, ty, tz = cos_psi * sx + sin_psi * ax, cos_psi * sy + sin_psi * ay, cos_psi * sz + sin_psi * az
    nx, ny = beta * nx, beta * ny
    norm = math.sqrt(nx * nx + ny * ny + nz * nz)
    nx, ny, nz = nx / norm, ny / norm, nz / norm
    tz = beta * tz
    d = tx * nx + ty * ny + tz * nz
    tx, ty, tz = tx - d * nx, ty - d * ny, tz - d * nz
    norm = math.sqrt(tx * tx + ty * ty + tz * tz)
    return nx, ny, nz, tx / norm, ty / norm, tz / norm


@njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def ply_frames(u, v, psi, beta):
    """(N, 6) = (n_p, t_p) of :func:`ply_frame_at` for u, v, psi (radians) and beta, each (N,)."""
    n = u.shape[0]
    out = np.empty((n, 6))
    for k in range(n):
        out[k, 0], out[k, 1], out[k, 2], out[k, 3], out[k, 4], out[k, 5] = ply_frame_at(
            u[k], v[k], math.cos(psi[k]), math.sin(psi[k]), beta[k])
    return out


#: columns of the per-yarn-type table of :func:`texture_points`
YARN_W, YARN_L, YARN_UMAX, YARN_COS_PSI, YARN_SIN_PSI, YARN_BETA, YARN_ALPHA, YARN_HALF = range(8)


@njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def texture_points(u, v, which, wi, wo, area_i, area_o, cell_seg, seg_u, seg_v, seg_weft, yarn, blend, out):
    """Texture point values in one pass (:mod:`clothlab.models.surface.texture`): point p at (u[p], v[p])
    (tiles) with the fabric-frame directions of row ``which[p]`` of wi, wo (D, 3) and that row's tile areas
    area_i, area_o (D,), so the points of a footprint share their directions' work.  The segment lookup
    (Irawan & Marschner 2012, sec. 7.2; :func:`clothlab.weave.lookup.locate_segments`) reads ``cell_seg`` (H,
    W) (segment index per cell, rows from the top) and the segments' centres (cells) and kinds; eq. 11 gives
    the cylinder angles, :func:`ply_frame_at` the frame, :func:`shade` the values.  ``yarn`` (2, 8): per yarn
    type (warp, weft) w, l (cells), umax (rad), cos psi, sin psi, beta, alpha and the ply's half width (1 - g)
    w / 2 (cells).  Writes ``out`` (P, 4): diffuse_warp, diffuse_weft, specular_warp, specular_weft (1/sr, unit
    coefficients); the gap, the other yarn type's columns and pairs with wi_z or wo_z <= 0 give 0."""
    height, width = cell_seg.shape
    for p in range(u.shape[0]):
        for c in range(4):
            out[p, c] = 0.0
        d = which[p]
        ix, iy, iz, ox, oy, oz = wi[d, 0], wi[d, 1], wi[d, 2], wo[d, 0], wo[d, 1], wo[d, 2]
        if iz <= 0.0 or oz <= 0.0:
            continue
        big_u, big_v = u[p] * width, v[p] * height  # cells
        seg = cell_seg[height - 1 - int(math.floor(big_v)) % height, int(math.floor(big_u)) % width]
        du = big_u - seg_u[seg]
        du -= width * math.floor(du / width + 0.5)  # the nearest periodic image
        dv = big_v - seg_v[seg]
        dv -= height * math.floor(dv / height + 0.5)
        kind = 1 if seg_weft[seg] else 0
        x, y = (-dv, du) if kind else (du, dv)
        if abs(x) >= yarn[kind, YARN_HALF]:
            continue  # the gap
        if kind:  # the weft's yarn frame: (x, y, z) -> (-y, x, z) (clothlab.frames.to_yarn_frame)
            ix, iy, ox, oy = -iy, ix, -oy, ox
        hx, hy, hz, inv_i, inv_o = pair_terms(ix, iy, iz, ox, oy, oz, area_i[d], area_o[d])
        nx, ny, nz, tx, ty, tz = ply_frame_at(2.0 * yarn[kind, YARN_UMAX] * y / yarn[kind, YARN_L],
                                              math.pi * x / yarn[kind, YARN_W], yarn[kind, YARN_COS_PSI],
                                              yarn[kind, YARN_SIN_PSI], yarn[kind, YARN_BETA])  # eq. 11
        s, f = shade(nx, ny, nz, tx, ty, tz, ix, iy, iz, ox, oy, oz, hx, hy, hz, inv_i, inv_o,
                     yarn[kind, YARN_ALPHA], blend)
        out[p, kind] = f
        out[p, 2 + kind] = s


@njit(cache=True)
def direction_runs(w, run):
    """Runs of equal consecutive rows of ``w`` (N, 3): ``run[i]`` = the run of row i (0, 1, ...); returns the
    number of runs."""
    count = 0
    for i in range(w.shape[0]):
        if i > 0 and (w[i, 0] != w[i - 1, 0] or w[i, 1] != w[i - 1, 1] or w[i, 2] != w[i - 1, 2]):
            count += 1
        run[i] = count
    return count + 1 if w.shape[0] else 0


@njit(cache=True)
def yarn_area(w, umax, beta, half, nodes):
    """mean over u in [-umax, umax] (midpoint, ``nodes``) and v in [-half, half] (exact) of
    max(0, w_z + beta (w_x tan v / cos u + w_y tan u)) for yarn-frame directions w (N, 3), umax and beta
    (N,): (N,) (:mod:`clothlab.models.surface.geometry`, the ply's projected area)."""
    n = w.shape[0]
    out = np.zeros(n)
    log_cos_half = math.log(math.cos(half))
    tan_half = math.tan(half)
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
            r = -c / d  # c + d tan v > 0 for v > lo = atan(r), clipped to [-half, half]
            if r <= -tan_half:  # lit across the whole ply
                total += 2.0 * half * c
            elif r < tan_half:  # log cos(atan r) = -log(1 + r^2) / 2
                total += max(c * (half - math.atan(r)) - d * (log_cos_half + 0.5 * math.log1p(r * r)), 0.0)
        out[k] = total / (nodes * 2.0 * half)
    return out
