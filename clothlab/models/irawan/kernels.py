"""Compiled (numba) kernels of the yarn integrals: one pass over directions x nodes, no temporaries.

The formulas are those of :mod:`clothlab.models.irawan.yarn` (see its docstring for the equations); this
module holds their only implementation.  Imported lazily (numba costs ~0.5 s to import) by
:func:`clothlab.models.irawan.yarn.yarn_integral`.  Compiled code is cached on disk (``cache=True``).
Serial on purpose: numba's ``parallel=True`` thread pool made a 1,575-direction evaluation 10-40x slower
on a loaded 2-core machine (measured 0.7 ms serial vs 16-32 ms parallel); run fits in separate processes.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def spine_radius_scalar(u, umax, kappa, w, l):
    """R(u) of :func:`clothlab.models.irawan.spine.spine_radius` for scalars (same formula)."""
    r_hat = 1.0 + kappa * (1.0 + 1.0 / math.tan(umax))
    q = r_hat * abs(r_hat)
    cot = 1.0 / math.tan(umax)
    half = max(0.5 * l - 0.5 * w * math.sin(umax), 0.0)
    scale = half * math.sqrt(max(cot * cot + q, 0.0))
    u = min(max(u, -umax), umax)
    c = math.cos(u)
    s = math.sin(u)
    return scale / (c * c + q * s * s) ** 1.5


@njit(cache=True, inline="always")
def staple_value(wix, wiy, wiz, wox, woy, woz, hx, hy, hz, su, cu, radius, cot_psi, abs_sin_psi, a):
    """G_v A at one node u given sin u, cos u and R(u) (eqs. 3, 5, 8; bounded form, yarn.py docstring)."""
    b = hy * su + hz * cu
    rho = math.sqrt(hx * hx + b * b)
    if rho <= 0.0:
        return 0.0
    d = (hy * cu - hz * su) * cot_psi / rho
    if abs(d) > 1.0:
        return 0.0
    root = math.sqrt(max(1.0 - d * d, 0.0))
    cos_v = (hx * d + b * root) / rho
    if cos_v <= 0.0:
        return 0.0
    sin_v = (hx * root - b * d) / rho
    ci = wix * sin_v + (wiy * su + wiz * cu) * cos_v
    cr = wox * sin_v + (woy * su + woz * cu) * cos_v
    if ci <= 0.0 or cr <= 0.0:
        return 0.0
    total = ci + cr
    return a * (radius + a * cos_v) * ci * cr / (abs_sin_psi * total * total)


@njit(cache=True)
def staple_quadrature(wi, wo, nodes, weights, psi, umax, kappa, w, l):
    """sum_k weights[n, k] G_v A(nodes[n, k]) for each direction pair n (rows of wi, wo: yarn frame).

    ``nodes`` / ``weights`` of shape (1, K) are shared by all directions: sin, cos and R are then computed
    once per node instead of once per (direction, node)."""
    n_dir = wi.shape[0]
    n_nodes = nodes.shape[1]
    shared = nodes.shape[0] == 1
    out = np.zeros(n_dir)
    cot_psi = math.cos(psi) / math.sin(psi)
    abs_sin_psi = abs(math.sin(psi))
    a = 0.5 * w
    su = np.empty(n_nodes)
    cu = np.empty(n_nodes)
    radius = np.empty(n_nodes)
    if shared:
        for k in range(n_nodes):
            su[k] = math.sin(nodes[0, k])
            cu[k] = math.cos(nodes[0, k])
            radius[k] = spine_radius_scalar(nodes[0, k], umax, kappa, w, l)
    for n in range(n_dir):
        wix, wiy, wiz = wi[n, 0], wi[n, 1], wi[n, 2]
        wox, woy, woz = wo[n, 0], wo[n, 1], wo[n, 2]
        sx, sy, sz = wix + wox, wiy + woy, wiz + woz
        length = math.sqrt(sx * sx + sy * sy + sz * sz)
        if wiz <= 0.0 or woz <= 0.0 or length <= 0.0:
            continue
        hx, hy, hz = sx / length, sy / length, sz / length
        row = 0 if shared else n
        acc = 0.0
        for k in range(n_nodes):
            wk = weights[row, k]
            if wk == 0.0:
                continue
            if shared:
                s, c, r = su[k], cu[k], radius[k]
            else:
                u = nodes[n, k]
                s, c, r = math.sin(u), math.cos(u), spine_radius_scalar(u, umax, kappa, w, l)
            acc += wk * staple_value(wix, wiy, wiz, wox, woy, woz, hx, hy, hz, s, c, r, cot_psi, abs_sin_psi, a)
        out[n] = acc
    return out


@njit(cache=True, inline="always")
def filament_setup(wix, wiy, wiz, wox, woy, woz, umax, delta):
    """Per-direction part of the filament integrand (eqs. 4, 6, 9): (ok, u, scale, p_i, p_o) with u the
    specular inclination of eq. 4, scale = smoothstep fade / (|wi + wo| |(t x h)_x|) and p = w_y sin u + w_z cos u
    (so that w.n = w_x sin v + p cos v)."""
    sx, sy, sz = wix + wox, wiy + woy, wiz + woz
    length = math.sqrt(sx * sx + sy * sy + sz * sz)
    if wiz <= 0.0 or woz <= 0.0 or length <= 0.0:
        return False, 0.0, 0.0, 0.0, 0.0
    hy, hz = sy / length, sz / length
    u = math.atan(hy / hz)
    if abs(u) >= umax:
        return False, u, 0.0, 0.0, 0.0
    fade = 1.0
    if delta > 0.0:
        x = min(max((abs(u) - (1.0 - delta) * umax) / (delta * umax), 0.0), 1.0)
        fade = 1.0 - x * x * (3.0 - 2.0 * x)
    rho_yz = math.sqrt(hy * hy + hz * hz)
    if fade <= 0.0 or rho_yz <= 0.0:
        return False, u, 0.0, 0.0, 0.0
    su = math.sin(u)
    cu = math.cos(u)
    return True, u, fade / (length * rho_yz), wiy * su + wiz * cu, woy * su + woz * cu


@njit(cache=True, inline="always")
def filament_node(wix, p_i, wox, p_o, sv, cv, a, radius):
    """a (R + a cos v) c_i c_r / (c_i + c_r) at one v (eq. 8 with eq. 6's volume element); 0 if a cosine <= 0."""
    ci = wix * sv + p_i * cv
    cr = wox * sv + p_o * cv
    if ci <= 0.0 or cr <= 0.0:
        return 0.0
    return a * (radius + a * cv) * ci * cr / (ci + cr)


@njit(cache=True, inline="always")
def positive_arc(x, p):
    """The interval of v in (-pi/2, pi/2) where x sin v + p cos v > 0, as (lo, hi) (empty if lo >= hi):
    dividing by cos v > 0, x tan v + p > 0."""
    if x == 0.0:
        return (-0.5 * math.pi, 0.5 * math.pi) if p > 0.0 else (0.0, 0.0)
    v0 = math.atan(-p / x)
    if x > 0.0:
        return v0, 0.5 * math.pi
    return -0.5 * math.pi, v0


@njit(cache=True)
def filament_quadrature(wi, wo, nodes, weights, umax, kappa, w, l, delta, on_arc):
    """sum_k weights[n, k] G_u A_s(nodes[n, k]) (eqs. 4, 6, 8, 9) for each direction pair n (yarn frame).

    ``nodes`` / ``weights`` of shape (1, K) are shared by all directions (sin v, cos v computed once).
    ``on_arc``: the nodes are unit nodes in [0, 1] mapped per direction onto the closed-form arc where both
    clamped cosines of eq. 8 are positive (the only place the integrand is non-zero, and analytic inside)."""
    n_dir = wi.shape[0]
    n_nodes = nodes.shape[1]
    shared = nodes.shape[0] == 1
    out = np.zeros(n_dir)
    a = 0.5 * w
    sv_shared = np.empty(n_nodes)
    cv_shared = np.empty(n_nodes)
    if shared and not on_arc:
        for k in range(n_nodes):
            sv_shared[k] = math.sin(nodes[0, k])
            cv_shared[k] = math.cos(nodes[0, k])
    for n in range(n_dir):
        wix, wox = wi[n, 0], wo[n, 0]
        ok, u, scale, p_i, p_o = filament_setup(wix, wi[n, 1], wi[n, 2], wox, wo[n, 1], wo[n, 2], umax, delta)
        if not ok:
            continue
        radius = spine_radius_scalar(u, umax, kappa, w, l)
        row = 0 if shared else n
        acc = 0.0
        if on_arc:
            lo_i, hi_i = positive_arc(wix, p_i)
            lo_o, hi_o = positive_arc(wox, p_o)
            lo, hi = max(lo_i, lo_o), min(hi_i, hi_o)
            span = hi - lo
            if span <= 0.0:
                continue
            for k in range(n_nodes):
                v = lo + span * nodes[row, k]
                acc += weights[row, k] * filament_node(wix, p_i, wox, p_o, math.sin(v), math.cos(v), a, radius)
            acc *= span
        else:
            for k in range(n_nodes):
                wk = weights[row, k]
                if wk == 0.0:
                    continue
                if shared:
                    sv, cv = sv_shared[k], cv_shared[k]
                else:
                    sv, cv = math.sin(nodes[n, k]), math.cos(nodes[n, k])
                acc += wk * filament_node(wix, p_i, wox, p_o, sv, cv, a, radius)
        out[n] = acc * scale
    return out


# ---------------------------------------------------------------------------------------------------------
# Pointwise kernels of the texture model (sec. 7.2, Algorithms 3-4): the integrand at one node per point
# *and* the position of the ideal specular point, which the texture needs for the band chi of eq. 12.


@njit(cache=True)
def staple_points(wi, wo, u, umax, psi, kappa, w, l):
    """G_v A at u[n] and the specular v(u) of eq. 3 (+ root) for each point n (Algorithm 3).

    wi, wo: (N, 3) or (1, 3) yarn-frame directions (one row: shared by all points); u, umax: (N,) radians.
    Returns (value, v): value 0 (and v 0) where |u| > umax, |D| > 1, |v| >= pi/2 or a cosine is <= 0.
    """
    n_pts = u.shape[0]
    value = np.zeros(n_pts)
    vpos = np.zeros(n_pts)
    shared = wi.shape[0] == 1
    cot_psi = math.cos(psi) / math.sin(psi)
    abs_sin_psi = abs(math.sin(psi))
    a = 0.5 * w
    for n in range(n_pts):
        row = 0 if shared else n
        wix, wiy, wiz = wi[row, 0], wi[row, 1], wi[row, 2]
        wox, woy, woz = wo[row, 0], wo[row, 1], wo[row, 2]
        sx, sy, sz = wix + wox, wiy + woy, wiz + woz
        length = math.sqrt(sx * sx + sy * sy + sz * sz)
        if wiz <= 0.0 or woz <= 0.0 or length <= 0.0 or abs(u[n]) > umax[n]:
            continue
        hx, hy, hz = sx / length, sy / length, sz / length
        su = math.sin(u[n])
        cu = math.cos(u[n])
        r = spine_radius_scalar(u[n], umax[n], kappa, w, l)
        g = staple_value(wix, wiy, wiz, wox, woy, woz, hx, hy, hz, su, cu, r, cot_psi, abs_sin_psi, a)
        if g <= 0.0:
            continue
        # the same root as staple_value: cos v, sin v of the +arccos(D) solution (yarn.py docstring)
        b = hy * su + hz * cu
        rho = math.sqrt(hx * hx + b * b)
        d = (hy * cu - hz * su) * cot_psi / rho
        root = math.sqrt(max(1.0 - d * d, 0.0))
        value[n] = g
        vpos[n] = math.atan2((hx * root - b * d) / rho, (hx * d + b * root) / rho)
    return value, vpos


@njit(cache=True)
def filament_points(wi, wo, v, umax, kappa, w, l, delta):
    """G_u A_s at v[n] and the specular u of eq. 4 for each point n (Algorithm 4).

    wi, wo: (N, 3) or (1, 3) yarn-frame directions (one row: shared); v, umax: (N,) radians.
    Returns (value, u): value 0 where |v| > pi/2, |u| >= umax or a cosine is <= 0 (u is returned anyway).
    Same integrand as :func:`filament_quadrature` (eqs. 4, 6, 8, 9, bounded form).
    """
    n_pts = v.shape[0]
    value = np.zeros(n_pts)
    upos = np.zeros(n_pts)
    shared = wi.shape[0] == 1
    a = 0.5 * w
    for n in range(n_pts):
        row = 0 if shared else n
        wix, wox = wi[row, 0], wo[row, 0]
        ok, uu, scale, p_i, p_o = filament_setup(wix, wi[row, 1], wi[row, 2], wox, wo[row, 1], wo[row, 2],
                                                 umax[n], delta)
        upos[n] = uu
        if not ok or abs(v[n]) > 0.5 * math.pi:
            continue
        radius = spine_radius_scalar(uu, umax[n], kappa, w, l)
        value[n] = filament_node(wix, p_i, wox, p_o, math.sin(v[n]), math.cos(v[n]), a, radius) * scale
    return value, upos
