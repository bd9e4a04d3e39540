"""The IM yarn-integral kernels before the equation-by-equation rewrite, frozen for one regression test.

A frozen copy of ``clothlab.models.irawan.kernels`` (the quadrature kernels) and of the yarn integral of
``clothlab.models.irawan.yarn`` as they were before the kernels were split into helpers named for the
equations of Irawan & Marschner 2012 (eqs. 3-9).  tests/test_irawan_kernels.py checks that the current
kernels give the same values (the rewrite's speed ratio is reported in docs/notes).  Not part of the package.
"""

from __future__ import annotations

import math

import numpy as np

from clothlab.models.irawan.quadrature import (
    ADAPTIVE_MAX_NODES,
    ADAPTIVE_RTOL,
    compact_breaks,
    interval_rule,
    piecewise_rule,
    unit_rule,
)
from clothlab.models.irawan.yarn import staple_path
from clothlab.models.jit import njit


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
    """G_v A at one node u given sin u, cos u and R(u) (eqs. 3, 5, 8; bounded form)."""
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


def half_vectors(wi: np.ndarray, wo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit half vectors (N, 3) and |wi + wo| (N,); a degenerate pair (wo = -wi) gets length 0."""
    s = wi + wo
    length = np.sqrt(np.einsum("nk,nk->n", s, s))
    h = s / np.where(length > 0.0, length, 1.0)[:, None]
    return h, length


def _staple_breaks(h, psi, umax):
    """Breakpoints (N, P+1) of the staple integrand over [-umax, umax]: support ends and |v| = pi/2."""
    hy, hz = h[:, 1], h[:, 2]
    rho = np.sqrt(hy * hy + hz * hz)
    gamma = np.arctan2(hz, hy)
    c0 = np.arccos(np.minimum(abs(np.sin(psi)) / np.where(rho > 0, rho, 1.0), 1.0))
    k = np.pi * np.arange(-2, 3)
    base = np.stack([-gamma + c0, -gamma - c0, psi - gamma + 0.5 * np.pi, -psi - gamma + 0.5 * np.pi], axis=1)
    candidates = (base[:, :, None] + k).reshape(len(h), -1)
    return compact_breaks(-umax, umax, candidates)


def _integrate(wi, wo, rule, n, staple, psi, umax, kappa, w, l, delta):
    def staple_sum(rows, nodes, weights):
        return staple_quadrature(wi[rows], wo[rows], nodes, weights, psi, umax, kappa, w, l)

    def filament_sum(rows, nodes, weights, on_arc=False):
        return filament_quadrature(wi[rows], wo[rows], nodes, weights, umax, kappa, w, l, delta, on_arc)

    every = slice(None)
    if rule in ("trapezoid", "gauss"):
        lo, hi = (-umax, umax) if staple else (-0.5 * np.pi, 0.5 * np.pi)
        nodes, weights = interval_rule(rule, n, lo, hi)
        return (staple_sum if staple else filament_sum)(every, nodes[None, :], weights[None, :])
    if rule not in ("support", "adaptive"):
        raise ValueError(f"unknown quadrature rule {rule!r}")
    if staple:
        breaks = _staple_breaks(half_vectors(wi, wo)[0], psi, umax)

        def evaluate(rows, m):
            return staple_sum(rows, *piecewise_rule(breaks[rows], m))
    else:
        def evaluate(rows, m):  # Gauss-Legendre on the arc where both cosines of eq. 8 are positive
            t, wt = unit_rule("gauss", m)
            return filament_sum(rows, t[None, :], wt[None, :], on_arc=True)

    value = evaluate(every, n)
    if rule == "support":
        return value
    todo = np.arange(len(wi))
    while n < ADAPTIVE_MAX_NODES and todo.size:
        n *= 2
        new = evaluate(todo, n)
        changed = np.abs(new - value[todo]) > ADAPTIVE_RTOL * np.abs(new)
        value[todo] = new
        todo = todo[changed]
    return value


def yarn_integral(wi, wo, *, psi, umax, kappa, w, l, delta=0.0, rule="trapezoid", n=11, psi_threshold=1e-3):
    """The former I(wi, wo) = integral of G A (eq. 10) for one segment type; (N,) for (N, 3) yarn-frame directions.

    Staple path when |psi| >= psi_threshold (radians), filament path otherwise (sec. 6.2); see
    :func:`staple_path`.
    """
    wi = np.ascontiguousarray(wi, dtype=np.float64)
    wo = np.ascontiguousarray(wo, dtype=np.float64)
    out = np.zeros(len(wi))
    front = np.flatnonzero((wi[:, 2] > 0.0) & (wo[:, 2] > 0.0))
    if front.size:
        staple = staple_path(psi, umax, rule, n, psi_threshold)
        out[front] = _integrate(wi[front], wo[front], rule, n, staple, float(psi), float(umax), float(kappa),
                                float(w), float(l), float(delta))
    return out
