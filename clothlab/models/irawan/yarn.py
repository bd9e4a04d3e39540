"""The specular integral of one yarn segment type (Irawan & Marschner 2012, eqs. 1-10, Algorithms 1-2).

Both functions return the geometric part  I(wi, wo) = integral G A  of eq. 10; the phase function f_c
(eq. 7) depends on wi.wo only, so it factors out of the integral and is applied by the caller.
Directions are (N, 3) unit vectors in the *yarn* frame (z normal, y along the yarn), both with z > 0.
Angles in radians; w and l in any common length unit (only w / l matters after normalisation).

Staple yarns (psi != 0) integrate over u (eq. 1, Algorithm 1).  With h the unit half vector and
B = h_y sin u + h_z cos u, eq. 3 gives v = atan2(-B, h_x) + arccos(D), D = (h_y cos u - h_z sin u) cot psi
/ sqrt(h_x^2 + B^2); only the +arccos root has n.h >= 0 (sec. 6.3), and it is evaluated without
trigonometric calls via cos v = (h_x D + B sqrt(1-D^2)) / rho, sin v = (h_x sqrt(1-D^2) - B D) / rho.
Since c_i + c_r = |wi + wo| (n.h), the product of eq. 5 and Seeliger's law (eq. 8) is the bounded

    G_v A = a (R(u) + a cos v) c_i c_r / (|sin psi| (c_i + c_r)^2),

finite where n.h -> 0 although eq. 5 alone is not.  Zero unless |D| <= 1 and |v| < pi/2 (Algorithm 1).

Filament yarns (psi = 0) integrate over v (eq. 2, Algorithm 2).  Eq. 4 gives u = atan(h_y / h_z), the root in
(-pi/2, pi/2); |(t x h)_x| = sqrt(h_y^2 + h_z^2), so with eqs. 6, 8, 9

    G_u A_s = a (R(u) + a cos v) c_i c_r / ((c_i + c_r) |wi + wo| sqrt(h_y^2 + h_z^2)) (1 - s(...)).

The staple integrand's specular support is closed-form: |D| <= 1 <=> |cos(u + gamma)| <= |sin psi| / rho
with rho = sqrt(h_y^2 + h_z^2), gamma = atan2(h_z, h_y); the visibility cut |v| = pi/2 happens where
cos(u -/+ psi + gamma) = 0.  The ``support`` rule splits the integral at these points (numerics.md).
"""

from __future__ import annotations

import numpy as np

from clothlab.models.irawan.quadrature import (
    ADAPTIVE_MAX_NODES,
    ADAPTIVE_RTOL,
    compact_breaks,
    interval_rule,
    piecewise_rule,
    unit_rule,
)


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


def _filament_breaks(wi, wo, h):
    """Breakpoints (N, 4) over [-pi/2, pi/2]: where c_i or c_r of eq. 8 cross zero."""
    hy, hz = h[:, 1], h[:, 2]
    u = np.arctan(hy / np.where(hz > 0.0, hz, 1.0))
    cols = []
    for d in (wi, wo):
        c = d[:, 1] * np.sin(u) + d[:, 2] * np.cos(u)
        v = np.arctan2(-c, d[:, 0])
        v = np.where(v > 0.5 * np.pi, v - np.pi, v)
        v = np.where(v <= -0.5 * np.pi, v + np.pi, v)
        cols.append(v)
    return compact_breaks(-0.5 * np.pi, 0.5 * np.pi, np.stack(cols, axis=1))


def _integrate(wi, wo, rule, n, staple, psi, umax, kappa, w, l, delta):
    from clothlab.models.irawan import kernels

    def staple_sum(rows, nodes, weights):
        return kernels.staple_quadrature(wi[rows], wo[rows], nodes, weights, psi, umax, kappa, w, l)

    def filament_sum(rows, nodes, weights, on_arc=False):
        return kernels.filament_quadrature(wi[rows], wo[rows], nodes, weights, umax, kappa, w, l, delta, on_arc)

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


def staple_path(psi, umax, rule, n, psi_threshold) -> bool:
    """Whether |psi| is large enough for the staple integral (eq. 1) with this rule.

    The staple support in u is |cos(u + gamma)| <= |sin psi| / rho, about 2 |sin psi| / rho wide near
    psi = 0.  The support-aware rules resolve any width, so they switch to the filament integral (eq. 2, its
    psi -> 0 limit) only below ``psi_threshold``.  Fixed-node rules (trapezoid, gauss) cannot: with node spacing
    d = 2 umax / (n - 1) a narrower support falls between nodes or onto one with full weight (measured: the
    trapezoid-11 staple sum just above 0.057 deg was 20x the filament value).  They switch below
    max(psi_threshold, d / 2) instead, trading that artefact for the O(psi) staple-filament difference.
    """
    threshold = psi_threshold
    if rule in ("trapezoid", "gauss"):
        threshold = max(threshold, umax / max(n - 1, 1))
    return abs(psi) >= threshold


def yarn_integral(wi, wo, *, psi, umax, kappa, w, l, delta=0.0, rule="trapezoid", n=11, psi_threshold=1e-3):
    """I(wi, wo) = integral of G A (eq. 10) for one segment type; (N,) for (N, 3) yarn-frame directions.

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
